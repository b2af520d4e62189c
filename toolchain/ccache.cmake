# The compiler cache, for every tree (CI's four and a developer's; docs/ci.md).
# One cache per machine, outside any clone, so that CI's fresh clone in another
# folder hits what the working tree just built:
# - CCACHE_BASEDIR is the clone's root: ccache rewrites the absolute paths under
#   it (sources, -I, the build tree, which lies inside the clone) to relative ones
#   before hashing, so two clones hash alike.
# - -ffile-prefix-map: the clone's paths leave __FILE__ and the debug information
#   (relative paths, as the packages have had), so ccache need not hash the
#   working directory of a -g compile either.
# - sloppiness: the tests' precompiled header (GoogleTest, Eigen) is hashed by
#   its contents, not its time stamps; clang's PCH carries no time stamp. In the
#   clang (sanitizer) trees its header lives outside the clone, beside the cache
#   (tests/CMakeLists.txt), so that it and the tests that use it hit in another
#   clone too (docs/ci.md).
# - inode_cache: ccache checks a manifest's hit by hashing every file the compile
#   included, the 150-210 MB .gch too, once per test: about 1 s of CPU a hit
#   (108 s for the arm64 tree's 95 tests). With it, a file is hashed once per
#   device, inode, size and time stamps and then looked up (ccache 4.10 turns it
#   on by default; Debian 12 has 4.7): the same 95 hits took 3.3 s.
# The compiler (its mtime and size: compiler_check's default), every flag and
# the sanitizer options stay in the hash as ccache does by default, so the
# sanitizer and cross trees never share an object with the others.
# FOVEA_CCACHE=OFF builds without it; FOVEA_CCACHE_DIR (or $FOVEA_CCACHE_DIR at
# configure time) moves the cache; the default is /var/cache/fovea/ccache where
# it can be written (root, as CI runs), else ccache's own (~/.cache/ccache).
option(FOVEA_CCACHE "Compile through ccache when it is installed (docs/ci.md)" ON)
set(_fovea_ccache_default_dir "$ENV{FOVEA_CCACHE_DIR}")
if(NOT _fovea_ccache_default_dir)
  execute_process(COMMAND sh -c "mkdir -p /var/cache/fovea/ccache && test -w /var/cache/fovea/ccache"
                  RESULT_VARIABLE _fovea_ccache_dir_status OUTPUT_QUIET ERROR_QUIET)
  if(_fovea_ccache_dir_status EQUAL 0)
    set(_fovea_ccache_default_dir /var/cache/fovea/ccache)
  endif()
endif()
set(FOVEA_CCACHE_DIR "${_fovea_ccache_default_dir}" CACHE PATH "ccache's directory (empty: ccache's default)")
if(FOVEA_CCACHE)
  find_program(FOVEA_CCACHE_PROGRAM ccache)
endif()
if(FOVEA_CCACHE AND FOVEA_CCACHE_PROGRAM)
  set(_fovea_ccache_env
    CCACHE_BASEDIR=${PROJECT_SOURCE_DIR}
    CCACHE_SLOPPINESS=pch_defines,time_macros,include_file_mtime,include_file_ctime
    CCACHE_NOHASHDIR=1
    CCACHE_INODECACHE=1
    CCACHE_MAXSIZE=12G)
  if(FOVEA_CCACHE_DIR)
    list(APPEND _fovea_ccache_env CCACHE_DIR=${FOVEA_CCACHE_DIR})
  endif()
  # env(1) sets ccache's configuration per compile without touching the user's
  # ccache.conf; CCACHE_STATSLOG (toolchain/ci, one file per stage) passes through.
  set(CMAKE_CXX_COMPILER_LAUNCHER /usr/bin/env ${_fovea_ccache_env} ${FOVEA_CCACHE_PROGRAM})
  set(CMAKE_C_COMPILER_LAUNCHER ${CMAKE_CXX_COMPILER_LAUNCHER})
  add_compile_options(-ffile-prefix-map=${PROJECT_SOURCE_DIR}=.)
  if(CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    # clang writes the header's mtime into the PCH, which ccache cannot share.
    add_compile_options("SHELL:-Xclang -fno-pch-timestamp")
  endif()
  message(STATUS "fovea: compiling through ccache (${FOVEA_CCACHE_PROGRAM}; cache ${FOVEA_CCACHE_DIR})")
elseif(FOVEA_CCACHE)
  message(STATUS "fovea: ccache not found: compiling without a cache (toolchain/setup-host installs it)")
endif()

# fovea_cache_shared_file(SUBDIR PREFIX SUFFIX TEXT OUT_VAR): a generated file
# that compiles refer to by its path (the clang trees' test header, whose path
# the PCH records; UBSan's ignore list), written once as SUBDIR/PREFIX-KEYSUFFIX,
# KEY a hash of TEXT, beside the compiler cache, outside every clone: ccache hashes
# such a path as written, so a path inside the clone missed in every other
# clone, and a path that did not change with the text would keep stale objects.
# Without the cache, in the build tree. OUT_VAR: the file's path.
function(fovea_cache_shared_file subdir prefix suffix text out_var)
  string(SHA256 key "${text}")
  string(SUBSTRING "${key}" 0 16 key)
  set(dir "${PROJECT_BINARY_DIR}/${subdir}")
  if(FOVEA_CCACHE_DIR AND CMAKE_CXX_COMPILER_LAUNCHER)
    get_filename_component(shared_dir "${FOVEA_CCACHE_DIR}/../${subdir}" ABSOLUTE)
    execute_process(COMMAND sh -c "mkdir -p '${shared_dir}' && test -w '${shared_dir}'"
                    RESULT_VARIABLE dir_status OUTPUT_QUIET ERROR_QUIET)
    if(dir_status EQUAL 0)
      set(dir "${shared_dir}")
    endif()
  endif()
  set(path "${dir}/${prefix}-${key}${suffix}")
  if(NOT EXISTS "${path}")
    # Written aside and renamed: another clone's configure may write it too.
    file(WRITE "${path}.${key}.tmp" "${text}")
    file(RENAME "${path}.${key}.tmp" "${path}")
  endif()
  # Removed from outside the tree (the cache's directory emptied): written again.
  set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS "${path}")
  set(${out_var} "${path}" PARENT_SCOPE)
endfunction()

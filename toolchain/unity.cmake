# Unity batches that another clone's compiler cache can answer directly.
#
# CMake's own unity files (UNITY_BUILD) name each source by its absolute path
# (#include "/work/main/core/clock.cpp"). ccache's direct mode hashes a source's
# bytes, which CCACHE_BASEDIR cannot rewrite, so every batch missed it in a
# clone in another folder and ran the preprocessor for a hit in preprocessed
# mode: 40 batches a tree, whose compiles took 15, 17, 65 and 242 s of ninja's
# job time in the amd64, arm64, ASan and TSan trees of a warm CI run (m39; the
# clang trees' preprocessor ran niced beside three test stages; docs/ci.md). fovea_relocatable_unity() writes the same batches itself, each
# source named relative to its batch file, which lies in the build tree: a build
# tree inside its clone (build-amd64/, as every script makes them) then writes
# the same bytes in every clone.
#
# The batches are CMake's: a target's sources in their order, eight to a file
# (UNITY_BUILD_BATCH_SIZE), C++ only, leaving out those CMake leaves out (a
# source with SKIP_UNITY_BUILD_INCLUSION or options, definitions or include
# directories of its own). Unlike CMake's, a source a custom command generates
# (the viewer's assets, the Foxglove schemas) compiles alone: it stays in the
# target's sources, which keeps its command ordered before the compile. Every
# target the given directories (and theirs) made with UNITY_BUILD on gets the
# batches, and UNITY_BUILD is then turned off for it.

include(${CMAKE_CURRENT_LIST_DIR}/targets.cmake)

# True when CMake's unity build would put `source` (absolute) of `target` in a batch.
function(_fovea_unity_batchable target source out)
  set(${out} FALSE PARENT_SCOPE)
  if(NOT source MATCHES "\\.(cpp|cc|cxx)$")
    return()
  endif()
  foreach(property SKIP_UNITY_BUILD_INCLUSION GENERATED HEADER_FILE_ONLY COMPILE_OPTIONS COMPILE_DEFINITIONS
                   COMPILE_FLAGS INCLUDE_DIRECTORIES)
    get_property(value SOURCE "${source}" TARGET_DIRECTORY ${target} PROPERTY ${property})
    if(value)
      return()
    endif()
  endforeach()
  set(${out} TRUE PARENT_SCOPE)
endfunction()

function(_fovea_unity_target target)
  get_target_property(source_dir ${target} SOURCE_DIR)
  get_target_property(binary_dir ${target} BINARY_DIR)
  get_target_property(sources ${target} SOURCES)
  get_target_property(batch_size ${target} UNITY_BUILD_BATCH_SIZE)
  if(NOT batch_size)
    set(batch_size 8)
  endif()
  set(batch_dir "${binary_dir}/CMakeFiles/${target}.dir/FoveaUnity")
  set(kept "")
  set(batch "")
  set(batch_count 0)
  set(index 0)
  foreach(source IN LISTS sources)
    if(source MATCHES "^\\$<")  # a generator expression: left to CMake
      list(APPEND kept "${source}")
      continue()
    endif()
    get_filename_component(absolute "${source}" ABSOLUTE BASE_DIR "${source_dir}")
    _fovea_unity_batchable(${target} "${absolute}" batchable)
    if(NOT batchable)
      list(APPEND kept "${absolute}")
      continue()
    endif()
    file(RELATIVE_PATH relative "${batch_dir}" "${absolute}")
    string(APPEND batch "#include \"${relative}\"\n")
    math(EXPR batch_count "${batch_count} + 1")
    if(batch_count EQUAL batch_size)
      _fovea_unity_write("${batch_dir}" ${index} "${batch}" kept)
      math(EXPR index "${index} + 1")
      set(batch "")
      set(batch_count 0)
    endif()
  endforeach()
  if(batch_count GREATER 0)
    _fovea_unity_write("${batch_dir}" ${index} "${batch}" kept)
  endif()
  set_property(TARGET ${target} PROPERTY SOURCES "${kept}")
  set_property(TARGET ${target} PROPERTY UNITY_BUILD OFF)
endfunction()

# Writes batch `index` (only when its bytes change, so an unchanged batch is not
# rebuilt) and appends its path to the list named by `sources_var`.
macro(_fovea_unity_write batch_dir index content sources_var)
  file(CONFIGURE OUTPUT "${batch_dir}/unity_${index}.cxx"
       CONTENT "/* fovea's unity batch: toolchain/unity.cmake */\n${content}" @ONLY)
  list(APPEND ${sources_var} "${batch_dir}/unity_${index}.cxx")
endmacro()

function(fovea_relocatable_unity)
  foreach(dir IN LISTS ARGN)
    fovea_targets_under("${dir}" targets)
    foreach(target IN LISTS targets)
      get_target_property(type ${target} TYPE)
      get_target_property(unity ${target} UNITY_BUILD)
      if(unity AND NOT type STREQUAL "INTERFACE_LIBRARY")
        _fovea_unity_target(${target})
      endif()
    endforeach()
  endforeach()
endfunction()

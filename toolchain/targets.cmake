# The targets made in `dir` and every directory below it (CMake lists each
# directory's own), for the configure-time passes over fovea's targets
# (toolchain/library_graph.cmake, toolchain/unity.cmake).
include_guard(GLOBAL)
function(fovea_targets_under dir out)
  get_property(targets DIRECTORY "${dir}" PROPERTY BUILDSYSTEM_TARGETS)
  get_property(subdirs DIRECTORY "${dir}" PROPERTY SUBDIRECTORIES)
  foreach(sub IN LISTS subdirs)
    fovea_targets_under("${sub}" sub_targets)
    list(APPEND targets ${sub_targets})
  endforeach()
  set(${out} "${targets}" PARENT_SCOPE)
endfunction()

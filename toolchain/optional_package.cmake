# The one policy for fovea's optional dependencies (camera backends, status
# GPIO, USB, the journal, the PCL baseline): each has a cache variable
# FOVEA_WITH_<NAME> = AUTO (built when found), ON (required) or OFF.
#
#   fovea_optional(<NAME> "<what it gives>" [BACKEND] [UNAVAILABLE "<why not here>"])
#     declares FOVEA_WITH_<NAME> and sets FOVEA_WANT_<NAME> (look for it) and
#     FOVEA_NEED_<NAME> (fail the configure when it is missing). BACKEND: with
#     FOVEA_REQUIRE_BACKENDS=ON an AUTO backend is required (toolchain/ builds,
#     so CI and the packages, set it: a missing -dev package fails the configure
#     instead of quietly dropping a backend and its tests). UNAVAILABLE: this
#     build cannot use it whatever is installed; AUTO then leaves it out saying
#     why, ON still builds it.
#   fovea_optional_found(<NAME> <found> "<what is missing and how to install it>")
#     after the caller's look-up: a status line saying what is built, or a
#     fatal error when it was needed.
# Most are found through pkg-config: looked for once, here at the top level.
find_package(PkgConfig QUIET)
option(FOVEA_REQUIRE_BACKENDS "Every AUTO backend (camera, GPIO, USB, journal) is required: toolchain/ builds set it" OFF)

function(fovea_optional name what)
  cmake_parse_arguments(ARG "BACKEND" "UNAVAILABLE" "" ${ARGN})
  set(FOVEA_WITH_${name} AUTO CACHE STRING "${what}: AUTO, ON or OFF")
  set_property(CACHE FOVEA_WITH_${name} PROPERTY STRINGS AUTO ON OFF)
  set(mode "${FOVEA_WITH_${name}}")
  if(NOT mode MATCHES "^(AUTO|ON|OFF)$")
    message(FATAL_ERROR "fovea: FOVEA_WITH_${name} must be AUTO, ON or OFF (got '${mode}')")
  endif()
  set(want ON)
  set(need OFF)
  if(mode STREQUAL "OFF")
    set(want OFF)
    message(STATUS "fovea: ${what}: off (FOVEA_WITH_${name}=OFF)")
  elseif(mode STREQUAL "ON")
    set(need ON)
  elseif(ARG_UNAVAILABLE)
    set(want OFF)
    message(STATUS "fovea: ${what}: not built: ${ARG_UNAVAILABLE}")
  elseif(ARG_BACKEND AND FOVEA_REQUIRE_BACKENDS)
    set(need ON)
  endif()
  set(FOVEA_WANT_${name} ${want} PARENT_SCOPE)
  set(FOVEA_NEED_${name} ${need} PARENT_SCOPE)
  set(FOVEA_WHAT_${name} "${what}" PARENT_SCOPE)
endfunction()

function(fovea_optional_found name found missing)
  if(found)
    message(STATUS "fovea: ${FOVEA_WHAT_${name}}: built")
  elseif(FOVEA_NEED_${name})
    set(why "FOVEA_WITH_${name}=ON")
    if(NOT FOVEA_WITH_${name} STREQUAL "ON")
      set(why "FOVEA_REQUIRE_BACKENDS=ON (toolchain/ builds: CI and the packages)")
    endif()
    message(FATAL_ERROR "fovea: ${FOVEA_WHAT_${name}} is required (${why}) but missing: ${missing}")
  else()
    message(STATUS "fovea: ${FOVEA_WHAT_${name}}: not built, missing: ${missing}")
  endif()
endfunction()

# OpenNI2 RGB-D cameras (PrimeSense, Asus Xtion, Orbbec Astra) and OpenNI2's
# synthetic Dummy device: libopenni2-dev through pkg-config (Debian 12: 2.2.0.3).
# FOVEA_WITH_OPENNI2 AUTO/ON/OFF; exports FOVEA_HAVE_OPENNI2.
set(FOVEA_WITH_OPENNI2 AUTO CACHE STRING "OpenNI2 camera backend (needs libopenni2-dev): AUTO, ON or OFF")
set_property(CACHE FOVEA_WITH_OPENNI2 PROPERTY STRINGS AUTO ON OFF)
if(NOT FOVEA_WITH_OPENNI2 STREQUAL "OFF")
  find_package(PkgConfig QUIET)
  if(PkgConfig_FOUND)
    if(FOVEA_WITH_OPENNI2 STREQUAL "ON")
      pkg_check_modules(OPENNI2 REQUIRED IMPORTED_TARGET libopenni2)
    else()
      pkg_check_modules(OPENNI2 QUIET IMPORTED_TARGET libopenni2)
    endif()
  elseif(FOVEA_WITH_OPENNI2 STREQUAL "ON")
    message(FATAL_ERROR "fovea: FOVEA_WITH_OPENNI2=ON needs pkg-config (apt-get install pkg-config)")
  endif()
  if(OPENNI2_FOUND)
    # fovea::hal_openni2: OpenNI2 devices behind hal::Camera.
    add_library(fovea_hal_openni2 ${CMAKE_CURRENT_LIST_DIR}/openni2_camera.cpp)
    add_library(fovea::hal_openni2 ALIAS fovea_hal_openni2)
    target_link_libraries(fovea_hal_openni2 PUBLIC fovea::hal_types fovea_build_flags Eigen3::Eigen
                          PRIVATE PkgConfig::OPENNI2)
    target_compile_definitions(fovea_hal_openni2 PUBLIC FOVEA_HAVE_OPENNI2=1)
    list(APPEND fovea_hal_backends fovea::hal_openni2)
    message(STATUS "fovea: OpenNI2 camera backend (libopenni2 ${OPENNI2_VERSION})")
  else()
    message(STATUS "fovea: libopenni2 not found, OpenNI2 camera backend not built (apt-get install libopenni2-dev)")
  endif()
endif()

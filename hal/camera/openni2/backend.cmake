# OpenNI2 RGB-D cameras (PrimeSense, Asus Xtion, Orbbec Astra) and OpenNI2's
# synthetic Dummy device: libopenni2-dev through pkg-config (Debian 12: 2.2.0.3).
# FOVEA_WITH_OPENNI2 (toolchain/optional_package.cmake); exports FOVEA_HAVE_OPENNI2.
fovea_optional(OPENNI2 "OpenNI2 camera backend" BACKEND)
if(FOVEA_WANT_OPENNI2)
  if(PkgConfig_FOUND)
    pkg_check_modules(OPENNI2 QUIET IMPORTED_TARGET GLOBAL libopenni2)  # GLOBAL: tests/unit/hal's leak probe links it too
  endif()
  fovea_optional_found(OPENNI2 "${OPENNI2_FOUND}" "libopenni2 through pkg-config (apt-get install libopenni2-dev pkg-config)")
  if(OPENNI2_FOUND)
    # fovea::hal_openni2: OpenNI2 devices behind hal::Camera.
    add_library(fovea_hal_openni2
      ${CMAKE_CURRENT_LIST_DIR}/openni2_camera.cpp
      ${CMAKE_CURRENT_LIST_DIR}/openni2_options.cpp
      ${CMAKE_CURRENT_LIST_DIR}/video_modes.cpp
    )
    add_library(fovea::hal_openni2 ALIAS fovea_hal_openni2)
    target_link_libraries(fovea_hal_openni2 PUBLIC fovea::hal_types fovea_build_flags Eigen3::Eigen
                          PRIVATE PkgConfig::OPENNI2)
    target_compile_definitions(fovea_hal_openni2 PUBLIC FOVEA_HAVE_OPENNI2=1)
    list(APPEND fovea_hal_backends fovea::hal_openni2)
  endif()
endif()

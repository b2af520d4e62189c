# fovea::hal_v4l2: UVC depth cameras (and a colour node beside them) through
# V4L2. Needs the kernel headers (<linux/videodev2.h>) and libv4l2 (colour
# nodes are opened through it so it can convert formats fovea does not decode);
# libturbojpeg decodes MJPEG colour. FOVEA_WITH_V4L2
# (toolchain/optional_package.cmake); exports FOVEA_HAVE_V4L2.
fovea_optional(V4L2 "V4L2 camera backend" BACKEND)
if(FOVEA_WANT_V4L2)
  include(CheckIncludeFileCXX)
  set(_fovea_v4l2_missing "")
  check_include_file_cxx(linux/videodev2.h FOVEA_VIDEODEV2_H)
  if(NOT FOVEA_VIDEODEV2_H)
    list(APPEND _fovea_v4l2_missing "<linux/videodev2.h> (linux-libc-dev)")
  endif()
  if(PkgConfig_FOUND)
    pkg_check_modules(LIBV4L2 QUIET IMPORTED_TARGET libv4l2)
    pkg_check_modules(TURBOJPEG QUIET IMPORTED_TARGET libturbojpeg)
    if(NOT LIBV4L2_FOUND)
      list(APPEND _fovea_v4l2_missing "libv4l2 (libv4l-dev)")
    endif()
    if(NOT TURBOJPEG_FOUND)
      list(APPEND _fovea_v4l2_missing "libturbojpeg (libturbojpeg0-dev)")
    endif()
  else()
    list(APPEND _fovea_v4l2_missing "pkg-config")
  endif()
  set(_fovea_v4l2_found OFF)
  if(_fovea_v4l2_missing STREQUAL "")
    set(_fovea_v4l2_found ON)
  endif()
  list(JOIN _fovea_v4l2_missing ", " _fovea_v4l2_missing)
  fovea_optional_found(V4L2 "${_fovea_v4l2_found}" "${_fovea_v4l2_missing} (apt-get install libv4l-dev libturbojpeg0-dev pkg-config)")
  if(_fovea_v4l2_found)
    add_library(fovea_hal_v4l2
      ${CMAKE_CURRENT_LIST_DIR}/v4l2_options.cpp
      ${CMAKE_CURRENT_LIST_DIR}/pixel_formats.cpp
      ${CMAKE_CURRENT_LIST_DIR}/sysfs.cpp
      ${CMAKE_CURRENT_LIST_DIR}/v4l2_node.cpp
      ${CMAKE_CURRENT_LIST_DIR}/node_selection.cpp
      ${CMAKE_CURRENT_LIST_DIR}/v4l2_camera.cpp
    )
    add_library(fovea::hal_v4l2 ALIAS fovea_hal_v4l2)
    # fovea::hal_registration: the depth-to-colour registration kernel.
    # calib=FILE through fovea::hal_calibration; resetDevice() through
    # fovea::hal_usb (a USB port reset; it reports kUnavailable without libusb).
    target_link_libraries(fovea_hal_v4l2 PUBLIC fovea::hal_types fovea_build_flags Eigen3::Eigen
                          PRIVATE fovea::hal_registration fovea::hal_calibration fovea::hal_usb PkgConfig::LIBV4L2
                                  PkgConfig::TURBOJPEG)
    target_compile_definitions(fovea_hal_v4l2 PUBLIC FOVEA_HAVE_V4L2=1)
    list(APPEND fovea_hal_backends fovea::hal_v4l2)
  endif()
endif()

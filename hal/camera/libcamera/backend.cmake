# A libcamera colour camera paired with a depth camera of another backend:
# libcamera-dev through pkg-config (Debian 12: 0.0.3). FOVEA_WITH_LIBCAMERA
# AUTO/ON/OFF; exports FOVEA_HAVE_LIBCAMERA.
set(FOVEA_WITH_LIBCAMERA AUTO CACHE STRING "libcamera camera backend (needs libcamera-dev): AUTO, ON or OFF")
set_property(CACHE FOVEA_WITH_LIBCAMERA PROPERTY STRINGS AUTO ON OFF)
# Debian 12's libcamera links liblttng-ust, whose load-time constructor never
# returns under qemu-user 7.2 (seen with an empty arm64 program linked with it):
# every binary linking fovea::hal would hang when tests run in the emulator. So
# AUTO leaves libcamera out of cross builds that test through qemu-user; ON
# builds it anyway (board images, the arm64 VM with its real kernel).
set(fovea_libcamera_skip "")
if(FOVEA_WITH_LIBCAMERA STREQUAL "AUTO" AND CMAKE_CROSSCOMPILING AND CMAKE_CROSSCOMPILING_EMULATOR MATCHES "qemu")
  string(CONCAT fovea_libcamera_skip "this cross build runs its tests in ${CMAKE_CROSSCOMPILING_EMULATOR}, where "
         "Debian's libcamera hangs at load (liblttng-ust's constructor): -DFOVEA_WITH_LIBCAMERA=ON builds it anyway")
endif()
if(fovea_libcamera_skip)
  message(STATUS "fovea: libcamera camera backend not built: ${fovea_libcamera_skip}")
elseif(NOT FOVEA_WITH_LIBCAMERA STREQUAL "OFF")
  find_package(PkgConfig QUIET)
  if(PkgConfig_FOUND)
    if(FOVEA_WITH_LIBCAMERA STREQUAL "ON")
      pkg_check_modules(LIBCAMERA REQUIRED IMPORTED_TARGET libcamera)
    else()
      pkg_check_modules(LIBCAMERA QUIET IMPORTED_TARGET libcamera)
    endif()
  elseif(FOVEA_WITH_LIBCAMERA STREQUAL "ON")
    message(FATAL_ERROR "fovea: FOVEA_WITH_LIBCAMERA=ON needs pkg-config (apt-get install pkg-config)")
  endif()
  if(LIBCAMERA_FOUND)
    # fovea::hal_libcamera: libcamera colour + a depth camera, registered.
    add_library(fovea_hal_libcamera ${CMAKE_CURRENT_LIST_DIR}/libcamera_camera.cpp)
    add_library(fovea::hal_libcamera ALIAS fovea_hal_libcamera)
    # fovea_hal: createCamera() makes the depth camera (a cycle of static
    # libraries, which CMake links twice); fovea_registration: the kernel.
    target_link_libraries(fovea_hal_libcamera PUBLIC fovea::hal_types fovea_build_flags Eigen3::Eigen
                          PRIVATE PkgConfig::LIBCAMERA fovea_hal fovea_registration)
    target_compile_definitions(fovea_hal_libcamera PUBLIC FOVEA_HAVE_LIBCAMERA=1)
    list(APPEND fovea_hal_backends fovea::hal_libcamera)
    message(STATUS "fovea: libcamera camera backend (libcamera ${LIBCAMERA_VERSION})")
  else()
    message(STATUS "fovea: libcamera not found, libcamera camera backend not built (apt-get install libcamera-dev)")
  endif()
endif()

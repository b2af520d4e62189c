# A libcamera colour camera paired with a depth camera of another backend:
# libcamera-dev through pkg-config (Debian 12: 0.0.3). FOVEA_WITH_LIBCAMERA
# (toolchain/optional_package.cmake); exports FOVEA_HAVE_LIBCAMERA.
# Debian 12's libcamera links liblttng-ust, whose load-time constructor never
# returns under qemu-user 7.2 (seen with an empty arm64 program linked with it):
# every binary linking fovea::hal would hang when tests run in the emulator. So
# AUTO leaves libcamera out of cross builds that test through qemu-user; ON
# builds it anyway (board images, the arm64 VM with its real kernel).
set(fovea_libcamera_skip "")
if(CMAKE_CROSSCOMPILING AND CMAKE_CROSSCOMPILING_EMULATOR MATCHES "qemu")
  string(CONCAT fovea_libcamera_skip "this cross build runs its tests in ${CMAKE_CROSSCOMPILING_EMULATOR}, where "
         "Debian's libcamera hangs at load (liblttng-ust's constructor): -DFOVEA_WITH_LIBCAMERA=ON builds it anyway")
endif()
fovea_optional(LIBCAMERA "libcamera camera backend" BACKEND UNAVAILABLE "${fovea_libcamera_skip}")
if(FOVEA_WANT_LIBCAMERA)
  if(PkgConfig_FOUND)
    pkg_check_modules(LIBCAMERA QUIET IMPORTED_TARGET libcamera)
  endif()
  fovea_optional_found(LIBCAMERA "${LIBCAMERA_FOUND}" "libcamera through pkg-config (apt-get install libcamera-dev pkg-config)")
  if(LIBCAMERA_FOUND)
    # fovea::hal_libcamera: libcamera colour + a depth camera, registered.
    add_library(fovea_hal_libcamera ${CMAKE_CURRENT_LIST_DIR}/libcamera_camera.cpp)
    add_library(fovea::hal_libcamera ALIAS fovea_hal_libcamera)
    # The depth camera comes from hal::createCamera, handed in by the backend
    # table (no link to fovea::hal, which links this); fovea::hal_registration:
    # the kernel.
    target_link_libraries(fovea_hal_libcamera PUBLIC fovea::hal_types fovea_build_flags Eigen3::Eigen
                          PRIVATE PkgConfig::LIBCAMERA fovea::hal_registration)
    target_compile_definitions(fovea_hal_libcamera PUBLIC FOVEA_HAVE_LIBCAMERA=1)
    list(APPEND fovea_hal_backends fovea::hal_libcamera)
  endif()
endif()

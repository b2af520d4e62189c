# The USB side of USB cameras (hal/usb/): the table of known RGB-D camera ids
# and the udev rules made from it (pure, always built), and with libusb 1.0
# (pkg-config libusb-1.0, Debian 12: 1.0.26) enumeration, hot-plug and the port
# reset. FOVEA_WITH_LIBUSB (toolchain/optional_package.cmake); with libusb, fovea::hal_usb exports
# FOVEA_HAVE_LIBUSB, without it the same functions return kUnavailable saying
# why, so callers (the V4L2 and OpenNI2 backends, the service) need no #ifdef.

# fovea::hal_usb_ids: the id table and the udev rules, no libusb.
add_library(fovea_hal_usb_ids usb/usb_ids.cpp)
add_library(fovea::hal_usb_ids ALIAS fovea_hal_usb_ids)
target_link_libraries(fovea_hal_usb_ids PUBLIC fovea_build_flags)

set(LIBUSB_FOUND FALSE)
fovea_optional(LIBUSB "libusb USB camera enumeration, hot-plug and port reset" BACKEND)
if(FOVEA_WANT_LIBUSB)
  if(PkgConfig_FOUND)
    pkg_check_modules(LIBUSB QUIET IMPORTED_TARGET libusb-1.0)
  endif()
  fovea_optional_found(LIBUSB "${LIBUSB_FOUND}" "libusb-1.0 through pkg-config (apt-get install libusb-1.0-0-dev pkg-config)")
endif()

# fovea::hal_usb: enumeration, hot-plug monitor, port reset (stubs without libusb).
add_library(fovea_hal_usb usb/usb_common.cpp)
add_library(fovea::hal_usb ALIAS fovea_hal_usb)
target_link_libraries(fovea_hal_usb PUBLIC fovea::hal_usb_ids fovea::hal_types fovea_build_flags)
if(LIBUSB_FOUND)
  find_package(Threads REQUIRED)
  target_sources(fovea_hal_usb PRIVATE usb/usb_libusb.cpp usb/usb_monitor.cpp)
  target_link_libraries(fovea_hal_usb PRIVATE PkgConfig::LIBUSB Threads::Threads)
  target_compile_definitions(fovea_hal_usb PUBLIC FOVEA_HAVE_LIBUSB=1)
else()
  target_sources(fovea_hal_usb PRIVATE usb/usb_unavailable.cpp)
endif()
list(APPEND fovea_hal_backends fovea::hal_usb)

# The udev rules, generated at build time from the table (one source of truth)
# into ${build}/60-fovea-rgbd-cameras.rules and installed to lib/udev/rules.d.
add_executable(fovea_udev_rules usb/gen_udev_rules.cpp)
target_link_libraries(fovea_udev_rules PRIVATE fovea::hal_usb_ids fovea_build_flags)
if(NOT CMAKE_CROSSCOMPILING OR CMAKE_CROSSCOMPILING_EMULATOR)
  set(FOVEA_UDEV_RULES_FILE ${PROJECT_BINARY_DIR}/60-fovea-rgbd-cameras.rules CACHE INTERNAL "")
  add_custom_command(OUTPUT ${FOVEA_UDEV_RULES_FILE}
    COMMAND fovea_udev_rules ${FOVEA_UDEV_RULES_FILE}
    DEPENDS fovea_udev_rules
    COMMENT "udev rules for the known RGB-D cameras: ${FOVEA_UDEV_RULES_FILE}")
  add_custom_target(fovea_udev_rules_file ALL DEPENDS ${FOVEA_UDEV_RULES_FILE})
  # Debian 12 keeps rules in /lib/udev/rules.d: a package build sets FOVEA_UDEV_RULES_DIR.
  set(FOVEA_UDEV_RULES_DIR lib/udev/rules.d CACHE STRING "Where udev rules are installed (relative: under the prefix)")
  install(FILES ${FOVEA_UDEV_RULES_FILE} DESTINATION ${FOVEA_UDEV_RULES_DIR})
else()
  unset(FOVEA_UDEV_RULES_FILE CACHE)
  message(STATUS "fovea: cross-compiling without an emulator: the udev rules file is not generated (run fovea_udev_rules on the target)")
endif()

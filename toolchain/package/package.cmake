# The parts of an installation that are not programs (man pages, the Debian
# copyright file and changelog, the GPIO udev rule) and the Debian package itself,
# built by CPack's DEB generator from the same install() rules as `cmake --install`.
# toolchain/build-packages drives it; docs/boards.md ("Flash a board") says why CPack.
include(GNUInstallDirs)
set(_fovea_pkg_dir ${CMAKE_CURRENT_LIST_DIR})

# --- man pages: help2man runs each program's --help at build time ------------
# A cross build runs the target's binaries through CMAKE_CROSSCOMPILING_EMULATOR
# (qemu-aarch64), so the arm64 package gets the pages of its own binaries.
set(FOVEA_MAN_PAGES AUTO CACHE STRING "Man pages from --help with help2man: AUTO, ON or OFF")
set_property(CACHE FOVEA_MAN_PAGES PROPERTY STRINGS AUTO ON OFF)
if(NOT FOVEA_MAN_PAGES STREQUAL "OFF")
  find_program(FOVEA_HELP2MAN help2man)
  set(_fovea_man_ok TRUE)
  if(NOT FOVEA_HELP2MAN)
    set(_fovea_man_ok FALSE)
    set(_fovea_man_why "help2man not found (apt-get install help2man)")
  elseif(CMAKE_CROSSCOMPILING AND NOT CMAKE_CROSSCOMPILING_EMULATOR)
    set(_fovea_man_ok FALSE)
    set(_fovea_man_why "cross-compiling without an emulator cannot run --help")
  endif()
  if(NOT _fovea_man_ok AND FOVEA_MAN_PAGES STREQUAL "ON")
    message(FATAL_ERROR "fovea: FOVEA_MAN_PAGES=ON but ${_fovea_man_why}")
  elseif(NOT _fovea_man_ok)
    message(STATUS "fovea: no man pages: ${_fovea_man_why}")
  else()
    # page name | target | arguments before --help | one-line description
    set(_fovea_man_table
      "fovead|fovead||foveated point clouds for immersive telerobotics: the robot-side service"
      "fovead-serve|fovead|serve|run fovea as a service (capture, foveation, streaming threads)"
      "fovead-run|fovead|run|run the foveation pipeline on a camera and report, optionally streaming"
      "fovead-foveate|fovead|foveate|foveate a recorded PLY cloud for a given gaze"
      "fovead-keygen|fovead|keygen|write a pre-shared key file for the stream"
      "fovead-cameras|fovead|cameras|list the cameras this build can see"
      "fovead-print-config|fovead|print-config|print fovead's effective configuration as TOML"
      "fovea-operator|fovea-operator||the operator station without the headset: gaze out, foveated frames in"
      "fovea-error-report|fovea-error-report||speed against error of the foveation presets"
      "fovea-eval|fovea-eval||the paper's Table II over real sockets, with objective image quality")
    set(_fovea_man_dir ${PROJECT_BINARY_DIR}/man)
    string(JOIN " " _fovea_emulator ${CMAKE_CROSSCOMPILING_EMULATOR})
    set(_fovea_man_outputs "")
    foreach(_row IN LISTS _fovea_man_table)
      string(REPLACE "|" ";" _row "${_row}")
      list(GET _row 0 _page)
      list(GET _row 1 _target)
      list(GET _row 2 _args)
      list(GET _row 3 _what)
      # help2man runs "PROGRAM --help"; the page's name is the program's file name,
      # so each page gets a wrapper of that name (never installed).
      file(GENERATE OUTPUT ${_fovea_man_dir}/bin/${_page}
           CONTENT "#!/bin/sh\nexec ${_fovea_emulator} \"$<TARGET_FILE:${_target}>\" ${_args} \"$@\"\n"
           FILE_PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE GROUP_READ GROUP_EXECUTE WORLD_READ WORLD_EXECUTE)
      add_custom_command(OUTPUT ${_fovea_man_dir}/${_page}.1.gz
        COMMAND ${FOVEA_HELP2MAN} --no-info --no-discard-stderr --section=1 --version-string=${PROJECT_VERSION}
                --name=${_what} --output=${_fovea_man_dir}/${_page}.1 ${_fovea_man_dir}/bin/${_page}
        COMMAND gzip -9nf ${_fovea_man_dir}/${_page}.1
        DEPENDS ${_target}
        COMMENT "man page ${_page}(1) from ${_target} ${_args} --help"
        VERBATIM)
      list(APPEND _fovea_man_outputs ${_fovea_man_dir}/${_page}.1.gz)
    endforeach()
    add_custom_target(fovea_man_pages ALL DEPENDS ${_fovea_man_outputs})
    install(FILES ${_fovea_man_outputs} DESTINATION ${CMAKE_INSTALL_MANDIR}/man1)
  endif()
endif()

# --- AppStream metadata: the cameras the udev rules are for ------------------
if(FOVEA_UDEV_RULES_FILE)
  set(_fovea_metainfo ${PROJECT_BINARY_DIR}/package/fovea.metainfo.xml)
  add_custom_command(OUTPUT ${_fovea_metainfo}
    COMMAND ${CMAKE_COMMAND} -DRULES=${FOVEA_UDEV_RULES_FILE} -DOUT=${_fovea_metainfo} -P ${_fovea_pkg_dir}/metainfo.cmake
    DEPENDS ${FOVEA_UDEV_RULES_FILE} ${_fovea_pkg_dir}/metainfo.cmake
    COMMENT "AppStream metadata of the udev rules' cameras")
  add_custom_target(fovea_metainfo ALL DEPENDS ${_fovea_metainfo})
  # The rules file is another directory's custom output: order on its target.
  add_dependencies(fovea_metainfo fovea_udev_rules_file)
  install(FILES ${_fovea_metainfo} DESTINATION ${CMAKE_INSTALL_DATADIR}/metainfo)
endif()

# --- the GPIO chips to group gpio (the package creates the group) -------------
if(DEFINED FOVEA_UDEV_RULES_DIR)
  install(FILES ${_fovea_pkg_dir}/60-fovea-gpio.rules DESTINATION ${FOVEA_UDEV_RULES_DIR})
else()
  install(FILES ${_fovea_pkg_dir}/60-fovea-gpio.rules DESTINATION lib/udev/rules.d)
endif()

# --- the Debian package ---------------------------------------------------------
# FOVEA_PACKAGE_BOARD: a board-tuned package (toolchain/build-packages --board),
# versioned VERSION+BOARD so the file says which board it is for.
set(FOVEA_PACKAGE_BOARD "" CACHE STRING "Board a tuned package is built for (its version gets +BOARD)")
set(FOVEA_DEB_MAINTAINER "fovea maintainers <fovea-maintainers@users.noreply.github.com>" CACHE STRING
    "The Maintainer field of the Debian package")
set(FOVEA_DEB_VERSION ${PROJECT_VERSION})
if(FOVEA_PACKAGE_BOARD)
  string(REPLACE "-" "." _fovea_board_version "${FOVEA_PACKAGE_BOARD}")
  string(APPEND FOVEA_DEB_VERSION "+${_fovea_board_version}")
endif()
if(CMAKE_SYSTEM_PROCESSOR MATCHES "^(aarch64|arm64|ARM64)$")
  set(_fovea_deb_arch arm64)
elseif(CMAKE_SYSTEM_PROCESSOR MATCHES "^(x86_64|AMD64|amd64)$")
  set(_fovea_deb_arch amd64)
else()
  set(_fovea_deb_arch "")  # CPack asks dpkg
endif()

# /usr/share/doc/fovea: the copyright file (machine-readable) and the changelog
# (a native package: changelog.gz), as lintian expects.
string(TIMESTAMP _fovea_changelog_date "%a, %d %b %Y %H:%M:%S +0000" UTC)
configure_file(${_fovea_pkg_dir}/changelog.in ${PROJECT_BINARY_DIR}/package/changelog @ONLY)
add_custom_command(OUTPUT ${PROJECT_BINARY_DIR}/package/changelog.gz
  COMMAND gzip -9nc ${PROJECT_BINARY_DIR}/package/changelog > ${PROJECT_BINARY_DIR}/package/changelog.gz
  DEPENDS ${PROJECT_BINARY_DIR}/package/changelog)
add_custom_target(fovea_changelog ALL DEPENDS ${PROJECT_BINARY_DIR}/package/changelog.gz)
install(FILES ${_fovea_pkg_dir}/copyright ${PROJECT_BINARY_DIR}/package/changelog.gz
        DESTINATION ${CMAKE_INSTALL_DOCDIR})
install(FILES ${_fovea_pkg_dir}/lintian-overrides DESTINATION ${CMAKE_INSTALL_DATADIR}/lintian/overrides
        RENAME fovea)

# Maintainer scripts and the conffile list (the default configuration).
configure_file(${_fovea_pkg_dir}/conffiles.in ${PROJECT_BINARY_DIR}/package/conffiles @ONLY)

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME fovea)
set(CPACK_PACKAGE_VENDOR "the fovea authors")
set(CPACK_PACKAGE_VERSION ${FOVEA_DEB_VERSION})
set(CPACK_PACKAGING_INSTALL_PREFIX ${CMAKE_INSTALL_PREFIX})
set(CPACK_STRIP_FILES ON)
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "foveated RGB-D point clouds for immersive telerobotics")
# The long description: CPack writes it under the summary, indenting each line and
# turning an empty line into Debian's " .".
set(_fovea_tuned "")
if(FOVEA_PACKAGE_BOARD)
  set(_fovea_tuned "\n\nThis build is tuned for the board ${FOVEA_PACKAGE_BOARD}\n(-mcpu=${FOVEA_MCPU}): it runs on that core and newer ones only.")
endif()
set(CPACK_DEBIAN_PACKAGE_DESCRIPTION "fovea is the robot-side service of an immersive telerobotics link: it turns
each RGB-D camera frame into a point cloud, keeps full detail where the remote
operator looks and thins the rest out as the eye's acuity falls off, and
streams it to the operator over authenticated, encrypted UDP.

This package holds the service fovead (a systemd unit, installed but not
enabled), the operator station fovea-operator, the reports fovea-error-report
and fovea-eval, board profiles, a default configuration and udev rules for the
known RGB-D cameras and the GPIO chips.${_fovea_tuned}")
set(CPACK_DEBIAN_PACKAGE_VERSION ${FOVEA_DEB_VERSION})
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_MAINTAINER "${FOVEA_DEB_MAINTAINER}")
set(CPACK_DEBIAN_PACKAGE_SECTION net)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
if(_fovea_deb_arch)
  set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE ${_fovea_deb_arch})
endif()
# Dependencies: the libraries the binaries link, from dpkg-shlibdeps (a cross
# build needs the arm64 libraries installed: toolchain/setup-host --cross), and
# adduser for the maintainer scripts and procps for the unit's ExecReload (/bin/kill).
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_DEPENDS "adduser, procps")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
    ${_fovea_pkg_dir}/postinst ${_fovea_pkg_dir}/prerm ${_fovea_pkg_dir}/postrm ${PROJECT_BINARY_DIR}/package/conffiles)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
set(CPACK_DEBIAN_COMPRESSION_TYPE xz)
set(CPACK_OUTPUT_FILE_PREFIX ${PROJECT_BINARY_DIR}/package)
include(CPack)

# cmake -DRULES=60-fovea-rgbd-cameras.rules -DOUT=fovea.metainfo.xml -P metainfo.cmake
# The AppStream metadata announcing the USB cameras the udev rules give access to
# (Debian's lintian asks for it: appstream-metadata-missing-modalias-provide), made
# from the generated rules so the camera table (hal/usb/usb_ids.cpp) stays the one source.
file(STRINGS "${RULES}" _lines REGEX "^SUBSYSTEM==\"usb\"")
set(_provides "")
foreach(_line IN LISTS _lines)
  if(_line MATCHES "ATTR\\{idVendor\\}==\"([0-9a-fA-F]+)\".*ATTR\\{idProduct\\}==\"([0-9a-fA-F]+)\"")
    string(TOUPPER "${CMAKE_MATCH_1}" _vendor)
    string(TOUPPER "${CMAKE_MATCH_2}" _product)
    string(APPEND _provides "    <modalias>usb:v${_vendor}p${_product}d*</modalias>\n")
  endif()
endforeach()
if(_provides STREQUAL "")
  message(FATAL_ERROR "metainfo.cmake: no USB rules in ${RULES}")
endif()
file(WRITE "${OUT}" "<?xml version=\"1.0\" encoding=\"UTF-8\"?>
<!-- Generated from 60-fovea-rgbd-cameras.rules at build time: the RGB-D cameras fovea supports. -->
<component>
  <id>fovea</id>
  <metadata_license>FSFAP</metadata_license>
  <name>fovea</name>
  <summary>Foveated RGB-D point clouds for immersive telerobotics</summary>
  <provides>
${_provides}  </provides>
</component>
")

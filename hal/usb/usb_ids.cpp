#include "hal/usb/usb_ids.h"

#include <algorithm>
#include <cstdio>

namespace fovea::hal::usb {

namespace {

using B = UsbCameraBackend;

constexpr std::string_view kNeedsOrbbecOpenNI2 =
    "needs Orbbec's OpenNI2 driver (Debian's OpenNI2 knows PrimeSense ids only)";
constexpr std::string_view kOrbbecUvc = "UVC depth";

// Sorted by (vendor, product). Sources, checked when this table was written:
//  [usb.ids]  Debian 12's usb.ids 2025.07.26 (/var/lib/usbutils/usb.ids)
//  [rs-d400]  librealsense src/ds/d400/d400-private.h (pid constants, rs400_sku_names)
//  [rs-sr3]   librealsense src/sr300.h (SR300_PID, SR300v2_PID)
//  [ob-ros]   OrbbecSDK_ROS orbbec_camera/include/orbbec_camera/constants.h (*_PID)
//  [ob-udev]  Orbbec's 56-orbbec-usb.rules (SYMLINK names per product)
//  [ps1080]   the product table inside Debian's libPS1080.so.0 (0500 0600 0601 0609)
//  [fn]       libfreenect freenect_internal.h (PID_NUI_*, PID_K4W_*)
//  [fn2]      libfreenect2 libfreenect2.hpp (ProductId, ProductIdPreview)
//  [xlink]    Movidius XLink usb_boot.h: "0xf63b: once opened in VSC mode, VID/PID change"
constexpr KnownUsbCamera kCameras[] = {
    // Intel Movidius Myriad X: Luxonis OAK cameras (and the Neural Compute Stick 2).
    {0x03e7, 0x2485, "Luxonis OAK (Myriad X, not booted)", B::kNone, true,
     "needs Luxonis depthai; an Intel NCS2 has the same id"},                                    // [usb.ids]
    {0x03e7, 0xf63b, "Luxonis OAK (Myriad X, booted)", B::kNone, true, "needs Luxonis depthai"},  // [usb.ids] [xlink]
    // Microsoft Kinect.
    {0x045e, 0x02ae, "Microsoft Kinect (Xbox 360) camera", B::kNone, false,
     "needs libfreenect (Debian's OpenNI2 has no Kinect driver)"},                      // [usb.ids] [fn]
    {0x045e, 0x02b0, "Microsoft Kinect (Xbox 360) motor", B::kNone, false, "tilt motor and LED, not a camera"},  // [usb.ids] [fn]
    {0x045e, 0x02bf, "Microsoft Kinect for Windows camera", B::kNone, false, "needs libfreenect"},  // [usb.ids] [fn]
    {0x045e, 0x02c2, "Microsoft Kinect for Windows motor", B::kNone, false, "tilt motor, not a camera"},  // [usb.ids]
    {0x045e, 0x02c4, "Microsoft Kinect v2 (preview)", B::kNone, true, "needs libfreenect2"},  // [fn2]
    {0x045e, 0x02d8, "Microsoft Kinect v2", B::kNone, true, "needs libfreenect2"},            // [fn2]
    {0x045e, 0x097c, "Microsoft Azure Kinect depth camera", B::kNone, true, "needs the Azure Kinect SDK"},  // [usb.ids]
    {0x045e, 0x097d, "Microsoft Azure Kinect 4K camera", B::kNone, true,
     "colour only (UVC); its depth is the 097c device"},  // [usb.ids]
    // PrimeSense PS1080 devices (Debian's OpenNI2 PS1080 driver).
    {0x1d27, 0x0600, "PrimeSense / Asus Xtion (PS1080)", B::kOpenNI2, false, ""},  // [ps1080]
    {0x1d27, 0x0601, "Asus Xtion PRO LIVE", B::kOpenNI2, false, ""},               // [ps1080] [usb.ids: Xtion]
    {0x1d27, 0x0609, "PrimeSense Carmine 1.09", B::kOpenNI2, false, ""},           // [ps1080]
    // Stereolabs ZED: side-by-side stereo colour over UVC, depth computed by the SDK.
    {0x2b03, 0xf580, "Stereolabs ZED", B::kNone, true, "depth needs the ZED SDK (CUDA)"},       // [usb.ids]
    {0x2b03, 0xf582, "Stereolabs ZED", B::kNone, true, "depth needs the ZED SDK (CUDA)"},       // [usb.ids]
    {0x2b03, 0xf680, "Stereolabs ZED Mini", B::kNone, true, "depth needs the ZED SDK (CUDA)"},  // [usb.ids]
    {0x2b03, 0xf682, "Stereolabs ZED Mini", B::kNone, true, "depth needs the ZED SDK (CUDA)"},  // [usb.ids]
    {0x2b03, 0xf684, "Stereolabs ZED Mini", B::kNone, true, "depth needs the ZED SDK (CUDA)"},  // [usb.ids]
    // Orbbec.
    {0x2bc5, 0x0401, "Orbbec Astra", B::kOpenNI2, false, kNeedsOrbbecOpenNI2},       // [usb.ids] [ob-udev]
    {0x2bc5, 0x0402, "Orbbec Astra S", B::kOpenNI2, false, kNeedsOrbbecOpenNI2},     // [ob-udev]
    {0x2bc5, 0x0403, "Orbbec Astra Pro", B::kOpenNI2, false,
     "needs Orbbec's OpenNI2 driver; its colour is a separate UVC camera (v4l2)"},  // [usb.ids] [ob-udev]
    {0x2bc5, 0x0404, "Orbbec Astra Mini", B::kOpenNI2, false, kNeedsOrbbecOpenNI2},  // [ob-ros] [ob-udev]
    {0x2bc5, 0x0407, "Orbbec Astra Mini S", B::kOpenNI2, false, kNeedsOrbbecOpenNI2},  // [usb.ids] [ob-ros]
    {0x2bc5, 0x0501, "Orbbec Astra UVC colour camera", B::kV4l2, false, "colour only"},  // [ob-udev: astrauvc]
    {0x2bc5, 0x060d, "Orbbec Astra Pro Plus", B::kOpenNI2, false, kNeedsOrbbecOpenNI2},  // [ob-udev]
    {0x2bc5, 0x0635, "Orbbec Femto", B::kOpenNI2, true, kNeedsOrbbecOpenNI2},           // [ob-ros]
    {0x2bc5, 0x0636, "Orbbec Astra+", B::kOpenNI2, false, kNeedsOrbbecOpenNI2},         // [ob-ros]
    {0x2bc5, 0x0637, "Orbbec Astra+ S", B::kOpenNI2, false, kNeedsOrbbecOpenNI2},       // [ob-ros]
    {0x2bc5, 0x0669, "Orbbec Femto Mega", B::kV4l2, true, kOrbbecUvc},                  // [ob-ros]
    {0x2bc5, 0x066b, "Orbbec Femto Bolt", B::kV4l2, true, kOrbbecUvc},                  // [ob-ros]
    {0x2bc5, 0x0670, "Orbbec Gemini 2", B::kV4l2, true, kOrbbecUvc},                    // [ob-ros]
    {0x2bc5, 0x0800, "Orbbec Gemini 335", B::kV4l2, true, kOrbbecUvc},                  // [ob-ros]
    {0x2bc5, 0x0801, "Orbbec Gemini 330", B::kV4l2, true, kOrbbecUvc},                  // [ob-ros]
    {0x2bc5, 0x0803, "Orbbec Gemini 336", B::kV4l2, true, kOrbbecUvc},                  // [ob-ros]
    {0x2bc5, 0x0804, "Orbbec Gemini 335L", B::kV4l2, true, kOrbbecUvc},                 // [ob-ros]
    // Intel RealSense: UVC depth (Z16) through uvcvideo.
    {0x8086, 0x0aa5, "Intel RealSense SR300", B::kV4l2, true, ""},             // [usb.ids] [rs-sr3]
    {0x8086, 0x0ad2, "Intel RealSense D410", B::kV4l2, true, ""},              // [usb.ids] [rs-d400]
    {0x8086, 0x0ad3, "Intel RealSense D415", B::kV4l2, true, ""},              // [usb.ids] [rs-d400]
    {0x8086, 0x0ad4, "Intel RealSense D430", B::kV4l2, true, ""},              // [rs-d400]
    {0x8086, 0x0b07, "Intel RealSense D435", B::kV4l2, true, ""},              // [usb.ids] [rs-d400]
    {0x8086, 0x0b3a, "Intel RealSense D435i", B::kV4l2, true, ""},             // [rs-d400]
    {0x8086, 0x0b48, "Intel RealSense SR305", B::kV4l2, true, ""},             // [rs-sr3]
    {0x8086, 0x0b4b, "Intel RealSense D430i", B::kV4l2, true, ""},             // [rs-d400]
    {0x8086, 0x0b5b, "Intel RealSense D405", B::kV4l2, true, ""},              // [rs-d400]
    {0x8086, 0x0b5c, "Intel RealSense D455", B::kV4l2, true, ""},              // [rs-d400]
    {0x8086, 0x0b64, "Intel RealSense L515", B::kV4l2, true, ""},              // [usb.ids]
};

struct Vendor {
  uint16_t id;
  std::string_view name;
};
constexpr Vendor kVendors[] = {
    {0x03e7, "Intel Movidius"}, {0x045e, "Microsoft"}, {0x1d27, "PrimeSense"},
    {0x2b03, "Stereolabs"},     {0x2bc5, "Orbbec"},    {0x8086, "Intel"},
};

constexpr bool lessById(const KnownUsbCamera& a, const KnownUsbCamera& b) {
  return a.vendor_id != b.vendor_id ? a.vendor_id < b.vendor_id : a.product_id < b.product_id;
}
static_assert(std::is_sorted(std::begin(kCameras), std::end(kCameras), lessById),
              "kCameras must stay sorted by (vendor_id, product_id)");

}  // namespace

const char* usbCameraBackendName(UsbCameraBackend backend) {
  switch (backend) {
    case UsbCameraBackend::kOpenNI2: return "openni2";
    case UsbCameraBackend::kV4l2: return "v4l2";
    case UsbCameraBackend::kNone: return "none";
  }
  return "?";
}

std::span<const KnownUsbCamera> knownUsbCameras() { return kCameras; }

const KnownUsbCamera* findKnownUsbCamera(uint16_t vendor_id, uint16_t product_id) {
  KnownUsbCamera key;
  key.vendor_id = vendor_id;
  key.product_id = product_id;
  const auto* it = std::lower_bound(std::begin(kCameras), std::end(kCameras), key, lessById);
  if (it == std::end(kCameras) || it->vendor_id != vendor_id || it->product_id != product_id) return nullptr;
  return it;
}

std::string_view usbVendorName(uint16_t vendor_id) {
  for (const Vendor& v : kVendors) {
    if (v.id == vendor_id) return v.name;
  }
  return {};
}

std::string udevRules() {
  std::string out;
  out += "# ";
  out += kUdevRulesFileName;
  out +=
      ": RGB-D cameras fovea knows (generated from hal/usb/usb_ids.cpp; do not edit).\n"
      "# Gives the USB device node to group plugdev and its V4L2 nodes to group video,\n"
      "# mode 0660, and tags both for the logged-in user (uaccess). The fovea service\n"
      "# user needs to be in plugdev and video. After installing:\n"
      "#   udevadm control --reload && udevadm trigger\n";
  char line[320];
  for (const KnownUsbCamera& c : kCameras) {
    std::snprintf(line, sizeof line, "\n# %.*s (fovea backend: %s)\n", static_cast<int>(c.model.size()),
                  c.model.data(), usbCameraBackendName(c.backend));
    out += line;
    std::snprintf(line, sizeof line,
                  "SUBSYSTEM==\"usb\", ENV{DEVTYPE}==\"usb_device\", ATTR{idVendor}==\"%04x\", "
                  "ATTR{idProduct}==\"%04x\", MODE=\"0660\", GROUP=\"%.*s\", TAG+=\"uaccess\"\n",
                  c.vendor_id, c.product_id, static_cast<int>(kUdevUsbGroup.size()), kUdevUsbGroup.data());
    out += line;
    std::snprintf(line, sizeof line,
                  "SUBSYSTEM==\"video4linux\", ATTRS{idVendor}==\"%04x\", ATTRS{idProduct}==\"%04x\", "
                  "MODE=\"0660\", GROUP=\"%.*s\", TAG+=\"uaccess\"\n",
                  c.vendor_id, c.product_id, static_cast<int>(kUdevVideoGroup.size()), kUdevVideoGroup.data());
    out += line;
  }
  return out;
}

}  // namespace fovea::hal::usb

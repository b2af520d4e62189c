#include "core/clock.h"
#include "core/sanitizer.h"
#include "hal/camera/openni2/openni2_camera.h"

#include <time.h>
#ifdef FOVEA_ADDRESS_SANITIZER
#include <dlfcn.h>
#include <link.h>
#endif

#include <OpenNI.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <mutex>
#include <thread>
#include <utility>

namespace fovea::hal::openni2 {

namespace {

constexpr double kPi = 3.14159265358979323846;
// PrimeSense Carmine 1.08 / Asus Xtion nominal fields of view, for a device
// that reports none (OpenNI2's Dummy device reports 0).
constexpr double kNominalHfovRad = 58.0 * kPi / 180.0;
constexpr double kNominalVfovRad = 45.0 * kPi / 180.0;
constexpr std::size_t kColourSlots = 3;
// Depth frames that may wait for their colour frame: the Dummy's colour runs a
// frame behind its depth, real devices' colour up to a frame or two.
constexpr std::size_t kPendingDepthFrames = 3;
// Consecutive depth frames without a colour frame (while colour frames keep
// coming) after which the streams are out of step for good: the Dummy's
// colour thread can fall whole frames behind its depth thread under load, and
// its stamps count frames. acquire() then says so; a restart re-aligns them.
constexpr uint64_t kOutOfStepFrames = 8;
constexpr const char* kNoDeviceHint =
    "plug in the camera; `lsusb` should list it (Orbbec 2bc5:..., PrimeSense/Asus 1d27:...); if it is listed, "
    "check USB permission: install the udev rules fovea ships for known camera ids, or add the user to the "
    "group the rules name (video; plugdev on some distributions) (docs/cameras-openni2.md)";

std::vector<VideoModeDesc> modesOf(const openni::SensorInfo* sensor) {
  std::vector<VideoModeDesc> modes;
  if (sensor == nullptr) return modes;
  const openni::Array<openni::VideoMode>& list = sensor->getSupportedVideoModes();
  for (int i = 0; i < list.getSize(); ++i) {
    modes.push_back({list[i].getResolutionX(), list[i].getResolutionY(), list[i].getFps(), list[i].getPixelFormat()});
  }
  return modes;
}

VideoModeDesc descOf(const openni::VideoMode& mode) {
  return {mode.getResolutionX(), mode.getResolutionY(), mode.getFps(), mode.getPixelFormat()};
}

bool sameMode(const VideoModeDesc& a, const VideoModeDesc& b) {
  return a.width == b.width && a.height == b.height && a.fps == b.fps && a.pixel_format == b.pixel_format;
}

// Under AddressSanitizer: OpenNI2's drivers (OpenNI2/Drivers/lib*.so) allocate
// objects they never free, and OpenNI::shutdown() unloads them, so LeakSanitizer
// would find those blocks under an unknown module. Each loaded driver gets a
// reference that is never released (RTLD_NODELETE), so it stays mapped to the
// end and LeakSanitizer names it: toolchain/lsan.supp suppresses the drivers
// only. A stream or device that fovea forgets to destroy is allocated by
// libOpenNI2.so itself and is still reported (CTest openni2.leaks shows it).
void keepDriversLoadedForLeakReports() {
#ifdef FOVEA_ADDRESS_SANITIZER
  std::vector<std::string> drivers;
  dl_iterate_phdr(
      [](dl_phdr_info* info, std::size_t, void* out) {
        if (info->dlpi_name != nullptr && std::strstr(info->dlpi_name, "/OpenNI2/Drivers/") != nullptr) {
          static_cast<std::vector<std::string>*>(out)->emplace_back(info->dlpi_name);
        }
        return 0;
      },
      &drivers);
  // dlopen() outside the iteration, which holds the loader's lock.
  for (const std::string& path : drivers) dlopen(path.c_str(), RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);
#endif
}

// libOpenNI2 2.2 itself leaks inside VideoStream::start() and stop() (a frame
// holder and its buffers, each time). These two wrappers stay frames of their
// own (not inlined) so that toolchain/lsan.supp can suppress exactly these calls
// by name, and nothing else fovea asks of libOpenNI2.
[[gnu::noinline]] openni::Status startStreamLeakingInOpenNI2(openni::VideoStream& stream) { return stream.start(); }
[[gnu::noinline]] void stopStreamLeakingInOpenNI2(openni::VideoStream& stream) { stream.stop(); }

// openni::OpenNI::initialize() once per process for however many cameras (and
// discoveries) use it; shutdown when the last one lets go.
class Runtime {
 public:
  static Status acquire() {
    std::lock_guard<std::mutex> lock(mutex());
    if (users() == 0) {
      if (openni::OpenNI::initialize() != openni::STATUS_OK) {
        return {ErrorCode::kUnavailable, std::string("openni2: OpenNI2 failed to initialise: ") +
                                             openni::OpenNI::getExtendedError() +
                                             " (are its drivers installed? apt-get install libopenni2-0)"};
      }
      keepDriversLoadedForLeakReports();
    }
    ++users();
    return Status::ok();
  }
  static void release() {
    std::lock_guard<std::mutex> lock(mutex());
    if (users() > 0 && --users() == 0) openni::OpenNI::shutdown();
  }

 private:
  static std::mutex& mutex() {
    static std::mutex m;
    return m;
  }
  static int& users() {
    static int n = 0;
    return n;
  }
};

// Holds the runtime for one scope (discovery).
class RuntimeUse {
 public:
  RuntimeUse() : status_(Runtime::acquire()) {}
  ~RuntimeUse() {
    if (status_) Runtime::release();
  }
  RuntimeUse(const RuntimeUse&) = delete;
  RuntimeUse& operator=(const RuntimeUse&) = delete;
  const Status& status() const { return status_; }

 private:
  Status status_;
};

std::string deviceModel(const openni::DeviceInfo& info) {
  std::string vendor = info.getVendor() != nullptr ? info.getVendor() : "";
  std::string name = info.getName() != nullptr ? info.getName() : "";
  if (vendor.empty()) return name;
  if (name.empty()) return vendor;
  return vendor + " " + name;
}

std::string deviceSerial(openni::Device& device) {
  char serial[128] = {};
  int size = sizeof(serial) - 1;
  if (!device.isPropertySupported(ONI_DEVICE_PROPERTY_SERIAL_NUMBER)) return "";
  if (device.getProperty(ONI_DEVICE_PROPERTY_SERIAL_NUMBER, serial, &size) != openni::STATUS_OK) return "";
  serial[sizeof(serial) - 1] = '\0';
  return serial;
}

std::string usbIds(const openni::DeviceInfo& info) {
  char text[32];
  std::snprintf(text, sizeof(text), "usb %04x:%04x", info.getUsbVendorId(), info.getUsbProductId());
  return text;
}

// Copies a w x h image of `bytes_per_pixel` with the source's stride into a
// packed destination.
void copyRows(const uint8_t* src, int stride_bytes, int width, int height, int bytes_per_pixel, uint8_t* dst) {
  const std::size_t row = static_cast<std::size_t>(width) * bytes_per_pixel;
  if (static_cast<std::size_t>(stride_bytes) == row) {
    std::memcpy(dst, src, row * height);
    return;
  }
  for (int y = 0; y < height; ++y) std::memcpy(dst + row * y, src + static_cast<std::size_t>(stride_bytes) * y, row);
}

// True when `frame` holds a complete w x h image of bpp bytes per pixel.
bool frameHasSize(const openni::VideoFrameRef& frame, int width, int height, int bytes_per_pixel) {
  if (!frame.isValid() || frame.getData() == nullptr) return false;
  if (frame.getWidth() != width || frame.getHeight() != height) return false;
  const int stride = frame.getStrideInBytes();
  if (stride < width * bytes_per_pixel) return false;
  return static_cast<int64_t>(frame.getDataSize()) >=
         static_cast<int64_t>(stride) * (height - 1) + static_cast<int64_t>(width) * bytes_per_pixel;
}

}  // namespace

struct OpenNI2Camera::Impl {
  // Sets a flag when OpenNI2 reports our device gone (called on OpenNI2's thread).
  class DisconnectListener final : public openni::OpenNI::DeviceDisconnectedListener {
   public:
    DisconnectListener(std::string uri, std::shared_ptr<std::atomic<bool>> flag)
        : uri_(std::move(uri)), flag_(std::move(flag)) {}
    void onDeviceDisconnected(const openni::DeviceInfo* info) override {
      if (info != nullptr && info->getUri() != nullptr && uri_ == info->getUri()) flag_->store(true);
    }

   private:
    std::string uri_;
    std::shared_ptr<std::atomic<bool>> flag_;
  };

  openni::Device device;
  openni::VideoStream depth;
  openni::VideoStream colour;
  openni::VideoFrameRef frame;
  std::unique_ptr<DisconnectListener> listener;
};

// ---------------------------------------------------------------------------
// Device time

int64_t DeviceClockMapper::toHostNs(uint64_t device_us, int64_t host_now_ns) {
  const int64_t device_ns = static_cast<int64_t>(std::min<uint64_t>(device_us, INT64_MAX / 1000)) * 1000;
  if (!anchored_ || device_ns < last_device_ns_) {
    if (anchored_) ++reanchors_;
    offset_ns_ = host_now_ns - device_ns;
    anchored_ = true;
  }
  last_device_ns_ = device_ns;
  return device_ns + offset_ns_;
}

// ---------------------------------------------------------------------------
// Discovery

Result<std::vector<DeviceListing>> discoverOpenNI2Cameras() {
  RuntimeUse runtime;
  if (!runtime.status()) return runtime.status();
  openni::Array<openni::DeviceInfo> devices;
  openni::OpenNI::enumerateDevices(&devices);
  std::vector<DeviceListing> listings;
  for (int i = 0; i < devices.getSize(); ++i) {
    const openni::DeviceInfo& info = devices[i];
    const std::string uri = info.getUri() != nullptr ? info.getUri() : "";
    if (uri == "Dummy") continue;  // only enumerated once something opened it: not a camera
    DeviceListing listing;
    listing.spec = "openni2:" + uri;
    listing.model = deviceModel(info);
    listing.detail = usbIds(info);
    openni::Device device;
    if (device.open(uri.c_str()) == openni::STATUS_OK) {
      listing.serial = deviceSerial(device);
      for (const VideoModeDesc& m : modesOf(device.getSensorInfo(openni::SENSOR_DEPTH))) {
        listing.modes.push_back("depth " + describeVideoMode(m));
      }
      for (const VideoModeDesc& m : modesOf(device.getSensorInfo(openni::SENSOR_COLOR))) {
        listing.modes.push_back("colour " + describeVideoMode(m));
      }
      device.close();
    } else {
      listing.detail += std::string("; cannot open it to list its modes (in use, or no permission: ") + kNoDeviceHint +
                        "): " + openni::OpenNI::getExtendedError();
    }
    listings.push_back(std::move(listing));
  }
  return listings;
}

// ---------------------------------------------------------------------------
// The camera

OpenNI2Camera::OpenNI2Camera(OpenNI2CameraOptions options)
    : options_(std::move(options)), disconnected_(std::make_shared<std::atomic<bool>>(false)) {
  info_.name = "openni2:" + options_.uri;
}

OpenNI2Camera::~OpenNI2Camera() { close(); }

Result<std::unique_ptr<Camera>> OpenNI2Camera::create(std::string_view args) {
  Result<OpenNI2CameraOptions> options = parseOpenNI2CameraOptions(args);
  if (!options) return options.status();
  return std::unique_ptr<Camera>(std::make_unique<OpenNI2Camera>(std::move(options).value()));
}

Status OpenNI2Camera::setCalibration(const CameraCalibration& calibration) {
  if (calibration.colour || calibration.T_colour_depth) {
    // Software registration (hal::DepthToColourRegistration) is not wired
    // into this backend yet; refusing beats silently ignoring half of it.
    return {ErrorCode::kInvalidArgument,
            "openni2: a colour calibration or T_colour_depth (from " + calibration.source +
                ") is not used by this backend: OpenNI2 devices register colour in hardware (registration=on); "
                "give only the depth intrinsics and depth_scale_m"};
  }
  calibration_ = calibration;
  return Status::ok();
}

void OpenNI2Camera::close() {
  stop();
  if (impl_) {
    impl_->frame.release();
    if (impl_->listener) openni::OpenNI::removeDeviceDisconnectedListener(impl_->listener.get());
    impl_->depth.destroy();
    impl_->colour.destroy();
    impl_->device.close();
    impl_.reset();
  }
  if (runtime_held_) {
    Runtime::release();
    runtime_held_ = false;
  }
  opened_ = false;
}

Status OpenNI2Camera::open() {
  close();
  notes_.clear();
  disconnected_->store(false);
  if (isOniRecordingUri(options_.uri)) {
    return {ErrorCode::kInvalidArgument,
            "openni2: " + options_.uri +
                " is an .oni recording: Debian's OpenNI2 2.2 plays .oni files back without frames and can crash "
                "in libOniFile, so fovea does not open them; convert the recording to a TUM RGB-D folder "
                "(depth and rgb PNGs, associations.txt) and replay it with tum:PATH, or use the live camera"};
  }
  if (Status s = Runtime::acquire(); !s) return s;
  runtime_held_ = true;
  impl_ = std::make_unique<Impl>();

  Status status = openDevice();
  if (!status) {
    close();
    return status;
  }
  const std::string uri = impl_->device.getDeviceInfo().getUri();
  info_.model = deviceModel(impl_->device.getDeviceInfo());
  info_.serial = deviceSerial(impl_->device);
  status = openDepthStream(uri);
  if (status) status = openColourStream(uri);
  if (status) status = chooseIntrinsics(uri);
  if (status) status = checkUnregisteredColour(uri);
  if (!status) {
    close();
    return status;
  }

  // Colour frames wait here for their depth frame: allocated now, never per frame.
  colour_slots_.assign(colour_enabled_ ? kColourSlots : 0,
                       std::vector<uint8_t>(static_cast<std::size_t>(depth_mode_.width) * depth_mode_.height * 3));
  pending_.assign(colour_enabled_ ? kPendingDepthFrames : 0,
                  PendingDepth{std::vector<uint16_t>(static_cast<std::size_t>(depth_mode_.width) * depth_mode_.height),
                               0, 0});
  pending_head_ = 0;
  pending_size_ = 0;
  const int64_t period_ns = static_cast<int64_t>(1e9 / info_.fps);
  pairer_ = TimestampPairer(kColourSlots, period_ns / 2);

  impl_->listener = std::make_unique<Impl::DisconnectListener>(uri, disconnected_);
  openni::OpenNI::addDeviceDisconnectedListener(impl_->listener.get());
  for (const std::string& note : notes_) std::fprintf(stderr, "%s\n", note.c_str());
  opened_ = true;
  return Status::ok();
}

// The device the URI names, or without one the first OpenNI2 enumerates
// (the synthetic Dummy device aside).
Status OpenNI2Camera::openDevice() {
  if (options_.uri.empty()) {
    openni::Array<openni::DeviceInfo> devices;
    openni::OpenNI::enumerateDevices(&devices);
    int usable = -1;
    for (int i = 0; i < devices.getSize() && usable < 0; ++i) {
      if (devices[i].getUri() != nullptr && std::string_view(devices[i].getUri()) != "Dummy") usable = i;
    }
    if (usable < 0) {
      return {ErrorCode::kNotFound, std::string("no OpenNI2 device found: ") + kNoDeviceHint +
                                        " (openni2:Dummy is OpenNI2's synthetic device, for trying fovea without one)"};
    }
    options_.uri = devices[usable].getUri();
    info_.name = "openni2:" + options_.uri;
  }
  if (impl_->device.open(options_.uri.c_str()) != openni::STATUS_OK) {
    const std::string why = openni::OpenNI::getExtendedError();
    return {ErrorCode::kNotFound, "openni2: cannot open device '" + options_.uri + "': " + why +
                                      " (is it still plugged in, and not in use by another program? " + kNoDeviceHint +
                                      ")"};
  }
  return Status::ok();
}

// Depth stream and mode.
Status OpenNI2Camera::openDepthStream(const std::string& uri) {
  if (impl_->depth.create(impl_->device, openni::SENSOR_DEPTH) != openni::STATUS_OK) {
    const std::string why = openni::OpenNI::getExtendedError();
    return {ErrorCode::kUnavailable, "openni2: " + uri + " has no usable depth stream: " + why};
  }
  const std::vector<VideoModeDesc> modes = modesOf(impl_->device.getSensorInfo(openni::SENSOR_DEPTH));
  Result<int> chosen = chooseVideoMode(
      modes, {openni::PIXEL_FORMAT_DEPTH_1_MM, openni::PIXEL_FORMAT_DEPTH_100_UM}, options_.width, options_.height,
      options_.fps, descOf(impl_->depth.getVideoMode()), "depth");
  if (!chosen) return chosen.status();
  depth_mode_ = modes[chosen.value()];
  const openni::Array<openni::VideoMode>& list = impl_->device.getSensorInfo(openni::SENSOR_DEPTH)->getSupportedVideoModes();
  // Only when it differs: some drivers (the Dummy) refuse to set any mode.
  if (!sameMode(descOf(impl_->depth.getVideoMode()), depth_mode_) &&
      impl_->depth.setVideoMode(list[chosen.value()]) != openni::STATUS_OK) {
    const std::string why = openni::OpenNI::getExtendedError();
    return {ErrorCode::kUnavailable, "openni2: " + uri + " refused depth mode " + describeVideoMode(depth_mode_) +
                                         ": " + why};
  }
  info_.depth_scale_m = depth_mode_.pixel_format == openni::PIXEL_FORMAT_DEPTH_100_UM ? 0.0001 : 0.001;
  info_.fps = depth_mode_.fps > 0 ? depth_mode_.fps : 30.0;
  return Status::ok();
}

// Colour stream, at the depth image's size when it offers it; with it the
// device's frame sync and registration as the options ask.
Status OpenNI2Camera::openColourStream(const std::string& uri) {
  colour_enabled_ = false;
  hardware_registration_ = false;
  if (!options_.colour) return Status::ok();
  if (impl_->device.getSensorInfo(openni::SENSOR_COLOR) == nullptr ||
      impl_->colour.create(impl_->device, openni::SENSOR_COLOR) != openni::STATUS_OK) {
    return {ErrorCode::kUnavailable, "openni2: " + uri + " has no colour stream; use colour=off"};
  }
  const std::vector<VideoModeDesc> modes = modesOf(impl_->device.getSensorInfo(openni::SENSOR_COLOR));
  Result<int> chosen = chooseVideoMode(modes, {openni::PIXEL_FORMAT_RGB888}, depth_mode_.width, depth_mode_.height,
                                       depth_mode_.fps, depth_mode_, "colour");
  if (!chosen) {
    return {chosen.status().code(),
            chosen.status().message() + "\n(the colour image must have the depth image's size, " +
                std::to_string(depth_mode_.width) + "x" + std::to_string(depth_mode_.height) +
                ", to be registered to it; or use colour=off)"};
  }
  colour_mode_ = modes[chosen.value()];
  const openni::Array<openni::VideoMode>& list = impl_->device.getSensorInfo(openni::SENSOR_COLOR)->getSupportedVideoModes();
  // Only when it differs: some drivers (the Dummy) refuse to set any mode.
  if (!sameMode(descOf(impl_->colour.getVideoMode()), colour_mode_) &&
      impl_->colour.setVideoMode(list[chosen.value()]) != openni::STATUS_OK) {
    const std::string why = openni::OpenNI::getExtendedError();
    return {ErrorCode::kUnavailable, "openni2: " + uri + " refused colour mode " + describeVideoMode(colour_mode_) +
                                         ": " + why};
  }
  colour_enabled_ = true;
  if (options_.sync) impl_->device.setDepthColorSyncEnabled(true);  // best effort: many devices lack it
  if (options_.registration) {
    if (impl_->device.isImageRegistrationModeSupported(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR) &&
        impl_->device.setImageRegistrationMode(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR) == openni::STATUS_OK) {
      hardware_registration_ = true;
    }
  } else {
    impl_->device.setImageRegistrationMode(openni::IMAGE_REGISTRATION_OFF);
  }
  return Status::ok();
}

// Intrinsics: with hardware registration the depth image is in the colour
// camera's view, so the colour stream's field of view describes it. A
// calibration's depth intrinsics and depth scale override what the device says.
Status OpenNI2Camera::chooseIntrinsics(const std::string& uri) {
  openni::VideoStream& view = hardware_registration_ ? impl_->colour : impl_->depth;
  double hfov = view.getHorizontalFieldOfView();
  double vfov = view.getVerticalFieldOfView();
  const bool fov_valid = std::isfinite(hfov) && std::isfinite(vfov) && hfov > 0.01 && hfov < 3.0 && vfov > 0.01 &&
                         vfov < 3.0;
  if (!fov_valid) {
    hfov = kNominalHfovRad;
    vfov = kNominalVfovRad;
  }
  info_.intrinsics = intrinsicsFromFov(depth_mode_.width, depth_mode_.height, hfov, vfov);
  bool calibrated = false;
  if (calibration_) {
    if (calibration_->depth) {
      const CameraIntrinsics& k = calibration_->depth->intrinsics;
      if (k.width != depth_mode_.width || k.height != depth_mode_.height) {
        return {ErrorCode::kInvalidArgument,
                "openni2: the calibration from " + calibration_->source + " is for " + std::to_string(k.width) + "x" +
                    std::to_string(k.height) + " depth images, the camera delivers " +
                    std::to_string(depth_mode_.width) + "x" + std::to_string(depth_mode_.height) +
                    ": calibrate at that size or set size=" + std::to_string(k.width) + "x" + std::to_string(k.height)};
      }
      info_.intrinsics = k;
      calibrated = true;
    }
    if (calibration_->depth_scale_m) info_.depth_scale_m = *calibration_->depth_scale_m;
  }
  if (!fov_valid && !calibrated) {
    notes_.push_back("openni2: " + uri + " reports no field of view; using the PrimeSense nominal 58 x 45 degrees "
                     "(give a calibration for accurate geometry)");
  }
  return Status::ok();
}

// Colour without hardware registration is delivered only when its image has
// the depth image's size and field of view (said once, as a note); otherwise
// open() refuses and says what to do.
Status OpenNI2Camera::checkUnregisteredColour(const std::string& uri) {
  if (!colour_enabled_ || hardware_registration_) return Status::ok();
  const double colour_hfov = impl_->colour.getHorizontalFieldOfView();
  const double colour_vfov = impl_->colour.getVerticalFieldOfView();
  const double depth_hfov = impl_->depth.getHorizontalFieldOfView();
  const double depth_vfov = impl_->depth.getVerticalFieldOfView();
  const bool same_view = colour_mode_.width == depth_mode_.width && colour_mode_.height == depth_mode_.height &&
                         std::abs(colour_hfov - depth_hfov) < 1e-3 && std::abs(colour_vfov - depth_vfov) < 1e-3;
  if (!same_view) {
    return {ErrorCode::kUnavailable,
            "openni2: " + uri + (options_.registration ? " offers no hardware depth-to-colour registration"
                                                       : " was asked for registration=off") +
                " and its colour camera sees differently from its depth camera (field of view " +
                std::to_string(colour_hfov) + " vs " + std::to_string(depth_hfov) +
                " rad): use colour=off (depth only)" +
                (options_.registration ? std::string() : std::string(", or registration=on"))};
  }
  notes_.push_back("openni2: " + uri +
                   (options_.registration ? " offers no hardware registration" : ": registration=off") +
                   "; its colour image has the depth image's size and field of view and is delivered unregistered");
  return Status::ok();
}

Status OpenNI2Camera::start() {
  if (!opened_) return {ErrorCode::kUnavailable, "openni2 camera: call open() before start()"};
  if (started_) return Status::ok();
  if (startStreamLeakingInOpenNI2(impl_->depth) != openni::STATUS_OK) {
    return {ErrorCode::kUnavailable,
            "openni2: cannot start the depth stream of " + options_.uri + ": " + openni::OpenNI::getExtendedError()};
  }
  if (colour_enabled_ && startStreamLeakingInOpenNI2(impl_->colour) != openni::STATUS_OK) {
    const std::string why = openni::OpenNI::getExtendedError();
    stopStreamLeakingInOpenNI2(impl_->depth);
    return {ErrorCode::kUnavailable, "openni2: cannot start the colour stream of " + options_.uri + ": " + why};
  }
  pairer_.clear();
  newest_colour_ns_ = INT64_MIN;
  pending_head_ = 0;
  pending_size_ = 0;
  depth_seen_ = false;
  colour_seen_ = false;
  unmatched_run_ = 0;
  clock_.reset();
  started_ = true;
  return Status::ok();
}

void OpenNI2Camera::stop() {
  if (!started_) return;
  started_ = false;
  impl_->frame.release();
  pending_size_ = 0;
  // Some drivers only ask their frame thread to stop and return (OpenNI2's
  // Dummy: OzStream::stop() clears a flag the thread looks at once a frame
  // period, and the thread itself sets that flag when it starts running).
  // Stopping before the thread ran leaves it running for ever; destroying the
  // stream or unloading the driver before it has left crashes. Both happened on
  // a loaded machine (CI m29; docs/cameras-openni2.md): a new thread waited
  // more than two frame periods for a core and started on a destroyed stream,
  // and a thread woken late from its frame period asked a destroyed stream for
  // a buffer before looking at the flag. So a stream that delivered nothing
  // yet is given up to a second to deliver a frame (its thread is then
  // running) before it is stopped, and after stopping the threads get two
  // frame periods, at least a quarter of a second, to leave, slept in short
  // steps: a starved process's steps overrun, so the wait grows with the
  // starvation that delays the driver's thread too.
  const int grace_ms = std::max(static_cast<int>(2000.0 / info_.fps) + 10, 250);
  const int first_frame_ms = std::max(grace_ms, 1000);
  openni::VideoStream* streams[2] = {&impl_->depth, &impl_->colour};
  const bool seen[2] = {depth_seen_, colour_seen_};
  for (int i = 0; i < (colour_enabled_ ? 2 : 1); ++i) {
    int ready = -1;
    if (!seen[i]) (void)openni::OpenNI::waitForAnyStream(&streams[i], 1, &ready, first_frame_ms);
  }
  stopStreamLeakingInOpenNI2(impl_->depth);
  if (colour_enabled_) stopStreamLeakingInOpenNI2(impl_->colour);
  constexpr int kStepMs = 5;
  for (int slept_ms = 0; slept_ms < grace_ms; slept_ms += kStepMs) {
    std::this_thread::sleep_for(std::chrono::milliseconds(kStepMs));
  }
}

// Reads the colour frame that is ready into the next colour slot.
Status OpenNI2Camera::readColour() {
  openni::VideoFrameRef& frame = impl_->frame;
  if (impl_->colour.readFrame(&frame) != openni::STATUS_OK) {
    counters_.error();
    return Status(ErrorCode::kIoError, "readFrame");
  }
  colour_seen_ = true;
  const bool ok = frameHasSize(frame, depth_mode_.width, depth_mode_.height, 3);
  if (ok) {
    const int slot = pairer_.nextColourSlot();
    copyRows(static_cast<const uint8_t*>(frame.getData()), frame.getStrideInBytes(), depth_mode_.width,
             depth_mode_.height, 3, colour_slots_[slot].data());
    const int64_t stamp_ns = static_cast<int64_t>(frame.getTimestamp()) * 1000;
    pairer_.pushColour(stamp_ns);
    newest_colour_ns_ = stamp_ns;
  }
  frame.release();
  ++frames_released_;
  if (!ok) {
    counters_.badFrame();
    return Status(ErrorCode::kInvalidInput, "colour size");
  }
  return Status::ok();
}

// Reads the depth frame that is ready. Without colour it goes straight into
// the slot (delivered); with colour it joins the depth frames awaiting their
// colour frame, and when that queue is full its oldest frame is decided first
// (delivered into the slot if a colour frame pairs with it).
Status OpenNI2Camera::readDepth(RgbdFrame& slot, bool& delivered) {
  delivered = false;
  openni::VideoFrameRef& frame = impl_->frame;
  if (impl_->depth.readFrame(&frame) != openni::STATUS_OK) {
    counters_.error();
    return Status(ErrorCode::kIoError, "readFrame");
  }
  depth_seen_ = true;
  if (!frameHasSize(frame, depth_mode_.width, depth_mode_.height, 2)) {
    frame.release();
    ++frames_released_;
    counters_.badFrame();
    return Status(ErrorCode::kInvalidInput, "depth size");
  }
  const uint64_t device_us = frame.getTimestamp();
  const int64_t host_ns = clock_.toHostNs(device_us, monotonicNs());
  if (!colour_enabled_) {
    copyRows(static_cast<const uint8_t*>(frame.getData()), frame.getStrideInBytes(), depth_mode_.width,
             depth_mode_.height, 2, reinterpret_cast<uint8_t*>(slot.depth()));
    frame.release();
    ++frames_released_;
    slot.has_rgb = false;
    slot.stamp_ns = host_ns;
    delivered = true;
    return Status::ok();
  }
  if (pending_size_ == pending_.size()) delivered = deliverOldestPending(slot);
  PendingDepth& entry = pending_[(pending_head_ + pending_size_) % pending_.size()];
  copyRows(static_cast<const uint8_t*>(frame.getData()), frame.getStrideInBytes(), depth_mode_.width,
           depth_mode_.height, 2, reinterpret_cast<uint8_t*>(entry.depth.data()));
  frame.release();
  ++frames_released_;
  entry.device_ns = static_cast<int64_t>(device_us) * 1000;
  entry.host_ns = host_ns;
  ++pending_size_;
  return Status::ok();
}

// Decides the oldest depth frame awaiting colour: paired with the nearest
// colour frame into the slot (true), or dropped as unmatched (counted by the
// pairer).
bool OpenNI2Camera::deliverOldestPending(RgbdFrame& slot) {
  const PendingDepth& oldest = pending_[pending_head_];
  pending_head_ = (pending_head_ + 1) % pending_.size();
  --pending_size_;
  const std::optional<int> c = pairer_.pairDepth(oldest.device_ns);
  if (!c) {
    ++unmatched_run_;
    return false;
  }
  unmatched_run_ = 0;
  std::memcpy(slot.depth(), oldest.depth.data(), oldest.depth.size() * sizeof(uint16_t));
  std::memcpy(slot.rgb(), colour_slots_[*c].data(), colour_slots_[*c].size());
  slot.has_rgb = true;
  slot.stamp_ns = oldest.host_ns;
  return true;
}

Status OpenNI2Camera::acquire(RgbdFrame& slot, std::chrono::nanoseconds timeout) {
  if (!started_) {
    counters_.error();
    return Status(ErrorCode::kUnavailable, "not started");
  }
  if (disconnected_->load(std::memory_order_relaxed)) {
    counters_.disconnect();
    return Status(ErrorCode::kNotFound, "device gone");
  }
  if (!slot.setSize(depth_mode_.width, depth_mode_.height)) {
    counters_.error();
    return Status(ErrorCode::kCapacityExceeded, "slot too small");
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  openni::VideoStream* streams[2] = {&impl_->depth, &impl_->colour};
  const int stream_count = colour_enabled_ ? 2 : 1;
  bool delivered = false;
  while (!delivered) {
    // A waiting depth frame is decided once a colour frame as new as it has
    // arrived (later ones are farther away in time), oldest first.
    while (pending_size_ > 0 && newest_colour_ns_ != INT64_MIN &&
           newest_colour_ns_ >= pending_[pending_head_].device_ns && !delivered) {
      delivered = deliverOldestPending(slot);
    }
    if (delivered) break;
    if (unmatched_run_ >= kOutOfStepFrames) {
      unmatched_run_ = 0;
      counters_.error();
      return Status(ErrorCode::kUnavailable, "out of step");
    }
    const auto left = deadline - std::chrono::steady_clock::now();
    const int left_ms = static_cast<int>(std::clamp<int64_t>(
        std::chrono::duration_cast<std::chrono::milliseconds>(left + std::chrono::microseconds(999)).count(), 0,
        3'600'000));
    if (left_ms <= 0) {
      counters_.timeout();
      return Status(ErrorCode::kUnavailable, "timeout");
    }
    int ready = -1;
    const openni::Status waited = openni::OpenNI::waitForAnyStream(streams, stream_count, &ready, left_ms);
    if (disconnected_->load(std::memory_order_relaxed)) {
      counters_.disconnect();
      return Status(ErrorCode::kNotFound, "device gone");
    }
    if (waited == openni::STATUS_TIME_OUT) {
      counters_.timeout();
      return Status(ErrorCode::kUnavailable, "timeout");
    }
    if (waited != openni::STATUS_OK || ready < 0) {
      counters_.error();
      return Status(ErrorCode::kIoError, "wait failed");
    }
    if (ready == 1) {
      if (Status s = readColour(); !s) return s;
    } else {
      if (Status s = readDepth(slot, delivered); !s) return s;
    }
  }
  slot.intrinsics = info_.intrinsics;
  slot.depth_scale_m = info_.depth_scale_m;
  slot.T_world_cam = Pose();
  slot.sequence = sequence_++;
  counters_.frameDelivered();
  return Status::ok();
}

}  // namespace fovea::hal::openni2

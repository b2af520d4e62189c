#include "hal/spec_options.h"
#include "hal/camera/libcamera/libcamera_camera.h"

#include <sys/mman.h>

#include <algorithm>
#include <charconv>
#include <condition_variable>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <utility>

#include <libcamera/libcamera.h>

#include "hal/camera/registration/registration.h"

namespace fovea::hal::libcam {

namespace {

Status invalid(std::string message) { return Status(ErrorCode::kInvalidArgument, "libcamera: " + std::move(message)); }

constexpr const char* kFormatsWeConvert = "BGR888, RGB888, XBGR8888, XRGB8888";
constexpr const char* kNoCameraHint =
    "libcamera sees no camera: is the camera's ribbon cable seated and its overlay enabled (e.g. "
    "dtoverlay=imx219 in config.txt on a Raspberry Pi), and does the board's ISP have a pipeline handler in this "
    "libcamera (Debian 12's 0.0.3 has raspberrypi (VC4: Pi 4 and older; not the Pi 5's PiSP), rkisp1, ipu3, "
    "imx8-isi, simple, uvcvideo, vimc)? `cam --list` (libcamera-tools) shows what libcamera sees";

// One CameraManager per process, started for the first user and stopped when
// the last one goes (0.0.3 allows one instance at a time).
class ManagerHolder {
 public:
  static Result<libcamera::CameraManager*> acquire() {
    std::lock_guard<std::mutex> lock(mutex());
    if (users() == 0) {
      // libcamera logs INFO and WARN lines to stderr (its version, "No IPA
      // found" on machines without libcamera-ipa): errors only, unless the
      // user set LIBCAMERA_LOG_LEVELS. Its logger reads that variable when it
      // is first used (its categories are made lazily, so logSetLevel() now
      // would miss them).
      setenv("LIBCAMERA_LOG_LEVELS", "*:ERROR", 0);
      manager() = std::make_unique<libcamera::CameraManager>();
      if (const int ret = manager()->start(); ret != 0) {
        manager().reset();
        return Result<libcamera::CameraManager*>(
            ErrorCode::kUnavailable, "libcamera: the camera manager failed to start: " + std::string(std::strerror(-ret)));
      }
    }
    ++users();
    return manager().get();
  }
  static void release() {
    std::lock_guard<std::mutex> lock(mutex());
    if (users() > 0 && --users() == 0) {
      manager()->stop();
      manager().reset();
    }
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
  static std::unique_ptr<libcamera::CameraManager>& manager() {
    static std::unique_ptr<libcamera::CameraManager> m;
    return m;
  }
};

std::string cameraModel(const libcamera::Camera& camera) {
  const std::optional<std::string> model = camera.properties().get(libcamera::properties::Model);
  return model ? *model : std::string();
}

}  // namespace

// ---------------------------------------------------------------------------
// Options and formats

Result<LibcameraCameraOptions> parseLibcameraCameraOptions(std::string_view args) {
  LibcameraCameraOptions options;
  // depth=SPEC is another backend's whole spec, commas and all: it ends the options.
  const SpecTokens tokens = tokenizeSpec(args, {.head = SpecTokenRules::Head::kFirstItem, .rest_key = "depth", .bare_continues_value = false});
  const bool depth_given =
      !tokens.items.empty() && tokens.items.back().has_value && tokens.items.back().key == "depth";
  const std::string_view camera = tokens.head.value_or("");
  if (!depth_given && camera.substr(0, 6) == "depth=") {
    return invalid("name the colour camera first: libcamera:N|ID[,...],depth=SPEC");
  }
  if (camera.empty() || camera.find('=') != std::string_view::npos) {
    return invalid("expected libcamera:N|ID[,size=WxH,format=F,buffers=N],depth=SPEC (N: index from `fovead "
                   "cameras`)");
  }
  options.camera = std::string(camera);
  for (const auto& [key, value, has_value] : tokens.items) {
    if (!has_value) {
      return invalid("option '" + std::string(key) + "' is not key=value (keys: size, format, buffers, depth)");
    }
    if (key == "depth") {
      options.depth_spec = std::string(value);
    } else if (key == "size") {
      if (Status s = parseSpecSize("libcamera", key, value, 1, 16384, options.width, options.height); !s) return s;
    } else if (key == "format") {
      if (!packedRgbLayout(value)) {
        return invalid("format: '" + std::string(value) + "' is not converted by this backend (it takes " +
                       kFormatsWeConvert + "; YUYV and MJPEG cameras are UVC: use the v4l2 backend)");
      }
      options.format = std::string(value);
    } else if (key == "buffers") {
      int n = 0;
      if (!parseSpecInt(value, n) || n < 2 || n > 32) {
        return invalid("buffers: expected 2..32, got '" + std::string(value) + "'");
      }
      options.buffers = n;
    } else {
      return invalid("unknown option '" + std::string(key) + "' (keys: size, format, buffers, depth)");
    }
  }
  if (options.depth_spec.empty()) {
    return invalid("depth=SPEC is required and comes last: libcamera delivers colour only, so name the depth "
                   "camera it is paired with, e.g. libcamera:0,depth=v4l2:serial=123");
  }
  if (options.depth_spec.rfind("libcamera:", 0) == 0) {
    return invalid("depth=" + options.depth_spec + ": the depth camera must be another backend (v4l2, openni2)");
  }
  return options;
}

std::string libcameraCameraHelp() {
  return "libcamera:N|ID[,size=WxH,format=F,buffers=N],depth=SPEC  a libcamera colour camera (N: index, ID: "
         "libcamera's camera id) paired with the depth camera SPEC of another backend (depth= is required and comes "
         "last); colour is registered to depth through the calibration (colour intrinsics, T_colour_depth); "
         "format: BGR888|RGB888|XBGR8888|XRGB8888";
}

std::optional<PackedRgbLayout> packedRgbLayout(std::string_view name) {
  // DRM fourccs name the bits of a little-endian word, so RGB888 is B, G, R in memory.
  if (name == "BGR888") return PackedRgbLayout{3, 0, 1, 2};
  if (name == "RGB888") return PackedRgbLayout{3, 2, 1, 0};
  if (name == "XBGR8888") return PackedRgbLayout{4, 0, 1, 2};
  if (name == "XRGB8888") return PackedRgbLayout{4, 2, 1, 0};
  return std::nullopt;
}

bool packedRgbToRgb8(const PackedRgbLayout& layout, const uint8_t* src, std::size_t bytes, std::size_t stride,
                     int width, int height, uint8_t* rgb) {
  const std::size_t row_bytes = static_cast<std::size_t>(width) * layout.bytes_per_pixel;
  if (width <= 0 || height <= 0 || stride < row_bytes) return false;
  if (bytes < stride * static_cast<std::size_t>(height - 1) + row_bytes) return false;
  for (int y = 0; y < height; ++y) {
    const uint8_t* s = src + stride * static_cast<std::size_t>(y);
    uint8_t* d = rgb + static_cast<std::size_t>(width) * 3 * y;
    if (layout.bytes_per_pixel == 3 && layout.r == 0 && layout.b == 2) {
      std::memcpy(d, s, row_bytes);
      continue;
    }
    for (int x = 0; x < width; ++x, s += layout.bytes_per_pixel, d += 3) {
      d[0] = s[layout.r];
      d[1] = s[layout.g];
      d[2] = s[layout.b];
    }
  }
  return true;
}

// ---------------------------------------------------------------------------
// Discovery

Result<std::vector<DeviceListing>> discoverLibcameraCameras() {
  Result<libcamera::CameraManager*> manager = ManagerHolder::acquire();
  if (!manager) return manager.status();
  std::vector<DeviceListing> listings;
  const std::vector<std::shared_ptr<libcamera::Camera>> cameras = manager.value()->cameras();
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    libcamera::Camera& camera = *cameras[i];
    DeviceListing listing;
    listing.spec = "libcamera:" + std::to_string(i) + ",depth=...";
    listing.model = cameraModel(camera);
    listing.detail = "id " + camera.id() + " (libcamera:" + camera.id() + " works too); colour only: pair it with "
                     "a depth camera (depth=SPEC) and a calibration";
    std::unique_ptr<libcamera::CameraConfiguration> config =
        camera.generateConfiguration({libcamera::StreamRole::Viewfinder});
    if (config && !config->empty()) {
      const libcamera::StreamFormats& formats = config->at(0).formats();
      for (const libcamera::PixelFormat& f : formats.pixelformats()) {
        const libcamera::SizeRange range = formats.range(f);
        listing.modes.push_back("colour " + f.toString() + " " + range.min.toString() + " .. " +
                                range.max.toString() + (packedRgbLayout(f.toString()) ? "" : " (not converted)"));
      }
    }
    listings.push_back(std::move(listing));
  }
  ManagerHolder::release();
  return listings;
}

// ---------------------------------------------------------------------------
// ColourStream

struct ColourStream::Impl {
  libcamera::CameraManager* manager = nullptr;
  std::shared_ptr<libcamera::Camera> camera;
  bool acquired = false;
  bool started = false;
  std::unique_ptr<libcamera::CameraConfiguration> config;
  libcamera::Stream* stream = nullptr;
  std::unique_ptr<libcamera::FrameBufferAllocator> allocator;
  std::vector<std::unique_ptr<libcamera::Request>> requests;
  struct Mapping {
    void* base = MAP_FAILED;
    std::size_t size = 0;
  };
  std::vector<Mapping> mappings;
  std::map<const libcamera::FrameBuffer*, const uint8_t*> plane0;  // built at open, read-only after
  std::string id;
  std::string model;
  PackedRgbLayout layout;
  int width = 0;
  int height = 0;
  std::size_t stride = 0;
  std::size_t mapped_bytes = 0;

  // Completed requests, from libcamera's thread to acquire(): a ring sized at
  // open() to the number of requests, so a push never finds it full.
  std::mutex mutex;
  std::condition_variable ready;
  std::vector<libcamera::Request*> ring;
  std::size_t head = 0;
  std::size_t size = 0;
  uint64_t failed = 0;

  // open()'s steps, in order; each leaves what it made for close() to undo.
  Status selectCamera(const std::string& camera_option);
  Status configure(const LibcameraCameraOptions& options);
  Status mapBuffersAndMakeRequests();

  void onRequestCompleted(libcamera::Request* request) {
    if (request->status() == libcamera::Request::RequestCancelled) return;  // stop() takes them back
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (size == ring.size()) return;  // cannot happen: one entry per request
      ring[(head + size) % ring.size()] = request;
      ++size;
    }
    ready.notify_one();
  }
};

ColourStream::ColourStream() : impl_(std::make_unique<Impl>()) {}
ColourStream::~ColourStream() { close(); }

const std::string& ColourStream::id() const { return impl_->id; }
const std::string& ColourStream::model() const { return impl_->model; }
int ColourStream::width() const { return impl_->width; }
int ColourStream::height() const { return impl_->height; }
const PackedRgbLayout& ColourStream::layout() const { return impl_->layout; }
uint64_t ColourStream::failedFrames() const { return impl_->failed; }
std::size_t ColourStream::mappedBytes() const { return impl_->mapped_bytes; }

Status ColourStream::open(const LibcameraCameraOptions& options) {
  close();
  Impl& d = *impl_;
  Result<libcamera::CameraManager*> manager = ManagerHolder::acquire();
  if (!manager) return manager.status();
  d.manager = manager.value();
  Status status = d.selectCamera(options.camera);
  if (status) status = d.configure(options);
  if (status) status = d.mapBuffersAndMakeRequests();
  if (!status) {
    close();
    return status;
  }
  d.ring.assign(d.requests.size(), nullptr);
  d.head = d.size = 0;
  d.camera->requestCompleted.connect(impl_.get(), &Impl::onRequestCompleted);
  return Status::ok();
}

// The camera the option names (an index into libcamera's list, or an id),
// acquired for this process.
Status ColourStream::Impl::selectCamera(const std::string& camera_option) {
  const std::vector<std::shared_ptr<libcamera::Camera>> cameras = manager->cameras();
  if (cameras.empty()) return {ErrorCode::kNotFound, std::string("libcamera: no camera found: ") + kNoCameraHint};
  std::size_t index = 0;
  const char* const first = camera_option.data();
  const char* const last = first + camera_option.size();
  const auto [end, ec] = std::from_chars(first, last, index);
  if (ec == std::errc() && end == last) {
    if (index >= cameras.size()) {
      return {ErrorCode::kNotFound, "libcamera: no camera " + camera_option + ": libcamera sees " +
                                        std::to_string(cameras.size()) + " (`fovead cameras` lists them)"};
    }
    camera = cameras[index];
  } else {
    camera = manager->get(camera_option);
    if (!camera) {
      std::string ids;
      for (const auto& c : cameras) ids += "\n  " + c->id();
      return {ErrorCode::kNotFound, "libcamera: no camera with id '" + camera_option + "'; it sees:" + ids};
    }
  }
  id = camera->id();
  model = cameraModel(*camera);
  if (camera->acquire() != 0) {
    return {ErrorCode::kUnavailable, "libcamera: camera " + id + " is in use by another program"};
  }
  acquired = true;
  return Status::ok();
}

// A viewfinder stream in the requested format and size (without a format:
// the first this backend converts), validated and applied to the camera.
Status ColourStream::Impl::configure(const LibcameraCameraOptions& options) {
  config = camera->generateConfiguration({libcamera::StreamRole::Viewfinder});
  if (!config || config->empty()) {
    return {ErrorCode::kUnavailable, "libcamera: camera " + id + " offers no viewfinder stream"};
  }
  libcamera::StreamConfiguration& sc = config->at(0);
  std::string wanted = options.format;
  if (wanted.empty()) {
    for (const char* name : {"BGR888", "RGB888", "XBGR8888", "XRGB8888"}) {
      for (const libcamera::PixelFormat& f : sc.formats().pixelformats()) {
        if (wanted.empty() && f.toString() == name) wanted = name;
      }
    }
    if (wanted.empty()) {
      std::string offered;
      for (const libcamera::PixelFormat& f : sc.formats().pixelformats()) offered += " " + f.toString();
      return {ErrorCode::kUnavailable, "libcamera: camera " + id + " offers none of the formats this backend "
                                           "converts (" + kFormatsWeConvert + "); it offers:" + offered +
                                           " (a UVC camera: use the v4l2 backend)"};
    }
  }
  sc.pixelFormat = libcamera::PixelFormat::fromString(wanted);
  if (options.width > 0) sc.size = libcamera::Size(options.width, options.height);
  sc.bufferCount = static_cast<unsigned int>(options.buffers);
  const libcamera::CameraConfiguration::Status validated = config->validate();
  if (validated == libcamera::CameraConfiguration::Invalid) {
    return {ErrorCode::kInvalidArgument, "libcamera: camera " + id + " cannot stream " + wanted + " " +
                                             sc.size.toString()};
  }
  if (sc.pixelFormat.toString() != wanted ||
      (options.width > 0 && (sc.size.width != static_cast<unsigned>(options.width) ||
                             sc.size.height != static_cast<unsigned>(options.height)))) {
    return {ErrorCode::kInvalidArgument, "libcamera: camera " + id + " cannot stream " + wanted + " " +
                                             std::to_string(options.width) + "x" + std::to_string(options.height) +
                                             "; the nearest it offers is " + sc.toString()};
  }
  if (camera->configure(config.get()) != 0) {
    return {ErrorCode::kUnavailable, "libcamera: camera " + id + " refused the configuration " + sc.toString()};
  }
  layout = *packedRgbLayout(wanted);
  width = static_cast<int>(sc.size.width);
  height = static_cast<int>(sc.size.height);
  stride = sc.stride;
  stream = sc.stream();
  return Status::ok();
}

// The stream's buffers, each dmabuf mapped once, and one request per buffer.
Status ColourStream::Impl::mapBuffersAndMakeRequests() {
  allocator = std::make_unique<libcamera::FrameBufferAllocator>(camera);
  if (allocator->allocate(stream) < 0) {
    return {ErrorCode::kUnavailable, "libcamera: cannot allocate buffers for camera " + id};
  }
  for (const std::unique_ptr<libcamera::FrameBuffer>& buffer : allocator->buffers(stream)) {
    // Map each dmabuf once, over every plane that lives in it.
    std::map<int, std::size_t> extent;
    for (const libcamera::FrameBuffer::Plane& p : buffer->planes()) {
      const std::size_t offset = p.offset == libcamera::FrameBuffer::Plane::kInvalidOffset ? 0 : p.offset;
      extent[p.fd.get()] = std::max(extent[p.fd.get()], offset + p.length);
    }
    std::map<int, const uint8_t*> bases;
    for (const auto& [fd, bytes] : extent) {
      void* base = mmap(nullptr, bytes, PROT_READ, MAP_SHARED, fd, 0);
      if (base == MAP_FAILED) {
        const int err = errno;
        return {ErrorCode::kIoError, "libcamera: cannot map a buffer of camera " + id + ": " + std::strerror(err)};
      }
      mappings.push_back({base, bytes});
      mapped_bytes += bytes;
      bases[fd] = static_cast<const uint8_t*>(base);
    }
    const libcamera::FrameBuffer::Plane& p0 = buffer->planes()[0];
    plane0[buffer.get()] =
        bases[p0.fd.get()] + (p0.offset == libcamera::FrameBuffer::Plane::kInvalidOffset ? 0 : p0.offset);
    std::unique_ptr<libcamera::Request> request = camera->createRequest();
    if (!request || request->addBuffer(stream, buffer.get()) != 0) {
      return {ErrorCode::kUnavailable, "libcamera: cannot make a request for camera " + id};
    }
    requests.push_back(std::move(request));
  }
  return Status::ok();
}

Status ColourStream::start() {
  Impl& d = *impl_;
  if (!d.camera || d.requests.empty()) return {ErrorCode::kUnavailable, "libcamera: open the camera first"};
  if (d.started) return Status::ok();
  {
    std::lock_guard<std::mutex> lock(d.mutex);
    d.head = d.size = 0;
  }
  if (d.camera->start() != 0) return {ErrorCode::kUnavailable, "libcamera: camera " + d.id + " failed to start"};
  d.started = true;
  for (std::unique_ptr<libcamera::Request>& request : d.requests) {
    request->reuse(libcamera::Request::ReuseBuffers);
    if (d.camera->queueRequest(request.get()) != 0) {
      stop();
      return {ErrorCode::kUnavailable, "libcamera: camera " + d.id + " refused a request"};
    }
  }
  return Status::ok();
}

Status ColourStream::next(Frame& frame, std::chrono::nanoseconds timeout) {
  Impl& d = *impl_;
  for (;;) {
    libcamera::Request* request = nullptr;
    {
      std::unique_lock<std::mutex> lock(d.mutex);
      if (!d.ready.wait_for(lock, timeout, [&] { return d.size > 0; })) return Status(ErrorCode::kUnavailable, "timeout");
      request = d.ring[d.head];
      d.head = (d.head + 1) % d.ring.size();
      --d.size;
    }
    const libcamera::FrameBuffer* buffer = request->findBuffer(d.stream);
    const auto found = buffer != nullptr ? d.plane0.find(buffer) : d.plane0.end();
    if (found == d.plane0.end() || buffer->metadata().status != libcamera::FrameMetadata::FrameSuccess ||
        buffer->metadata().planes().empty()) {
      ++d.failed;
      frame.token = reinterpret_cast<uintptr_t>(request);
      release(frame);
      timeout = std::chrono::nanoseconds(0);  // only what is already there
      continue;
    }
    frame.data = found->second;
    frame.bytes = buffer->metadata().planes()[0].bytesused;
    frame.stride = d.stride;
    frame.stamp_ns = static_cast<int64_t>(buffer->metadata().timestamp);
    frame.token = reinterpret_cast<uintptr_t>(request);
    return Status::ok();
  }
}

void ColourStream::release(const Frame& frame) {
  Impl& d = *impl_;
  auto* request = reinterpret_cast<libcamera::Request*>(static_cast<uintptr_t>(frame.token));
  if (!d.started || request == nullptr) return;
  request->reuse(libcamera::Request::ReuseBuffers);
  (void)d.camera->queueRequest(request);
}

void ColourStream::stop() {
  Impl& d = *impl_;
  if (!d.started) return;
  d.started = false;
  d.camera->stop();  // completes every queued request as cancelled
  std::lock_guard<std::mutex> lock(d.mutex);
  d.head = d.size = 0;
}

void ColourStream::close() {
  Impl& d = *impl_;
  stop();
  if (d.camera) d.camera->requestCompleted.disconnect(impl_.get());
  d.requests.clear();
  for (const Impl::Mapping& m : d.mappings) munmap(m.base, m.size);
  d.mappings.clear();
  d.plane0.clear();
  d.mapped_bytes = 0;
  if (d.allocator && d.stream) d.allocator->free(d.stream);
  d.allocator.reset();
  d.config.reset();
  d.stream = nullptr;
  if (d.acquired) d.camera->release();
  d.acquired = false;
  d.camera.reset();
  if (d.manager) ManagerHolder::release();
  d.manager = nullptr;
}

// ---------------------------------------------------------------------------
// LibcameraCamera

struct LibcameraCamera::Registration {
  explicit Registration(hal::DepthToColourRegistration r) : kernel(std::move(r)) {}
  hal::DepthToColourRegistration kernel;
};

LibcameraCamera::LibcameraCamera(LibcameraCameraOptions options, DepthCameraFactory make_depth)
    : options_(std::move(options)), make_depth_(make_depth), colour_(std::make_unique<ColourStream>()) {
  info_.name = "libcamera:" + options_.camera;
}

LibcameraCamera::LibcameraCamera(LibcameraCameraOptions options, std::unique_ptr<Camera> depth,
                                 std::unique_ptr<ColourSource> colour)
    : options_(std::move(options)), depth_(std::move(depth)), colour_(std::move(colour)) {
  info_.name = "libcamera:" + options_.camera;
}

LibcameraCamera::~LibcameraCamera() {
  stop();
  colour_->close();
}

Result<std::unique_ptr<Camera>> LibcameraCamera::create(std::string_view args, DepthCameraFactory make_depth) {
  Result<LibcameraCameraOptions> options = parseLibcameraCameraOptions(args);
  if (!options) return options.status();
  // The depth camera's spec is checked now, so a bad one fails with the rest.
  Result<std::unique_ptr<Camera>> depth = make_depth(options->depth_spec);
  if (!depth) return Status(depth.status().code(), "libcamera: depth=" + options->depth_spec + ": " +
                                                        depth.status().message());
  auto camera = std::make_unique<LibcameraCamera>(std::move(options).value(), make_depth);
  camera->depth_ = std::move(depth).value();
  return std::unique_ptr<Camera>(std::move(camera));
}

Status LibcameraCamera::setCalibration(const CameraCalibration& calibration) {
  calibration_ = calibration;
  return Status::ok();
}

CameraCounters LibcameraCamera::counters() const {
  CameraCounters c = counters_.snapshot();
  if (depth_) {
    const CameraCounters d = depth_->counters();
    c.timeouts += d.timeouts;
    c.errors += d.errors;
    c.stalls += d.stalls;
    c.disconnects += d.disconnects;
    c.bad_frames += d.bad_frames;
  }
  c.bad_frames += colour_->failedFrames();
  return c;
}

Status LibcameraCamera::open() {
  stop();
  opened_ = false;
  registration_.reset();
  if (!depth_) {
    if (make_depth_ == nullptr) return {ErrorCode::kInvalidArgument, "libcamera: no depth camera was given"};
    Result<std::unique_ptr<Camera>> depth = make_depth_(options_.depth_spec);
    if (!depth) return depth.status();
    depth_ = std::move(depth).value();
  }
  if (!calibration_ || !calibration_->colour || !calibration_->T_colour_depth) {
    return {ErrorCode::kInvalidArgument,
            "libcamera: the colour camera must be registered to the depth camera " + options_.depth_spec +
                ": give a calibration with the colour camera's intrinsics and T_colour_depth (board profile "
                "[camera.calibration] or a calibration file, docs/cameras-libcamera.md)"};
  }
  if (calibration_->depth || calibration_->depth_scale_m) {
    CameraCalibration depth_part;
    depth_part.depth = calibration_->depth;
    depth_part.depth_scale_m = calibration_->depth_scale_m;
    depth_part.source = calibration_->source;
    if (Status s = depth_->setCalibration(depth_part); !s) return s;
  }
  if (Status s = depth_->open(); !s) {
    return {s.code(), "libcamera: depth camera " + options_.depth_spec + ": " + s.message()};
  }
  if (Status s = colour_->open(options_); !s) return s;
  const StreamCalibration& colour_cal = *calibration_->colour;
  if (colour_cal.intrinsics.width != colour_->width() || colour_cal.intrinsics.height != colour_->height()) {
    const std::string size = std::to_string(colour_->width()) + "x" + std::to_string(colour_->height());
    colour_->close();
    return {ErrorCode::kInvalidArgument,
            "libcamera: the colour calibration from " + calibration_->source + " is for " +
                std::to_string(colour_cal.intrinsics.width) + "x" + std::to_string(colour_cal.intrinsics.height) +
                ", camera " + colour_->id() + " streams " + size + ": set size= to the calibrated size"};
  }
  const CameraInfo& depth_info = depth_->info();
  hal::RegistrationParams params;
  params.depth.intrinsics = depth_info.intrinsics;
  params.colour = colour_cal;
  params.T_colour_depth = *calibration_->T_colour_depth;
  params.depth_scale_m = depth_info.depth_scale_m;
  Result<hal::DepthToColourRegistration> registration = hal::DepthToColourRegistration::create(params);
  if (!registration) {
    colour_->close();
    return {registration.status().code(), "libcamera: calibration from " + calibration_->source + ": " +
                                              registration.status().message()};
  }
  registration_ = std::make_unique<Registration>(std::move(registration).value());

  info_ = depth_info;
  info_.name = "libcamera:" + options_.camera;
  info_.model = colour_->model() + " + " + (depth_info.model.empty() ? options_.depth_spec : depth_info.model);
  info_.device_buffer_bytes = depth_info.device_buffer_bytes + colour_->mappedBytes();
  constexpr std::size_t kColourSlots = 3;
  colour_slots_.assign(kColourSlots,
                       std::vector<uint8_t>(static_cast<std::size_t>(colour_->width()) * colour_->height() * 3));
  pairer_ = TimestampPairer(kColourSlots, static_cast<int64_t>(0.5e9 / std::max(info_.fps, 1.0)));
  opened_ = true;
  return Status::ok();
}

Status LibcameraCamera::start() {
  if (!opened_) return {ErrorCode::kUnavailable, "libcamera camera: call open() before start()"};
  if (started_) return Status::ok();
  if (Status s = depth_->start(); !s) return s;
  if (Status s = colour_->start(); !s) {
    depth_->stop();
    return s;
  }
  pairer_.clear();
  newest_colour_ns_ = INT64_MIN;
  started_ = true;
  return Status::ok();
}

void LibcameraCamera::stop() {
  if (!started_) return;
  started_ = false;
  colour_->stop();
  depth_->stop();
}

// Converts every completed colour frame into the pairer's slots, waiting up to
// `wait` for the first.
void LibcameraCamera::drainColour(std::chrono::nanoseconds wait) {
  ColourFrame frame;
  while (colour_->next(frame, wait).isOk()) {
    wait = std::chrono::nanoseconds(0);
    const int slot = pairer_.nextColourSlot();
    if (packedRgbToRgb8(colour_->layout(), frame.data, frame.bytes, frame.stride, colour_->width(), colour_->height(),
                        colour_slots_[static_cast<std::size_t>(slot)].data())) {
      pairer_.pushColour(frame.stamp_ns);
      newest_colour_ns_ = frame.stamp_ns;
    } else {
      counters_.badFrame();
    }
    colour_->release(frame);
  }
}

Status LibcameraCamera::acquire(RgbdFrame& slot, std::chrono::nanoseconds timeout) {
  if (!started_) {
    counters_.error();
    return Status(ErrorCode::kUnavailable, "not started");
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  drainColour(std::chrono::nanoseconds(0));
  const Status depth = depth_->acquire(slot, timeout);
  if (!depth) return depth;
  // Its colour frame may still be on its way: wait for one as new as the
  // depth frame, at most the pairing tolerance (and the caller's deadline).
  const auto colour_deadline =
      std::min(deadline, std::chrono::steady_clock::now() + std::chrono::nanoseconds(pairer_.toleranceNs()));
  drainColour(std::chrono::nanoseconds(0));
  while (newest_colour_ns_ < slot.stamp_ns) {
    const auto left = colour_deadline - std::chrono::steady_clock::now();
    if (left <= std::chrono::nanoseconds(0)) break;
    drainColour(left);
  }
  if (const std::optional<int> c = pairer_.pairDepth(slot.stamp_ns)) {
    (void)registration_->kernel.apply(slot.depth(), colour_slots_[static_cast<std::size_t>(*c)].data(), slot.rgb());
    slot.has_rgb = true;
  } else {
    slot.has_rgb = false;
  }
  counters_.frameDelivered();
  return Status::ok();
}

}  // namespace fovea::hal::libcam

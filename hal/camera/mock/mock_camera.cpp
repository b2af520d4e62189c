#include "hal/spec_options.h"
#include "hal/camera/mock/mock_camera.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>
#include <thread>
#include <utility>

#include "hal/camera/mock/hash.h"

namespace fovea::hal::mock {

namespace {

using Eigen::Vector3d;

// Kinect v1 nominal focal length at 640 pixels wide.
constexpr double kFocalAt640 = 525.0;
constexpr double kDepthScaleM = 0.001;
constexpr double kMinRangeM = 0.4;
constexpr double kMaxRangeM = 8.0;
// Nguyen, Izadi, Lovell 2012, axial noise.
constexpr double kSigmaBaseM = 0.0012;
constexpr double kSigmaQuadraticPerM = 0.0019;
constexpr double kSigmaAngleM = 0.0001;
constexpr double kSigmaAngleCapRad = 80.0 * std::numbers::pi / 180.0;
// Dropout: incidence ramp, random speckle, discontinuity bands.
constexpr double kGrazingStartDeg = 75.0;
constexpr double kGrazingFullDeg = 85.0;
constexpr double kRandomDropout = 0.003;
constexpr double kEdgeJumpM = 0.03;     // a neighbour nearer by more than this
constexpr double kEdgeJumpPerM = 0.02;  // ... plus this per metre of its depth is an occluder
constexpr float kShadowDropout = 0.5f;  // second pixel of the projector's shadow
constexpr int kEdgeReachPx = 2;
constexpr int kRgbNoiseLevels = 4;  // +- per channel

constexpr int kMinSide = 16;
constexpr int kMaxSide = 4096;
constexpr double kMaxFps = 1000.0;

constexpr std::string_view kKeyList =
    "seed, size, fps, path, noise, temporal_noise, realtime, fault";
constexpr std::string_view kPathValues = "static|pan|orbit|dolly|keyframes:t,x,y,z,tx,ty,tz;...";

Status invalid(std::string message) {
  return Status(ErrorCode::kInvalidArgument, "mock: " + std::move(message));
}

std::string formatNumber(double value) {
  char buffer[32];
  const auto [end, ec] = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return ec == std::errc() ? std::string(buffer, end) : std::string("?");
}

Status parseKeyframes(std::string_view list, std::vector<Keyframe>& keyframes) {
  const std::string format =
      "expected keyframes:t,x,y,z,tx,ty,tz;... (time in s, eye and look-at target in world m)";
  std::size_t start = 0;
  while (start <= list.size()) {
    const std::size_t semi = std::min(list.find(';', start), list.size());
    const std::string_view group = list.substr(start, semi - start);
    start = semi + 1;
    if (group.empty()) {
      if (start > list.size()) break;  // a trailing ';'
      return invalid("path: empty keyframe; " + format);
    }
    const std::string label = "path: keyframe " + std::to_string(keyframes.size() + 1);
    double numbers[7];
    int count = 0;
    std::size_t pos = 0;
    while (pos <= group.size()) {
      const std::size_t comma = std::min(group.find(',', pos), group.size());
      const std::string_view field = group.substr(pos, comma - pos);
      if (count == 7) return invalid(label + " has more than 7 numbers; " + format);
      if (!parseSpecDouble(field, numbers[count])) {
        return invalid(label + ": '" + std::string(field) + "' is not a number; " + format);
      }
      ++count;
      pos = comma + 1;
    }
    if (count != 7) {
      return invalid(label + " has " + std::to_string(count) + " numbers; " + format);
    }
    Keyframe k;
    k.t_s = numbers[0];
    k.eye_m = Vector3d(numbers[1], numbers[2], numbers[3]);
    k.target_m = Vector3d(numbers[4], numbers[5], numbers[6]);
    if ((k.target_m - k.eye_m).norm() < 1e-6) {
      return invalid(label + ": the eye and the target coincide");
    }
    if (!keyframes.empty() && !(k.t_s > keyframes.back().t_s)) {
      return invalid(label + ": times must increase, got " + formatNumber(k.t_s) + " s after " +
                     formatNumber(keyframes.back().t_s) + " s");
    }
    keyframes.push_back(k);
  }
  if (keyframes.empty()) return invalid("path: no keyframes; " + format);
  return Status::ok();
}

Status parsePath(std::string_view value, CameraPath& path) {
  constexpr std::string_view kKeyframesPrefix = "keyframes:";
  path.keyframes.clear();
  if (value == "static") {
    path.kind = PathKind::kStatic;
  } else if (value == "pan") {
    path.kind = PathKind::kPan;
  } else if (value == "orbit") {
    path.kind = PathKind::kOrbit;
  } else if (value == "dolly") {
    path.kind = PathKind::kDolly;
  } else if (value.substr(0, kKeyframesPrefix.size()) == kKeyframesPrefix) {
    path.kind = PathKind::kKeyframes;
    return parseKeyframes(value.substr(kKeyframesPrefix.size()), path.keyframes);
  } else {
    return invalid("path: expected " + std::string(kPathValues) + ", got '" + std::string(value) +
                   "'");
  }
  return Status::ok();
}

Vector3d lerp(const Vector3d& a, const Vector3d& b, double alpha) { return a + (b - a) * alpha; }

uint8_t toByte(float channel) {
  return static_cast<uint8_t>(std::clamp(channel, 0.0f, 1.0f) * 255.0f + 0.5f);
}

// acos on [0, 1] within 7e-5 rad (Abramowitz and Stegun 4.4.45); libm's acos
// was a tenth of the render time.
double acosUnit(double x) {
  return std::sqrt(1.0 - x) * (1.5707288 + x * (-0.2121144 + x * (0.0742610 - 0.0187293 * x)));
}

bool inRange(double z_m) { return z_m >= kMinRangeM && z_m <= kMaxRangeM; }

// Nearest depth unit (halves round up), at least 1 (0 means "no measurement").
uint16_t toDepthUnits(double z_m) {
  const double units = std::clamp(z_m / kDepthScaleM + 0.5, 1.0, 65535.0);
  return static_cast<uint16_t>(units);
}

uint8_t addRgbNoise(uint8_t clean, uint64_t bits) {
  const int byte = static_cast<int>(bits & 0xFFu);
  const int delta = ((byte * (2 * kRgbNoiseLevels + 1)) >> 8) - kRgbNoiseLevels;
  return static_cast<uint8_t>(std::clamp(clean + delta, 0, 255));
}

}  // namespace

Pose cameraPoseAt(const CameraPath& path, const SceneInfo& scene, double time_s) {
  const Vector3d& eye = scene.default_eye_m;
  const Vector3d& target = scene.default_target_m;
  switch (path.kind) {
    case PathKind::kStatic: break;
    case PathKind::kPan: {
      const double yaw = scene.pan_amplitude_rad * std::sin(kTwoPi * time_s / scene.pan_period_s);
      const Vector3d d = target - eye;
      const double c = std::cos(yaw);
      const double s = std::sin(yaw);
      return lookAtPose(eye, eye + Vector3d(c * d.x() - s * d.y(), s * d.x() + c * d.y(), d.z()));
    }
    case PathKind::kOrbit: {
      const Vector3d& focus = scene.focus_point_m;
      const double azimuth0 = std::atan2(eye.y() - focus.y(), eye.x() - focus.x());
      const double phase = kTwoPi * time_s / scene.orbit_period_s;
      const double azimuth = scene.orbit_sweep_rad == 0.0
                                 ? azimuth0 + phase
                                 : azimuth0 + scene.orbit_sweep_rad * std::sin(phase);
      const Vector3d orbit_eye(focus.x() + scene.orbit_radius_m * std::cos(azimuth),
                               focus.y() + scene.orbit_radius_m * std::sin(azimuth),
                               scene.orbit_height_m);
      return lookAtPose(orbit_eye, focus);
    }
    case PathKind::kDolly: {
      const Vector3d forward = (target - eye).normalized();
      const double travel_m =
          scene.dolly_distance_m * 0.5 * (1.0 - std::cos(kTwoPi * time_s / scene.dolly_period_s));
      return lookAtPose(eye + travel_m * forward, target + travel_m * forward);
    }
    case PathKind::kKeyframes: {
      const std::vector<Keyframe>& keys = path.keyframes;
      if (keys.empty()) break;
      if (time_s <= keys.front().t_s) return lookAtPose(keys.front().eye_m, keys.front().target_m);
      if (time_s >= keys.back().t_s) return lookAtPose(keys.back().eye_m, keys.back().target_m);
      const auto next = std::upper_bound(keys.begin(), keys.end(), time_s,
                                         [](double t, const Keyframe& k) { return t < k.t_s; });
      const Keyframe& b = *next;
      const Keyframe& a = *(next - 1);
      const double alpha = (time_s - a.t_s) / (b.t_s - a.t_s);
      return lookAtPose(lerp(a.eye_m, b.eye_m, alpha), lerp(a.target_m, b.target_m, alpha));
    }
  }
  return lookAtPose(eye, target);
}

Result<MockCameraOptions> parseMockCameraOptions(std::string_view args) {
  MockCameraOptions options;
  // A piece without '=' continues the previous value (keyframe lists hold commas).
  const SpecTokens tokens = tokenizeSpec(args, {.head = SpecTokenRules::Head::kFirstItem, .rest_key = {}, .bare_continues_value = true});
  const std::string_view scene = tokens.head.value_or("");
  if (scene.empty()) {
    return invalid("missing scene: expected mock:SCENE[,key=value...] with SCENE one of " +
                   Scene::names());
  }
  if (!Scene::isKnown(scene)) {
    return invalid("unknown scene '" + std::string(scene) + "'; accepted: " + Scene::names());
  }
  options.scene = std::string(scene);
  // A bare item can only come first: after a key=value, bare pieces continue its value.
  if (!tokens.items.empty() && !tokens.items.front().has_value) {
    return invalid("expected key=value after the scene, got '" + std::string(tokens.items.front().key) +
                   "'; keys: " + std::string(kKeyList));
  }

  std::vector<std::string_view> seen;
  for (const SpecItem& item : tokens.items) {
    const std::string key(item.key);
    const std::string value(item.value);
    if (std::find(seen.begin(), seen.end(), item.key) != seen.end()) {
      return invalid("key '" + key + "' given twice");
    }
    seen.push_back(item.key);
    Status status;
    if (key == "seed") {
      if (!parseSpecUint(value, options.seed)) {
        status = invalid("seed: expected an unsigned integer, got '" + value + "'");
      }
    } else if (key == "size") {
      status = parseSpecSize("mock", key, value, kMinSide, kMaxSide, options.width, options.height);
    } else if (key == "fps") {
      if (!parseSpecDouble(value, options.fps) || options.fps <= 0.0 || options.fps > kMaxFps) {
        status = invalid("fps: expected a number in (0, " + formatNumber(kMaxFps) + "], got '" +
                         value + "'");
      }
    } else if (key == "path") {
      status = parsePath(value, options.path);
    } else if (key == "noise") {
      status = parseSpecOnOff("mock", key, value, options.noise);
    } else if (key == "temporal_noise") {
      status = parseSpecOnOff("mock", key, value, options.temporal_noise);
    } else if (key == "realtime") {
      status = parseSpecOnOff("mock", key, value, options.realtime);
    } else if (key == "fault") {
      Result<std::vector<FaultSpec>> faults = parseFaults(value);
      if (faults.isOk()) {
        options.faults = std::move(faults).value();
      } else {
        status = faults.status();
      }
    } else {
      status = invalid("unknown key '" + key + "'; accepted keys: " + std::string(kKeyList));
    }
    if (!status.isOk()) return status;
  }
  return options;
}

std::string mockCameraHelp() {
  return "mock:SCENE[,key=value...]  ray-cast Kinect-like RGB-D camera. SCENE: " + Scene::names() +
         ". Keys (default): seed=UINT (1), size=WxH (640x480), fps=F (30), path=" +
         std::string(kPathValues) +
         " (static), noise=on|off (on), temporal_noise=on|off (on), realtime=on|off (off), " +
         faultHelp();
}

void MockCamera::CleanImage::resize(std::size_t pixels) {
  depth_m.assign(pixels, 0.0);
  sigma_m.assign(pixels, 0.0f);
  drop_prob.assign(pixels, 1.0f);
  rgb.assign(pixels * 3, 0);
}

MockCamera::MockCamera(MockCameraOptions options) : options_(std::move(options)) {
  fault_fired_.assign(options_.faults.size(), false);
  Result<Scene> scene = Scene::create(options_.scene);
  if (scene.isOk()) scene_ = std::move(scene).value();
  info_.name = "mock:" + options_.scene;
  CameraIntrinsics& k = info_.intrinsics;
  k.width = options_.width;
  k.height = options_.height;
  k.fx = kFocalAt640 * options_.width / 640.0;
  k.fy = k.fx;
  k.cx = (options_.width - 1) / 2.0;
  k.cy = (options_.height - 1) / 2.0;
  info_.depth_scale_m = kDepthScaleM;
  info_.fps = options_.fps;
  if (scene_.shapeCount() > 0) info_.focus_point_m = scene_.info().focus_point_m;
}

Result<std::unique_ptr<Camera>> MockCamera::create(std::string_view args) {
  Result<MockCameraOptions> options = parseMockCameraOptions(args);
  if (!options.isOk()) return options.status();
  return std::unique_ptr<Camera>(std::make_unique<MockCamera>(std::move(options).value()));
}

// The device-gone messages fit std::string's small buffer: reconnect attempts
// do not allocate.
Status MockCamera::open() {
  if (!connected_) {
    if (clock_->nowNs() < gone_until_ns_) return Status(ErrorCode::kNotFound, "device gone");
    connected_ = true;
  }
  if (opened_) return Status::ok();
  const int w = options_.width;
  const int h = options_.height;
  if (w < kMinSide || w > kMaxSide || h < kMinSide || h > kMaxSide) {
    return invalid("size " + std::to_string(w) + "x" + std::to_string(h) + " is outside " +
                   std::to_string(kMinSide) + ".." + std::to_string(kMaxSide));
  }
  if (!(options_.fps > 0.0 && options_.fps <= kMaxFps)) {
    return invalid("fps " + formatNumber(options_.fps) + " is outside (0, 1000]");
  }
  if (scene_.shapeCount() == 0) return invalid("unknown scene '" + options_.scene + "'");
  if (options_.path.kind == PathKind::kKeyframes && options_.path.keyframes.empty()) {
    return invalid("path: no keyframes");
  }
  const auto pixels = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  ray_x_.resize(static_cast<std::size_t>(w));
  ray_y_.resize(static_cast<std::size_t>(h));
  const CameraIntrinsics& k = info_.intrinsics;
  for (int x = 0; x < w; ++x) ray_x_[static_cast<std::size_t>(x)] = (x - k.cx) / k.fx;
  for (int y = 0; y < h; ++y) ray_y_[static_cast<std::size_t>(y)] = (y - k.cy) / k.fy;
  work_.resize(pixels);
  if (scene_.isDynamic()) background_.resize(pixels);
  final_drop_prob_.assign(pixels, 1.0f);
  near_row_min_m_.assign(pixels, 0.0f);
  const std::size_t shapes = scene_.staticShapeCount();
  if (shapes > 65535) return invalid("scene has more than 65535 static shapes");
  shape_rects_.resize(shapes);
  shape_order_.resize(shapes);
  row_shapes_.resize(shapes);
  active_shapes_.resize(shapes);
  row_hits_.resize(static_cast<std::size_t>(w));
  have_render_ = false;
  dynamic_rect_ = {};
  opened_ = true;
  return Status::ok();
}

Status MockCamera::start() {
  if (!opened_) return Status(ErrorCode::kUnavailable, "mock camera: call open() before start()");
  if (!connected_) return Status(ErrorCode::kNotFound, "device gone");
  started_ = true;
  start_time_ = std::chrono::steady_clock::now();
  start_sequence_ = sequence_;
  return Status::ok();
}

void MockCamera::stop() { started_ = false; }

// Error messages here stay within std::string's small-buffer capacity (15
// characters in libstdc++), so even the error paths do not allocate.
Status MockCamera::acquire(RgbdFrame& slot, std::chrono::nanoseconds timeout) {
  if (!started_) {
    counters_.error();
    return Status(ErrorCode::kUnavailable, "not started");
  }
  if (!connected_) {
    counters_.error();
    return Status(ErrorCode::kNotFound, "disconnected");
  }
  if (!slot.setSize(options_.width, options_.height)) {
    counters_.error();
    return Status(ErrorCode::kCapacityExceeded, "slot too small");
  }
  if (options_.realtime) {
    using Clock = std::chrono::steady_clock;
    const auto dueAt = [&](uint64_t sequence) {
      const double offset_s = static_cast<double>(sequence - start_sequence_) / options_.fps;
      return start_time_ +
             std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(offset_s));
    };
    const Clock::time_point now = Clock::now();
    const double elapsed_s = std::chrono::duration<double>(now - start_time_).count();
    const uint64_t latest = start_sequence_ + static_cast<uint64_t>(elapsed_s * options_.fps);
    if (latest > sequence_) sequence_ = latest;  // the consumer was slow: frames dropped
    const Clock::time_point due = dueAt(sequence_);
    if (due > now) {
      if (due - now > timeout) {
        std::this_thread::sleep_for(timeout);
        counters_.timeout();
        return Status(ErrorCode::kUnavailable, "timeout");
      }
      std::this_thread::sleep_until(due);
    }
  }

  if (!options_.faults.empty()) {
    if (Status s = fireFaults(); !s) return s;
    if (stalling_) {
      // Nothing comes until the stall ends: block for the timeout, or until the end.
      const int64_t now_ns = clock_->nowNs();
      if (now_ns < stall_until_ns_) {
        if (stall_until_ns_ - now_ns > timeout.count()) {
          clock_->sleepUntilNs(now_ns + std::max<int64_t>(timeout.count(), 0));
          counters_.timeout();
          return Status(ErrorCode::kUnavailable, "stalled");
        }
        clock_->sleepUntilNs(stall_until_ns_);
      }
      stalling_ = false;
    }
    if (wrong_size_pending_ > 0) {
      // The device's frame header says a size the intrinsics do not: checked
      // before anything is copied, so the slot is never written out of bounds
      // (its pixels keep the previous frame's).
      --wrong_size_pending_;
      const int device_width = options_.width + 16;
      const int device_height = options_.height + 8;
      if (device_width != info_.intrinsics.width || device_height != info_.intrinsics.height) {
        ++sequence_;  // the malformed frame is gone; the next one may be fine
        counters_.badFrame();
        counters_.error();
        return Status(ErrorCode::kInvalidInput, "wrong size");
      }
    }
  }

  const uint64_t sequence = sequence_;
  const double time_s = static_cast<double>(sequence) / options_.fps;
  const Pose pose = cameraPoseAt(options_.path, scene_.info(), time_s);
  renderClean(pose, time_s);
  if (garbage_pending_ > 0) {
    --garbage_pending_;
    writeGarbage(slot, sequence);
    counters_.injectedGarbage();
  } else {
    writeFrame(slot, sequence);
  }
  slot.intrinsics = info_.intrinsics;
  slot.depth_scale_m = kDepthScaleM;
  slot.T_world_cam = pose;
  slot.has_rgb = true;
  slot.stamp_ns =
      static_cast<int64_t>(std::llround(static_cast<double>(sequence) * 1e9 / options_.fps));
  slot.sequence = sequence;
  ++sequence_;
  counters_.frameDelivered();
  return Status::ok();
}

Status MockCamera::fireFaults() {
  Status result;
  for (std::size_t i = 0; i < options_.faults.size(); ++i) {
    const FaultSpec& fault = options_.faults[i];
    if (fault_fired_[i] || fault.at_frame > sequence_) continue;
    fault_fired_[i] = true;
    switch (fault.kind) {
      case FaultKind::kStall:
        stall_until_ns_ = std::max(stalling_ ? stall_until_ns_ : clock_->nowNs(),
                                   clock_->nowNs() + fault.duration_ns);
        stalling_ = true;
        counters_.stall();
        break;
      case FaultKind::kDisconnect:
        gone_until_ns_ = clock_->nowNs() + fault.duration_ns;
        connected_ = false;
        counters_.disconnect();
        counters_.error();
        result = Status(ErrorCode::kNotFound, "disconnected");
        break;
      case FaultKind::kWrongSize: wrong_size_pending_ += fault.count; break;
      case FaultKind::kGarbage: garbage_pending_ += fault.count; break;
    }
  }
  return result;
}

// Random depth with both extremes well represented, random colour; a pure
// function of (seed, sequence, pixel) like the sensor noise.
void MockCamera::writeGarbage(RgbdFrame& slot, uint64_t sequence) const {
  const std::size_t pixels =
      static_cast<std::size_t>(options_.width) * static_cast<std::size_t>(options_.height);
  uint16_t* depth = slot.depth();
  uint8_t* rgb = slot.rgb();
  const uint64_t frame_key = hash2(hash2(options_.seed, 0x6761726261676521ull), sequence);
  for (std::size_t i = 0; i < pixels; ++i) {
    const uint64_t h = hash2(frame_key, i);
    switch (h & 7u) {
      case 0: depth[i] = 0; break;
      case 1: depth[i] = 65535; break;
      default: depth[i] = static_cast<uint16_t>(h >> 16); break;
    }
    rgb[3 * i] = static_cast<uint8_t>(h >> 32);
    rgb[3 * i + 1] = static_cast<uint8_t>(h >> 40);
    rgb[3 * i + 2] = static_cast<uint8_t>(h >> 48);
  }
}

void MockCamera::renderClean(const Pose& pose, double time_s) {
  const bool same_pose = have_render_ && pose.R_world_cam == rendered_pose_.R_world_cam &&
                         pose.t_world_cam == rendered_pose_.t_world_cam;
  if (!scene_.isDynamic()) {
    if (same_pose) return;
    renderRect(pose, time_s, SceneLayer::kAll, fullRect(), work_);
    updateDropouts(fullRect());
  } else {
    PixelRect dirty;
    if (!same_pose) {
      renderRect(pose, time_s, SceneLayer::kStatic, fullRect(), background_);
      dirty = fullRect();
      copyRect(background_, dirty, work_);
    } else {
      dirty = dynamic_rect_;
      copyRect(background_, dirty, work_);
    }
    const PixelRect rect = dynamicRect(pose, time_s);
    renderRect(pose, time_s, SceneLayer::kDynamic, rect, work_);
    dynamic_rect_ = rect;
    updateDropouts(grow(unite(dirty, rect), kEdgeReachPx));
  }
  rendered_pose_ = pose;
  have_render_ = true;
}

void MockCamera::renderRect(const Pose& pose, double time_s, SceneLayer layer,
                            const PixelRect& rect, CleanImage& out) {
  if (rect.empty()) return;
  const Vector3d origin = pose.t_world_cam;
  const Vector3d r0 = pose.R_world_cam.col(0);
  const Vector3d r1 = pose.R_world_cam.col(1);
  const Vector3d r2 = pose.R_world_cam.col(2);
  const std::size_t width = static_cast<std::size_t>(options_.width);
  const bool static_layer = layer != SceneLayer::kDynamic;
  const bool dynamic_layer = layer != SceneLayer::kStatic && scene_.isDynamic();
  // Screen-space culling of the static shapes: each shape's projected bounds,
  // the shapes sorted by their first column, and per row a sweep that keeps
  // the shapes covering the current pixel.
  const std::size_t shape_count = scene_.staticShapeCount();
  if (static_layer) {
    for (std::size_t s = 0; s < shape_count; ++s) {
      Vector3d lo, hi;
      shape_rects_[s] = scene_.staticShapeBounds(s, lo, hi) ? projectBox(pose, lo, hi) : fullRect();
      shape_order_[s] = static_cast<uint16_t>(s);
    }
    std::sort(shape_order_.begin(), shape_order_.end(), [&](uint16_t a, uint16_t b) {
      return shape_rects_[a].x0 < shape_rects_[b].x0 ||
             (shape_rects_[a].x0 == shape_rects_[b].x0 && a < b);
    });
  }
  for (int y = rect.y0; y < rect.y1; ++y) {
    const Vector3d row = r1 * ray_y_[static_cast<std::size_t>(y)] + r2;
    std::size_t row_count = 0;
    std::size_t next_in_row = 0;
    std::size_t active_count = 0;
    std::size_t hit_count = 0;
    if (static_layer) {
      for (const uint16_t s : shape_order_) {
        const PixelRect& r = shape_rects_[s];
        if (!r.empty() && y >= r.y0 && y < r.y1) row_shapes_[row_count++] = s;
      }
    }
    for (int x = rect.x0; x < rect.x1; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * width + static_cast<std::size_t>(x);
      // d_cam = (x', y', 1), so the ray parameter t of a hit is its depth z.
      const Vector3d dir = r0 * ray_x_[static_cast<std::size_t>(x)] + row;
      Hit hit;
      bool found = false;
      double t_max = kInf;
      if (static_layer) {
        while (next_in_row < row_count && shape_rects_[row_shapes_[next_in_row]].x0 <= x) {
          active_shapes_[active_count++] = row_shapes_[next_in_row++];
        }
        std::size_t kept = 0;
        for (std::size_t j = 0; j < active_count; ++j) {
          if (shape_rects_[active_shapes_[j]].x1 > x) active_shapes_[kept++] = active_shapes_[j];
        }
        active_count = kept;
        found = scene_.intersectShapes(origin, dir, active_shapes_.data(), active_count, kInf, hit);
        if (found) t_max = hit.t;
      } else if (out.depth_m[i] > 0.0) {
        t_max = out.depth_m[i];  // the static layer already rendered there
      }
      if (dynamic_layer)
        found |= scene_.intersect(origin, dir, time_s, SceneLayer::kDynamic, t_max, hit);
      if (!found) {
        if (static_layer) {
          out.depth_m[i] = 0.0;
          out.sigma_m[i] = 0.0f;
          out.drop_prob[i] = 1.0f;
          std::memset(&out.rgb[3 * i], 0, 3);
        }
        continue;
      }
      out.depth_m[i] = hit.t;
      const Eigen::Vector3f color = scene_.shade(origin, dir, hit);
      out.rgb[3 * i + 0] = toByte(color.x());
      out.rgb[3 * i + 1] = toByte(color.y());
      out.rgb[3 * i + 2] = toByte(color.z());
      row_hits_[hit_count++] = {x, static_cast<float>(std::abs(hit.normal.dot(dir))),
                                static_cast<float>(dir.squaredNorm()), scene_.irDropout(hit)};
    }
    // Second pass over the row's hits: the noise model's square roots and
    // divisions, in a tight loop whose iterations overlap (inline with the
    // ray cast, their latency was a third of the render time).
    const std::size_t row_start = static_cast<std::size_t>(y) * width;
    for (std::size_t k = 0; k < hit_count; ++k) {
      const RowHit& h = row_hits_[k];
      const std::size_t i = row_start + static_cast<std::size_t>(h.x);
      const double z_m = out.depth_m[i];
      const double cos_incidence = std::min(
          1.0, static_cast<double>(h.n_dot_d) / std::sqrt(static_cast<double>(h.d_squared)));
      const double theta_rad = acosUnit(cos_incidence);
      const double theta_capped = std::min(theta_rad, kSigmaAngleCapRad);
      const double angle_ratio = theta_capped / (std::numbers::pi / 2.0 - theta_capped);
      const double sigma_m = kSigmaBaseM + kSigmaQuadraticPerM * (z_m - 0.4) * (z_m - 0.4) +
                             kSigmaAngleM / std::sqrt(z_m) * angle_ratio * angle_ratio;
      const double theta_deg = theta_rad * (180.0 / std::numbers::pi);
      const double p_grazing = std::clamp(
          (theta_deg - kGrazingStartDeg) / (kGrazingFullDeg - kGrazingStartDeg), 0.0, 1.0);
      const double p_keep = (1.0 - p_grazing) * (1.0 - h.ir_dropout) * (1.0 - kRandomDropout);
      out.sigma_m[i] = static_cast<float>(sigma_m);
      out.drop_prob[i] = static_cast<float>(1.0 - p_keep);
    }
  }
}

void MockCamera::copyRect(const CleanImage& from, const PixelRect& rect, CleanImage& to) const {
  if (rect.empty()) return;
  const auto width = static_cast<std::size_t>(options_.width);
  const auto n = static_cast<std::size_t>(rect.x1 - rect.x0);
  for (int y = rect.y0; y < rect.y1; ++y) {
    const std::size_t i = static_cast<std::size_t>(y) * width + static_cast<std::size_t>(rect.x0);
    std::memcpy(&to.depth_m[i], &from.depth_m[i], n * sizeof(double));
    std::memcpy(&to.sigma_m[i], &from.sigma_m[i], n * sizeof(float));
    std::memcpy(&to.drop_prob[i], &from.drop_prob[i], n * sizeof(float));
    std::memcpy(&to.rgb[3 * i], &from.rgb[3 * i], 3 * n);
  }
}

// The pixels whose rays can meet the box. Rays reach only z > kMinT in the
// camera frame, so the box is clipped there first: its projection is bounded by
// the projections of the corners in front and of the points where its edges
// cross the clipping plane. Then a margin of a pixel; empty when the box is
// wholly behind.
MockCamera::PixelRect MockCamera::projectBox(const Pose& pose, const Vector3d& lo,
                                             const Vector3d& hi) const {
  constexpr double kNearM = Scene::kMinT;
  const CameraIntrinsics& k = info_.intrinsics;
  Vector3d corners[8];
  for (int c = 0; c < 8; ++c) {
    const Vector3d p_world((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(),
                           (c & 4) ? hi.z() : lo.z());
    corners[c] = pose.R_world_cam.transpose() * (p_world - pose.t_world_cam);
  }
  double u_min = kInf, u_max = -kInf, v_min = kInf, v_max = -kInf;
  const auto include = [&](const Vector3d& p) {
    const double u = k.fx * p.x() / p.z() + k.cx;
    const double v = k.fy * p.y() / p.z() + k.cy;
    u_min = std::min(u_min, u);
    u_max = std::max(u_max, u);
    v_min = std::min(v_min, v);
    v_max = std::max(v_max, v);
  };
  for (int c = 0; c < 8; ++c) {
    if (corners[c].z() >= kNearM) include(corners[c]);
    for (const int bit : {1, 2, 4}) {  // the three edges from c to a corner with one more bit
      if ((c & bit) != 0) continue;
      const Vector3d& a = corners[c];
      const Vector3d& b = corners[c | bit];
      if ((a.z() < kNearM) == (b.z() < kNearM)) continue;
      Vector3d crossing = a + (b - a) * ((kNearM - a.z()) / (b.z() - a.z()));
      crossing.z() = kNearM;
      include(crossing);
    }
  }
  if (u_min > u_max) return {};  // wholly behind the clipping plane
  const auto clampTo = [](double value, int limit) {
    return static_cast<int>(std::clamp(value, 0.0, static_cast<double>(limit)));
  };
  PixelRect r;
  r.x0 = clampTo(std::floor(u_min) - 1.0, options_.width);
  r.x1 = clampTo(std::ceil(u_max) + 2.0, options_.width);
  r.y0 = clampTo(std::floor(v_min) - 1.0, options_.height);
  r.y1 = clampTo(std::ceil(v_max) + 2.0, options_.height);
  return r;
}

// Every pixel whose ray can hit a dynamic shape at time_s.
MockCamera::PixelRect MockCamera::dynamicRect(const Pose& pose, double time_s) const {
  Vector3d lo, hi;
  if (!scene_.dynamicBounds(time_s, lo, hi)) return {};
  return projectBox(pose, lo, hi);
}

MockCamera::PixelRect MockCamera::unite(const PixelRect& a, const PixelRect& b) const {
  if (a.empty()) return b;
  if (b.empty()) return a;
  return {std::min(a.x0, b.x0), std::min(a.y0, b.y0), std::max(a.x1, b.x1), std::max(a.y1, b.y1)};
}

MockCamera::PixelRect MockCamera::grow(const PixelRect& r, int pixels) const {
  if (r.empty()) return r;
  return {std::max(0, r.x0 - pixels), std::max(0, r.y0 - pixels),
          std::min(options_.width, r.x1 + pixels), std::min(options_.height, r.y1 + pixels)};
}

// Discontinuity bands: a pixel next to (8-neighbourhood) a surface nearer by
// more than the jump threshold is always lost; the pixel two to the left of
// such an occluder (the projector's shadow side) is lost half of the time.
// The 3 x 3 minimum is separable: a horizontal pass into near_row_min_m_, then
// a vertical one.
void MockCamera::updateDropouts(const PixelRect& rect) {
  if (rect.empty()) return;
  const int w = options_.width;
  const int h = options_.height;
  const auto at = [w](int x, int y) {
    return static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
  };
  const double* depth = work_.depth_m.data();
  const auto surface = [](double z) { return z > 0.0 ? z : kInf; };  // 0: nothing there
  for (int y = std::max(0, rect.y0 - 1); y < std::min(h, rect.y1 + 1); ++y) {
    for (int x = rect.x0; x < rect.x1; ++x) {
      double nearest = surface(depth[at(x, y)]);
      if (x > 0) nearest = std::min(nearest, surface(depth[at(x - 1, y)]));
      if (x + 1 < w) nearest = std::min(nearest, surface(depth[at(x + 1, y)]));
      near_row_min_m_[at(x, y)] = static_cast<float>(nearest);
    }
  }
  for (int y = rect.y0; y < rect.y1; ++y) {
    const int y_above = std::max(0, y - 1);
    const int y_below = std::min(h - 1, y + 1);
    for (int x = rect.x0; x < rect.x1; ++x) {
      const std::size_t i = at(x, y);
      float p = work_.drop_prob[i];
      const double z = depth[i];
      if (z > 0.0 && p < 1.0f) {
        // z - zq > kEdgeJumpM + kEdgeJumpPerM * zq, solved for zq. The pixel
        // itself is never nearer than that.
        const double occluder_below_m = (z - kEdgeJumpM) / (1.0 + kEdgeJumpPerM);
        const float nearest = std::min(
            {near_row_min_m_[at(x, y_above)], near_row_min_m_[i], near_row_min_m_[at(x, y_below)]});
        if (nearest < occluder_below_m) {
          p = 1.0f;
        } else if (x + kEdgeReachPx < w) {
          const double zq = depth[i + kEdgeReachPx];
          if (zq > 0.0 && zq < occluder_below_m) p = 1.0f - (1.0f - p) * (1.0f - kShadowDropout);
        }
      }
      final_drop_prob_[i] = p;
    }
  }
}

// The sensor model's random part. Pixels go in pairs that share one Box-Muller
// draw (its cosine and sine branches), which halves the transcendental work.
// Per pair: hash a = (u1: 24 bits, u2: 24 bits, dropout of the first: 16 bits),
// hash b = mix64(a) = (dropout of the second: 16 bits, RGB noise: 2 x 24 bits).
void MockCamera::writeFrame(RgbdFrame& slot, uint64_t sequence) const {
  const std::size_t pixels =
      static_cast<std::size_t>(options_.width) * static_cast<std::size_t>(options_.height);
  uint16_t* depth = slot.depth();
  uint8_t* rgb = slot.rgb();
  if (!options_.noise) {
    for (std::size_t i = 0; i < pixels; ++i) {
      const double z = work_.depth_m[i];
      depth[i] = inRange(z) ? toDepthUnits(z) : 0;
    }
    std::memcpy(rgb, work_.rgb.data(), 3 * pixels);
    return;
  }
  const uint64_t frame_key = hash2(options_.seed, options_.temporal_noise ? sequence : 0);
  for (std::size_t first = 0; first < pixels; first += 2) {
    const uint64_t a = hash2(frame_key, first / 2);
    const uint64_t b = mix64(a);
    const double u1 = static_cast<double>((a >> 40) + 1) * 0x1.0p-24;  // (0, 1]
    const double u2 = static_cast<double>((a >> 16) & 0xFFFFFFu) * 0x1.0p-24;
    const double radius = std::sqrt(-2.0 * std::log(u1));
    const double angle = 2.0 * std::numbers::pi * u2;
    const double gaussian[2] = {radius * std::cos(angle), radius * std::sin(angle)};
    const uint64_t drop_bits[2] = {a & 0xFFFFu, b & 0xFFFFu};
    const std::size_t count = std::min<std::size_t>(2, pixels - first);
    for (std::size_t k = 0; k < count; ++k) {
      const std::size_t i = first + k;
      const double z = work_.depth_m[i];
      uint16_t units = 0;
      if (inRange(z)) {
        const float u_drop = static_cast<float>(drop_bits[k]) * 0x1.0p-16f;
        if (u_drop >= final_drop_prob_[i]) units = toDepthUnits(z + work_.sigma_m[i] * gaussian[k]);
      }
      depth[i] = units;
      const uint64_t rgb_bits = b >> (16 + 24 * k);
      for (std::size_t c = 0; c < 3; ++c) {
        rgb[3 * i + c] = addRgbNoise(work_.rgb[3 * i + c], rgb_bits >> (8 * c));
      }
    }
  }
}

}  // namespace fovea::hal::mock

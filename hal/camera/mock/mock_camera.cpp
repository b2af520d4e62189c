#include "hal/spec_options.h"
#include "hal/camera/mock/mock_camera.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <utility>

#include "hal/camera/mock/hash.h"
#include "hal/camera/mock/sensor_model.h"
#include "hal/camera/pacing.h"

namespace fovea::hal::mock {

namespace {

using Eigen::Vector3d;

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

void MockCamera::CleanImage::resize(int image_width, int image_height, int ring_rows) {
  width = image_width;
  rows = ring_rows;
  const std::size_t pixels =
      static_cast<std::size_t>(image_width) * static_cast<std::size_t>(ring_rows > 0 ? ring_rows : image_height);
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
  ray_x_.resize(static_cast<std::size_t>(w));
  ray_y_.resize(static_cast<std::size_t>(h));
  const CameraIntrinsics& k = info_.intrinsics;
  for (int x = 0; x < w; ++x) ray_x_[static_cast<std::size_t>(x)] = (x - k.cx) / k.fx;
  for (int y = 0; y < h; ++y) ray_y_[static_cast<std::size_t>(y)] = (y - k.cy) / k.fy;
  // A camera that moves every frame (orbit, pan, dolly) re-renders every pixel
  // each frame; a dynamic scene keeps its static layer (background_), and a
  // camera that may stand still (static, or keyframes, which hold at their
  // ends) its whole render.
  const PathKind kind = options_.path.kind;
  const bool always_moving = kind == PathKind::kOrbit || kind == PathKind::kPan || kind == PathKind::kDolly;
  rows_only_ = options_.stream_rows && !scene_.isDynamic() && always_moving;
  work_.resize(w, h, rows_only_ ? 3 : 0);
  if (scene_.isDynamic()) background_.resize(w, h, 0);
  near_row_min_m_.assign(3 * static_cast<std::size_t>(w), 0.0f);
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
    if (Status s = waitUntilDue(timeout); !s) return s;
  }
  if (!options_.faults.empty()) {
    if (Status s = applyFaults(timeout); !s) return s;
  }

  const uint64_t sequence = sequence_;
  const double time_s = static_cast<double>(sequence) / options_.fps;
  const Pose pose = cameraPoseAt(options_.path, scene_.info(), time_s);
  if (!rows_only_) renderClean(pose, time_s);
  if (garbage_pending_ > 0) {
    --garbage_pending_;
    writeGarbage(slot, sequence);
    counters_.injectedGarbage();
  } else if (rows_only_) {
    renderAndWriteRows(pose, time_s, slot, sequence);
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

// realtime=on: sleeps until frame sequence_ is due on the wall clock, first
// skipping the frames a slow consumer missed; a timeout when it is due later
// than the timeout allows.
Status MockCamera::waitUntilDue(std::chrono::nanoseconds timeout) {
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
  return waitForFrameDue(dueAt(sequence_), now, timeout, counters_);
}

// The injected faults' effect on this acquire(): those due fire, a stall
// blocks (up to the timeout), a wrong-size frame is refused.
Status MockCamera::applyFaults(std::chrono::nanoseconds timeout) {
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

}  // namespace fovea::hal::mock

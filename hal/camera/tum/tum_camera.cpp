#include "hal/spec_options.h"
#include "hal/camera/tum/tum_camera.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <utility>

#include "hal/camera/pacing.h"
#include "hal/camera/tum/png_reader.h"

namespace fovea::hal::tum {

namespace {

Status invalid(std::string message) { return Status(ErrorCode::kInvalidArgument, "tum: " + std::move(message)); }

// Whitespace-separated fields of one line.
std::vector<std::string_view> splitFields(std::string_view line) {
  std::vector<std::string_view> fields;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    const std::size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
    if (i > start) fields.push_back(line.substr(start, i - start));
  }
  return fields;
}

Result<std::string> readWholeFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) {
      return Result<std::string>(ErrorCode::kNotFound, "tum: " + path.string() + " does not exist");
    }
    return Result<std::string>(ErrorCode::kIoError, "tum: cannot read " + path.string());
  }
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// Calls fn(line_number, line) for each line that is neither empty nor a comment.
template <typename Fn>
Status forEachDataLine(std::string_view text, Fn fn) {
  std::size_t line_number = 0;
  std::size_t pos = 0;
  while (pos < text.size()) {
    const std::size_t eol = std::min(text.find('\n', pos), text.size());
    std::string_view line = text.substr(pos, eol - pos);
    pos = eol + 1;
    ++line_number;
    const std::size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string_view::npos || line[first] == '#') continue;
    if (Status s = fn(line_number, line); !s) return s;
  }
  return Status::ok();
}

}  // namespace

Result<int64_t> parseTumTimestampNs(std::string_view text) {
  const auto fail = [&] {
    return Result<int64_t>(ErrorCode::kParseError, "'" + std::string(text) + "' is not a timestamp (seconds)");
  };
  const std::size_t dot = text.find('.');
  const std::string_view whole = text.substr(0, dot);
  const std::string_view fraction = dot == std::string_view::npos ? std::string_view() : text.substr(dot + 1);
  if (whole.empty() || whole.size() > 10 || fraction.size() > 9) return fail();
  int64_t seconds = 0;
  const auto [end, ec] = std::from_chars(whole.data(), whole.data() + whole.size(), seconds);
  if (ec != std::errc() || end != whole.data() + whole.size() || seconds < 0) return fail();
  int64_t ns = 0;
  for (std::size_t i = 0; i < 9; ++i) {
    int digit = 0;
    if (i < fraction.size()) {
      if (fraction[i] < '0' || fraction[i] > '9') return fail();
      digit = fraction[i] - '0';
    }
    ns = ns * 10 + digit;
  }
  return seconds * 1'000'000'000 + ns;
}

Result<std::vector<StampedPose>> parseGroundTruth(std::string_view text, const std::string& path_for_errors) {
  std::vector<StampedPose> poses;
  Status s = forEachDataLine(text, [&](std::size_t line_number, std::string_view line) -> Status {
    const std::string where = path_for_errors + ":" + std::to_string(line_number) + ": ";
    const std::vector<std::string_view> f = splitFields(line);
    if (f.size() != 8) {
      return {ErrorCode::kParseError, where + "expected 8 fields (timestamp tx ty tz qx qy qz qw), got " +
                                          std::to_string(f.size())};
    }
    Result<int64_t> stamp = parseTumTimestampNs(f[0]);
    if (!stamp) return {ErrorCode::kParseError, where + stamp.status().message()};
    double v[7];
    for (int i = 0; i < 7; ++i) {
      if (!parseSpecDouble(f[static_cast<std::size_t>(i) + 1], v[i])) {
        return {ErrorCode::kParseError, where + "'" + std::string(f[static_cast<std::size_t>(i) + 1]) +
                                            "' is not a finite number"};
      }
    }
    StampedPose p;
    p.stamp_ns = stamp.value();
    p.t_world_cam = Eigen::Vector3d(v[0], v[1], v[2]);
    // The file rounds to 4 decimals: normalised.
    if (!normalisedQuaternion(v[3], v[4], v[5], v[6], p.q_world_cam)) {
      return {ErrorCode::kParseError, where + "quaternion is not of unit length"};
    }
    if (!poses.empty() && p.stamp_ns <= poses.back().stamp_ns) {
      return {ErrorCode::kParseError, where + "timestamps must increase"};
    }
    poses.push_back(p);
    return Status::ok();
  });
  if (!s) return s;
  return poses;
}

std::vector<TumAssociation> associateTumStamps(const std::vector<int64_t>& rgb_ns, const std::vector<int64_t>& depth_ns,
                                               int64_t max_difference_ns) {
  struct Candidate {
    int64_t difference;
    std::size_t rgb, depth;
  };
  std::vector<Candidate> candidates;
  // Both lists increase: the colour stamps within reach of a depth stamp are a window.
  std::size_t first = 0;
  for (std::size_t d = 0; d < depth_ns.size(); ++d) {
    while (first < rgb_ns.size() && rgb_ns[first] < depth_ns[d] - max_difference_ns) ++first;
    for (std::size_t r = first; r < rgb_ns.size() && rgb_ns[r] <= depth_ns[d] + max_difference_ns; ++r) {
      candidates.push_back({std::abs(rgb_ns[r] - depth_ns[d]), r, d});
    }
  }
  std::stable_sort(candidates.begin(), candidates.end(),
                   [](const Candidate& a, const Candidate& b) { return a.difference < b.difference; });
  std::vector<uint8_t> rgb_used(rgb_ns.size(), 0), depth_used(depth_ns.size(), 0);
  std::vector<TumAssociation> pairs;
  for (const Candidate& c : candidates) {
    if (rgb_used[c.rgb] || depth_used[c.depth]) continue;
    rgb_used[c.rgb] = depth_used[c.depth] = 1;
    pairs.push_back({c.rgb, c.depth});
  }
  std::sort(pairs.begin(), pairs.end(), [](const TumAssociation& a, const TumAssociation& b) { return a.depth < b.depth; });
  return pairs;
}

namespace {

// rgb.txt or depth.txt: `timestamp filename` per line, stamps increasing.
Status readTumList(const std::filesystem::path& path, std::vector<int64_t>& stamps, std::vector<std::string>& files) {
  Result<std::string> text = readWholeFile(path);
  if (!text) return text.status();
  return forEachDataLine(text.value(), [&](std::size_t line_number, std::string_view line) -> Status {
    const std::string where = path.string() + ":" + std::to_string(line_number) + ": ";
    const std::vector<std::string_view> f = splitFields(line);
    if (f.size() != 2) {
      return {ErrorCode::kParseError, where + "expected 2 fields (timestamp file), got " + std::to_string(f.size())};
    }
    Result<int64_t> t = parseTumTimestampNs(f[0]);
    if (!t) return {ErrorCode::kParseError, where + t.status().message()};
    if (!stamps.empty() && t.value() <= stamps.back()) return {ErrorCode::kParseError, where + "timestamps must increase"};
    stamps.push_back(t.value());
    files.emplace_back(f[1]);
    return Status::ok();
  });
}

// One frame of a sequence's list: its depth stamp and the files of its two
// images (relative to the sequence folder).
struct TumListEntry {
  int64_t depth_ns;
  std::string rgb, depth;
};

// The frames of a sequence without associations.txt: rgb.txt and depth.txt
// paired by stamp, as TUM's associate.py pairs them.
Result<std::vector<TumListEntry>> pairTumLists(const std::filesystem::path& folder) {
  std::vector<int64_t> rgb_ns, depth_ns;
  std::vector<std::string> rgb_files, depth_files;
  if (Status s = readTumList(folder / "rgb.txt", rgb_ns, rgb_files); !s) return s;
  if (Status s = readTumList(folder / "depth.txt", depth_ns, depth_files); !s) return s;
  std::vector<TumListEntry> entries;
  for (const TumAssociation& a : associateTumStamps(rgb_ns, depth_ns)) {
    entries.push_back({depth_ns[a.depth], rgb_files[a.rgb], depth_files[a.depth]});
  }
  if (entries.empty()) {
    return Result<std::vector<TumListEntry>>(
        ErrorCode::kParseError,
        "tum: no depth stamp in " + (folder / "depth.txt").string() + " has a colour stamp in rgb.txt within 20 ms");
  }
  return entries;
}

// The frames associations.txt lists: `t_rgb rgb/x.png t_depth depth/y.png`
// per line, depth stamps increasing.
Result<std::vector<TumListEntry>> readTumAssociations(const std::filesystem::path& associations_path) {
  Result<std::string> associations = readWholeFile(associations_path);
  if (!associations) return associations.status();
  std::vector<TumListEntry> entries;
  Status listed = forEachDataLine(associations.value(), [&](std::size_t line_number, std::string_view line) -> Status {
    const std::string where = associations_path.string() + ":" + std::to_string(line_number) + ": ";
    const std::vector<std::string_view> f = splitFields(line);
    if (f.size() != 4) {
      return {ErrorCode::kParseError,
              where + "expected 4 fields (t_rgb rgb/x.png t_depth depth/y.png), got " + std::to_string(f.size())};
    }
    Result<int64_t> t_rgb = parseTumTimestampNs(f[0]);
    Result<int64_t> t_depth = parseTumTimestampNs(f[2]);
    if (!t_rgb) return {ErrorCode::kParseError, where + t_rgb.status().message()};
    if (!t_depth) return {ErrorCode::kParseError, where + t_depth.status().message()};
    if (!entries.empty() && t_depth.value() <= entries.back().depth_ns) {
      return {ErrorCode::kParseError, where + "depth timestamps must increase"};
    }
    entries.push_back({t_depth.value(), std::string(f[1]), std::string(f[3])});
    return Status::ok();
  });
  if (!listed) return listed;
  if (entries.empty()) {
    return Result<std::vector<TumListEntry>>(ErrorCode::kParseError,
                                             "tum: " + associations_path.string() + " lists no frames");
  }
  return entries;
}

// Decodes one frame's depth and colour PNGs (kWidth x kHeight) into depth and rgb.
Status decodeTumImages(const std::filesystem::path& folder, const TumListEntry& entry, std::vector<uint16_t>& depth,
                       std::vector<uint8_t>& rgb) {
  depth.resize(static_cast<std::size_t>(kWidth) * kHeight);
  rgb.resize(static_cast<std::size_t>(kWidth) * kHeight * 3);
  if (Status s = readDepthPng((folder / entry.depth).string(), kWidth, kHeight, depth.data()); !s) {
    return {s.code(), "tum: depth " + s.message()};
  }
  if (Status s = readRgbPng((folder / entry.rgb).string(), kWidth, kHeight, rgb.data()); !s) {
    return {s.code(), "tum: rgb " + s.message()};
  }
  return Status::ok();
}

}  // namespace

CameraIntrinsics tumIntrinsics(TumSensor sensor) {
  switch (sensor) {
    case TumSensor::kFr1: return {kWidth, kHeight, 517.3, 516.5, 318.6, 255.3};
    case TumSensor::kFr2: return {kWidth, kHeight, 520.9, 521.0, 325.1, 249.7};
    case TumSensor::kFr3: return {kWidth, kHeight, kFx, kFy, kCx, kCy};
    case TumSensor::kRos: return {kWidth, kHeight, 525.0, 525.0, 319.5, 239.5};
  }
  return {kWidth, kHeight, kFx, kFy, kCx, kCy};
}

TumSensor tumSensorForPath(std::string_view path) {
  // The last folder name that names one: "rgbd_dataset_freiburg1_desk", "fr2_xyz".
  while (!path.empty() && path.back() == '/') path.remove_suffix(1);
  const std::size_t slash = path.rfind('/');
  const std::string_view name = slash == std::string_view::npos ? path : path.substr(slash + 1);
  for (const auto& [key, sensor] : {std::pair<std::string_view, TumSensor>{"freiburg1", TumSensor::kFr1},
                                    {"freiburg2", TumSensor::kFr2}, {"freiburg3", TumSensor::kFr3},
                                    {"fr1", TumSensor::kFr1}, {"fr2", TumSensor::kFr2}, {"fr3", TumSensor::kFr3}}) {
    if (name.find(key) != std::string_view::npos) return sensor;
  }
  return TumSensor::kFr3;
}

Result<TumCameraOptions> parseTumCameraOptions(std::string_view args) {
  TumCameraOptions options;
  const SpecTokens tokens = tokenizeSpec(args);
  const std::string_view path = tokens.head.value_or("");
  if (path.empty()) return invalid("expected tum:PATH[,loop=on|off|bounce,realtime=on|off,frames=N,groundtruth=auto|on|off,intrinsics=fr1|fr2|fr3|ros]");
  options.path = std::string(path);
  for (const auto& [key, value, has_value] : tokens.items) {
    if (!has_value) {
      return invalid("option '" + std::string(key) + "' is not key=value (keys: loop, realtime, frames, groundtruth, intrinsics)");
    }
    if (key == "loop") {
      options.bounce = value == "bounce";
      if (options.bounce) {
        options.loop = true;
      } else if (Status s = parseSpecOnOff("tum", key, value, options.loop); !s) {
        return s;
      }
    } else if (key == "realtime") {
      if (Status s = parseSpecOnOff("tum", key, value, options.realtime); !s) return s;
    } else if (key == "frames") {
      std::size_t n = 0;
      const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), n);
      if (value.empty() || ec != std::errc() || end != value.data() + value.size() || n == 0) {
        return invalid("frames: expected a positive integer, got '" + std::string(value) + "'");
      }
      options.max_frames = n;
    } else if (key == "intrinsics") {
      if (value == "fr1") {
        options.sensor = TumSensor::kFr1;
      } else if (value == "fr2") {
        options.sensor = TumSensor::kFr2;
      } else if (value == "fr3") {
        options.sensor = TumSensor::kFr3;
      } else if (value == "ros") {
        options.sensor = TumSensor::kRos;
      } else {
        return invalid("intrinsics: expected fr1, fr2, fr3 or ros, got '" + std::string(value) + "'");
      }
    } else if (key == "groundtruth") {
      if (value == "auto") {
        options.groundtruth = TumCameraOptions::GroundTruth::kAuto;
      } else if (value == "on") {
        options.groundtruth = TumCameraOptions::GroundTruth::kOn;
      } else if (value == "off") {
        options.groundtruth = TumCameraOptions::GroundTruth::kOff;
      } else {
        return invalid("groundtruth: expected auto, on or off, got '" + std::string(value) + "'");
      }
    } else {
      return invalid("unknown option '" + std::string(key) + "' (keys: loop, realtime, frames, groundtruth, intrinsics)");
    }
  }
  return options;
}

std::string tumCameraHelp() {
  return "tum:PATH[,loop=on|off|bounce,realtime=on|off,frames=N,groundtruth=auto|on|off,intrinsics=fr1|fr2|fr3|ros]  a TUM "
         "RGB-D sequence folder (associations.txt or rgb.txt and depth.txt, rgb/, depth/, groundtruth.txt); the "
         "intrinsics of the sensor its name says (freiburg1/2/3; fr3 otherwise), ground-truth poses (auto: when "
         "groundtruth.txt is there, identity poses otherwise); loop=on (default) restarts at the "
         "end, loop=bounce plays it backwards from there (the camera's path stays continuous), realtime=on paces frames to their timestamps, frames=N keeps the first N (all are decoded into "
         "memory at open, 1.5 MB each)";
}

TumCamera::TumCamera(TumCameraOptions options) : options_(std::move(options)) {
  info_.name = "tum:" + options_.path;
  info_.intrinsics = tumIntrinsics(options_.sensor.value_or(tumSensorForPath(options_.path)));
  info_.depth_scale_m = kDepthScaleM;
  info_.fps = 30.0;
}

Result<std::unique_ptr<Camera>> TumCamera::create(std::string_view args) {
  Result<TumCameraOptions> options = parseTumCameraOptions(args);
  if (!options) return options.status();
  return std::unique_ptr<Camera>(std::make_unique<TumCamera>(std::move(options).value()));
}

Status TumCamera::open() {
  namespace fs = std::filesystem;
  opened_ = false;
  frames_.clear();
  frames_without_pose_ = 0;
  const fs::path folder(options_.path);
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) {
    return {ErrorCode::kNotFound, "tum: sequence folder " + options_.path + " does not exist (or is not a folder)"};
  }
  const fs::path associations_path = folder / "associations.txt";
  const fs::path groundtruth_path = folder / "groundtruth.txt";
  const bool have_associations = fs::exists(associations_path, ec);
  if (!have_associations && !(fs::exists(folder / "rgb.txt", ec) && fs::exists(folder / "depth.txt", ec))) {
    return {ErrorCode::kNotFound, "tum: " + associations_path.string() +
                                      " does not exist, nor do rgb.txt and depth.txt beside it to pair (TUM's "
                                      "associate.py makes one: python associate.py rgb.txt depth.txt > associations.txt)"};
  }
  bool use_groundtruth = options_.groundtruth == TumCameraOptions::GroundTruth::kOn;
  if (options_.groundtruth == TumCameraOptions::GroundTruth::kAuto) use_groundtruth = fs::exists(groundtruth_path, ec);
  std::vector<StampedPose> poses;
  if (use_groundtruth) {
    Result<std::string> groundtruth = readWholeFile(groundtruth_path);
    if (!groundtruth) return groundtruth.status();
    Result<std::vector<StampedPose>> parsed = parseGroundTruth(groundtruth.value(), groundtruth_path.string());
    if (!parsed) return parsed.status();
    poses = std::move(parsed).value();
  }
  info_.model = use_groundtruth ? "TUM RGB-D sequence, ground-truth poses"
                                : "TUM RGB-D sequence without ground truth: every frame's pose is the identity";
  if (Status s = readFrames(folder, have_associations, use_groundtruth ? &poses : nullptr); !s) return s;

  const int64_t span_ns = frames_.back().depth_stamp_ns - frames_.front().depth_stamp_ns;
  const int64_t period_ns = frames_.size() > 1 ? span_ns / static_cast<int64_t>(frames_.size() - 1) : 33'333'333;
  loop_period_ns_ = span_ns + period_ns;
  period_ns_ = std::max<int64_t>(period_ns, 1);
  info_.fps = 1e9 / static_cast<double>(period_ns);
  opened_ = true;
  next_ = 0;
  next_stamp_ns_ = frames_.front().depth_stamp_ns;
  backwards_ = false;
  finished_ = false;
  return Status::ok();
}

// open()'s second half: the sequence's list of frames (associations.txt, or
// rgb.txt and depth.txt paired), then every frame decoded into frames_ (up to
// max_frames; with ground truth, only those it gives a pose).
Status TumCamera::readFrames(const std::filesystem::path& folder, bool have_associations,
                             const std::vector<StampedPose>* poses) {
  const std::filesystem::path associations_path = folder / "associations.txt";
  Result<std::vector<TumListEntry>> entries =
      have_associations ? readTumAssociations(associations_path) : pairTumLists(folder);
  if (!entries) return entries.status();
  for (const TumListEntry& e : entries.value()) {
    if (options_.max_frames != 0 && frames_.size() == options_.max_frames) break;
    Pose pose;
    if (poses != nullptr && !interpolatePose(*poses, e.depth_ns, kPoseClampNs, pose)) {
      ++frames_without_pose_;
      continue;
    }
    Frame frame;
    frame.depth_stamp_ns = e.depth_ns;
    frame.pose = pose;
    if (Status s = decodeTumImages(folder, e, frame.depth, frame.rgb); !s) return s;
    frames_.push_back(std::move(frame));
  }
  if (frames_.empty()) {
    return {ErrorCode::kNotFound, "tum: none of the " + std::to_string(entries.value().size()) + " frames in " +
                                      associations_path.string() + " lies within the ground truth's time span (" +
                                      (folder / "groundtruth.txt").string() + ")"};
  }
  return Status::ok();
}

Status TumCamera::start() {
  if (!opened_) return Status(ErrorCode::kUnavailable, "tum camera: call open() before start()");
  started_ = true;
  start_time_ = std::chrono::steady_clock::now();
  start_stamp_ns_ = next_stamp_ns_;
  return Status::ok();
}

void TumCamera::stop() { started_ = false; }

// Error messages stay within std::string's small-buffer capacity (15
// characters in libstdc++), so even the error paths do not allocate.
Status TumCamera::acquire(RgbdFrame& slot, std::chrono::nanoseconds timeout) {
  if (!started_) {
    counters_.error();
    return Status(ErrorCode::kUnavailable, "not started");
  }
  if (finished_) return Status(ErrorCode::kUnavailable, "end of record");
  if (!slot.setSize(kWidth, kHeight)) {
    counters_.error();
    return Status(ErrorCode::kCapacityExceeded, "slot too small");
  }
  const Frame& frame = frames_[next_];
  const int64_t stamp_ns = next_stamp_ns_;
  if (options_.realtime) {
    using Clock = std::chrono::steady_clock;
    const Clock::time_point due = start_time_ + std::chrono::nanoseconds(stamp_ns - start_stamp_ns_);
    if (Status s = waitForFrameDue(due, Clock::now(), timeout, counters_); !s) return s;
  }
  std::copy(frame.depth.begin(), frame.depth.end(), slot.depth());
  std::copy(frame.rgb.begin(), frame.rgb.end(), slot.rgb());
  slot.intrinsics = info_.intrinsics;
  slot.depth_scale_m = kDepthScaleM;
  slot.T_world_cam = frame.pose;
  slot.has_rgb = true;
  slot.stamp_ns = stamp_ns;
  slot.sequence = sequence_++;
  advance();
  counters_.frameDelivered();
  return Status::ok();
}

void TumCamera::advance() {
  const std::size_t last = frames_.size() - 1;
  if (!options_.bounce) {
    if (next_ < last) {
      ++next_;
      next_stamp_ns_ += frames_[next_].depth_stamp_ns - frames_[next_ - 1].depth_stamp_ns;
      return;
    }
    // The next loop's first frame, one mean period after this one's last.
    next_ = 0;
    next_stamp_ns_ += loop_period_ns_ - (frames_[last].depth_stamp_ns - frames_[0].depth_stamp_ns);
    if (!options_.loop) finished_ = true;
    return;
  }
  if (last == 0) {
    next_stamp_ns_ += period_ns_;
    return;
  }
  if (backwards_ ? next_ == 0 : next_ == last) backwards_ = !backwards_;
  const std::size_t from = next_;
  next_ = backwards_ ? next_ - 1 : next_ + 1;
  const int64_t gap = frames_[std::max(from, next_)].depth_stamp_ns - frames_[std::min(from, next_)].depth_stamp_ns;
  next_stamp_ns_ += gap > 0 ? gap : period_ns_;
}

}  // namespace fovea::hal::tum

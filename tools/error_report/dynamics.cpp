#include "tools/error_report/dynamics.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <numbers>
#include <span>
#include <sstream>
#include <utility>

#include <Eigen/Geometry>

#include "net/codec.h"
#include "pipeline/backproject.h"
#include "pipeline/eye_speed.h"
#include "tools/common/nan.h"
#include "tools/error_report/report.h"
#include "tools/operator/gaze_script.h"

namespace fovea::tools {

namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

// Key of one output point: region in the top 3 bits; a voxel's lattice cell
// (20 bits per axis, wrapping: cells 2^20 apart never meet in one frame) or a raw
// point's pixel below.
uint64_t voxelKey(int region, const Eigen::Vector3d& world_m, double voxel_m) {
  constexpr uint64_t kMask = (1u << 20) - 1;
  uint64_t key = static_cast<uint64_t>(region) << 61;
  for (int a = 0; a < 3; ++a) {
    const auto cell = static_cast<int64_t>(std::floor(world_m[a] / voxel_m));
    key |= (static_cast<uint64_t>(cell) & kMask) << (20 * a);
  }
  return key;
}

void outputKeys(const pipeline::FoveatedCloud& out, const pipeline::FoveationStats& stats, const hal::RgbdFrame& frame,
                std::vector<uint64_t>& keys) {
  keys.clear();
  const hal::CameraIntrinsics& k = frame.intrinsics;
  const Eigen::Matrix3d R_cam_world = frame.T_world_cam.R_world_cam.transpose();
  for (std::size_t o = 0; o < out.size(); ++o) {
    const int region = out.region[o];
    const Eigen::Vector3d world = out.points.world(o);
    if (region == 0) {
      // A raw point is the pixel it came from: projected back through the camera.
      const Eigen::Vector3d c = R_cam_world * (world - frame.T_world_cam.t_world_cam);
      const long u = std::lround(k.fx * c.x() / c.z() + k.cx), v = std::lround(k.fy * c.y() / c.z() + k.cy);
      keys.push_back(static_cast<uint64_t>(v) * static_cast<uint64_t>(k.width) + static_cast<uint64_t>(u));
    } else {
      keys.push_back(voxelKey(region, world, stats.regions[region].voxel_size_m));
    }
  }
  std::sort(keys.begin(), keys.end());
}

// Share of `now` (sorted) that `before` (sorted) lacks.
double changedShare(const std::vector<uint64_t>& before, const std::vector<uint64_t>& now) {
  if (now.empty()) return 0.0;
  std::size_t common = 0;
  auto b = before.begin();
  for (uint64_t key : now) {
    b = std::lower_bound(b, before.end(), key);
    if (b != before.end() && *b == key) ++common;
  }
  return 1.0 - static_cast<double>(common) / static_cast<double>(now.size());
}

// The angle in degrees between two directions (any length).
double angleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) / kDegToRad;
}

std::string fixed(double v, int precision) { return formatFixed(v, precision); }

std::string point(const Eigen::Vector3d& p) {
  char buffer[96];
  std::snprintf(buffer, sizeof buffer, "%.3f,%.3f,%.3f", p.x(), p.y(), p.z());
  return buffer;
}

}  // namespace

std::vector<DynamicsConfig> dynamicsConfigs(double slope, const std::vector<AcuityFloor>& floors,
                                            const std::vector<std::pair<double, int>>& refined) {
  std::vector<DynamicsConfig> configs;
  for (pipeline::Preset preset : {pipeline::Preset::kF1, pipeline::Preset::kF2, pipeline::Preset::kF3}) {
    DynamicsConfig c;
    c.config.acuity.preset = preset;
    c.config.acuity.slope = slope;
    configs.push_back(c);
  }
  std::vector<std::pair<bool, AcuityFloor>> variants = {{false, {}}, {true, {}}};
  for (const AcuityFloor& floor : floors) {
    if (floor.m > 0.0 || floor.per_m2 > 0.0) variants.emplace_back(true, floor);
  }
  for (const auto& [growth, floor] : variants) {
    DynamicsConfig c;
    c.config.acuity.preset = pipeline::Preset::kAcuity;
    c.config.acuity.slope = slope;
    c.config.acuity.floor_m = floor.m;
    c.config.acuity.floor_per_m2 = floor.per_m2;
    c.growth = growth;
    configs.push_back(c);
  }
  // Refined (margin, passes), with growth: what the service would run.
  for (const auto& [margin, passes] : refined) {
    DynamicsConfig c;
    c.config.acuity.preset = pipeline::Preset::kAcuity;
    c.config.acuity.slope = slope;
    c.config.acuity.level_margin = margin;
    c.config.acuity.refine_passes = passes;
    c.growth = true;
    configs.push_back(c);
  }
  for (DynamicsConfig& c : configs) c.name = configName(c.config.acuity, c.growth ? " growth" : "");
  return configs;
}

namespace {

// What both figures use, sized once for the camera. The SIMD kernels: their
// output is the reference's (docs/kernels.md), and the coverage figure foveates
// twice per simulated frame.
struct DynamicsRig {
  pipeline::Foveator foveator;
  net::ChunkEncoder encoder;
  pipeline::PointCloud cloud;
  pipeline::FoveatedCloud out;
  pipeline::FoveationStats stats;
  pipeline::DepthRange range;  // fovead's defaults
};

// The eye on the stability figure's first frame (where it is, where it looks,
// the world's up) and that frame, which the coverage figure replays.
struct StabilityStart {
  Eigen::Vector3d eye = Eigen::Vector3d::Zero(), look = Eigen::Vector3d::UnitZ(), up = -Eigen::Vector3d::UnitY();
  hal::RgbdFrame first;
};

// Temporal stability: each configuration on the camera's next frames with a
// fixed and a drifting gaze, into report.stability.
Status measureStability(hal::Camera& camera, const std::vector<DynamicsConfig>& configs,
                        const DynamicsOptions& options, DynamicsRig& rig, StabilityStart& start,
                        DynamicsReport& report) {
  const hal::CameraInfo& info = camera.info();
  hal::RgbdFrame frame(info.intrinsics.width, info.intrinsics.height);
  const std::size_t n = configs.size();
  std::vector<std::vector<uint64_t>> previous(2 * n), current(2 * n);
  std::vector<double> changed(2 * n, 0.0), points(n, 0.0);
  Eigen::Vector3d& eye = start.eye;
  Eigen::Vector3d& look = start.look;
  Eigen::Vector3d& up = start.up;
  int pairs = 0;
  for (int f = 0; f < options.stability_frames; ++f) {
    if (Status s = camera.acquire(frame, std::chrono::seconds(2)); !s) return s;
    if (f == 0) {
      eye = frame.T_world_cam.t_world_cam + frame.T_world_cam.R_world_cam * options.eye_offset_cam;
      look = info.focus_point_m ? Eigen::Vector3d(*info.focus_point_m - eye)
                                : Eigen::Vector3d(frame.T_world_cam.R_world_cam.col(2));
      up = -frame.T_world_cam.R_world_cam.col(1);
      start.first = frame;
    }
    pipeline::BackprojectCounts counts;
    if (Status s = pipeline::backprojectRef(frame, rig.range, rig.cloud, counts); !s) return s;
    for (int mode = 0; mode < 2; ++mode) {
      pipeline::Gaze gaze;
      gaze.origin_m = eye;
      const double drift_deg = mode == 1 ? options.drift_deg_s * f / options.fps : 0.0;
      gaze.direction = Eigen::AngleAxisd(drift_deg * kDegToRad, up.normalized()) * look;
      for (std::size_t c = 0; c < n; ++c) {
        if (Status s = rig.foveator.setConfig(configs[c].config); !s) return s;
        if (Status s = rig.foveator.foveate(rig.cloud, gaze, rig.out, rig.stats); !s) return s;
        std::vector<uint64_t>& keys = current[mode * n + c];
        outputKeys(rig.out, rig.stats, frame, keys);
        if (f > 0) changed[mode * n + c] += changedShare(previous[mode * n + c], keys);
        if (mode == 0) points[c] += static_cast<double>(rig.out.size());
        std::swap(keys, previous[mode * n + c]);
      }
    }
    if (f > 0) ++pairs;
  }
  report.stability_pairs = pairs;
  for (std::size_t c = 0; c < n; ++c) {
    StabilityResult r;
    r.name = configs[c].name;
    r.changed_fixed = pairs ? changed[c] / pairs : kNaN;
    r.changed_drift = pairs ? changed[n + c] / pairs : kNaN;
    r.points_fixed = options.stability_frames ? points[c] / options.stability_frames : kNaN;
    report.stability.push_back(r);
  }
  return Status::ok();
}

// The coverage figure's scan, as fovea-operator --gaze takes it: four fixations
// around the scene's centre, 24 degrees apart across and 12 up and down.
std::string coverageScript(const StabilityStart& start) {
  const double distance = start.look.norm();
  const Eigen::Vector3d forward = start.look.normalized();
  const Eigen::Vector3d side = start.up.normalized().cross(forward).normalized();
  const Eigen::Vector3d lift = forward.cross(side).normalized();
  std::string script = "scan:" + point(start.eye) + ">";
  const double offsets[4][2] = {{-12, 6}, {12, 6}, {12, -6}, {-12, -6}};
  for (int t = 0; t < 4; ++t) {
    const Eigen::Vector3d d = Eigen::AngleAxisd(offsets[t][1] * kDegToRad, side) *
                              (Eigen::AngleAxisd(offsets[t][0] * kDegToRad, lift) * forward);
    script += (t ? ";" : "") + point(start.eye + distance * d);
  }
  script += "@400/50";
  return script;
}

// Of the cloud's points within the radius (cos_radius) of where the eye is when
// the frame is shown, those `sent` at least as finely as `needed` there: `within`
// and `covered` counted.
void countCovered(const pipeline::PointCloud& cloud, const std::vector<uint8_t>& sent,
                  const std::vector<uint8_t>& needed, const GazePoint& shown, double cos_radius, uint64_t& within,
                  uint64_t& covered) {
  const Eigen::Vector3d e = shown.direction.normalized();
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (sent[i] >= pipeline::kMaxRegions || needed[i] >= pipeline::kMaxRegions) continue;
    const Eigen::Vector3d v = cloud.world(i) - shown.origin_m;
    const double norm = v.norm();
    if (!(norm > 0.0) || v.dot(e) < norm * cos_radius) continue;
    ++within;
    covered += sent[i] <= needed[i];
  }
}

// Latency-corrected fovea coverage of one configuration over the scan, on the
// cloud in rig (the first frame's: a static scene). sent and needed: scratch, a
// byte per point.
Result<CoverageResult> measureCoverage(const DynamicsConfig& dc, const GazeScript& scan,
                                       const DynamicsOptions& options, DynamicsRig& rig, std::vector<uint8_t>& sent,
                                       std::vector<uint8_t>& needed) {
  const auto ns = [](double ms) { return static_cast<int64_t>(std::llround(ms * 1e6)); };
  const int64_t period_ns = static_cast<int64_t>(std::llround(1e9 / options.gaze_hz));
  const int64_t up_ns = ns(options.up_ms), down_ns = ns(options.down_ms), lead_ns = ns(options.lead_ms);
  const int frames = static_cast<int>(std::floor(options.coverage_seconds * options.fps));
  const double cos_radius = std::cos(options.coverage_radius_deg * kDegToRad);
  pipeline::Foveator& foveator = rig.foveator;
  const pipeline::PointCloud& cloud = rig.cloud;
  if (Status s = foveator.setConfig(dc.config); !s) return s;
  pipeline::EyeSpeed eye_speed;
  CoverageResult r;
  r.name = dc.name;
  uint64_t within = 0, covered = 0, within_moving = 0, covered_moving = 0;
  double bytes = 0.0, growth_sum = 0.0;
  r.worst_frame = 1.0;
  for (int f = 0; f < frames; ++f) {
    // Captured at t (a capture at time 0 would have no sample yet: start a frame in).
    const int64_t t_ns = static_cast<int64_t>(std::llround((f + 1) * 1e9 / options.fps));
    // The newest sample that has reached the robot, stamped at a multiple of the period.
    const int64_t stamp_ns = (t_ns - up_ns) / period_ns * period_ns;
    const GazePoint sample = scan.at(stamp_ns);
    eye_speed.observe(sample.direction, stamp_ns);
    pipeline::Gaze gaze;
    gaze.origin_m = sample.origin_m;
    gaze.direction = sample.direction;
    if (dc.growth) {
      gaze.fovea_growth_deg =
          pipeline::foveaGrowthDeg(eye_speed.speedDegS(), t_ns - (stamp_ns + up_ns), lead_ns, options.growth_max_deg);
    }
    growth_sum += gaze.fovea_growth_deg;
    if (Status s = foveator.foveate(cloud, gaze, rig.out, rig.stats); !s) return s;
    std::copy(foveator.lastRegions(), foveator.lastRegions() + cloud.size(), sent.begin());
    std::array<double, pipeline::kMaxRegions> voxel_m{};
    for (int reg = 0; reg < rig.stats.region_count; ++reg) voxel_m[reg] = rig.stats.regions[reg].voxel_size_m;
    if (Status s = rig.encoder.encode(rig.out, std::span<const double>(voxel_m.data(), rig.stats.region_count), 0, 0);
        !s) {
      return s;
    }
    for (std::size_t i = 0; i < rig.encoder.chunkCount(); ++i) bytes += rig.encoder.chunk(i).size() + net::kDatagramOverhead;
    // Where the eye is when the frame is shown, and what a gaze there would send.
    const GazePoint shown = scan.at(t_ns + down_ns);
    pipeline::Gaze truth;
    truth.origin_m = shown.origin_m;
    truth.direction = shown.direction;
    if (Status s = foveator.foveate(cloud, truth, rig.out, rig.stats); !s) return s;
    std::copy(foveator.lastRegions(), foveator.lastRegions() + cloud.size(), needed.begin());
    const bool moving = angleDeg(sample.direction, shown.direction) > 1.0;
    uint64_t w = 0, c = 0;
    countCovered(cloud, sent, needed, shown, cos_radius, w, c);
    within += w;
    covered += c;
    if (moving) {
      within_moving += w;
      covered_moving += c;
      ++r.moving_frames;
    }
    if (w > 0) r.worst_frame = std::min(r.worst_frame, static_cast<double>(c) / static_cast<double>(w));
    ++r.frames;
  }
  r.coverage_all = within ? static_cast<double>(covered) / static_cast<double>(within) : kNaN;
  r.coverage_moving = within_moving ? static_cast<double>(covered_moving) / static_cast<double>(within_moving) : kNaN;
  r.bytes_per_frame = frames ? bytes / frames : kNaN;
  r.growth_mean_deg = frames ? growth_sum / frames : kNaN;
  return r;
}

}  // namespace

Result<DynamicsReport> measureDynamics(hal::Camera& camera, const std::vector<DynamicsConfig>& configs,
                                       const DynamicsOptions& options) {
  DynamicsReport report;
  report.options = options;
  const hal::CameraInfo& info = camera.info();
  const int width = info.intrinsics.width, height = info.intrinsics.height;
  const std::size_t max_points = static_cast<std::size_t>(width) * height;
  Result<pipeline::Foveator> foveator =
      pipeline::Foveator::create({max_points, max_points, fovea::KernelSet::kSimd, 1}, configs.front().config);
  if (!foveator) return foveator.status();
  Result<net::ChunkEncoder> encoder = net::ChunkEncoder::create(net::CodecConfig{}, max_points);
  if (!encoder) return encoder.status();
  DynamicsRig rig{std::move(foveator.value()), std::move(encoder.value()), pipeline::PointCloud(max_points),
                  pipeline::FoveatedCloud(max_points), {}, {}};

  // ---- temporal stability ----
  StabilityStart start;
  start.first = hal::RgbdFrame(width, height);
  if (Status s = measureStability(camera, configs, options, rig, start, report); !s) return s;

  // ---- latency-corrected fovea coverage, on the first frame (a static scene) ----
  pipeline::BackprojectCounts counts;
  if (Status s = pipeline::backprojectRef(start.first, rig.range, rig.cloud, counts); !s) return s;
  const std::string script = coverageScript(start);
  Result<GazeScript> scan = GazeScript::parse(script);
  if (!scan) return scan.status();
  report.script = script;
  std::vector<uint8_t> sent(max_points), needed(max_points);
  for (const DynamicsConfig& dc : configs) {
    Result<CoverageResult> r = measureCoverage(dc, *scan, options, rig, sent, needed);
    if (!r) return r.status();
    report.coverage.push_back(std::move(r.value()));
  }
  return report;
}

std::string dynamicsMarkdown(const DynamicsReport& report) {
  const DynamicsOptions& o = report.options;
  std::ostringstream md;
  md << "\n## Temporal stability\n\n"
     << report.stability_pairs << " pairs of consecutive frames of the same camera, every configuration on each frame. "
     << "The share of a frame's output points that the previous frame's output did not have: a voxel is its region "
        "and world lattice cell, a raw point its pixel (noise that only moves a centroid is no change; a point that "
        "changes region or level, or a voxel that appears, is). Fixed gaze: the report's gaze; drifting: the same "
        "gaze turning about the camera's up axis at "
     << fixed(o.drift_deg_s, 1) << " degrees per second (" << fixed(o.fps, 0) << " fps).\n\n"
     << "| configuration | points / frame | changed, fixed gaze | changed, drifting gaze |\n"
     << "|---|---:|---:|---:|\n";
  for (const StabilityResult& r : report.stability) {
    md << "| " << r.name << " | " << fixed(r.points_fixed, 0) << " | " << fixed(100.0 * r.changed_fixed, 1) << " % | "
       << fixed(100.0 * r.changed_drift, 1) << " % |\n";
  }
  md << "\n## Latency-corrected fovea coverage\n\n"
     << "The scan `" << report.script << "` (`fovea-operator --gaze` takes it as written): fixations of 400 ms, "
     << "saccades of 50 ms, sampled at " << fixed(o.gaze_hz, 0) << " Hz on the operator's clock, reaching the robot "
     << fixed(o.up_ms, 1) << " ms later; frames captured at " << fixed(o.fps, 0) << " fps from the first frame "
     << "(a static scene) and shown " << fixed(o.down_ms, 1)
     << " ms after capture (the stream's capture-to-decoded p50 on loopback). For each frame, of the points within "
     << fixed(o.coverage_radius_deg, 1)
     << " degrees of where the eye is when the frame is shown: the share sent at least as finely as a gaze there "
        "would have sent them (region, or ACUITY level, no greater). Moving frames: the robot's gaze more than 1 degree "
        "off the eye at display. Growth: the gaze policy's fovea growth (eye speed x (age + "
     << fixed(o.lead_ms, 0) << " ms), at most " << fixed(o.growth_max_deg, 0) << " degrees).\n\n"
     << "| configuration | coverage, all frames | coverage, moving frames | worst frame | mean growth | bytes / frame |\n"
     << "|---|---:|---:|---:|---:|---:|\n";
  for (const CoverageResult& r : report.coverage) {
    md << "| " << r.name << " | " << fixed(100.0 * r.coverage_all, 1) << " % | " << fixed(100.0 * r.coverage_moving, 1)
       << " % (" << r.moving_frames << " of " << r.frames << ") | " << fixed(100.0 * r.worst_frame, 1) << " % | "
       << fixed(r.growth_mean_deg, 2) << " deg | " << fixed(r.bytes_per_frame / 1e6, 3) << " MB |\n";
  }
  return md.str();
}

Status writeDynamicsCsv(const std::string& path, const DynamicsReport& report) {
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  if (!file) return {ErrorCode::kIoError, path + ": cannot open for writing"};
  file << "configuration,points_per_frame,changed_fixed,changed_drift,coverage_all,coverage_moving,moving_frames,"
          "frames,worst_frame,growth_mean_deg,bytes_per_frame\n";
  for (std::size_t c = 0; c < report.stability.size() && c < report.coverage.size(); ++c) {
    const StabilityResult& s = report.stability[c];
    const CoverageResult& r = report.coverage[c];
    file << s.name << ',' << s.points_fixed << ',' << s.changed_fixed << ',' << s.changed_drift << ','
         << r.coverage_all << ',' << r.coverage_moving << ',' << r.moving_frames << ',' << r.frames << ','
         << r.worst_frame << ',' << r.growth_mean_deg << ',' << r.bytes_per_frame << '\n';
  }
  file.close();
  if (!file) return {ErrorCode::kIoError, path + ": write failed"};
  return Status::ok();
}

}  // namespace fovea::tools

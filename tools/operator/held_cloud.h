// What the operator draws at one frame, saved for fovea-eval (fovea-operator
// --save-held FRAME_ID:FILE.ply; docs/eval.md, "MAP-DELTA"): the frame's live
// points and every brick the operator holds of the robot's map (each held slot
// of its net::BrickCache, the version drawn), in world coordinates with colour,
// as one PLY (io/ply) and a small text file beside it (FILE.ply.txt) that says
// which frame it was and how big the splats are drawn.
//
// PLY vertices: the live points first (region byte: their region, 0 .. 7), then
// the map's (region byte: tools::kViewMapRegion + the brick's level, as the
// viewer's frames carry them, tools/operator/view_frame.h).
//
// FILE.ply.txt, one "key values" line each:
//   frame_id ID
//   live_points N
//   map_points M
//   map_bricks B
//   live_step_m S0 .. S7     the frame's lattice step per region (0: none arrived)
//   map_step_m  L0 .. L7     per brick level, the largest step of a held brick of it (0: none)
//   periphery_step_ratio R   a level's voxel is its step over R (net::CodecConfig)
//
// Header-only: fovea-operator writes it, fovea-eval and the tests read it.
// Saving allocates (the cloud of held and live points): it is a one-off, once a
// run, not part of the per-frame path.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "core/result.h"
#include "io/ply.h"
#include "net/brick_cache.h"
#include "net/codec.h"
#include "pipeline/acuity.h"
#include "pipeline/point_cloud.h"

namespace fovea::tools {

// A map point's region byte in the saved cloud: this + its brick's level (the
// viewer's kViewMapRegion, tools/operator/view_frame.h).
inline constexpr uint8_t kHeldMapRegion = pipeline::kMaxRegions;

struct HeldCloudInfo {
  uint32_t frame_id = 0;
  std::size_t live_points = 0, map_points = 0, map_bricks = 0;
  std::array<double, pipeline::kMaxRegions> live_step_m{};
  std::array<double, pipeline::kMaxRegions> map_step_m{};
  double periphery_step_ratio = net::CodecConfig{}.periphery_step_ratio;
};

struct HeldCloud {
  HeldCloudInfo info;
  pipeline::PointCloud points;  // live points, then the map's (world = origin_m + point)
  std::vector<uint8_t> region;  // per point, as above
};

// Whether a frame arrived whole: its summary and every chunk the summary lists.
inline bool frameComplete(const net::AssembledFrame& f) {
  if (!f.summary_received || f.cloud == nullptr) return false;
  for (std::size_t r = 0; r < f.chunks_expected.size(); ++r) {
    if (f.chunks_received[r] < f.chunks_expected[r]) return false;
  }
  return true;
}

// The cloud the operator draws at frame f: f's points and the held bricks.
inline HeldCloud heldCloud(const net::AssembledFrame& f, const net::BrickCache& cache) {
  HeldCloud out;
  out.info.frame_id = f.frame_id;
  out.info.live_step_m = f.step_m;
  const pipeline::PointCloud* live = f.cloud != nullptr ? &f.cloud->points : nullptr;
  out.info.live_points = live != nullptr ? live->size() : 0;
  for (std::size_t slot = 0; slot < cache.slotCount(); ++slot) {
    if (!cache.held(slot)) continue;
    ++out.info.map_bricks;
    out.info.map_points += cache.pointCount(slot);
    const uint8_t level = cache.level(slot);
    if (level < pipeline::kMaxRegions) {
      out.info.map_step_m[level] = std::max(out.info.map_step_m[level], cache.stepM(slot));
    }
  }
  out.points = pipeline::PointCloud(out.info.live_points + out.info.map_points);
  out.region.resize(out.info.live_points + out.info.map_points);
  out.points.origin_m = live != nullptr ? live->origin_m : Eigen::Vector3d::Zero();
  out.points.has_color = true;
  std::size_t n = 0;
  for (std::size_t i = 0; i < out.info.live_points; ++i) {
    (void)out.points.push(live->x()[i], live->y()[i], live->z()[i], live->rgb()[i]);
    out.region[n++] = f.cloud->region[i];
  }
  const Eigen::Vector3d origin = out.points.origin_m;
  for (std::size_t slot = 0; slot < cache.slotCount(); ++slot) {
    if (!cache.held(slot)) continue;
    const auto region = static_cast<uint8_t>(kHeldMapRegion + cache.level(slot));
    cache.forEachPoint(slot, [&](const Eigen::Vector3d& world, uint32_t rgb) {
      const Eigen::Vector3d p = world - origin;
      (void)out.points.push(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()), rgb);
      out.region[n++] = region;
    });
  }
  return out;
}

inline std::string heldInfoText(const HeldCloudInfo& info) {
  std::ostringstream o;
  o.precision(17);
  o << "frame_id " << info.frame_id << "\nlive_points " << info.live_points << "\nmap_points " << info.map_points
    << "\nmap_bricks " << info.map_bricks << "\nlive_step_m";
  for (double s : info.live_step_m) o << ' ' << s;
  o << "\nmap_step_m";
  for (double s : info.map_step_m) o << ' ' << s;
  o << "\nperiphery_step_ratio " << info.periphery_step_ratio << "\n";
  return o.str();
}

// Writes path (binary PLY, double coordinates, colour, region) and path + ".txt".
inline Status saveHeldCloud(const std::string& path, const HeldCloud& cloud) {
  io::PlyWriteOptions ply;
  ply.double_coords = true;
  if (Status s = io::writePly(path, cloud.points, cloud.region.data(), ply); !s) return s;
  std::ofstream txt(path + ".txt");
  txt << heldInfoText(cloud.info);
  if (!txt) return {ErrorCode::kIoError, path + ".txt: cannot write"};
  return Status::ok();
}

// Reads what saveHeldCloud wrote. kNotFound / kIoError / kParseError naming the
// file; kParseError when the PLY's points or regions do not match the text's counts.
inline Result<HeldCloud> loadHeldCloud(const std::string& path) {
  using R = Result<HeldCloud>;
  std::ifstream txt(path + ".txt");
  if (!txt) return R(ErrorCode::kNotFound, path + ".txt: cannot read");
  HeldCloud out;
  bool have[7] = {};
  for (std::string line; std::getline(txt, line);) {
    std::istringstream in(line);
    std::string key;
    in >> key;
    bool ok = true;
    if (key == "frame_id") { ok = static_cast<bool>(in >> out.info.frame_id); have[0] = true; }
    else if (key == "live_points") { ok = static_cast<bool>(in >> out.info.live_points); have[1] = true; }
    else if (key == "map_points") { ok = static_cast<bool>(in >> out.info.map_points); have[2] = true; }
    else if (key == "map_bricks") { ok = static_cast<bool>(in >> out.info.map_bricks); have[3] = true; }
    else if (key == "live_step_m") { for (double& s : out.info.live_step_m) ok = ok && static_cast<bool>(in >> s); have[4] = true; }
    else if (key == "map_step_m") { for (double& s : out.info.map_step_m) ok = ok && static_cast<bool>(in >> s); have[5] = true; }
    else if (key == "periphery_step_ratio") { ok = static_cast<bool>(in >> out.info.periphery_step_ratio) && out.info.periphery_step_ratio > 0; have[6] = true; }
    else if (!key.empty()) ok = false;
    if (!ok) return R(ErrorCode::kParseError, path + ".txt: bad line '" + line + "'");
  }
  for (bool h : have) {
    if (!h) return R(ErrorCode::kParseError, path + ".txt: a line is missing (" + heldInfoText(HeldCloudInfo{}) + ")");
  }
  Result<io::PlyCloud> ply = io::readPly(path);
  if (!ply) return ply.status();
  const std::size_t n = out.info.live_points + out.info.map_points;
  if (ply->points.size() != n || !ply->has_region || ply->region.size() != n) {
    return R(ErrorCode::kParseError, path + ": " + std::to_string(ply->points.size()) + " points with" +
                                         (ply->has_region ? "" : "out") + " regions, the text says " + std::to_string(n));
  }
  out.points = std::move(ply->points);
  out.region = std::move(ply->region);
  return out;
}

}  // namespace fovea::tools

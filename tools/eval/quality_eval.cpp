#include "tools/eval/quality_eval.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <span>
#include <string>
#include <utility>

#include <Eigen/Geometry>

#include "net/codec.h"
#include "pipeline/backproject.h"
#include "pipeline/error_metrics.h"
#include "pipeline/foveator.h"
#include "tools/common/splat_spacing.h"
#include "tools/eval/quality/held_error.h"
#include "tools/eval/quality/png_writer.h"
#include "tools/eval/quality/splat_renderer.h"

namespace fovea::tools::eval {

struct QualityEvaluator::State {
  std::size_t max_points = 0;
  pipeline::PointCloud cloud;
  pipeline::FoveatedCloud out;
  pipeline::FoveatedCloud decoded;
  std::vector<uint32_t> representative;
  std::vector<float> size_m;
  pipeline::ErrorEvaluator errors;
  net::ChunkEncoder encoder;
  pipeline::Foveator foveator;  // reconfigured per condition
  Image reference, image;
  std::vector<float> spacing = std::vector<float>(4096 * pipeline::kMaxRegions);  // sampled pairs, per region
  float raw_spacing_m = 0.0f;  // FREF's, for the raw points of every condition

  // What every condition of one evaluate() call is drawn and judged with.
  struct View {
    const hal::RgbdFrame& frame;
    const Dataset& dataset;
    const HmdPosition& position;
    const QualityOptions& options;
    pipeline::Gaze gaze;
    EyeCamera camera;
    double fx;               // the camera's: a lone point is drawn as the pixel it came from
    Eigen::Vector3d sensor;  // the camera's position
  };

  // The steps of evaluate(), in quality_eval.cpp below.
  Status draw(const View& view, const SplatCloud& splats, const std::string& name, std::vector<double> lines,
              QualityRow& row);
  static QualityRow newRow(const View& view, const Condition& c);
  static QualityRow unmeasuredRow(const View& view, const Condition& c, const QualityRow& reference_row);
  std::vector<float> heldSplatSizes(const View& view, const tools::HeldCloud& h);
  Result<QualityRow> heldRow(const View& view, const Condition& c, const tools::HeldCloud& h);
  Status foveateCondition(const View& view, const Condition& c, firmware::FrameFoveator* map,
                          pipeline::Foveator*& foveator, const pipeline::PointCloud*& input,
                          pipeline::FoveationStats& stats);
  Status decodeAndSize(const View& view, const Condition& c, const pipeline::FoveationStats& stats);
  Result<QualityRow> foveatedRow(const View& view, const Condition& c, firmware::FrameFoveator* map);
};

QualityEvaluator::QualityEvaluator(std::unique_ptr<State> state) : s_(std::move(state)) {}
QualityEvaluator::~QualityEvaluator() = default;

Result<std::unique_ptr<QualityEvaluator>> QualityEvaluator::create(std::size_t max_points) {
  Result<pipeline::ErrorEvaluator> errors = pipeline::ErrorEvaluator::create(max_points);
  if (!errors) return errors.status();
  // The stream's codec at its defaults (what fovead serve sends).
  Result<net::ChunkEncoder> encoder = net::ChunkEncoder::create(net::CodecConfig{}, max_points);
  if (!encoder) return encoder.status();
  Result<pipeline::Foveator> foveator =
      pipeline::Foveator::create({max_points, max_points, fovea::KernelSet::kSimd, 1}, pipeline::FoveationConfig{});
  if (!foveator) return foveator.status();
  auto state = std::unique_ptr<State>(new State{max_points, pipeline::PointCloud(max_points),
                                                pipeline::FoveatedCloud(max_points), pipeline::FoveatedCloud(max_points),
                                                std::vector<uint32_t>(max_points), std::vector<float>(max_points),
                                                std::move(errors.value()), std::move(encoder.value()),
                                                std::move(foveator.value()), {}, {}});
  return std::unique_ptr<QualityEvaluator>(new QualityEvaluator(std::move(state)));
}

EyeCamera eyeCamera(const HmdPosition& position, const Eigen::Vector3d& up, const QualityOptions& options) {
  EyeCamera camera;
  camera.position_m = position.eye_m;
  const Eigen::Vector3d forward = (position.targets_m.front() - position.eye_m).normalized();
  Eigen::Vector3d down = -(up - up.dot(forward) * forward);
  down = down.norm() > 1e-9 ? Eigen::Vector3d(down.normalized()) : forward.unitOrthogonal();
  const Eigen::Vector3d right = down.cross(forward);  // x = y cross z
  camera.world_from_eye.col(0) = right;
  camera.world_from_eye.col(1) = down;
  camera.world_from_eye.col(2) = forward;
  camera.width = options.width;
  camera.height = options.height;
  camera.horizontal_fov_deg = options.horizontal_fov_deg;
  return camera;
}

// Draws `splats` from the eye, measures it against the reference (or makes it
// the reference) and writes the side-by-side image with `lines` (empty: the rings).
Status QualityEvaluator::State::draw(const View& view, const SplatCloud& splats, const std::string& name,
                                     std::vector<double> lines, QualityRow& row) {
  const QualityOptions& options = view.options;
  const bool is_reference = name == "FREF";
  Image& target = is_reference ? reference : image;
  (void)renderSplats(splats, view.camera, {0, 0, 0}, target);
  Result<FoveatedQuality> q =
      foveatedQuality(reference, target, view.camera, view.gaze.direction, options.ring_edges_deg, options.slope);
  if (!q) return q.status();
  row.quality = q.value();
  if (!options.image_path_prefix.empty() && !is_reference) {
    if (lines.size() < 2) lines = options.ring_edges_deg;
    row.image = options.image_path_prefix + "_" + name + ".png";
    if (Status st = writeSideBySidePng(row.image, reference, target, view.camera, view.gaze.direction, lines,
                                       options.image_scale);
        !st) {
      return st;
    }
  }
  return Status::ok();
}

// A row of this position's table for condition c.
QualityRow QualityEvaluator::State::newRow(const View& view, const Condition& c) {
  QualityRow row;
  row.dataset = view.dataset.name;
  row.condition = c.name;
  row.position = view.position.index;
  return row;
}

// MAP-DELTA without what the operator held: a row not measured.
QualityRow QualityEvaluator::State::unmeasuredRow(const View& view, const Condition& c,
                                                  const QualityRow& reference_row) {
  QualityRow row = newRow(view, c);
  row.frame = static_cast<int>(view.frame.sequence);
  row.measured = false;
  row.quality = reference_row.quality;  // FREF's rings (their bounds and weights), every figure NaN
  for (Ring& r : row.quality.rings) r.psnr_db = r.ssim = std::numeric_limits<double>::quiet_NaN();
  row.quality.weighted_psnr_db = row.quality.weighted_ssim = row.quality.psnr_db = row.quality.ssim =
      std::numeric_limits<double>::quiet_NaN();
  row.above_mar_share = std::numeric_limits<double>::quiet_NaN();
  return row;
}

// Splats as for every other condition: a live region's median spacing or
// its voxel, whichever is larger, FREF's raw spacing for raw points; the
// same per brick level (level 0, raw surfels: at least FREF's raw spacing
// and the brick's step). The viewer draws a level at its voxel alone
// (tools/operator/view_frame.h), which leaves holes where the map's
// surfels lie farther apart than a fine level's voxel.
std::vector<float> QualityEvaluator::State::heldSplatSizes(const View& view, const tools::HeldCloud& h) {
  const std::size_t n = h.points.size();
  pipeline::FoveatedCloud live;
  live.points = h.points;
  live.region = h.region;
  std::array<uint32_t, pipeline::kMaxRegions> region_points{};
  for (uint8_t r : h.region) {
    if (r < pipeline::kMaxRegions) ++region_points[r];
  }
  std::array<float, pipeline::kMaxRegions> live_size = medianNeighbourSpacing(live, region_points, spacing);
  const double ratio = h.info.periphery_step_ratio;
  for (int r = 1; r < pipeline::kMaxRegions; ++r) {
    live_size[r] = std::max(live_size[r], static_cast<float>(h.info.live_step_m[r] / ratio));
  }
  live_size[0] = raw_spacing_m;
  // The map's points by level, measured the same way (a brick's points keep
  // the codec's Morton order in the cache).
  pipeline::FoveatedCloud bricks;
  bricks.points = h.points;
  bricks.region.assign(n, pipeline::kMaxRegions);  // the live points: in no level
  std::array<uint32_t, pipeline::kMaxRegions> level_points{};
  for (std::size_t i = 0; i < n; ++i) {
    const uint8_t r = h.region[i];
    if (r >= tools::kHeldMapRegion && r < tools::kHeldMapRegion + pipeline::kMaxRegions) {
      bricks.region[i] = static_cast<uint8_t>(r - tools::kHeldMapRegion);
      ++level_points[bricks.region[i]];
    }
  }
  std::array<float, pipeline::kMaxRegions> map_size = medianNeighbourSpacing(bricks, level_points, spacing);
  map_size[0] = std::max({map_size[0], raw_spacing_m, static_cast<float>(h.info.map_step_m[0])});
  for (int l = 1; l < pipeline::kMaxRegions; ++l) {
    map_size[l] = std::max(map_size[l], static_cast<float>(h.info.map_step_m[l] / ratio));
  }
  std::vector<float> sizes(n);
  for (std::size_t i = 0; i < n; ++i) {
    const uint8_t r = h.region[i];
    float size = 0.0f;
    if (r < pipeline::kMaxRegions) {
      size = live_size[r];
    } else if (r >= tools::kHeldMapRegion && r < tools::kHeldMapRegion + pipeline::kMaxRegions) {
      size = map_size[r - tools::kHeldMapRegion];
    }
    sizes[i] = size > 0.0f ? size : static_cast<float>((h.points.world(i) - view.sensor).norm() / view.fx);
  }
  return sizes;
}

// What the operator drew at this frame (fovea-operator --save-held), not a
// foveation of the frame here.
Result<QualityRow> QualityEvaluator::State::heldRow(const View& view, const Condition& c, const tools::HeldCloud& h) {
  using R = Result<QualityRow>;
  QualityRow row = newRow(view, c);
  row.frame = static_cast<int>(view.frame.sequence);
  if (h.info.frame_id != view.frame.sequence) {
    return R(ErrorCode::kInvalidArgument, c.name + ": the operator's cloud is of frame " + std::to_string(h.info.frame_id) +
                                              ", the quality frame is " + std::to_string(view.frame.sequence));
  }
  const std::size_t n = h.points.size();
  if (h.region.size() != n) return R(ErrorCode::kInvalidArgument, c.name + ": a region per point is needed");
  const std::vector<float> held_size_m = heldSplatSizes(view, h);
  SplatCloud splats;
  splats.x = h.points.x();
  splats.y = h.points.y();
  splats.z = h.points.z();
  splats.rgb = h.points.rgb();
  splats.size_m = held_size_m.data();
  splats.count = n;
  splats.origin_m = h.points.origin_m;
  row.points = static_cast<uint32_t>(n);
  row.above_mar_share = heldShareAboveMar(cloud, h.points, view.camera, view.gaze.direction, view.options.slope);
  if (Status st = draw(view, splats, c.name, {}, row); !st) return st;
  return row;
}

// The condition's foveation with each input point's representative into `out`:
// of the frame's cloud, or for the map source of `map`'s (foveator and input
// say which was used).
Status QualityEvaluator::State::foveateCondition(const View& view, const Condition& c, firmware::FrameFoveator* map,
                                                 pipeline::Foveator*& used, const pipeline::PointCloud*& input,
                                                 pipeline::FoveationStats& stats) {
  pipeline::FoveationConfig config;
  Result<pipeline::Preset> preset = pipeline::parsePreset(c.preset);
  if (!preset) return preset.status();
  config.acuity.preset = preset.value();
  config.acuity.slope = view.options.slope;
  config.acuity.floor_per_m2 = c.floor_per_m2;
  if (c.level_margin > 0.0) config.acuity.level_margin = c.level_margin;
  config.acuity.refine_passes = c.refine_passes;
  used = &foveator;
  input = &cloud;
  if (c.source == "map") {
    // The service's map source: the map's stable surfels this eye sees and the
    // frame's unexplained points, foveated together (its representatives from
    // the same foveation run again on that cloud).
    if (map == nullptr || map->source() != firmware::FoveationSource::kMap) {
      return Status(ErrorCode::kInvalidArgument, c.name + ": the quality frame has no map");
    }
    map->invalidate();
    if (Status st = map->use(&config); !st) return st;
    pipeline::FoveationStats map_stats;
    const Status st = map->foveate(view.gaze, out, map_stats);
    map->invalidate();  // (config is this iteration's)
    if (!st) return st;
    used = &map->foveator();
    input = &map->cloud();
  } else if (Status st = used->setConfig(config); !st) {
    return st;
  }
  if (input->size() > max_points) {
    return Status(ErrorCode::kCapacityExceeded, c.name + ": " + std::to_string(input->size()) + " points, room for " +
                                                    std::to_string(max_points));
  }
  return used->foveate(*input, view.gaze, out, stats, representative.data());
}

// Through the codec and back (what the operator draws) into `decoded`, and
// its splats' sizes into size_m.
Status QualityEvaluator::State::decodeAndSize(const View& view, const Condition& c,
                                              const pipeline::FoveationStats& stats) {
  std::array<double, pipeline::kMaxRegions> voxel_m{};
  for (int r = 0; r < stats.region_count; ++r) voxel_m[r] = stats.regions[r].voxel_size_m;
  if (Status st = encoder.encode(out, std::span<const double>(voxel_m.data(), stats.region_count), 0, 0); !st) {
    return st;
  }
  decoded.clear();
  for (std::size_t i = 0; i < encoder.chunkCount(); ++i) {
    Result<net::DecodedChunk> chunk = net::decodeChunk(encoder.chunk(i), decoded);
    if (!chunk) return Status(chunk.status().code(), "decoding " + c.name + ": " + chunk.status().message());
  }
  // Splats, per region: the median spacing of the region's decoded points, or its
  // voxel when that is larger, as the operator's viewer sizes them
  // (tools/operator/view_frame.h): voxels finer than the sensor's sampling (ACUITY's
  // 2 to 8 mm levels, one sample each) would otherwise leave holes. Raw points get
  // FREF's spacing in every condition (the same point is drawn the same in each).
  const pipeline::PointCloud& p = decoded.points;
  const std::vector<uint8_t>& regions = decoded.region;
  std::array<uint32_t, pipeline::kMaxRegions> region_points{};
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (regions[i] < pipeline::kMaxRegions) ++region_points[regions[i]];
  }
  std::array<float, pipeline::kMaxRegions> region_size = medianNeighbourSpacing(decoded, region_points, spacing);
  for (int r = 1; r < stats.region_count; ++r) {
    region_size[r] = std::max(static_cast<float>(stats.regions[r].voxel_size_m), region_size[r]);
  }
  if (c.name == "FREF") raw_spacing_m = region_size[0];
  region_size[0] = raw_spacing_m;
  for (std::size_t i = 0; i < p.size(); ++i) {
    // (A lone point of a region without pairs: the camera pixel it stands for.)
    const float size = region_size[regions[i] < pipeline::kMaxRegions ? regions[i] : 0];
    if (size > 0.0f) {
      size_m[i] = size;
    } else {
      const Eigen::Vector3d world = p.origin_m + Eigen::Vector3d(p.x()[i], p.y()[i], p.z()[i]);
      size_m[i] = static_cast<float>((world - view.sensor).norm() / view.fx);
    }
  }
  return Status::ok();
}

// A condition foveated here: its error against the input, then its cloud
// through the codec and back, drawn.
Result<QualityRow> QualityEvaluator::State::foveatedRow(const View& view, const Condition& c,
                                                        firmware::FrameFoveator* map) {
  pipeline::Foveator* used = nullptr;
  const pipeline::PointCloud* input = nullptr;
  pipeline::FoveationStats stats;
  if (Status st = foveateCondition(view, c, map, used, input, stats); !st) return st;
  QualityRow row = newRow(view, c);
  pipeline::ErrorModel model{&used->model(), {}, view.options.slope};
  for (int r = 0; r < stats.region_count; ++r) model.voxel_size_m[r] = stats.regions[r].voxel_size_m;
  pipeline::ErrorMetrics metrics;
  if (Status st = errors.evaluate(*input, used->lastRegions(), representative.data(), out.points, view.gaze, model,
                                  metrics);
      !st) {
    return st;
  }
  row.above_mar_share = metrics.all.shareAboveMar();
  if (Status st = decodeAndSize(view, c, stats); !st) return st;
  const pipeline::PointCloud& p = decoded.points;
  SplatCloud splats;
  splats.x = p.x();
  splats.y = p.y();
  splats.z = p.z();
  splats.rgb = p.rgb();
  splats.size_m = size_m.data();
  splats.count = p.size();
  splats.origin_m = p.origin_m;
  row.points = static_cast<uint32_t>(p.size());
  row.frame = static_cast<int>(view.frame.sequence);
  // The lines on the difference: the condition's own region borders (the paper's
  // cones), or, for ACUITY, which has none, the measuring rings.
  std::vector<double> lines = {0.0};
  for (int b = 0; b < used->model().boundCount(); ++b) {
    if (used->model().boundDeg(b) < 90.0) lines.push_back(used->model().boundDeg(b));
  }
  if (Status st = draw(view, splats, c.name, lines, row); !st) return st;
  return row;
}

Result<std::vector<QualityRow>> QualityEvaluator::evaluate(const hal::RgbdFrame& frame, const Dataset& dataset,
                                                           const HmdPosition& position,
                                                           const std::vector<Condition>& conditions,
                                                           const QualityOptions& options, firmware::FrameFoveator* map,
                                                           const tools::HeldCloud* held) {
  State& s = *s_;
  pipeline::BackprojectCounts counts;
  if (Status st = pipeline::backprojectRef(frame, pipeline::DepthRange{}, s.cloud, counts); !st) return st;
  pipeline::Gaze gaze;
  gaze.origin_m = position.eye_m;
  gaze.direction = (position.targets_m.front() - position.eye_m).normalized();
  gaze.view_known = true;  // the head looks where the eye does (fovea-operator's scripted head)
  gaze.view_forward = gaze.direction;
  const Eigen::Vector3d up = -frame.T_world_cam.R_world_cam.col(1);
  const State::View view{frame, dataset, position, options, gaze, eyeCamera(position, up, options),
                         frame.intrinsics.fx, frame.T_world_cam.t_world_cam};

  // FREF first: its drawing is the reference for every other condition.
  std::vector<Condition> order = {{"FREF", "FREF"}};
  for (const Condition& c : conditions) {
    if (c.name != "FREF") order.push_back(c);
  }
  std::vector<QualityRow> rows;
  for (const Condition& c : order) {
    if (c.map_delta && held == nullptr) {
      rows.push_back(State::unmeasuredRow(view, c, rows.front()));
      continue;
    }
    Result<QualityRow> row = c.map_delta ? s.heldRow(view, c, *held) : s.foveatedRow(view, c, map);
    if (!row) return row.status();
    rows.push_back(std::move(row.value()));
  }
  return rows;
}

}  // namespace fovea::tools::eval

#include "tools/eval/quality_eval.h"

#include <algorithm>
#include <cmath>
#include <limits>

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

Result<std::vector<QualityRow>> QualityEvaluator::evaluate(const hal::RgbdFrame& frame, const Dataset& dataset,
                                                           const HmdPosition& position,
                                                           const std::vector<Condition>& conditions,
                                                           const QualityOptions& options, firmware::FrameFoveator* map,
                                                           const tools::HeldCloud* held) {
  using R = Result<std::vector<QualityRow>>;
  State& s = *s_;
  pipeline::BackprojectCounts counts;
  if (Status st = pipeline::backprojectRef(frame, pipeline::DepthRange{}, s.cloud, counts); !st) return st;
  pipeline::Gaze gaze;
  gaze.origin_m = position.eye_m;
  gaze.direction = (position.targets_m.front() - position.eye_m).normalized();
  gaze.view_known = true;  // the head looks where the eye does (fovea-operator's scripted head)
  gaze.view_forward = gaze.direction;
  const Eigen::Vector3d up = -frame.T_world_cam.R_world_cam.col(1);
  const EyeCamera camera = eyeCamera(position, up, options);
  const double fx = frame.intrinsics.fx;
  const Eigen::Vector3d sensor = frame.T_world_cam.t_world_cam;

  // FREF first: its drawing is the reference for every other condition.
  std::vector<Condition> order = {{"FREF", "FREF"}};
  for (const Condition& c : conditions) {
    if (c.name != "FREF") order.push_back(c);
  }
  std::vector<QualityRow> rows;
  // Draws `splats` from the eye, measures it against the reference (or makes it
  // the reference) and writes the side-by-side image with `lines` (empty: the rings).
  const auto draw = [&](const SplatCloud& splats, const std::string& name, std::vector<double> lines,
                        QualityRow& row) -> Status {
    const bool is_reference = name == "FREF";
    Image& target = is_reference ? s.reference : s.image;
    (void)renderSplats(splats, camera, {0, 0, 0}, target);
    Result<FoveatedQuality> q =
        foveatedQuality(s.reference, target, camera, gaze.direction, options.ring_edges_deg, options.slope);
    if (!q) return q.status();
    row.quality = q.value();
    if (!options.image_path_prefix.empty() && !is_reference) {
      if (lines.size() < 2) lines = options.ring_edges_deg;
      row.image = options.image_path_prefix + "_" + name + ".png";
      if (Status st = writeSideBySidePng(row.image, s.reference, target, camera, gaze.direction, lines,
                                         options.image_scale);
          !st) {
        return st;
      }
    }
    return Status::ok();
  };
  for (const Condition& c : order) {
    if (c.map_delta) {
      // What the operator drew at this frame (fovea-operator --save-held), not a
      // foveation of the frame here.
      QualityRow row;
      row.dataset = dataset.name;
      row.condition = c.name;
      row.position = position.index;
      row.frame = static_cast<int>(frame.sequence);
      if (held == nullptr) {
        row.measured = false;
        row.quality = rows.front().quality;  // FREF's rings (their bounds and weights), every figure NaN
        for (Ring& r : row.quality.rings) r.psnr_db = r.ssim = std::numeric_limits<double>::quiet_NaN();
        row.quality.weighted_psnr_db = row.quality.weighted_ssim = row.quality.psnr_db = row.quality.ssim =
            std::numeric_limits<double>::quiet_NaN();
        row.above_mar_share = std::numeric_limits<double>::quiet_NaN();
        rows.push_back(std::move(row));
        continue;
      }
      const tools::HeldCloud& h = *held;
      if (h.info.frame_id != frame.sequence) {
        return R(ErrorCode::kInvalidArgument, c.name + ": the operator's cloud is of frame " + std::to_string(h.info.frame_id) +
                                                  ", the quality frame is " + std::to_string(frame.sequence));
      }
      const std::size_t n = h.points.size();
      if (h.region.size() != n) return R(ErrorCode::kInvalidArgument, c.name + ": a region per point is needed");
      // Splats as for every other condition: a live region's median spacing or
      // its voxel, whichever is larger, FREF's raw spacing for raw points; the
      // same per brick level (level 0, raw surfels: at least FREF's raw spacing
      // and the brick's step). The viewer draws a level at its voxel alone
      // (tools/operator/view_frame.h), which leaves holes where the map's
      // surfels lie farther apart than a fine level's voxel.
      pipeline::FoveatedCloud live;
      live.points = h.points;
      live.region = h.region;
      std::array<uint32_t, pipeline::kMaxRegions> region_points{};
      for (uint8_t r : h.region) {
        if (r < pipeline::kMaxRegions) ++region_points[r];
      }
      std::array<float, pipeline::kMaxRegions> live_size = medianNeighbourSpacing(live, region_points, s.spacing);
      const double ratio = h.info.periphery_step_ratio;
      for (int r = 1; r < pipeline::kMaxRegions; ++r) {
        live_size[r] = std::max(live_size[r], static_cast<float>(h.info.live_step_m[r] / ratio));
      }
      live_size[0] = s.raw_spacing_m;
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
      std::array<float, pipeline::kMaxRegions> map_size = medianNeighbourSpacing(bricks, level_points, s.spacing);
      map_size[0] = std::max({map_size[0], s.raw_spacing_m, static_cast<float>(h.info.map_step_m[0])});
      for (int l = 1; l < pipeline::kMaxRegions; ++l) {
        map_size[l] = std::max(map_size[l], static_cast<float>(h.info.map_step_m[l] / ratio));
      }
      std::vector<float> size_m(n);
      for (std::size_t i = 0; i < n; ++i) {
        const uint8_t r = h.region[i];
        float size = 0.0f;
        if (r < pipeline::kMaxRegions) {
          size = live_size[r];
        } else if (r >= tools::kHeldMapRegion && r < tools::kHeldMapRegion + pipeline::kMaxRegions) {
          size = map_size[r - tools::kHeldMapRegion];
        }
        size_m[i] = size > 0.0f ? size : static_cast<float>((h.points.world(i) - sensor).norm() / fx);
      }
      SplatCloud splats;
      splats.x = h.points.x();
      splats.y = h.points.y();
      splats.z = h.points.z();
      splats.rgb = h.points.rgb();
      splats.size_m = size_m.data();
      splats.count = n;
      splats.origin_m = h.points.origin_m;
      row.points = static_cast<uint32_t>(n);
      row.above_mar_share = heldShareAboveMar(s.cloud, h.points, camera, gaze.direction, options.slope);
      if (Status st = draw(splats, c.name, {}, row); !st) return st;
      rows.push_back(std::move(row));
      continue;
    }
    pipeline::FoveationConfig config;
    Result<pipeline::Preset> preset = pipeline::parsePreset(c.preset);
    if (!preset) return preset.status();
    config.acuity.preset = preset.value();
    config.acuity.slope = options.slope;
    config.acuity.floor_per_m2 = c.floor_per_m2;
    if (c.level_margin > 0.0) config.acuity.level_margin = c.level_margin;
    config.acuity.refine_passes = c.refine_passes;
    pipeline::Foveator* foveator = &s.foveator;
    const pipeline::PointCloud* input = &s.cloud;
    if (c.source == "map") {
      // The service's map source: the map's stable surfels this eye sees and the
      // frame's unexplained points, foveated together (its representatives from
      // the same foveation run again on that cloud).
      if (map == nullptr || map->source() != firmware::FoveationSource::kMap) {
        return R(ErrorCode::kInvalidArgument, c.name + ": the quality frame has no map");
      }
      map->invalidate();
      if (Status st = map->use(&config); !st) return st;
      pipeline::FoveationStats map_stats;
      const Status st = map->foveate(gaze, s.out, map_stats);
      map->invalidate();  // (config is this iteration's)
      if (!st) return st;
      foveator = &map->foveator();
      input = &map->cloud();
    } else if (Status st = foveator->setConfig(config); !st) {
      return st;
    }
    if (input->size() > s.max_points) {
      return R(ErrorCode::kCapacityExceeded, c.name + ": " + std::to_string(input->size()) + " points, room for " +
                                                 std::to_string(s.max_points));
    }
    pipeline::FoveationStats stats;
    if (Status st = foveator->foveate(*input, gaze, s.out, stats, s.representative.data()); !st) return st;
    QualityRow row;
    row.dataset = dataset.name;
    row.condition = c.name;
    row.position = position.index;
    pipeline::ErrorModel model{&foveator->model(), {}, options.slope};
    for (int r = 0; r < stats.region_count; ++r) model.voxel_size_m[r] = stats.regions[r].voxel_size_m;
    pipeline::ErrorMetrics metrics;
    if (Status st = s.errors.evaluate(*input, foveator->lastRegions(), s.representative.data(), s.out.points, gaze,
                                      model, metrics);
        !st) {
      return st;
    }
    row.above_mar_share = metrics.all.shareAboveMar();

    // Through the codec and back: what the operator draws.
    std::array<double, pipeline::kMaxRegions> voxel_m{};
    for (int r = 0; r < stats.region_count; ++r) voxel_m[r] = stats.regions[r].voxel_size_m;
    if (Status st = s.encoder.encode(s.out, std::span<const double>(voxel_m.data(), stats.region_count), 0, 0); !st) {
      return st;
    }
    s.decoded.clear();
    for (std::size_t i = 0; i < s.encoder.chunkCount(); ++i) {
      Result<net::DecodedChunk> chunk = net::decodeChunk(s.encoder.chunk(i), s.decoded);
      if (!chunk) return R(chunk.status().code(), "decoding " + c.name + ": " + chunk.status().message());
    }
    // Splats, per region: the median spacing of the region's decoded points, or its
    // voxel when that is larger, as the operator's viewer sizes them
    // (tools/operator/view_frame.h): voxels finer than the sensor's sampling (ACUITY's
    // 2 to 8 mm levels, one sample each) would otherwise leave holes. Raw points get
    // FREF's spacing in every condition (the same point is drawn the same in each).
    const pipeline::PointCloud& p = s.decoded.points;
    const std::vector<uint8_t>& regions = s.decoded.region;
    std::array<uint32_t, pipeline::kMaxRegions> region_points{};
    for (std::size_t i = 0; i < p.size(); ++i) {
      if (regions[i] < pipeline::kMaxRegions) ++region_points[regions[i]];
    }
    std::array<float, pipeline::kMaxRegions> region_size = medianNeighbourSpacing(s.decoded, region_points, s.spacing);
    for (int r = 1; r < stats.region_count; ++r) {
      region_size[r] = std::max(static_cast<float>(stats.regions[r].voxel_size_m), region_size[r]);
    }
    if (c.name == "FREF") s.raw_spacing_m = region_size[0];
    region_size[0] = s.raw_spacing_m;
    for (std::size_t i = 0; i < p.size(); ++i) {
      // (A lone point of a region without pairs: the camera pixel it stands for.)
      const float size = region_size[regions[i] < pipeline::kMaxRegions ? regions[i] : 0];
      if (size > 0.0f) {
        s.size_m[i] = size;
      } else {
        const Eigen::Vector3d world = p.origin_m + Eigen::Vector3d(p.x()[i], p.y()[i], p.z()[i]);
        s.size_m[i] = static_cast<float>((world - sensor).norm() / fx);
      }
    }
    SplatCloud splats;
    splats.x = p.x();
    splats.y = p.y();
    splats.z = p.z();
    splats.rgb = p.rgb();
    splats.size_m = s.size_m.data();
    splats.count = p.size();
    splats.origin_m = p.origin_m;
    row.points = static_cast<uint32_t>(p.size());
    row.frame = static_cast<int>(frame.sequence);
    // The lines on the difference: the condition's own region borders (the paper's
    // cones), or, for ACUITY, which has none, the measuring rings.
    std::vector<double> lines = {0.0};
    for (int b = 0; b < foveator->model().boundCount(); ++b) {
      if (foveator->model().boundDeg(b) < 90.0) lines.push_back(foveator->model().boundDeg(b));
    }
    if (Status st = draw(splats, c.name, lines, row); !st) return st;
    rows.push_back(std::move(row));
  }
  return rows;
}

}  // namespace fovea::tools::eval

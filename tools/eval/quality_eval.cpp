#include "tools/eval/quality_eval.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "net/codec.h"
#include "pipeline/backproject.h"
#include "pipeline/error_metrics.h"
#include "pipeline/foveator.h"
#include "tools/common/splat_spacing.h"
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
                                                           const QualityOptions& options, firmware::FrameFoveator* map) {
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
  for (const Condition& c : order) {
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
    const bool is_reference = c.name == "FREF";
    Image& target = is_reference ? s.reference : s.image;
    (void)renderSplats(splats, camera, {0, 0, 0}, target);
    Result<FoveatedQuality> q =
        foveatedQuality(s.reference, target, camera, gaze.direction, options.ring_edges_deg, options.slope);
    if (!q) return q.status();
    row.quality = q.value();
    if (!options.image_path_prefix.empty() && !is_reference) {
      // The lines on the difference: the condition's own region borders (the paper's
      // cones), or, for ACUITY, which has none, the measuring rings.
      std::vector<double> lines = {0.0};
      for (int b = 0; b < foveator->model().boundCount(); ++b) {
        if (foveator->model().boundDeg(b) < 90.0) lines.push_back(foveator->model().boundDeg(b));
      }
      if (lines.size() < 2) lines = options.ring_edges_deg;
      row.image = options.image_path_prefix + "_" + c.name + ".png";
      if (Status st = writeSideBySidePng(row.image, s.reference, target, camera, gaze.direction, lines,
                                         options.image_scale);
          !st) {
        return st;
      }
    }
    rows.push_back(std::move(row));
  }
  return rows;
}

}  // namespace fovea::tools::eval

// fovea-map-delta: the bytes a stream of map changes (pipeline/map/map_delta.h:
// bricks at the level the eye needs, sent once and again only when due) would
// send, against the frame-by-frame streams FREF and F1, on the mock camera with
// a scripted gaze, and how close what the operator then holds lies to the true
// surface. One process, no sockets, no loss: every stream is encoded by the
// same codec (net/codec.h) and counted in datagram bytes (payload plus the
// datagram's header and tag); the map's bricks carry their brick tag and are
// decoded into the operator's cache (net/brick_cache.h).
//
//   fovea-map-delta [--scene living-room] [--path static] [--frames 90] [--size 640x480]
//                   [--budget-mbps 12.5] [--fps 30] [--dwell-frames 9] [--eval-every 15]
//                   [--pose camera|track] [--change-fraction 0.01] [--growth-fraction 0.2]
//                   [--churn-fraction 0.2] [--explain-held on|off]
//
// The map is the service's: one pipeline::map::Mapper (pipeline/map/mapper.h)
// that poses (--pose track: its tracker, from the frames alone; camera, the
// default: the camera's own pose), fuses and plans each frame's bricks within
// the frame's share of the budget by the service's estimate of their bytes.
// The gaze: the operator's eye at the camera, fixating the scene's focus point
// and four points 0.25-0.4 m around it in turn, --dwell-frames frames each
// (9: 300 ms at 30 fps), with an instant saccade between.
//
// MAP-DELTA each frame, as the service sends it: the frame's points the map
// does not explain (ACUITY-foveated; a frame the map did not fuse goes whole),
// and the bricks Mapper::planBricks puts in the frame's batch (the fovea's
// first, the live points charged after them, then the other due bricks while
// the estimate fits the frame's share of the budget; the rest waits), each
// brick encoded on its own as the service's streamer does.
//
// Quality, every --eval-every frames from the second second on and at the
// last: for each point of the true surface the frame sees (the mock camera's
// noiseless twin, back-projected), the nearest point of what the operator
// draws (FREF's or F1's decoded frame; for MAP-DELTA the cache's bricks and the
// frame's live points), and whether it is displaced, seen from the eye, by more
// than the MAR at the true point's eccentricity (Eq. 1, m = 0.022). A
// nearest-point measure, unlike fovea-eval's (each input point against its own
// representative). And the other way: the points drawn that the camera sees
// through, more than 10 cm in front of the surface the reference frame
// measures (a ghost the true points' nearest-point measure cannot see).
//
// On a mock scene with movers (the balloon, the walker, the carried block:
// hal/camera/mock/built_in_scenes.cpp), the same frames judge the mover alone
// (issue 42): the true points the twin sees on it, the points F1 and MAP-DELTA
// draw on it (within 2 cm of its surface along the camera's ray) and the
// share of its true points above the MAR, frame by frame. An evaluation tool:
// it allocates freely.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Geometry>

#include "bench/bench_input.h"
#include "bench/mock_scene.h"
#include "hal/camera.h"
#include "hal/camera/mock/scene.h"
#include "net/brick_cache.h"
#include "net/codec.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "pipeline/map/brick_batch.h"
#include "pipeline/map/map_delta.h"
#include "pipeline/map/mapper.h"
#include "pipeline/map/surfel_map.h"
#include "pipeline/voxel_sampler.h"

namespace {

using namespace fovea;
using bench::option;

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// Datagram bytes of the encoder's last encode.
std::size_t datagramBytes(const net::ChunkEncoder& encoder) {
  std::size_t bytes = 0;
  for (std::size_t i = 0; i < encoder.chunkCount(); ++i) bytes += encoder.chunk(i).size() + net::kDatagramOverhead;
  return bytes;
}

// Decodes every chunk of the encoder's last encode: brick chunks into `cache`,
// frame chunks appended to `held` (world positions).
void decodeAll(const net::ChunkEncoder& encoder, net::BrickCache* cache, std::vector<Eigen::Vector3d>* held,
               pipeline::FoveatedCloud& scratch, int64_t now_ns) {
  alignas(16) static uint8_t aligned[net::kMaxMtu];
  for (std::size_t i = 0; i < encoder.chunkCount(); ++i) {
    const std::span<const uint8_t> c = encoder.chunk(i);
    std::memcpy(aligned, c.data(), c.size());
    scratch.clear();
    fovea::Result<net::DecodedChunk> d = net::decodeChunk(std::span<const uint8_t>(aligned, c.size()), scratch);
    if (!d) {
      std::fprintf(stderr, "fovea-map-delta: a chunk did not decode: %s\n", d.status().message().c_str());
      std::exit(1);
    }
    if (cache) cache->add(d.value(), scratch, 0, now_ns);
    if (held) {
      for (std::size_t p = 0; p < scratch.size(); ++p) held->push_back(scratch.points.world(p));
    }
  }
}

// The share of the true surface's points (a noiseless frame's) whose nearest
// point of `held` is displaced, seen from the eye, by more than the MAR at the
// point's eccentricity (Eq. 1, slope m). A true point with no held point within
// 10 cm counts as displaced (`missing`).
double shareAboveMar(const std::vector<Eigen::Vector3d>& held, const std::vector<Eigen::Vector3d>& truth,
                     const pipeline::Gaze& gaze, double slope, std::size_t& missing) {
  constexpr double kCell = 0.02;
  constexpr int kRings = 5;
  auto cellOf = [](const Eigen::Vector3d& p) {
    return Eigen::Vector3i(static_cast<int>(std::floor(p.x() / kCell)), static_cast<int>(std::floor(p.y() / kCell)),
                           static_cast<int>(std::floor(p.z() / kCell)));
  };
  auto key = [](const Eigen::Vector3i& c) {
    return (static_cast<int64_t>(c.x() & 0x1fffff) << 42) | (static_cast<int64_t>(c.y() & 0x1fffff) << 21) |
           static_cast<int64_t>(c.z() & 0x1fffff);
  };
  std::unordered_map<int64_t, std::vector<uint32_t>> grid;
  for (std::size_t i = 0; i < held.size(); ++i) grid[key(cellOf(held[i]))].push_back(static_cast<uint32_t>(i));
  const Eigen::Vector3d l = gaze.direction.normalized();
  std::size_t above = 0, seen = 0;
  missing = 0;
  for (std::size_t t = 0; t < truth.size(); ++t) {
    const Eigen::Vector3d& p = truth[t];
    const Eigen::Vector3i c = cellOf(p);
    double best = std::numeric_limits<double>::infinity();
    int nearest = -1;
    for (int r = 0; r <= kRings && !(best <= (r - 1) * kCell); ++r) {
      for (int dx = -r; dx <= r; ++dx) {
        for (int dy = -r; dy <= r; ++dy) {
          for (int dz = -r; dz <= r; ++dz) {
            if (std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) != r) continue;  // the ring's shell only
            const auto it = grid.find(key(c + Eigen::Vector3i(dx, dy, dz)));
            if (it == grid.end()) continue;
            for (uint32_t i : it->second) {
              const double d = (held[i] - p).norm();
              if (d < best) {
                best = d;
                nearest = static_cast<int>(i);
              }
            }
          }
        }
      }
    }
    ++seen;
    if (nearest < 0 || best > kRings * kCell) {
      ++missing;
      ++above;
      continue;
    }
    const Eigen::Vector3d a = p - gaze.origin_m, b = held[static_cast<std::size_t>(nearest)] - gaze.origin_m;
    const double alpha = std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / M_PI;
    const double ecc = std::atan2(a.cross(l).norm(), a.dot(l)) * 180.0 / M_PI;
    above += alpha > slope * ecc + pipeline::kMar0Deg ? 1 : 0;
  }
  return seen > 0 ? static_cast<double>(above) / static_cast<double>(seen) : 0.0;
}

// Held points the reference frame's camera sees through: inside its image, in
// front of the surface its depth measures there by more than 10 cm (a ghost: a
// surface the operator still draws where the camera now sees free space), away
// from depth edges (trueDepthAt). The reverse of shareAboveMar's "missing",
// which only looks from the true points.
std::size_t pointsInFreeSpace(const std::vector<Eigen::Vector3d>& held, const hal::RgbdFrame& reference,
                              const hal::CameraIntrinsics& k) {
  constexpr double kMargin = 0.10;
  const hal::Pose& pose = reference.T_world_cam;
  std::size_t ghosts = 0;
  for (const Eigen::Vector3d& p : held) {
    const Eigen::Vector3d c = pose.R_world_cam.transpose() * (p - pose.t_world_cam);
    if (!(c.z() > 0.0)) continue;
    const double z = bench::trueDepthAt(reference, k.fx * c.x() / c.z() + k.cx, k.fy * c.y() / c.z() + k.cy);
    if (c.z() < z - kMargin) ++ghosts;  // false for NaN: outside the image, no depth, or an edge
  }
  return ghosts;
}

struct Stream {
  const char* name;
  std::size_t bytes = 0;         // all frames
  std::size_t bytes_steady = 0;  // after the first second
};

struct DeltaOptions {
  std::string spec;    // the mock camera's (mock_scene.h)
  std::string scene;   // its scene's name (--scene), for the mover's own figures
  std::string camera;  // --camera: another camera (a TUM sequence) in its place, without a twin
  int frames = 90;
  double budget_mbps = 12.5;
  int fps = 30;
  int dwell = 9;
  int eval_every = 15;
  bool track = false;  // --pose track
  // --change-fraction, --growth-fraction, --churn-fraction: the resend rule's
  // bounds (map.change_fraction, map.growth_fraction, map.churn_fraction), and
  // --explain-held (map.explain_held_only), for sweeps.
  pipeline::map::MapDeltaConfig delta;
};

// Returns the options, or nothing after printing why they are refused.
std::optional<DeltaOptions> parseOptions(int argc, char** argv) {
  DeltaOptions o;
  o.spec = bench::mockSceneSpec(argc, argv, "static");
  o.scene = option(argc, argv, "--scene", "living-room");
  o.camera = option(argc, argv, "--camera", "");
  o.frames = std::atoi(option(argc, argv, "--frames", "90").c_str());
  o.budget_mbps = std::atof(option(argc, argv, "--budget-mbps", "12.5").c_str());
  o.fps = std::atoi(option(argc, argv, "--fps", "30").c_str());
  o.dwell = std::atoi(option(argc, argv, "--dwell-frames", "9").c_str());
  o.eval_every = std::atoi(option(argc, argv, "--eval-every", "15").c_str());
  if (o.frames < 1 || o.fps < 1 || o.dwell < 1 || o.eval_every < 1 || !(o.budget_mbps > 0.0)) {
    std::fprintf(stderr,
                 "fovea-map-delta: --frames, --fps, --dwell-frames, --eval-every and --budget-mbps must be positive\n");
    return std::nullopt;
  }
  const std::string pose = option(argc, argv, "--pose", "camera");
  if (pose != "camera" && pose != "track") {
    std::fprintf(stderr, "fovea-map-delta: --pose is camera or track, not '%s'\n", pose.c_str());
    return std::nullopt;
  }
  o.track = pose == "track";
  o.delta.change_fraction = std::atof(option(argc, argv, "--change-fraction", std::to_string(o.delta.change_fraction).c_str()).c_str());
  o.delta.churn_fraction = std::atof(option(argc, argv, "--churn-fraction", std::to_string(o.delta.churn_fraction).c_str()).c_str());
  o.delta.growth_fraction = std::atof(option(argc, argv, "--growth-fraction", std::to_string(o.delta.growth_fraction).c_str()).c_str());
  o.delta.explain_held_only = option(argc, argv, "--explain-held", "on") == "on";
  if (Status s = o.delta.validate(); !s) {
    std::fprintf(stderr, "fovea-map-delta: %s\n", s.message().c_str());
    return std::nullopt;
  }
  return o;
}

// What one frame's steps share: its gaze, stamp and what is left of its budget.
struct FrameStep {
  int f = 0;
  bool steady = false;  // after the first second
  pipeline::Gaze gaze;
  uint32_t frame_id = 0;
  int64_t now_ns = 0;
};

// The run: the camera and its twin, the map and its stream of changes, the
// encoder, the operator's side, and the figures gathered frame by frame.
class DeltaBench {
 public:
  // A brick holds at most this many stable surfels here (the mock room's hold a few thousand).
  static constexpr std::size_t kMaxBrickPoints = 1 << 18;

  // truth_camera: the noiseless twin, or nullptr (the frame itself is the reference).
  DeltaBench(const DeltaOptions& options, hal::Camera& camera, hal::Camera* truth_camera);
  // Every frame, the plan's worst case, then the report. Returns the exit status.
  int run();

 private:
  int step(int f);
  int sendFrameStreams(const FrameStep& s);
  int sendMapDelta(const FrameStep& s);
  bool sendBrick(const pipeline::map::BrickBatchEntry& e, const FrameStep& s);
  bool foveateLive(const pipeline::Gaze& gaze, bool steady, const pipeline::map::MapperFrame& figures);
  bool sendLive(const FrameStep& s);
  int evaluate(const FrameStep& s);
  void evaluateMover(const FrameStep& s, const std::vector<Eigen::Vector3d>& held);
  bool onMover(const Eigen::Vector3d& p, double time_s) const;
  int coldPlan(std::vector<double>& cold_ms);
  void printBytes() const;
  void printQuality(const std::vector<double>& cold_ms) const;
  void printMover() const;
  void count(Stream& stream, std::size_t bytes, bool steady) {
    stream.bytes += bytes;
    if (steady) stream.bytes_steady += bytes;
  }

  const DeltaOptions& o_;
  hal::Camera& camera_;
  hal::Camera* truth_camera_;  // the noiseless twin; nullptr: the frame itself is the reference
  const hal::CameraIntrinsics& k_;
  const std::size_t pixels_;
  Eigen::Vector3d focus_;
  const double budget_per_frame_;
  const pipeline::map::MapperConfig mapper_config_;
  pipeline::map::Mapper mapper_;
  pipeline::Foveator f1_foveator_;
  pipeline::Foveator live_foveator_;
  net::ChunkEncoder encoder_;
  pipeline::map::BrickBatch batch_;
  pipeline::PointCloud cloud_, live_;
  pipeline::FoveatedCloud out_, live_out_;
  // The operator's side: the bricks it holds (no loss here), and the last
  // frame's decoded F1 and live points.
  net::BrickCache cache_;
  pipeline::FoveatedCloud decoded_;
  std::vector<Eigen::Vector3d> f1_held_, live_held_;
  hal::RgbdFrame truth_;
  pipeline::PointCloud truth_cloud_;
  std::vector<double> above_mar_[3], held_points_, f1_points_;  // FREF, F1, MAP-DELTA held
  std::size_t missing_points_[3] = {};
  std::size_t free_space_points_[3] = {};  // held points in front of the true surface (pointsInFreeSpace)
  // The movers' scene (the twin's), when it has any; each evaluated frame's
  // figures for the mover alone.
  std::optional<hal::mock::Scene> mover_scene_;
  struct MoverFrame {
    int frame = 0;
    std::size_t true_points = 0, f1_points = 0, delta_points = 0;
    double f1_above = 0.0, delta_above = 0.0;  // % of its true points
  };
  std::vector<MoverFrame> mover_frames_;

  Stream fref_{"FREF"}, f1_stream_{"F1"}, bricks_{"MAP-DELTA bricks"}, live_stream_{"MAP-DELTA live"};
  std::vector<double> plan_ms_, brick_encode_ms_;
  std::size_t live_points_ = 0;  // after the first second
  std::size_t bricks_sent_ = 0, bricks_waited_ = 0, brick_points_sent_ = 0;
  std::array<std::size_t, pipeline::map::kBrickNeedCount> bricks_sent_by_need_ = {};  // by BrickNeed
  // Frames the map did not fuse (Mapper::collectLive); tracked (--pose track).
  std::size_t unfused_ = 0, tracked_ = 0;
  std::array<double, pipeline::kMaxRegions> live_sizes_{};  // the live points' voxel sizes by region
  int live_regions_ = 0;
  hal::Pose map_to_world_;  // the map's world in the truth's (--pose track: the first frame's true pose)
  hal::RgbdFrame frame_;
};

// The service's mapper for this camera, streaming bricks of at most
// kMaxBrickPoints surfels, in batches of a frame's share of the budget.
pipeline::map::MapperConfig mapperConfigFor(const hal::CameraIntrinsics& k, const DeltaOptions& o) {
  pipeline::map::MapperConfig config;
  config.delta = o.delta;
  config.map.max_width = k.width;
  config.map.max_height = k.height;
  config.tracking = o.track ? pipeline::map::PoseTracking::kAlone : pipeline::map::PoseTracking::kOff;
  config.output = pipeline::map::MapOutput::kBricks;
  config.max_brick_surfels = DeltaBench::kMaxBrickPoints;
  return config;
}

pipeline::Foveator foveatorFor(std::size_t pixels, const pipeline::FoveationConfig& config) {
  pipeline::PipelineCapacity capacity;
  capacity.max_points = capacity.max_voxels = pixels;
  return pipeline::Foveator::create(capacity, config).value();
}

pipeline::FoveationConfig f1Config() {
  pipeline::FoveationConfig f1;
  f1.acuity.preset = pipeline::Preset::kF1;
  return f1;
}

pipeline::FoveationConfig acuityConfig(const pipeline::map::MapDeltaConfig& delta_config) {
  pipeline::FoveationConfig acuity;
  acuity.acuity = delta_config.acuity;
  return acuity;
}

// A frame's batch holds the points its share of the budget can carry by the
// estimate, and at least one whole brick.
std::size_t batchPoints(double budget_per_frame) {
  return std::max(DeltaBench::kMaxBrickPoints,
                  static_cast<std::size_t>(budget_per_frame / pipeline::map::kWireBytesPerPointEstimate) + 1);
}

// A camera without a focus point (a recording): the point the first frame's
// centre pixel sees, or 1.5 m along its axis without a depth there.
Eigen::Vector3d centreOfView(const hal::RgbdFrame& frame) {
  const std::size_t centre = static_cast<std::size_t>(frame.height() / 2) * frame.width() + frame.width() / 2;
  const double depth = frame.depth()[centre] * frame.depth_scale_m;
  const double along = depth > 0.0 ? depth : 1.5;
  return frame.T_world_cam.t_world_cam + frame.T_world_cam.R_world_cam.col(2) * along;
}

net::BrickCache operatorCache() {
  net::BrickCacheConfig cache_config;
  cache_config.max_points = std::size_t{1} << 23;
  return net::BrickCache::create(cache_config).value();
}

DeltaBench::DeltaBench(const DeltaOptions& options, hal::Camera& camera, hal::Camera* truth_camera)
    : o_(options),
      camera_(camera),
      truth_camera_(truth_camera),
      k_(camera.info().intrinsics),
      pixels_(static_cast<std::size_t>(k_.width) * k_.height),
      focus_(camera.info().focus_point_m.value_or(Eigen::Vector3d(0, 0, 2))),
      budget_per_frame_(o_.budget_mbps * 1e6 / o_.fps),
      mapper_config_(mapperConfigFor(k_, o_)),
      mapper_(pipeline::map::Mapper::create(mapper_config_).value()),
      f1_foveator_(foveatorFor(pixels_, f1Config())),
      live_foveator_(foveatorFor(pixels_, acuityConfig(mapper_config_.delta))),
      encoder_(net::ChunkEncoder::create(net::CodecConfig{}, std::max(pixels_, kMaxBrickPoints)).value()),
      batch_(batchPoints(budget_per_frame_), 1024),
      cloud_(pixels_),
      live_(pixels_),
      out_(pixels_),
      live_out_(pixels_),
      cache_(operatorCache()),
      decoded_(std::max(pixels_, kMaxBrickPoints)),
      truth_(k_.width, k_.height),
      truth_cloud_(pixels_),
      frame_(k_.width, k_.height) {
  if (truth_camera_ != nullptr) {
    Result<hal::mock::Scene> scene = hal::mock::Scene::create(o_.scene);
    if (scene && scene.value().isDynamic()) mover_scene_ = std::move(scene.value());
  }
}

int DeltaBench::run() {
  for (int f = 0; f < o_.frames; ++f) {
    if (int status = step(f); status != 0) return status;
  }
  std::vector<double> cold_ms;
  if (int status = coldPlan(cold_ms); status != 0) return status;
  printBytes();
  printQuality(cold_ms);
  return 0;
}

// One frame: the gaze's fixation, the frame-by-frame streams, MAP-DELTA, and
// (when due) what the operator then holds against the true surface.
int DeltaBench::step(int f) {
  if (!camera_.acquire(frame_, std::chrono::seconds(5)) ||
      (truth_camera_ != nullptr && !truth_camera_->acquire(truth_, std::chrono::seconds(5)))) {
    std::fprintf(stderr, "fovea-map-delta: frame %d did not arrive\n", f);
    return 1;
  }
  if (truth_camera_ == nullptr) truth_ = frame_;  // the measured surface is the reference
  if (f == 0 && !camera_.info().focus_point_m) focus_ = centreOfView(frame_);
  static const Eigen::Vector3d offsets[5] = {{0, 0, 0}, {0.4, 0.25, 0}, {-0.4, 0.25, 0}, {-0.4, -0.25, 0}, {0.4, -0.25, 0}};
  FrameStep s;
  s.f = f;
  s.steady = f >= o_.fps;
  s.gaze.origin_m = frame_.T_world_cam.t_world_cam;
  const Eigen::Vector3d target = focus_ + frame_.T_world_cam.R_world_cam * offsets[(f / o_.dwell) % 5];
  s.gaze.direction = (target - s.gaze.origin_m).normalized();
  s.frame_id = static_cast<uint32_t>(f);
  s.now_ns = static_cast<int64_t>(f) * 1'000'000'000 / o_.fps;
  if (int status = sendFrameStreams(s); status != 0) return status;
  if (int status = sendMapDelta(s); status != 0) return status;
  // Every --eval-every frames after the first second, and at the last: what
  // the operator holds when it draws this frame (its bricks and this frame's
  // live points), against the true surface the frame sees, from this gaze;
  // FREF's and F1's frame the same way.
  if ((f >= o_.fps && (f - o_.fps) % o_.eval_every == 0) || f == o_.frames - 1) return evaluate(s);
  return 0;
}

// The frame-by-frame streams: FREF (every point) and F1.
int DeltaBench::sendFrameStreams(const FrameStep& s) {
  pipeline::BackprojectCounts bp;
  cloud_.clear();
  if (!pipeline::backprojectRef(frame_, mapper_config_.map.depth, cloud_, bp)) return 1;
  out_.points.origin_m = cloud_.origin_m;
  std::copy_n(cloud_.x(), cloud_.size(), out_.points.x());
  std::copy_n(cloud_.y(), cloud_.size(), out_.points.y());
  std::copy_n(cloud_.z(), cloud_.size(), out_.points.z());
  std::copy_n(cloud_.rgb(), cloud_.size(), out_.points.rgb());
  std::fill_n(out_.region.begin(), cloud_.size(), uint8_t{0});
  std::fill_n(out_.weight.begin(), cloud_.size(), 1u);
  if (!out_.points.resize(cloud_.size())) return 1;
  const double fovea_only[1] = {0.0};
  if (!encoder_.encode(out_, fovea_only, s.frame_id, 0)) return 1;
  count(fref_, datagramBytes(encoder_), s.steady);
  pipeline::FoveationStats fs;
  if (!f1_foveator_.foveate(cloud_, s.gaze, out_, fs)) return 1;
  double sizes[pipeline::kMaxRegions] = {};
  for (int r = 0; r < fs.region_count; ++r) sizes[r] = fs.regions[r].voxel_size_m;
  if (!encoder_.encode(out_, std::span<const double>(sizes, static_cast<std::size_t>(fs.region_count)), s.frame_id, 0)) {
    return 1;
  }
  count(f1_stream_, datagramBytes(encoder_), s.steady);
  f1_held_.clear();
  decodeAll(encoder_, nullptr, &f1_held_, decoded_, s.now_ns);
  return 0;
}

// MAP-DELTA as the service sends it: pose and fuse (Mapper::addFrame), the
// live points foveated for the gaze, the batch of bricks planned for the
// frame's share of the budget with the live points charged after the fovea's
// bricks, then every brick of the batch and the live points encoded.
int DeltaBench::sendMapDelta(const FrameStep& s) {
  // Tracking alone starts the map's world at the first frame's camera: the
  // truth's world is that frame's true pose away.
  if (s.f == 0 && o_.track) map_to_world_ = frame_.T_world_cam;
  pipeline::map::MapperFrame figures;
  const bool fused = mapper_.addFrame(frame_, /*outside_pose_valid=*/true, figures);
  if (o_.track && figures.track.outcome == pipeline::map::TrackOutcome::kTracked) ++tracked_;
  if (!fused) ++unfused_;
  pipeline::Gaze gaze = s.gaze;  // in the map's world
  const Eigen::Matrix3d Rt = map_to_world_.R_world_cam.transpose();
  gaze.origin_m = Rt * (s.gaze.origin_m - map_to_world_.t_world_cam);
  gaze.direction = Rt * s.gaze.direction;
  gaze.view_forward = Rt * s.gaze.view_forward;
  if (!foveateLive(gaze, s.steady, figures)) return 1;
  pipeline::map::MapperPlan plan;
  const double live_bytes = static_cast<double>(live_out_.size()) * pipeline::map::kWireBytesPerPointEstimate;
  const auto bricks_start = std::chrono::steady_clock::now();  // the plan, the sampling and the encoding
  if (!mapper_.planBricks(gaze, budget_per_frame_, live_bytes, frame_.T_world_cam.t_world_cam, batch_, plan)) {
    std::fprintf(stderr, "fovea-map-delta: frame %d: the bricks could not be planned\n", s.f);
    return 1;
  }
  plan_ms_.push_back(static_cast<double>(plan.delta.ns) * 1e-6);
  bricks_waited_ += plan.bricks_waiting;
  for (std::size_t n = 0; n < plan.planned_by_need.size(); ++n) bricks_sent_by_need_[n] += plan.planned_by_need[n];
  for (const pipeline::map::BrickBatchEntry& e : batch_.entries()) {
    if (!sendBrick(e, s)) return 1;
  }
  brick_encode_ms_.push_back(
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - bricks_start).count());
  return sendLive(s) ? 0 : 1;
}

// One brick of the batch, encoded on its own as the service's streamer does,
// and decoded into the operator's cache.
bool DeltaBench::sendBrick(const pipeline::map::BrickBatchEntry& e, const FrameStep& s) {
  const std::optional<net::EncodeInput> points = net::EncodeInput::slice(batch_.points, e.first, e.count);
  if (!points) return false;
  const net::BrickTag tag{e.key.x, e.key.y, e.key.z, e.version, e.level};
  if (!encoder_.encode(*points, std::span<const double>(batch_.level_step_m.data(), e.level + 1u), s.frame_id, 0, &tag)) {
    return false;
  }
  decodeAll(encoder_, &cache_, nullptr, decoded_, s.now_ns);
  count(bricks_, datagramBytes(encoder_), s.steady);
  brick_points_sent_ += e.count;
  ++bricks_sent_;
  return true;
}

// The frame's points the map does not explain (when the map did not fuse it,
// those its last fused view does not explain, or the whole frame if refused),
// ACUITY-foveated for the gaze into live_out_.
bool DeltaBench::foveateLive(const pipeline::Gaze& gaze, bool steady, const pipeline::map::MapperFrame& figures) {
  live_.origin_m = frame_.T_world_cam.t_world_cam;
  pipeline::map::LiveFigures lf;  // the cloud holds the whole frame: never thinned
  if (!mapper_.collectLive(frame_, figures, mapper_config_.map.depth, {}, live_, lf)) return false;
  if (steady) live_points_ += live_.size();
  live_out_.clear();
  pipeline::FoveationStats ls;
  if (live_.size() > 0 && !live_foveator_.foveate(live_, gaze, live_out_, ls)) return false;
  live_sizes_.fill(0.0);
  for (int r = 0; r < ls.region_count; ++r) live_sizes_[static_cast<std::size_t>(r)] = ls.regions[r].voxel_size_m;
  live_regions_ = live_.size() > 0 ? ls.region_count : 0;
  return true;
}

// The foveated live points, encoded and decoded as the operator's frame.
bool DeltaBench::sendLive(const FrameStep& s) {
  live_held_.clear();
  if (live_out_.size() == 0) return true;
  if (!encoder_.encode(live_out_, std::span<const double>(live_sizes_.data(), static_cast<std::size_t>(live_regions_)),
                       s.frame_id, 0)) {
    return false;
  }
  count(live_stream_, datagramBytes(encoder_), s.steady);
  decodeAll(encoder_, nullptr, &live_held_, decoded_, s.now_ns);
  return true;
}

int DeltaBench::evaluate(const FrameStep& s) {
  pipeline::BackprojectCounts truth_counts;
  truth_cloud_.clear();
  if (!pipeline::backprojectRef(truth_, mapper_config_.map.depth, truth_cloud_, truth_counts)) return 1;
  std::vector<Eigen::Vector3d> held = live_held_;
  for (std::size_t slot = 0; slot < cache_.slotCount(); ++slot) {
    if (!cache_.held(slot)) continue;
    cache_.forEachPoint(slot, [&](const Eigen::Vector3d& p, uint32_t) { held.push_back(p); });
  }
  for (Eigen::Vector3d& p : held) p = map_to_world_.R_world_cam * p + map_to_world_.t_world_cam;  // into the truth's world
  std::vector<Eigen::Vector3d> fref_held(cloud_.size());
  for (std::size_t i = 0; i < cloud_.size(); ++i) fref_held[i] = cloud_.world(i);
  std::vector<Eigen::Vector3d> truth(truth_cloud_.size());
  for (std::size_t i = 0; i < truth_cloud_.size(); ++i) truth[i] = truth_cloud_.world(i);
  std::size_t missing = 0;
  above_mar_[0].push_back(100.0 * shareAboveMar(fref_held, truth, s.gaze, pipeline::kDefaultSlope, missing));
  missing_points_[0] += missing;
  above_mar_[1].push_back(100.0 * shareAboveMar(f1_held_, truth, s.gaze, pipeline::kDefaultSlope, missing));
  missing_points_[1] += missing;
  above_mar_[2].push_back(100.0 * shareAboveMar(held, truth, s.gaze, pipeline::kDefaultSlope, missing));
  missing_points_[2] += missing;
  free_space_points_[0] += pointsInFreeSpace(fref_held, truth_, k_);
  free_space_points_[1] += pointsInFreeSpace(f1_held_, truth_, k_);
  free_space_points_[2] += pointsInFreeSpace(held, truth_, k_);
  held_points_.push_back(static_cast<double>(held.size()));
  f1_points_.push_back(static_cast<double>(f1_held_.size()));
  if (mover_scene_) evaluateMover(s, held);
  return 0;
}

// Whether world point p lies on a mover of the twin's scene at time_s: the
// camera's ray through it meets a moving or carried shape within 2 cm of it.
bool DeltaBench::onMover(const Eigen::Vector3d& p, double time_s) const {
  constexpr double kNear = 0.02;
  const hal::Pose& camera = truth_.T_world_cam;
  const Eigen::Vector3d to_p = p - camera.t_world_cam;
  const double z = (camera.R_world_cam.transpose() * to_p).z();
  if (!(z > 0.0)) return false;
  const Eigen::Vector3d dir = to_p / z;  // camera z 1: the ray parameter is the depth
  hal::mock::Hit hit;
  bool found = mover_scene_->intersect(camera.t_world_cam, dir, time_s, hal::mock::SceneLayer::kDynamic, z + kNear, hit);
  found |= mover_scene_->intersectCarried(camera, dir, found ? hit.t : z + kNear, hit);
  return found && std::abs(hit.t - z) <= kNear;
}

// The mover alone: its true points (the twin's pixels on it), what F1 and
// MAP-DELTA (the bricks held and the frame's live points) draw on it, and the
// share of its true points above the MAR for each.
void DeltaBench::evaluateMover(const FrameStep& s, const std::vector<Eigen::Vector3d>& held) {
  const double time_s = static_cast<double>(truth_.stamp_ns) * 1e-9;
  std::vector<Eigen::Vector3d> mover_truth;
  for (std::size_t i = 0; i < truth_cloud_.size(); ++i) {
    if (onMover(truth_cloud_.world(i), time_s)) mover_truth.push_back(truth_cloud_.world(i));
  }
  MoverFrame m;
  m.frame = s.f;
  m.true_points = mover_truth.size();
  for (const Eigen::Vector3d& p : f1_held_) m.f1_points += onMover(p, time_s) ? 1 : 0;
  for (const Eigen::Vector3d& p : held) m.delta_points += onMover(p, time_s) ? 1 : 0;
  std::size_t missing = 0;
  m.f1_above = 100.0 * shareAboveMar(f1_held_, mover_truth, s.gaze, pipeline::kDefaultSlope, missing);
  m.delta_above = 100.0 * shareAboveMar(held, mover_truth, s.gaze, pipeline::kDefaultSlope, missing);
  mover_frames_.push_back(m);
}

// The plan's worst case on the final map: an operator that holds nothing
// (every brick due, all sorted), median of 21.
int DeltaBench::coldPlan(std::vector<double>& cold_ms) {
  pipeline::map::MapDelta cold =
      pipeline::map::MapDelta::create(mapper_config_.delta, mapper_config_.map.max_bricks).value();
  pipeline::Gaze gaze;
  gaze.origin_m = frame_.T_world_cam.t_world_cam;
  gaze.direction = (focus_ - gaze.origin_m).normalized();
  for (int i = 0; i < 21; ++i) {
    cold.forgetAll();
    pipeline::map::MapDeltaStats ds;
    if (!cold.plan(mapper_.map(), gaze, ds)) return 1;
    cold_ms.push_back(static_cast<double>(ds.ns) * 1e-6);
  }
  return 0;
}

// Each stream's rate against FREF's, over all frames and after the first second.
void DeltaBench::printBytes() const {
  const double seconds = static_cast<double>(o_.frames) / o_.fps;
  const double steady_seconds = static_cast<double>(std::max(0, o_.frames - o_.fps)) / o_.fps;
  std::printf("fovea-map-delta: %s, %d frames at %d fps, gaze: 5 fixations of %d frames, budget %.1f MB/s\n",
              (o_.camera.empty() ? o_.spec : o_.camera).c_str(), o_.frames, o_.fps, o_.dwell, o_.budget_mbps);
  std::printf("  %-18s %10s %10s %16s %12s\n", "stream", "MB/s", "vs FREF", "MB/s after 1 s", "vs FREF");
  const Stream delta_total{"MAP-DELTA", bricks_.bytes + live_stream_.bytes,
                           bricks_.bytes_steady + live_stream_.bytes_steady};
  for (const Stream* s :
       std::initializer_list<const Stream*>{&fref_, &f1_stream_, &delta_total, &bricks_, &live_stream_}) {
    const double rate = static_cast<double>(s->bytes) / seconds * 1e-6;
    const double steady_rate = steady_seconds > 0 ? static_cast<double>(s->bytes_steady) / steady_seconds * 1e-6 : 0.0;
    const double vs = 100.0 * (1.0 - static_cast<double>(s->bytes) / static_cast<double>(fref_.bytes));
    const double vs_steady =
        fref_.bytes_steady > 0
            ? 100.0 * (1.0 - static_cast<double>(s->bytes_steady) / static_cast<double>(fref_.bytes_steady))
            : 0.0;
    std::printf("  %-18s %10.3f %9.1f%% %16.3f %11.1f%%\n", s->name, rate, vs, steady_rate, vs_steady);
  }
}

// The live points, the bricks, the plan's time and what the operator holds.
void DeltaBench::printQuality(const std::vector<double>& cold_ms) const {
  const int frames = o_.frames, fps = o_.fps;
  std::printf("  live points after 1 s: %.0f a frame\n",
              frames > fps ? static_cast<double>(live_points_) / (frames - fps) : 0.0);
  std::printf("  bricks sent %zu (%zu points; the operator lacked %zu, needed %zu finer, %zu had changed), waited %zu "
              "brick-frames; map %zu surfels in %zu bricks\n",
              bricks_sent_, brick_points_sent_, bricks_sent_by_need_[0], bricks_sent_by_need_[1],
              bricks_sent_by_need_[2], bricks_waited_, mapper_.map().size(), mapper_.map().brickCount());
  std::printf("  frames the map did not fuse (thinned by the last fused view, or whole): %zu", unfused_);
  if (o_.track) std::printf("; tracked %zu of %d", tracked_, frames);
  std::printf("\n");
  std::printf("  plan: median %.3f ms, max %.3f ms a frame; brick sampling and encoding: median %.3f ms a frame\n",
              median(plan_ms_), *std::max_element(plan_ms_.begin(), plan_ms_.end()), median(brick_encode_ms_));
  std::printf("  plan with every brick due (an operator that holds nothing): median %.3f ms\n", median(cold_ms));
  auto mean = [](const std::vector<double>& v) {
    double sum = 0.0;
    for (double x : v) sum += x;
    return v.empty() ? 0.0 : sum / static_cast<double>(v.size());
  };
  const std::vector<double>* above_mar = above_mar_;
  std::printf("  what the operator holds, against %s, %zu frames from the second on:\n",
              truth_camera_ != nullptr ? "the true surface (the noiseless twin)"
                                       : "the measured surface (the frame's own points: no noiseless twin)",
              above_mar[0].size());
  std::printf("    share above the MAR (m %.3f), mean [min, max]: FREF %.2f %% [%.2f, %.2f], F1 %.2f %% [%.2f, %.2f], "
              "MAP-DELTA held %.2f %% [%.2f, %.2f]\n",
              pipeline::kDefaultSlope, mean(above_mar[0]), *std::min_element(above_mar[0].begin(), above_mar[0].end()),
              *std::max_element(above_mar[0].begin(), above_mar[0].end()), mean(above_mar[1]),
              *std::min_element(above_mar[1].begin(), above_mar[1].end()),
              *std::max_element(above_mar[1].begin(), above_mar[1].end()), mean(above_mar[2]),
              *std::min_element(above_mar[2].begin(), above_mar[2].end()),
              *std::max_element(above_mar[2].begin(), above_mar[2].end()));
  std::printf("    points drawn, mean: F1 %.0f, MAP-DELTA held %.0f; true points with nothing within 10 cm: FREF %zu, F1 %zu, "
              "MAP-DELTA %zu\n",
              mean(f1_points_), mean(held_points_), missing_points_[0], missing_points_[1], missing_points_[2]);
  std::printf("    points drawn in front of the true surface by more than 10 cm (free space, the camera's view): FREF %zu, "
              "F1 %zu, MAP-DELTA %zu\n",
              free_space_points_[0], free_space_points_[1], free_space_points_[2]);
  if (mover_scene_) printMover();
}

// The mover's figures frame by frame, and their means.
void DeltaBench::printMover() const {
  std::printf("  the mover alone (%s), frame by frame: its true points; points drawn on it and its share above the MAR\n",
              o_.scene.c_str());
  double sums[5] = {};
  for (const MoverFrame& m : mover_frames_) {
    std::printf("    frame %3d: %6zu true; F1 %6zu points, %5.1f %% above; MAP-DELTA %6zu points, %5.1f %% above\n", m.frame,
                m.true_points, m.f1_points, m.f1_above, m.delta_points, m.delta_above);
    const double row[5] = {static_cast<double>(m.true_points), static_cast<double>(m.f1_points), m.f1_above,
                           static_cast<double>(m.delta_points), m.delta_above};
    for (int k = 0; k < 5; ++k) sums[k] += row[k];
  }
  const double n = std::max<double>(1.0, static_cast<double>(mover_frames_.size()));
  std::printf("    mean: %.0f true; F1 %.0f points, %.1f %% above; MAP-DELTA %.0f points, %.1f %% above\n", sums[0] / n,
              sums[1] / n, sums[2] / n, sums[3] / n, sums[4] / n);
}

}  // namespace

int main(int argc, char** argv) {
  const std::optional<DeltaOptions> options = parseOptions(argc, argv);
  if (!options) return 2;
  if (!options->camera.empty()) {
    fovea::Result<std::unique_ptr<hal::Camera>> camera = hal::createCamera(options->camera);
    if (!camera || !camera.value()->open() || !camera.value()->start()) {
      std::fprintf(stderr, "fovea-map-delta: %s: the camera did not start%s%s\n", options->camera.c_str(),
                   camera ? "" : ": ", camera ? "" : camera.status().message().c_str());
      return 1;
    }
    DeltaBench delta_bench(*options, *camera.value(), nullptr);
    return delta_bench.run();
  }
  bench::MockTwins twins;
  if (int status = bench::openMockTwins("fovea-map-delta", options->spec, twins); status != 0) return status;
  DeltaBench delta_bench(*options, *twins.noisy, twins.truth.get());
  return delta_bench.run();
}

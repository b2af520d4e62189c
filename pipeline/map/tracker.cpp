// FrameToModelTracker (tracker.h); its kernels' scalar references are in
// tracker_kernels.cpp. docs/tracking.md describes the method.
#include "pipeline/map/tracker.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/SVD>

#include "core/clock.h"
#include "core/depth_noise.h"
#include "pipeline/map/map_kernels.h"
#include "pipeline/map/surfel.h"
#include "pipeline/map/surfel_map.h"
#include "pipeline/map/tracker_kernels.h"

namespace fovea::pipeline::map {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegToRad = kPi / 180.0;
// The pyramid's 2x2 averages leave out a pixel whose depth differs from the
// block's first valid one by more than this share of it (a depth step).
constexpr float kStepShare = 0.05f;
// Fewer valid pixels than this at the finest level: no valid depth.
constexpr uint32_t kMinValidPixels = 64;

// exp of a twist [v, w] (left perturbation): a rotation and a translation.
void expTwist(const Eigen::Matrix<double, 6, 1>& x, Eigen::Matrix3d& R, Eigen::Vector3d& t) {
  const Eigen::Vector3d v = x.head<3>(), w = x.tail<3>();
  const double theta = w.norm();
  Eigen::Matrix3d W;
  W << 0, -w.z(), w.y(), w.z(), 0, -w.x(), -w.y(), w.x(), 0;
  if (theta < 1e-10) {
    R = Eigen::Matrix3d::Identity() + W;
    t = v;
    return;
  }
  const double a = std::sin(theta) / theta, b = (1.0 - std::cos(theta)) / (theta * theta),
               c = (1.0 - a) / (theta * theta);
  R = Eigen::Matrix3d::Identity() + a * W + b * W * W;
  const Eigen::Matrix3d V = Eigen::Matrix3d::Identity() + b * W + c * W * W;
  t = V * v;
}

// The intensity's gradient per pixel (central differences / 2; zero at the border).
void computeGradients(int w, int h, const float* in, float* gx, float* gy) {
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * w + u;
      if (u == 0 || v == 0 || u == w - 1 || v == h - 1) {
        gx[i] = gy[i] = 0.0f;
        continue;
      }
      gx[i] = 0.5f * (in[i + 1] - in[i - 1]);
      gy[i] = 0.5f * (in[i + w] - in[i - w]);
    }
  }
}

float intensityOf(const uint8_t* rgb) {
  return (0.299f * rgb[0] + 0.587f * rgb[1] + 0.114f * rgb[2]) * (1.0f / 255.0f);
}

}  // namespace

// ---------------------------------------------------------------- names, config

double rotationAngleDeg(const Eigen::Matrix3d& R) {
  // From the quaternion, 2 atan2(|v|, |w|): accurate near 0 and 180 degrees,
  // where acos of the trace loses half the digits.
  const Eigen::Quaterniond q(R);
  return 2.0 * std::atan2(q.vec().norm(), std::abs(q.w())) / kDegToRad;
}

std::string_view trackOutcomeName(TrackOutcome outcome) {
  switch (outcome) {
    case TrackOutcome::kFirstFrame: return "first-frame";
    case TrackOutcome::kTracked: return "tracked";
    case TrackOutcome::kRelocalised: return "relocalised";
    case TrackOutcome::kLost: return "lost";
  }
  return "unknown";
}

std::string_view lostReasonName(LostReason reason) {
  switch (reason) {
    case LostReason::kNone: return "none";
    case LostReason::kFewInliers: return "few-inliers";
    case LostReason::kResidualJump: return "residual-jump";
    case LostReason::kDegenerate: return "degenerate";
    case LostReason::kImplausibleMotion: return "implausible-motion";
    case LostReason::kNoValidDepth: return "no-valid-depth";
    case LostReason::kMostlyMoving: return "mostly-moving";
  }
  return "unknown";
}

Status TrackerConfig::validate() const {
  if (max_width < 8 || max_height < 8 || max_width > 8192 || max_height > 8192) {
    return invalidArgument("tracker: max_width and max_height must be within [8, 8192]");
  }
  for (int it : iterations) {
    if (it < 0 || it > 100) return invalidArgument("tracker: iterations per level must be within [0, 100]");
  }
  if (iterations[0] < 1) return invalidArgument("tracker: the finest level needs at least one iteration");
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!positive(icp_max_distance_m)) return invalidArgument("tracker: icp_max_distance_m must be > 0");
  if (!(std::isfinite(converged_step) && converged_step >= 0.0)) {
    return invalidArgument("tracker: converged_step must be >= 0");
  }
  if (!(icp_max_normal_deg > 0.0 && icp_max_normal_deg <= 90.0)) {
    return invalidArgument("tracker: icp_max_normal_deg must be within (0, 90]");
  }
  if (!(std::isfinite(photometric_weight) && photometric_weight >= 0.0)) {
    return invalidArgument("tracker: photometric_weight must be >= 0");
  }
  if (!(min_inlier_fraction >= 0.0 && min_inlier_fraction <= 1.0)) {
    return invalidArgument("tracker: min_inlier_fraction must be within [0, 1]");
  }
  if (!(max_moving_share > 0.0 && max_moving_share <= 1.0)) {
    return invalidArgument("tracker: max_moving_share must be within (0, 1]");
  }
  if (!(std::isfinite(max_residual_jump) && max_residual_jump > 1.0)) {
    return invalidArgument("tracker: max_residual_jump must be > 1");
  }
  if (!(std::isfinite(min_eigenvalue) && min_eigenvalue >= 0.0)) {
    return invalidArgument("tracker: min_eigenvalue must be >= 0");
  }
  if (!positive(max_motion_m) || !positive(max_motion_deg) || max_motion_deg > 180.0) {
    return invalidArgument("tracker: max_motion_m must be > 0 and max_motion_deg within (0, 180]");
  }
  if (!(std::isfinite(relocalise_search_deg) && relocalise_search_deg >= 0.0 && relocalise_search_deg <= 90.0)) {
    return invalidArgument("tracker: relocalise_search_deg must be within [0, 90]");
  }
  if (!(std::isfinite(residual_jump_floor_m) && residual_jump_floor_m >= 0.0)) {
    return invalidArgument("tracker: residual_jump_floor_m must be >= 0");
  }
  if (!(std::isfinite(max_depth_m) && max_depth_m >= 0.0)) return invalidArgument("tracker: max_depth_m must be >= 0");
  if (!positive(max_photometric_residual)) return invalidArgument("tracker: max_photometric_residual must be > 0");
  if (!(std::isfinite(icp_robust_scale_m) && icp_robust_scale_m >= 0.0) ||
      !(std::isfinite(photometric_robust_scale) && photometric_robust_scale >= 0.0)) {
    return invalidArgument("tracker: icp_robust_scale_m and photometric_robust_scale must be >= 0");
  }
  if (Status s = moving.validate(); !s) return invalidArgument("tracker: " + s.message());
  if (Status s = carried.validate(); !s) return invalidArgument("tracker: " + s.message());
  if (moving.enabled && moving.min_gap_m < icp_max_distance_m) {
    // A moving pixel must be beyond the finest level's association (leaveOutMovers()).
    return invalidArgument("tracker: moving.min_gap_m must be at least icp_max_distance_m");
  }
  return Status::ok();
}

// ---------------------------------------------------------------- the tracker

void FrameToModelTracker::Level::allocate(std::size_t pixels, bool gradients) {
  for (auto* v : {&x, &y, &z, &nx, &ny, &nz, &intensity}) v->assign(pixels, 0.0f);
  if (gradients) {
    gx.assign(pixels, 0.0f);
    gy.assign(pixels, 0.0f);
  }
}

void FrameToModelTracker::Level::allocateRays(int max_width, int max_height) {
  ray_u.assign(static_cast<std::size_t>(max_width), 0.0f);
  ray_v.assign(static_cast<std::size_t>(max_height), 0.0f);
}

std::size_t FrameToModelTracker::Level::bytes() const {
  std::size_t n = 0;
  for (const auto* v : {&x, &y, &z, &nx, &ny, &nz, &intensity, &gx, &gy, &ray_u, &ray_v}) n += v->capacity() * sizeof(float);
  return n;
}

FrameToModelTracker::FrameToModelTracker(const TrackerConfig& config, MovingPixels moving, CarriedPixels carried)
    : config_(config), moving_(std::move(moving)), carried_(std::move(carried)) {}

Result<FrameToModelTracker> FrameToModelTracker::create(const TrackerConfig& config) {
  if (Status s = config.validate(); !s.isOk()) return s;
  Result<MovingPixels> moving = MovingPixels::create(config.max_width, config.max_height, config.moving);
  if (!moving) return moving.status();
  Result<CarriedPixels> carried = CarriedPixels::create(config.max_width, config.max_height, config.carried);
  if (!carried) return carried.status();
  FrameToModelTracker t(config, std::move(moving.value()), std::move(carried.value()));
  for (int l = 0; l < kLevels; ++l) {
    const std::size_t pixels =
        static_cast<std::size_t>(config.max_width >> l) * static_cast<std::size_t>(config.max_height >> l);
    t.frame_[l].allocate(pixels, false);
    t.model_[l].allocate(pixels, true);
  }
  t.frame_[0].allocateRays(config.max_width, config.max_height);
  t.model_[0].allocateRays(config.max_width, config.max_height);
  t.model_from_surfel_.assign(static_cast<std::size_t>(config.max_width) * config.max_height, 0);
  return t;
}

std::size_t FrameToModelTracker::memoryBytes() const {
  std::size_t n = model_from_surfel_.capacity() + moving_.memoryBytes() + carried_.memoryBytes();
  for (const Level& l : frame_) n += l.bytes();
  for (const Level& l : model_) n += l.bytes();
  return n;
}

void FrameToModelTracker::reset() {
  have_model_ = false;
  lost_ = false;
  last_good_ = hal::Pose{};
  model_pose_ = hal::Pose{};
  residual_count_ = 0;
  moving_.clear();
  carried_.clear();
}

// The level below `from`: its camera, and its pixels by the kernel (2x2
// blocks; vertices averaged over the pixels within kStepShare of the block's
// first valid depth; intensity over all four; normals averaged and
// renormalised when `normals`, else recomputed by the caller).
void FrameToModelTracker::Level::downsampleFrom(const Level& from, bool normals, KernelSet kernels) {
  width = from.width / 2;
  height = from.height / 2;
  fx = from.fx * 0.5f;
  fy = from.fy * 0.5f;
  cx = (from.cx + 0.5f) * 0.5f - 0.5f;
  cy = (from.cy + 0.5f) * 0.5f - 0.5f;
  const PyramidLevelIn in{from.width,        from.height,    from.x.data(),  from.y.data(),
                          from.z.data(),     from.nx.data(), from.ny.data(), from.nz.data(),
                          from.intensity.data()};
  const PyramidLevelOut out{x.data(), y.data(), z.data(), nx.data(), ny.data(), nz.data(), intensity.data()};
  downsample(in, out, kStepShare, normals, kernels);
}

void FrameToModelTracker::Level::setCamera(int w, int h, const hal::CameraIntrinsics& k) {
  width = w;
  height = h;
  fx = static_cast<float>(k.fx), fy = static_cast<float>(k.fy);
  cx = static_cast<float>(k.cx), cy = static_cast<float>(k.cy);
  for (int u = 0; u < w; ++u) ray_u[static_cast<std::size_t>(u)] = (static_cast<float>(u) - cx) / fx;
  for (int v = 0; v < h; ++v) ray_v[static_cast<std::size_t>(v)] = (static_cast<float>(v) - cy) / fy;
}

bool FrameToModelTracker::Level::setMeasured(std::size_t i, int u, int v, uint16_t raw, float scale, float max_z,
                                             float intensity_value) {
  const float depth_m = static_cast<float>(raw) * scale;
  const bool ok = raw != 0 && std::isfinite(depth_m) && depth_m > 0.0f && depth_m <= max_z;
  z[i] = ok ? depth_m : 0.0f;
  x[i] = ok ? ray_u[static_cast<std::size_t>(u)] * depth_m : 0.0f;  // (u - cx) / fx * depth_m, the same bits
  y[i] = ok ? ray_v[static_cast<std::size_t>(v)] * depth_m : 0.0f;
  intensity[i] = intensity_value;
  return ok;
}

void FrameToModelTracker::Level::copyPixel(std::size_t from, std::size_t to) {
  x[to] = x[from], y[to] = y[from], z[to] = z[from];
  nx[to] = nx[from], ny[to] = ny[from], nz[to] = nz[from];
  intensity[to] = intensity[from];
}

float FrameToModelTracker::maxDepth() const {
  return config_.max_depth_m > 0.0 ? static_cast<float>(config_.max_depth_m) : std::numeric_limits<float>::infinity();
}

bool FrameToModelTracker::buildFramePyramid(const hal::RgbdFrame& frame) {
  const int w = frame.width(), h = frame.height();
  Level& l0 = frame_[0];
  l0.setCamera(w, h, frame.intrinsics);
  const float scale = static_cast<float>(frame.depth_scale_m);
  const float max_z = maxDepth();
  const uint16_t* depth = frame.depth();
  const uint8_t* rgb = frame.rgb();
  uint32_t valid = 0;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * w + u;
      valid += l0.setMeasured(i, u, v, depth[i], scale, max_z, frame.has_rgb ? intensityOf(rgb + 3 * i) : 0.0f) ? 1u : 0u;
    }
  }
  valid_pixels_ = valid;
  computeNormals(NormalMapIn{w, h, kNormalReach, kStepShare, l0.x.data(), l0.y.data(), l0.z.data(), nullptr},
                 l0.nx.data(), l0.ny.data(), l0.nz.data(), config_.kernels);
  for (int l = 1; l < kLevels; ++l) {
    frame_[l].downsampleFrom(frame_[l - 1], false, config_.kernels);
    Level& L = frame_[l];
    computeNormals(NormalMapIn{L.width, L.height, 1, kStepShare, L.x.data(), L.y.data(), L.z.data(), nullptr},
                   L.nx.data(), L.ny.data(), L.nz.data(), config_.kernels);
  }
  return valid >= kMinValidPixels;
}

// The model's finest level, pixel by pixel: the surfel the index map names,
// moved into the camera at `pose`, or where none is, the frame's own
// measurement (none where the frame's pixel was moving). Two things make it
// cheap without changing a bit: a surfel's values depend on the surfel and the
// pose alone, so a pixel naming the surfel its left neighbour named copies them
// (a footprint spans several pixels of a row); and the surfel kPrefetchPixels
// ahead is fetched early (the pool is tens of MB: without it most of the time
// went to waiting for it, perf on the mock orbit).
void FrameToModelTracker::modelFromIndexMap(const hal::RgbdFrame& frame, const hal::Pose& pose, const SurfelMap& map,
                                            const uint32_t* index, const uint8_t* moving) {
  constexpr std::size_t kPrefetchPixels = 24;
  const int w = frame.width(), h = frame.height();
  const std::size_t pixels = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  Level& l0 = model_[0];
  const Eigen::Matrix3d Rt = pose.R_world_cam.transpose();
  const Eigen::Matrix3f Rt_f = Rt.cast<float>();
  const float scale = static_cast<float>(frame.depth_scale_m);
  const float max_z = maxDepth();
  const uint16_t* depth = frame.depth();
  const uint8_t* rgb = frame.rgb();
  const std::size_t slots = map.slotCount();
  for (int v = 0; v < h; ++v) {
    uint32_t left = SurfelMap::kNoSurfel;  // the slot the pixel to the left took its values from
    for (int u = 0; u < w; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * w + u;
      if (index != nullptr && i + kPrefetchPixels < pixels) {
        const uint32_t ahead = index[i + kPrefetchPixels];
        if (ahead < slots) __builtin_prefetch(&map.surfel(ahead));
      }
      const uint32_t slot = index != nullptr ? index[i] : SurfelMap::kNoSurfel;
      if (slot != SurfelMap::kNoSurfel && slot == left) {
        l0.copyPixel(i - 1, i);
        model_from_surfel_[i] = 1;
        continue;
      }
      left = SurfelMap::kNoSurfel;
      if (slot < slots && map.live(slot)) {
        const Surfel& s = map.surfel(slot);
        const Eigen::Vector3d p = Rt * (map.worldPosition(slot) - pose.t_world_cam);
        if (p.z() > 0.0) {
          const Eigen::Vector3f n = Rt_f * decodeNormal(s.normal_radius >> 8);
          l0.x[i] = static_cast<float>(p.x()), l0.y[i] = static_cast<float>(p.y()), l0.z[i] = static_cast<float>(p.z());
          l0.nx[i] = n.x(), l0.ny[i] = n.y(), l0.nz[i] = n.z();
          const uint8_t c[3] = {s.red, s.green, s.blue};
          l0.intensity[i] = intensityOf(c);
          model_from_surfel_[i] = 1;
          left = slot;
          continue;
        }
      }
      model_from_surfel_[i] = 0;
      // A moving pixel's measurement is the mover: no model there.
      const uint16_t raw = moving != nullptr && moving[i] ? uint16_t{0} : depth[i];
      (void)l0.setMeasured(i, u, v, raw, scale, max_z, frame.has_rgb ? intensityOf(rgb + 3 * i) : 0.0f);
    }
  }
}

FrameToModelTracker::ModelView FrameToModelTracker::finestModel() const {
  const Level& l0 = model_[0];
  return {l0.width,        l0.height,       l0.x.data(),         l0.y.data(), l0.z.data(), l0.nx.data(),
          l0.ny.data(),    l0.nz.data(),    l0.intensity.data(), model_from_surfel_.data()};
}

void FrameToModelTracker::modelFused(const hal::RgbdFrame& frame, const hal::Pose& pose, const SurfelMap& map,
                                     const uint8_t* moving) {
  const int w = frame.width(), h = frame.height();
  if (w > config_.max_width || h > config_.max_height || w < 8 || h < 8) {
    have_model_ = false;
    return;
  }
  const bool index_ok = map.indexMapWidth() == w && map.indexMapHeight() == h;
  Level& l0 = model_[0];
  l0.setCamera(w, h, frame.intrinsics);
  modelFromIndexMap(frame, pose, map, index_ok ? map.indexMap() : nullptr, moving);
  // Normals of the pixels without a surfel: from the model's vertex map (the
  // frame's own measurement there, next to surfels as merged).
  computeNormals(
      NormalMapIn{w, h, kNormalReach, kStepShare, l0.x.data(), l0.y.data(), l0.z.data(), model_from_surfel_.data()},
      l0.nx.data(), l0.ny.data(), l0.nz.data(), config_.kernels);
  computeGradients(w, h, l0.intensity.data(), l0.gx.data(), l0.gy.data());
  for (int l = 1; l < kLevels; ++l) {
    model_[l].downsampleFrom(model_[l - 1], true, config_.kernels);
    Level& L = model_[l];
    computeGradients(L.width, L.height, L.intensity.data(), L.gx.data(), L.gy.data());
  }
  model_pose_ = pose;
  have_model_ = true;
}

FrameToModelTracker::Solve FrameToModelTracker::solve(const Eigen::Matrix3d& R0, const Eigen::Vector3d& t0,
                                                      bool photometric) {
  Solve s;
  s.R = R0;
  s.t = t0;
  TrackSums sums;
  const float min_cos = static_cast<float>(std::cos(config_.icp_max_normal_deg * kDegToRad));
  for (int l = kLevels - 1; l >= 0; --l) {
    const Level& F = frame_[l];
    const Level& M = model_[l];
    const TrackFrameLevel fl{F.width, F.height, F.x.data(), F.y.data(), F.z.data(),
                             F.nx.data(), F.ny.data(), F.nz.data(), F.intensity.data()};
    const TrackModelLevel ml{M.width, M.height, M.fx, M.fy, M.cx, M.cy, M.x.data(), M.y.data(), M.z.data(),
                             M.nx.data(), M.ny.data(), M.nz.data(), M.intensity.data(), M.gx.data(), M.gy.data()};
    TrackParams p;
    p.max_distance = static_cast<float>(config_.icp_max_distance_m * (l + 1));
    p.min_normal_cos = min_cos;
    p.noise_weighting = config_.icp_noise_weighting;
    p.use_photometric = photometric && config_.photometric_weight > 0.0;
    p.photometric_sqrt_weight = static_cast<float>(std::sqrt(config_.photometric_weight));
    p.max_photometric_residual = static_cast<float>(config_.max_photometric_residual);
    // Cauchy's weights (IRLS) from the first iteration when tracking from the
    // last pose; relocalising, least squares until the level converges and the
    // weights from there: started far off, they would take most of the pixels
    // that must pull the estimate in (the wall case: 12.5 mm ATE against 0.9).
    const bool robust_configured = config_.icp_robust_scale_m > 0.0 || config_.photometric_robust_scale > 0.0;
    bool robust = robust_configured && !lost_;
    // The finest level runs at least one pass so that the statistics are its own.
    const int iterations = l == 0 ? std::max(1, config_.iterations[0]) : config_.iterations[l];
    for (int it = 0; it < iterations; ++it) {
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) p.R[3 * r + c] = static_cast<float>(s.R(r, c));
        p.t[r] = static_cast<float>(s.t(r));
      }
      p.icp_robust_scale = robust ? static_cast<float>(config_.icp_robust_scale_m) : 0.0f;
      p.photometric_robust_scale = robust ? static_cast<float>(config_.photometric_robust_scale) : 0.0f;
      trackLevel(fl, ml, p, sums, config_.kernels);
      ++s.iterations;
      Eigen::Matrix<double, 6, 6> H;
      Eigen::Matrix<double, 6, 1> b;
      int k = 0;
      for (int a = 0; a < 6; ++a) {
        for (int c = a; c < 6; ++c) H(a, c) = H(c, a) = sums.h[k++];
        b(a) = sums.b[a];
      }
      s.inliers = sums.inliers;
      const double n = std::max<double>(1.0, sums.inliers);
      s.icp_rms = std::sqrt(sums.icp_sq / n);
      s.photometric_rms =
          sums.photometric_inliers > 0 && p.photometric_sqrt_weight > 0.0f
              ? std::sqrt(sums.photometric_sq / sums.photometric_inliers) / p.photometric_sqrt_weight
              : 0.0;
      if (sums.inliers < 6) {
        s.min_eigenvalue = 0.0;
        break;
      }
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eig(H / n, Eigen::EigenvaluesOnly);
      s.min_eigenvalue = eig.eigenvalues()(0);
      const Eigen::Matrix<double, 6, 1> x = H.ldlt().solve(-b);
      if (!x.allFinite()) {
        s.finite = false;
        break;
      }
      Eigen::Matrix3d dR;
      Eigen::Vector3d dt;
      expTwist(x, dR, dt);
      s.R = dR * s.R;
      s.t = dR * s.t + dt;
      if (x.head<3>().norm() < config_.converged_step && x.tail<3>().norm() < config_.converged_step) {
        if (robust || !robust_configured) break;
        robust = true;
      }
    }
  }
  // Re-orthonormalise (float-accumulated rounding over many updates).
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(s.R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  s.R = svd.matrixU() * svd.matrixV().transpose();
  return s;
}

double FrameToModelTracker::medianResidual() const {
  std::array<double, 15> v = residual_history_;
  const int n = std::min<int>(residual_count_, static_cast<int>(v.size()));
  std::nth_element(v.begin(), v.begin() + n / 2, v.begin() + n);
  return v[static_cast<std::size_t>(n / 2)];
}

double FrameToModelTracker::inlierFraction(uint32_t inliers, uint32_t left_out) const {
  const uint32_t used = valid_pixels_ - std::min(left_out, valid_pixels_);
  return used > 0 ? static_cast<double>(inliers) / used : 0.0;
}

LostReason FrameToModelTracker::check(const Solve& s, const hal::Pose& pose, const hal::Pose& reference,
                                      uint32_t left_out) const {
  if (!s.finite || !pose.R_world_cam.allFinite() || !pose.t_world_cam.allFinite()) return LostReason::kDegenerate;
  const double fraction = inlierFraction(s.inliers, left_out);
  if (fraction < config_.min_inlier_fraction || s.inliers < 6) return LostReason::kFewInliers;
  if (s.min_eigenvalue < config_.min_eigenvalue) return LostReason::kDegenerate;
  if (residual_count_ >= 5 && s.icp_rms > config_.residual_jump_floor_m &&
      s.icp_rms > config_.max_residual_jump * medianResidual()) {
    return LostReason::kResidualJump;
  }
  const double dt = (pose.t_world_cam - reference.t_world_cam).norm();
  const double dr = rotationAngleDeg(reference.R_world_cam.transpose() * pose.R_world_cam);
  if (dt > config_.max_motion_m || dr > config_.max_motion_deg) return LostReason::kImplausibleMotion;
  return LostReason::kNone;
}

// A solve from a world pose: the estimate is the new camera in the model camera.
FrameToModelTracker::Attempt FrameToModelTracker::attemptFrom(const hal::Pose& start, bool photometric) {
  const Eigen::Matrix3d Rk_t = model_pose_.R_world_cam.transpose();
  Attempt a;
  a.solve = solve(Rk_t * start.R_world_cam, Rk_t * (start.t_world_cam - model_pose_.t_world_cam), photometric);
  a.pose.R_world_cam = model_pose_.R_world_cam * a.solve.R;
  a.pose.t_world_cam = model_pose_.R_world_cam * a.solve.t + model_pose_.t_world_cam;
  a.left_out = carried_left_out_;
  a.reason = check(a.solve, a.pose, last_good_, a.left_out);
  return a;
}

// Relocalisation: the last good pose (and the prior), then rotations of
// +-relocalise_search_deg about each camera axis; the candidate with the most
// inliers that passes the checks, else the first candidate's attempt and reason.
FrameToModelTracker::Attempt FrameToModelTracker::relocalise(const hal::Pose* prior, bool photometric,
                                                             TrackStats& stats) {
  std::array<hal::Pose, 8> candidates;
  int n = 0;
  candidates[n++] = last_good_;
  if (prior != nullptr) candidates[n++] = *prior;
  if (config_.relocalise_search_deg > 0.0) {
    const double a = config_.relocalise_search_deg * kDegToRad;
    for (int axis = 0; axis < 3; ++axis) {
      for (double sign : {-1.0, 1.0}) {
        hal::Pose c = last_good_;
        c.R_world_cam =
            last_good_.R_world_cam * Eigen::AngleAxisd(sign * a, Eigen::Vector3d::Unit(axis)).toRotationMatrix();
        if (n < static_cast<int>(candidates.size())) candidates[n++] = c;
      }
    }
  }
  stats.relocalise_candidates = n;
  Attempt best;
  bool found = false;
  LostReason first_reason = LostReason::kFewInliers;
  for (int c = 0; c < n; ++c) {
    const Attempt attempt = attemptFrom(candidates[c], photometric);
    if (c == 0) first_reason = attempt.reason;
    stats.iterations += attempt.solve.iterations;
    if (attempt.reason == LostReason::kNone && (!found || attempt.solve.inliers > best.solve.inliers)) {
      best = attempt;
      found = true;
    } else if (!found && c == 0) {
      best = attempt;
    }
  }
  best.reason = found ? LostReason::kNone : first_reason;
  return best;
}

// The chosen attempt's figures, and its disagreement with the prior.
void FrameToModelTracker::recordAttempt(const Attempt& best, const hal::Pose* prior, TrackStats& stats) const {
  stats.iterations = std::max(stats.iterations, best.solve.iterations);
  stats.inliers = best.solve.inliers;
  stats.inlier_fraction = inlierFraction(best.solve.inliers, best.left_out);
  stats.icp_rms_m = best.solve.icp_rms;
  stats.photometric_rms = best.solve.photometric_rms;
  stats.min_eigenvalue = best.solve.min_eigenvalue;
  if (prior != nullptr) {
    stats.prior_disagreement_m = (best.pose.t_world_cam - prior->t_world_cam).norm();
    stats.prior_disagreement_deg = rotationAngleDeg(prior->R_world_cam.transpose() * best.pose.R_world_cam);
  }
}

// A frame whose size and intrinsics the tracker can take.
bool FrameToModelTracker::frameUsable(const hal::RgbdFrame& frame) const {
  const hal::CameraIntrinsics& k = frame.intrinsics;
  const bool size_ok = frame.width() >= 8 && frame.height() >= 8 && frame.width() <= config_.max_width &&
                       frame.height() <= config_.max_height;
  const bool intrinsics_ok = std::isfinite(k.fx) && std::isfinite(k.fy) && k.fx > 0.0 && k.fy > 0.0 &&
                             std::isfinite(k.cx) && std::isfinite(k.cy) && std::isfinite(frame.depth_scale_m) &&
                             frame.depth_scale_m > 0.0;
  return size_ok && intrinsics_ok;
}

TrackOutcome FrameToModelTracker::track(const hal::RgbdFrame& frame, const hal::Pose* prior, hal::Pose& pose,
                                        TrackStats& stats) {
  const int64_t t_start = monotonicNs();
  stats = TrackStats{};
  ++counters_.frames;
  const auto finish = [&](TrackOutcome outcome) {
    stats.outcome = outcome;
    stats.track_ns = monotonicNs() - t_start;
    return outcome;
  };
  const auto lose = [&](LostReason reason) {
    stats.lost_reason = reason;
    moving_.clear();
    pose = prior != nullptr ? *prior : last_good_;
    if (have_model_) lost_ = true;
    ++counters_.lost;
    return finish(TrackOutcome::kLost);
  };
  if (!frameUsable(frame)) return lose(LostReason::kNoValidDepth);
  if (prior != nullptr && !(prior->R_world_cam.allFinite() && prior->t_world_cam.allFinite())) {
    prior = nullptr;  // a broken outside pose: not a start, and not what the lost frame reports
    return lose(LostReason::kImplausibleMotion);
  }
  const bool has_depth = buildFramePyramid(frame);
  stats.valid_pixels = valid_pixels_;
  stats.pyramid_ns = monotonicNs() - t_start;
  if (!has_depth) return lose(LostReason::kNoValidDepth);
  leaveOutCarried(stats);
  if (!have_model_) {
    pose = prior != nullptr ? *prior : last_good_;
    last_good_ = pose;
    lost_ = false;
    moving_.clear();
    return finish(TrackOutcome::kFirstFrame);
  }
  const bool model_size_ok = model_[0].width == frame.width() && model_[0].height == frame.height();
  if (!model_size_ok) return lose(LostReason::kFewInliers);

  const bool photometric = frame.has_rgb;
  Attempt best =
      lost_ ? relocalise(prior, photometric, stats) : attemptFrom(prior != nullptr ? *prior : last_good_, photometric);
  if (config_.moving.enabled && best.solve.finite) {
    const int64_t t_moving = monotonicNs();
    leaveOutMovers(best, stats);
    stats.moving_ns = monotonicNs() - t_moving;
  }
  recordAttempt(best, prior, stats);
  if (best.reason != LostReason::kNone) return lose(best.reason);
  const TrackOutcome outcome = lost_ ? TrackOutcome::kRelocalised : TrackOutcome::kTracked;
  ++(lost_ ? counters_.relocalised : counters_.tracked);
  lost_ = false;
  pose = best.pose;
  last_good_ = best.pose;
  residual_history_[static_cast<std::size_t>(residual_count_) % residual_history_.size()] = best.solve.icp_rms;
  ++residual_count_;
  return finish(outcome);
}

// Found on the half level, each pixel against its reference (carried_pixels.h); a
// carried half pixel clears its 2 x 2 block of the finest level and the
// coarsest level's pixel over it, so that no level of the alignment sees it.
void FrameToModelTracker::leaveOutCarried(TrackStats& stats) {
  Level& f0 = frame_[0];
  Level& f1 = frame_[1];
  Level& f2 = frame_[2];
  const int64_t start_ns = monotonicNs();
  carried_left_out_ = 0;
  const uint32_t carried = carried_.find(CarriedPixels::FrameIn{f1.width, f1.height, f1.z.data(), f1.intensity.data()});
  stats.changed_share = carried_.changedShare();
  if (carried == 0) {
    stats.carried_ns = monotonicNs() - start_ns;
    return;
  }
  const uint8_t* mask = carried_.mask();
  const auto hw = static_cast<std::size_t>(f1.width), fw = static_cast<std::size_t>(f0.width);
  uint32_t cleared = 0;
  for (int V = 0; V < f1.height; ++V) {
    for (int U = 0; U < f1.width; ++U) {
      const std::size_t i = static_cast<std::size_t>(V) * hw + static_cast<std::size_t>(U);
      if (mask[i] == 0) continue;
      f1.z[i] = 0.0f;
      const std::size_t top = 2 * static_cast<std::size_t>(V) * fw + 2 * static_cast<std::size_t>(U);
      for (std::size_t j : {top, top + 1, top + fw, top + fw + 1}) {
        cleared += f0.z[j] > 0.0f ? 1u : 0u;
        f0.z[j] = 0.0f;
      }
      if (U / 2 < f2.width && V / 2 < f2.height) {
        f2.z[static_cast<std::size_t>(V / 2) * static_cast<std::size_t>(f2.width) + static_cast<std::size_t>(U / 2)] = 0.0f;
      }
    }
  }
  carried_left_out_ = cleared;
  stats.carried_pixels = cleared;
  stats.carried_ns = monotonicNs() - start_ns;
}

void FrameToModelTracker::markMoving(const Solve& s, TrackStats& stats) {
  const Level& F = frame_[1];
  const Level& M = model_[0];
  const MovingPixels::FrameIn half{F.width, F.height, F.x.data(), F.y.data(), F.z.data(), F.intensity.data()};
  const MovingPixels::ModelIn model{M.width, M.height, M.fx, M.fy, M.cx, M.cy, M.z.data(), model_from_surfel_.data()};
  const bool carried_fits = carried_.width() == F.width && carried_.height() == F.height;
  stats.moving_pixels = moving_.update(half, model, s.R.cast<float>(), s.t.cast<float>(),
                                       carried_fits ? carried_.mask() : nullptr);
  stats.moving_share = valid_pixels_ > 0 ? static_cast<double>(stats.moving_pixels) / valid_pixels_ : 0.0;
}

// ReFusion's order: align, find what the static model does not explain, and
// judge the alignment on the rest. A mover's pixels in front lie at least
// min_gap_m before the model's surfels, which TrackerConfig::validate() keeps at
// or beyond the finest level's association distance: the finest level, the
// alignment's last, never used them, so the alignment already is the one without
// them (only the unknown pixels a mover's region grows into, where the model
// holds the frame before's measurement, can have been used). Aligning again
// without them was measured and not kept: its extra finest iterations cost 2.1 ms
// and moved the ATE both ways (docs/tracking.md). What changes is the judgement:
// the inliers count against the pixels left in, so a mover over half the view is
// not "few inliers", and a view mostly moving is lost with its own reason, not
// tracked on what little is left.
void FrameToModelTracker::leaveOutMovers(Attempt& a, TrackStats& stats) {
  markMoving(a.solve, stats);
  if (stats.moving_pixels == 0) return;
  if (stats.moving_share > config_.max_moving_share) {
    a.reason = LostReason::kMostlyMoving;
    return;
  }
  const Level& f0 = frame_[0];
  const uint8_t* mask = moving_.mask();
  const int mask_width = moving_.width();
  const int rows = std::min(f0.height, moving_.height()), columns = std::min(f0.width, mask_width);
  uint32_t left_out = carried_left_out_;  // valid pixels under the mask (the carried ones' depth cleared already)
  for (int v = 0; v < rows; ++v) {
    const uint8_t* m = mask + static_cast<std::size_t>(v) * mask_width;
    const float* z = f0.z.data() + static_cast<std::size_t>(v) * f0.width;
    for (int u = 0; u < columns; ++u) left_out += (m[u] != 0 && z[u] > 0.0f) ? 1u : 0u;
  }
  a.left_out = left_out;
  a.reason = check(a.solve, a.pose, last_good_, a.left_out);
}

}  // namespace fovea::pipeline::map

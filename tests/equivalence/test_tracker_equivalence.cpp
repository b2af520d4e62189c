// The tracker's Highway kernel (trackLevelSimd, tracker_simd-inl.h) against its
// scalar reference (trackLevelRef, tracker_kernels.cpp) on every Highway target here:
// the same inliers, and each of the 27 sums within kTrackSimdTolerance of the
// reference's, relative to the sum's Cauchy-Schwarz scale (tracker_kernels.h),
// on random scenes and on adversarial ones (no valid pixel, NaN and huge depth,
// zero normals, a single valid pixel, rows shorter than a vector).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "pipeline/map/tracker_kernels.h"
#include "tests/support/simd_targets.h"

namespace fovea::pipeline::map {
namespace {

using test::TargetTest;

struct Levels {
  int w = 0, h = 0;
  std::vector<float> fx_, fy_, fz_, fnx, fny, fnz, fi;              // frame
  std::vector<float> mx, my, mz, mnx, mny, mnz, mi, mgx, mgy;       // model
  TrackFrameLevel frame() const { return {w, h, fx_.data(), fy_.data(), fz_.data(), fnx.data(), fny.data(), fnz.data(), fi.data()}; }
  TrackModelLevel model() const {
    return {w, h, 0.8f * w, 0.8f * w, 0.5f * w, 0.5f * h, mx.data(), my.data(), mz.data(), mnx.data(), mny.data(),
            mnz.data(), mi.data(), mgx.data(), mgy.data()};
  }
};

// A wavy surface seen by the model's camera, and the same surface as a frame
// seen after a small motion (with depth noise), intensities from a texture.
Levels makeScene(int w, int h, std::mt19937& rng) {
  Levels L;
  L.w = w, L.h = h;
  const std::size_t n = static_cast<std::size_t>(w) * h;
  for (auto* v : {&L.fx_, &L.fy_, &L.fz_, &L.fnx, &L.fny, &L.fnz, &L.fi, &L.mx, &L.my, &L.mz, &L.mnx, &L.mny, &L.mnz,
                  &L.mi, &L.mgx, &L.mgy}) {
    v->assign(n, 0.0f);
  }
  std::normal_distribution<float> noise(0.0f, 0.002f);
  const float f = 0.8f * w, cx = 0.5f * w, cy = 0.5f * h;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * w + u;
      const float z = 1.5f + 0.2f * std::sin(0.3f * u) * std::cos(0.2f * v);
      L.mz[i] = z;
      L.mx[i] = (u - cx) / f * z;
      L.my[i] = (v - cy) / f * z;
      Eigen::Vector3f nrm(-0.06f * std::cos(0.3f * u), 0.04f * std::sin(0.2f * v), -1.0f);
      nrm.normalize();
      L.mnx[i] = nrm.x(), L.mny[i] = nrm.y(), L.mnz[i] = nrm.z();
      L.mi[i] = 0.5f + 0.4f * std::sin(0.5f * u + 0.3f * v);
      // The frame: the model's points moved by a small motion, noisy.
      L.fx_[i] = L.mx[i] + 0.01f + noise(rng);
      L.fy_[i] = L.my[i] - 0.005f + noise(rng);
      L.fz_[i] = z + 0.02f + noise(rng);
      L.fnx[i] = nrm.x(), L.fny[i] = nrm.y(), L.fnz[i] = nrm.z();
      L.fi[i] = L.mi[i] + noise(rng) * 10.0f;
    }
  }
  for (int v = 1; v + 1 < h; ++v) {
    for (int u = 1; u + 1 < w; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * w + u;
      L.mgx[i] = 0.5f * (L.mi[i + 1] - L.mi[i - 1]);
      L.mgy[i] = 0.5f * (L.mi[i + w] - L.mi[i - w]);
    }
  }
  return L;
}

TrackParams makeParams(std::mt19937& rng, bool photometric, bool noise_weighting) {
  std::uniform_real_distribution<float> a(-0.03f, 0.03f);
  const Eigen::Matrix3f R = (Eigen::AngleAxisf(a(rng), Eigen::Vector3f::UnitX()) *
                             Eigen::AngleAxisf(a(rng), Eigen::Vector3f::UnitY()) *
                             Eigen::AngleAxisf(a(rng), Eigen::Vector3f::UnitZ()))
                                .toRotationMatrix();
  TrackParams p;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) p.R[3 * r + c] = R(r, c);
    p.t[r] = a(rng);
  }
  p.max_distance = 0.1f;
  p.min_normal_cos = 0.866f;
  p.noise_weighting = noise_weighting;
  p.use_photometric = photometric;
  p.photometric_sqrt_weight = 0.3f;
  p.max_photometric_residual = 0.3f;
  return p;
}

void expectEquivalent(const Levels& L, const TrackParams& p, const char* what) {
  TrackSums ref, simd;
  trackLevelRef(L.frame(), L.model(), p, ref);
  trackLevelSimd(L.frame(), L.model(), p, simd);
  ASSERT_EQ(simd.inliers, ref.inliers) << what;
  ASSERT_EQ(simd.photometric_inliers, ref.photometric_inliers) << what;
  const double r2 = ref.icp_sq + ref.photometric_sq;
  auto diag = [&](int a) {
    static constexpr int kDiag[6] = {0, 6, 11, 15, 18, 20};
    return ref.h[static_cast<std::size_t>(kDiag[a])];
  };
  int k = 0;
  for (int a = 0; a < 6; ++a) {
    for (int c = a; c < 6; ++c, ++k) {
      const double scale = std::sqrt(diag(a) * diag(c)) + 1e-30;
      EXPECT_LE(std::abs(simd.h[static_cast<std::size_t>(k)] - ref.h[static_cast<std::size_t>(k)]) / scale,
                kTrackSimdTolerance)
          << what << ": H(" << a << ", " << c << ")";
    }
    const double scale = std::sqrt(diag(a) * r2) + 1e-30;
    EXPECT_LE(std::abs(simd.b[static_cast<std::size_t>(a)] - ref.b[static_cast<std::size_t>(a)]) / scale,
              kTrackSimdTolerance)
        << what << ": b(" << a << ")";
  }
  EXPECT_LE(std::abs(simd.icp_sq - ref.icp_sq), kTrackSimdTolerance * ref.icp_sq + 1e-30) << what;
  EXPECT_LE(std::abs(simd.photometric_sq - ref.photometric_sq), kTrackSimdTolerance * ref.photometric_sq + 1e-30)
      << what;
}

TEST_P(TargetTest, TrackerKernelMatchesTheReferenceOnRandomScenes) {
  std::mt19937 rng(29);
  int cases = 0;
  for (const auto& [w, h] : {std::pair{160, 120}, std::pair{37, 23}, std::pair{5, 9}, std::pair{320, 240}}) {
    for (int trial = 0; trial < 3; ++trial) {
      const Levels L = makeScene(w, h, rng);
      for (bool photometric : {false, true}) {
        for (bool weighting : {false, true}) {
          for (bool robust : {false, true}) {  // Cauchy's weights (a scale of a few residuals' size), or none
            TrackParams p = makeParams(rng, photometric, weighting);
            p.icp_robust_scale = robust ? 0.002f : 0.0f;
            p.photometric_robust_scale = robust ? 0.06f : 0.0f;
            expectEquivalent(L, p, robust ? "random scene, robust" : "random scene");
            ++cases;
          }
        }
      }
    }
  }
  EXPECT_EQ(cases, 96);
}

TEST_P(TargetTest, TrackerKernelMatchesTheReferenceOnAdversarialInput) {
  std::mt19937 rng(7);
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  Levels base = makeScene(61, 17, rng);
  TrackParams p = makeParams(rng, true, true);
  p.icp_robust_scale = 0.002f;  // the tracker's defaults: the weights' lanes outside see NaNs too
  p.photometric_robust_scale = 0.06f;
  {
    Levels L = base;  // no valid depth at all
    std::fill(L.fz_.begin(), L.fz_.end(), 0.0f);
    expectEquivalent(L, p, "no valid depth");
    TrackSums simd;
    trackLevelSimd(L.frame(), L.model(), p, simd);
    EXPECT_EQ(simd.inliers, 0u);
  }
  {
    Levels L = base;  // NaN, infinite and huge depth, zero and NaN normals, sprinkled
    std::uniform_int_distribution<std::size_t> pick(0, L.fz_.size() - 1);
    for (int k = 0; k < 200; ++k) {
      const std::size_t i = pick(rng);
      switch (k % 6) {
        case 0: L.fz_[i] = nan; break;
        case 1: L.fz_[i] = inf; break;
        case 2: L.fz_[i] = 1e30f; break;
        case 3: L.fnx[i] = L.fny[i] = L.fnz[i] = 0.0f; break;
        case 4: L.mz[i] = nan; break;
        case 5: L.mnx[i] = nan; break;
      }
    }
    expectEquivalent(L, p, "NaN, infinite, huge");
  }
  {
    Levels L = base;  // one valid pixel, in a row's tail
    std::fill(L.fz_.begin(), L.fz_.end(), 0.0f);
    L.fz_[5 * 61 + 60] = base.fz_[5 * 61 + 60];
    expectEquivalent(L, p, "a single pixel");
  }
  {
    Levels L = base;  // everything projects outside the model
    TrackParams far = p;
    far.t = {100.0f, 0.0f, 0.0f};
    expectEquivalent(L, far, "outside the view");
  }
}

// The reference's robust weights, against a brute-force sum written here in
// double: each associated pixel's ICP and photometric terms (trackPixelRef)
// weighted by Cauchy's 1 / (1 + (r0 / c)^2), r0 the residual before the
// photometric weight. Weights below 1 must occur, or the test shows nothing.
TEST(TrackerRobust, TheReferenceWeightsEachTermByCauchysKernel) {
  std::mt19937 rng(42);
  const Levels L = makeScene(97, 61, rng);
  TrackParams p = makeParams(rng, true, true);
  p.icp_robust_scale = 0.002f;
  p.photometric_robust_scale = 0.06f;
  TrackSums sums;
  trackLevelRef(L.frame(), L.model(), p, sums);
  std::array<double, 21> h{};
  std::array<double, 6> b{};
  double least_weight = 1.0;
  const auto add = [&](const float* J, double r, double w) {
    int k = 0;
    for (int a = 0; a < 6; ++a) {
      for (int c = a; c < 6; ++c) h[static_cast<std::size_t>(k++)] += w * J[a] * J[c];
      b[static_cast<std::size_t>(a)] += w * J[a] * r;
    }
    least_weight = std::min(least_weight, w);
  };
  const auto cauchy = [](double r, double c) { return 1.0 / (1.0 + (r / c) * (r / c)); };
  for (std::size_t i = 0; i < static_cast<std::size_t>(97 * 61); ++i) {
    const TrackPixel px = trackPixelRef(L.frame(), L.model(), p, i);
    if (!px.icp) continue;
    add(px.j_icp, px.r_icp, cauchy(px.r_icp, p.icp_robust_scale));
    if (px.photometric) add(px.j_photo, px.r_photo, cauchy(px.r_photo / p.photometric_sqrt_weight, p.photometric_robust_scale));
  }
  ASSERT_GT(sums.inliers, 100u);
  EXPECT_LT(least_weight, 0.5) << "the scene's residuals must reach beyond the scales";
  for (std::size_t k = 0; k < 21; ++k) EXPECT_NEAR(sums.h[k], h[k], 1e-5 * (std::abs(h[k]) + 1e-9)) << "H " << k;
  for (std::size_t k = 0; k < 6; ++k) EXPECT_NEAR(sums.b[k], b[k], 1e-5 * (std::abs(b[k]) + 1e-9)) << "b " << k;
  // Without the weights the sums are the plain ones: larger.
  TrackParams plain = p;
  plain.icp_robust_scale = plain.photometric_robust_scale = 0.0f;
  TrackSums unweighted;
  trackLevelRef(L.frame(), L.model(), plain, unweighted);
  EXPECT_GT(unweighted.h[0], sums.h[0] * 1.01);
  EXPECT_EQ(unweighted.inliers, sums.inliers);
  EXPECT_DOUBLE_EQ(unweighted.icp_sq, sums.icp_sq) << "the residuals' sums stay unweighted";
}

// The normals kernel (computeNormalsSimd) against its reference, bit for bit:
// a noisy wavy surface with depth steps and holes, and adversarial maps (NaN,
// infinities, zero and huge depths, all steps, widths shorter than a vector
// and not a multiple of it, reach 1 and 2, every other pixel kept by `skip`).
struct NormalCase {
  int w, h, reach;
  std::vector<float> x, y, z;
  std::vector<uint8_t> skip;
};

NormalCase wavyNormals(int w, int h, int reach, std::mt19937& rng, bool with_skip) {
  NormalCase c{w, h, reach, {}, {}, {}, {}};
  const std::size_t n = static_cast<std::size_t>(w) * h;
  c.x.resize(n), c.y.resize(n), c.z.resize(n);
  std::normal_distribution<float> noise(0.0f, 0.003f);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * w + u;
      float z = 1.2f + 0.3f * std::sin(0.21f * u) * std::cos(0.17f * v) + noise(rng) + (u > w / 2 ? 0.4f : 0.0f);
      if (unit(rng) < 0.03f) z = 0.0f;  // holes
      c.z[i] = z;
      c.x[i] = (u - 0.5f * w) / (0.8f * w) * z;
      c.y[i] = (v - 0.5f * h) / (0.8f * w) * z;
    }
  }
  if (with_skip) {
    c.skip.resize(n);
    for (std::size_t i = 0; i < n; ++i) c.skip[i] = static_cast<uint8_t>(i % 2);
  }
  return c;
}

void expectSameNormals(const NormalCase& c) {
  const std::size_t n = c.z.size();
  const NormalMapIn in{c.w, c.h, c.reach, 0.05f, c.x.data(), c.y.data(), c.z.data(),
                       c.skip.empty() ? nullptr : c.skip.data()};
  // Kept pixels must stay as they were: both start from the same values.
  std::vector<float> rx(n, 7.0f), ry(n, -7.0f), rz(n, 0.5f), sx = rx, sy = ry, sz = rz;
  computeNormalsRef(in, rx.data(), ry.data(), rz.data());
  computeNormalsSimd(in, sx.data(), sy.data(), sz.data());
  for (std::size_t i = 0; i < n; ++i) {
    ASSERT_EQ(std::memcmp(&rx[i], &sx[i], 4), 0) << "pixel " << i << ": " << rx[i] << " vs " << sx[i];
    ASSERT_EQ(std::memcmp(&ry[i], &sy[i], 4), 0) << "pixel " << i;
    ASSERT_EQ(std::memcmp(&rz[i], &sz[i], 4), 0) << "pixel " << i;
  }
}

TEST_P(TargetTest, NormalsKernelMatchesTheReferenceBitForBit) {
  std::mt19937 rng(11);
  for (const int reach : {1, 2}) {
    for (const bool skip : {false, true}) {
      for (const auto& [w, h] : {std::pair{64, 48}, std::pair{37, 29}, std::pair{5, 5}, std::pair{3, 9}}) {
        SCOPED_TRACE(testing::Message() << w << "x" << h << " reach " << reach << (skip ? " skip" : ""));
        expectSameNormals(wavyNormals(w, h, reach, rng, skip));
      }
    }
  }
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  for (const float bad : {nan, inf, -inf, 0.0f, -1.0f, 1e30f, 1e-30f}) {
    NormalCase c = wavyNormals(33, 21, 2, rng, false);
    for (std::size_t i = 0; i < c.z.size(); i += 7) c.z[i] = bad;
    for (std::size_t i = 3; i < c.x.size(); i += 11) c.x[i] = bad;
    SCOPED_TRACE(testing::Message() << "bad value " << bad);
    expectSameNormals(c);
  }
  NormalCase steps = wavyNormals(40, 12, 1, rng, false);  // every pixel a depth step
  for (std::size_t i = 0; i < steps.z.size(); ++i) steps.z[i] = i % 2 ? 1.0f : 2.0f;
  expectSameNormals(steps);
}

// The downsampling kernel (downsampleSimd) against its reference, bit for
// bit: a noisy wavy level with depth steps, holes and normals that sometimes
// disagree, and adversarial levels (NaN, infinities, zero, negative, huge and
// tiny values in every channel, normals that cancel), at sizes odd and shorter
// than a vector, with and without normals (without, the normals `to` held
// must stay where a block has a vertex).
struct PyramidCase {
  int w = 0, h = 0;
  std::vector<float> x, y, z, nx, ny, nz, i;
  PyramidLevelIn in() const { return {w, h, x.data(), y.data(), z.data(), nx.data(), ny.data(), nz.data(), i.data()}; }
};

PyramidCase wavyLevel(int w, int h, std::mt19937& rng) {
  PyramidCase c;
  c.w = w, c.h = h;
  const std::size_t n = static_cast<std::size_t>(w) * h;
  for (auto* v : {&c.x, &c.y, &c.z, &c.nx, &c.ny, &c.nz, &c.i}) v->assign(n, 0.0f);
  std::normal_distribution<float> noise(0.0f, 0.003f);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t k = static_cast<std::size_t>(v) * w + u;
      float z = 1.2f + 0.3f * std::sin(0.21f * u) * std::cos(0.17f * v) + noise(rng) + (u % 7 == 3 ? 0.4f : 0.0f);
      if (unit(rng) < 0.05f) z = 0.0f;  // holes
      c.z[k] = z;
      c.x[k] = (u - 0.5f * w) / (0.8f * w) * z;
      c.y[k] = (v - 0.5f * h) / (0.8f * w) * z;
      Eigen::Vector3f nrm(noise(rng) * 100.0f, noise(rng) * 100.0f, -1.0f);
      if (unit(rng) < 0.1f) nrm = Eigen::Vector3f(unit(rng) - 0.5f, unit(rng) - 0.5f, unit(rng) - 0.5f);  // disagrees
      nrm.normalize();
      c.nx[k] = nrm.x(), c.ny[k] = nrm.y(), c.nz[k] = nrm.z();
      c.i[k] = unit(rng);
    }
  }
  return c;
}

void expectSameDownsample(const PyramidCase& c, bool normals) {
  const std::size_t n = static_cast<std::size_t>(c.w / 2) * static_cast<std::size_t>(c.h / 2);
  // Both start from the same values (kept normals must stay as they were).
  std::vector<float> ref[7], simd[7];
  for (int k = 0; k < 7; ++k) ref[k].assign(n + 1, 3.0f + static_cast<float>(k)), simd[k] = ref[k];
  auto out = [](std::vector<float>* v) {
    return PyramidLevelOut{v[0].data(), v[1].data(), v[2].data(), v[3].data(), v[4].data(), v[5].data(), v[6].data()};
  };
  downsampleRef(c.in(), out(ref), 0.05f, normals);
  downsampleSimd(c.in(), out(simd), 0.05f, normals);
  for (int k = 0; k < 7; ++k) {
    for (std::size_t o = 0; o <= n; ++o) {  // and nothing written past the level
      ASSERT_EQ(std::memcmp(&ref[k][o], &simd[k][o], 4), 0)
          << "channel " << k << " block " << o << ": " << ref[k][o] << " vs " << simd[k][o];
    }
  }
}

TEST_P(TargetTest, DownsampleKernelMatchesTheReferenceBitForBit) {
  std::mt19937 rng(13);
  for (const bool normals : {false, true}) {
    for (const auto& [w, h] : {std::pair{64, 48}, std::pair{37, 29}, std::pair{130, 7}, std::pair{5, 5},
                               std::pair{3, 9}, std::pair{2, 2}, std::pair{1, 1}}) {
      SCOPED_TRACE(testing::Message() << w << "x" << h << (normals ? " normals" : ""));
      expectSameDownsample(wavyLevel(w, h, rng), normals);
    }
  }
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  for (const float bad : {nan, inf, -inf, 0.0f, -0.0f, -1.0f, 1e30f, 1e-30f, 1e38f}) {
    PyramidCase c = wavyLevel(70, 22, rng);
    std::vector<float>* channels[7] = {&c.x, &c.y, &c.z, &c.nx, &c.ny, &c.nz, &c.i};
    for (int k = 0; k < 7; ++k) {
      for (std::size_t p = static_cast<std::size_t>(k); p < c.z.size(); p += 5 + static_cast<std::size_t>(k)) {
        (*channels[k])[p] = bad;
      }
    }
    for (const bool normals : {false, true}) {
      SCOPED_TRACE(testing::Message() << "bad value " << bad << (normals ? " normals" : ""));
      expectSameDownsample(c, normals);
    }
  }
  PyramidCase cancel = wavyLevel(48, 8, rng);  // each block's normals sum to nothing
  for (std::size_t p = 0; p < cancel.nz.size(); ++p) cancel.nz[p] = p % 2 ? 1.0f : -1.0f, cancel.nx[p] = cancel.ny[p] = 0.0f;
  expectSameDownsample(cancel, true);
}

INSTANTIATE_TEST_SUITE_P(Targets, TargetTest, ::testing::ValuesIn(test::simdTargetsHere()), test::simdTargetName);

}  // namespace
}  // namespace fovea::pipeline::map

// The surfel map's per-pixel kernel (pipeline/map/map_kernels.h): Highway's
// computeVerticesSimd against the scalar reference computeVerticesRef, bit for bit
// in all eight maps and the count, on random and adversarial frames and on every
// Highway target compiled in and supported here (TargetTest/<Case>/<TARGET>);
// the index map's gather (pipeline/map/index_map.h) the same way, and its
// reference against a brute force over every centre of the grid; the index
// map's first pass (pipeline/map/splat_plan.h) and the association's plans
// (pipeline/map/association_plan.h) the same way, and the explained view's
// judgement of a row (pipeline/map/view_judge.h); then whole maps fused with
// either kernel set, which must be the same map.
#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "tests/support/simd_targets.h"
#include "tests/support/test_time.h"
#include "hal/camera.h"
#include "core/depth_noise.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/map/association_plan.h"
#include "pipeline/map/index_map.h"
#include "pipeline/map/map_kernels.h"
#include "pipeline/map/splat_plan.h"
#include "pipeline/map/surfel_map.h"
#include "pipeline/map/view_judge.h"

namespace fovea::pipeline::map {
namespace {

using test::TargetTest;
using test::simdTargetsHere;

// The six maps of one kernel's run, pre-filled with a marker that no kernel
// writes, so a pixel left unwritten shows.
struct Maps {
  static constexpr uint32_t kUnwritten = 0x7fa5a5a5u;  // a NaN with a payload
  std::vector<float> m[6];
  explicit Maps(std::size_t pixels) {
    for (auto& v : m) v.assign(pixels, std::bit_cast<float>(kUnwritten));
  }
  PixelMaps view() { return {m[0].data(), m[1].data(), m[2].data(), m[3].data(), m[4].data(), m[5].data()}; }
};
constexpr int kMaps = 6;
constexpr const char* kMapNames[kMaps] = {"z", "nx", "ny", "nz", "radius", "weight"};

struct Result2 {
  uint32_t ref = 0, simd = 0;
};

// Runs both kernels on the frame; expects the same bits in every map and the same
// count; returns the counts.
Result2 expectSameVertices(const hal::RgbdFrame& frame, const DepthRange& range, const std::string& what) {
  const std::size_t pixels = frame.pixelCount();
  VertexTables tables(frame.width(), frame.height());
  const VertexParams params = prepareVertices(frame, rawDepthRange(range, frame.depth_scale_m), tables);
  Maps ref(pixels), simd(pixels);
  Result2 n;
  n.ref = computeVerticesRef(params, ref.view());
  n.simd = computeVerticesSimd(params, simd.view());
  EXPECT_EQ(n.ref, n.simd) << what;
  // The depths' count is the pixels with a vertex, by either kernel; the
  // normals leave the weights as they were (a moving pixel's 0 stays 0).
  const auto with_vertex = static_cast<uint32_t>(
      std::count_if(ref.m[0].begin(), ref.m[0].end(), [](float d) { return d != 0.0f; }));
  for (const KernelSet kernels : {KernelSet::kRef, KernelSet::kSimd}) {
    Maps again(pixels);
    EXPECT_EQ(computeDepths(params, again.m[0].data(), again.m[5].data(), kernels), with_vertex) << what;
    std::fill(again.m[5].begin(), again.m[5].end(), 0.5f);
    (void)computeNormals(params, again.view(), kernels);
    EXPECT_TRUE(std::all_of(again.m[5].begin(), again.m[5].end(), [](float x) { return x == 0.5f; }))
        << what << ": computeNormals wrote a weight";
  }
  int reported = 0;
  for (int k = 0; k < kMaps; ++k) {
    for (std::size_t i = 0; i < pixels; ++i) {
      const uint32_t a = std::bit_cast<uint32_t>(ref.m[k][i]), b = std::bit_cast<uint32_t>(simd.m[k][i]);
      EXPECT_NE(a, Maps::kUnwritten) << what << ": the reference left " << kMapNames[k] << " of pixel " << i;
      if (a != b && reported++ < 5) {
        ADD_FAILURE() << what << " (" << frame.width() << "x" << frame.height() << "): " << kMapNames[k]
                      << " of pixel " << i << " (u " << i % frame.width() << ", v " << i / frame.width()
                      << "): ref " << ref.m[k][i] << " (0x" << std::hex << a << "), simd " << simd.m[k][i]
                      << " (0x" << b << std::dec << ")";
      }
    }
  }
  return n;
}

hal::RgbdFrame frameOf(int w, int h, double fx, double fy, double cx, double cy, double scale) {
  hal::RgbdFrame frame(w, h);
  frame.intrinsics = {w, h, fx, fy, cx, cy};
  frame.depth_scale_m = scale;
  std::fill(frame.depth(), frame.depth() + frame.pixelCount(), uint16_t{0});
  return frame;
}

// Smooth slanted surfaces (most pixels get a normal), noise, holes and steps; or,
// one frame in four, uniformly random raw depth (mostly edges).
hal::RgbdFrame randomFrame(int w, int h, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> f(200.0, 700.0), c(-10.0, 10.0), unit(0.0, 1.0);
  const double scales[] = {0.001, 1.0 / 5000.0, 0.0001, 0.00025};
  hal::RgbdFrame frame = frameOf(w, h, f(rng), f(rng), w / 2.0 + c(rng), h / 2.0 + c(rng), scales[rng() % 4]);
  const bool uniform = rng() % 4 == 0;
  const double z0 = 0.5 + 3.0 * unit(rng), gu = (unit(rng) - 0.5) * 0.02, gv = (unit(rng) - 0.5) * 0.02;
  const double noise = 0.002 * unit(rng);
  std::normal_distribution<double> gauss(0.0, 1.0);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const uint64_t r = rng();
      uint16_t raw;
      if (uniform) {
        raw = static_cast<uint16_t>(r >> 16);
      } else {
        double z = z0 + gu * u + gv * v + noise * gauss(rng);
        if (u > w / 3 && u < w / 2) z *= 0.7;  // a step (an occluding edge)
        raw = static_cast<uint16_t>(std::clamp(z / frame.depth_scale_m, 0.0, 65535.0));
      }
      if (r % 11 == 0) raw = 0;  // holes
      frame.depth()[static_cast<std::size_t>(v) * w + u] = raw;
    }
  }
  return frame;
}

TEST_P(TargetTest, RandomFrames) {
  std::mt19937_64 rng(23);
  // Widths around every vector width (1..64 lanes) exercise the tails; 3x3 is the smallest frame fused.
  const int sizes[][2] = {{640, 480}, {3, 3}, {4, 3}, {5, 5}, {7, 5}, {15, 6}, {17, 5}, {31, 6}, {33, 7},
                          {63, 5}, {65, 9}, {67, 5}, {129, 5}, {1000, 5}, {3, 37}, {6, 40}, {320, 240}};
  uint32_t with_normal = 0;
  // Four frames of each size natively, two where a frame costs ten times as much
  // (sanitizers, qemu): every size and tail is still covered.
  const int reps = test::repetitions(4, 2);
  for (const auto& s : sizes) {
    for (int rep = 0; rep < reps; ++rep) {
      const hal::RgbdFrame frame = randomFrame(s[0], s[1], rng);
      const DepthRange ranges[] = {{}, {0.5, 3.0}, {0.0, 1e9}};
      for (const DepthRange& range : ranges) {
        with_normal += expectSameVertices(frame, range, std::to_string(s[0]) + "x" + std::to_string(s[1])).ref;
      }
    }
  }
  EXPECT_GT(with_normal, 50000u * static_cast<uint32_t>(reps)) << "the random frames should give most pixels a normal";
}

TEST_P(TargetTest, NoValidDepthAndTheExtremes) {
  for (const auto& s : {std::pair{3, 3}, std::pair{17, 9}, std::pair{640, 480}}) {
    hal::RgbdFrame frame = frameOf(s.first, s.second, 525.0, 525.0, s.first / 2.0, s.second / 2.0, 0.001);
    EXPECT_EQ(expectSameVertices(frame, {}, "all zero").ref, 0u);
    std::fill(frame.depth(), frame.depth() + frame.pixelCount(), uint16_t{65535});
    EXPECT_EQ(expectSameVertices(frame, {}, "all 65535, beyond the range").ref, 0u);
    const Result2 n = expectSameVertices(frame, {0.0, 1e9}, "all 65535, in range");
    EXPECT_EQ(n.ref, s.first >= 5 && s.second >= 5 ? static_cast<uint32_t>((s.first - 4) * (s.second - 4)) : 0u);
    for (std::size_t i = 0; i < frame.pixelCount(); ++i) frame.depth()[i] = (i * 7919u) % 3 == 0 ? 0 : 65535;
    expectSameVertices(frame, {0.0, 1e9}, "0 and 65535 mixed");
    for (std::size_t i = 0; i < frame.pixelCount(); ++i) frame.depth()[i] = i % 2 == 0 ? 1 : 65535;
    expectSameVertices(frame, {0.0, 1e9}, "1 and 65535 alternating");
  }
}

TEST_P(TargetTest, SingleValidPixels) {
  for (const auto& s : {std::pair{7, 5}, std::pair{19, 6}, std::pair{3, 3}}) {
    for (int at = 0; at < s.first * s.second; ++at) {
      hal::RgbdFrame frame = frameOf(s.first, s.second, 300.0, 310.0, s.first / 2.0, s.second / 2.0, 0.001);
      frame.depth()[at] = 1234;
      EXPECT_EQ(expectSameVertices(frame, {}, "single pixel " + std::to_string(at)).ref, 0u);
    }
  }
}

// Depth steps exactly at the threshold |z' - z| > (0.05 * kNormalReach) * z in the
// kernels' float arithmetic, and one raw unit either side of it: a neighbour
// at the threshold keeps the normal, one beyond it takes it away.
TEST_P(TargetTest, StepsAtTheThreshold) {
  const float scale = 0.001f;
  struct Step {
    uint16_t centre, neighbour;
  };
  std::vector<Step> ties;
  for (int d = 100; d < 60000 && ties.size() < 40; ++d) {
    const float z = static_cast<float>(d) * scale;
    const float step = (0.05f * kNormalReach) * z;
    for (int dn : {static_cast<int>(std::lround(d * 1.1)), static_cast<int>(std::lround(d * 0.9))}) {
      if (dn > 65535) continue;
      if (std::abs(static_cast<float>(dn) * scale - z) == step) ties.push_back({static_cast<uint16_t>(d), static_cast<uint16_t>(dn)});
    }
  }
  ASSERT_GE(ties.size(), 10u) << "no raw depths whose step is exactly the threshold";
  constexpr int w = 23, h = 7;  // not a multiple of any vector width
  int kept = 0, lost = 0;
  for (const Step& t : ties) {
    for (int delta : {0, -1, 1}) {
      const int dn = t.neighbour + delta;
      for (int which = 0; which < 4; ++which) {  // left, right, up, down
        for (int u : {2, 5, 11, 17, 20}) {
          hal::RgbdFrame frame = frameOf(w, h, 400.0, 400.0, 11.0, 3.0, scale);
          std::fill(frame.depth(), frame.depth() + frame.pixelCount(), t.centre);
          const int nu = u + (which == 0 ? -kNormalReach : which == 1 ? kNormalReach : 0);
          const int nv = 3 + (which == 2 ? -kNormalReach : which == 3 ? kNormalReach : 0);
          frame.depth()[nv * w + nu] = static_cast<uint16_t>(dn);
          VertexTables tables(w, h);
          const DepthRange all{0.0, 1e9};
          const VertexParams p = prepareVertices(frame, rawDepthRange(all, frame.depth_scale_m), tables);
          Maps ref(frame.pixelCount());
          (void)computeVerticesRef(p, ref.view());
          const bool has_normal = ref.m[4][3 * w + u] > 0.0f;  // a radius
          (has_normal ? kept : lost) += 1;
          if (delta == 0) {
            EXPECT_TRUE(has_normal) << "a step at the threshold keeps the normal";
          }
          expectSameVertices(frame, all, "step " + std::to_string(t.centre) + " -> " + std::to_string(dn));
        }
      }
    }
  }
  EXPECT_GT(kept, 0);
  EXPECT_GT(lost, 0) << "one raw unit beyond the threshold should take some normals away";
}

// The map refuses, before any kernel runs, intrinsics and depth scales that are
// not finite or not positive, as double or once converted to the kernels' float.
TEST_P(TargetTest, BadIntrinsicsAreRefusedBeforeTheKernel) {
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  constexpr double kInf = std::numeric_limits<double>::infinity();
  for (KernelSet kernels : {KernelSet::kRef, KernelSet::kSimd}) {
    SurfelMapConfig config;
    config.max_width = 32;
    config.max_height = 24;
    config.max_surfels = 4096;
    config.max_bricks = 64;
    config.kernels = kernels;
    SurfelMap map = SurfelMap::create(config).value();
    hal::RgbdFrame good = frameOf(32, 24, 30.0, 30.0, 16.0, 12.0, 0.001);
    std::fill(good.depth(), good.depth() + good.pixelCount(), uint16_t{1500});
    int64_t stamp = 0;
    for (int field = 0; field < 5; ++field) {
      for (double bad : {kNaN, kInf, -kInf, 1e39 /* infinite as float */, 1e-300 /* zero as float */, 0.0, -1.0}) {
        const bool may_be_fine = (field == 2 || field == 3) && (bad == 1e-300 || bad == 0.0 || bad == -1.0);
        if (may_be_fine) continue;  // any finite principal point is a principal point
        hal::RgbdFrame frame = good;
        double* fields[] = {&frame.intrinsics.fx, &frame.intrinsics.fy, &frame.intrinsics.cx, &frame.intrinsics.cy,
                            &frame.depth_scale_m};
        *fields[field] = bad;
        frame.stamp_ns = ++stamp;
        FuseStats stats;
        EXPECT_EQ(map.fuse(frame, stats), FuseOutcome::kRefusedSize)
            << kernelSetName(kernels) << ": field #" << field << " = " << bad;
      }
    }
    EXPECT_EQ(map.size(), 0u);
    EXPECT_EQ(map.counters().frames_fused, 0u);
    good.stamp_ns = ++stamp;
    FuseStats stats;
    EXPECT_EQ(map.fuse(good, stats), FuseOutcome::kFused);
    EXPECT_GT(map.size(), 0u);
  }
}

// The index map's fast path rounds a surfel's centre with roundHalfAwayFromZero;
// the reference with std::lround. Every half-integer of the projection's range
// (a frame up to 8192 pixels and the splat's reach beyond it), the floats either
// side of each, and a sweep of 2^20 floats in between.
TEST(MapRounding, RoundingIsLround) {
  int differ = 0;
  auto check = [&](float x) {
    if (roundHalfAwayFromZero(x) != static_cast<int>(std::lround(x)) && differ++ < 5) {
      ADD_FAILURE() << "x = " << x << " (0x" << std::hex << std::bit_cast<uint32_t>(x) << std::dec
                    << "): " << roundHalfAwayFromZero(x) << " against lround " << std::lround(x);
    }
  };
  for (int k = -8; k <= 2 * 8200; ++k) {
    const float half = 0.5f * static_cast<float>(k);
    check(half);
    check(std::nextafter(half, -1e9f));
    check(std::nextafter(half, 1e9f));
  }
  for (uint32_t k = 0; k < (1u << 20); ++k) check(-3.0f + 8200.0f * static_cast<float>(k) / 1048576.0f);
  check(0.0f);
  check(-0.0f);
  check(0.49999997f);
  check(-0.49999997f);
  EXPECT_EQ(differ, 0);
}

// ---- the index map's gather --------------------------------------------------

// Random centres over a w x h frame and its border: planes seen straight on and
// slanted, gradients that turn the inverse depth negative within the footprint,
// depths from a few values (ties within and across the tolerance), every reach,
// near-infinite depths, and cells left empty.
IndexMap randomCentres(int w, int h, std::mt19937_64& rng) {
  IndexMap map(w, h);
  map.reset(w, h);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const float depths[] = {0.5f, 0.5f, 0.503f, 1.0f, 1.004f, 2.5f, 4.0f};
  const int kind = static_cast<int>(rng() % 3);  // 0: sparse, 1: about one a pixel, 2: several a pixel
  const std::size_t offers = static_cast<std::size_t>(w * h) * (kind == 0 ? 1 : kind == 1 ? 4 : 12) / 4;
  for (std::size_t n = 0; n < offers; ++n) {
    const int u = static_cast<int>(rng() % static_cast<uint64_t>(w + 2 * kMaxReach)) - kMaxReach;
    const int v = static_cast<int>(rng() % static_cast<uint64_t>(h + 2 * kMaxReach)) - kMaxReach;
    IndexMap::Centre c;
    c.depth = rng() % 8 == 0 ? 3e30f + unit(rng) * 1e30f : depths[rng() % 7] * (1.0f + 0.002f * unit(rng));
    c.inv_depth = 1.0f / c.depth;
    c.same = 3.0f * depthSigma(c.depth);
    c.rank = static_cast<uint8_t>(rng() % 3 * 100);
    c.reach = static_cast<uint8_t>(rng() % 3);
    const int slant = static_cast<int>(rng() % 4);  // flat, slanted, steep, past the horizon
    const float scale = slant == 0 ? 0.0f : slant == 1 ? 0.01f : slant == 2 ? 0.2f : 0.8f;
    c.grad_u = (unit(rng) - 0.5f) * scale * c.inv_depth;
    c.grad_v = (unit(rng) - 0.5f) * scale * c.inv_depth;
    map.offerCentre(u, v, c, static_cast<uint32_t>(n));
  }
  return map;
}

struct Gathered {
  std::vector<uint32_t> slot;
  std::vector<float> depth;
  explicit Gathered(std::size_t pixels) : slot(pixels, 0xa5a5a5a5u), depth(pixels, std::bit_cast<float>(Maps::kUnwritten)) {}
  IndexOut out() { return {slot.data(), depth.data()}; }
};

// Pixel by pixel the same slot and the same depth bits; returns the pixels given a surfel.
std::size_t expectSameGather(const Gathered& a, const Gathered& b, const std::string& what) {
  std::size_t seen = 0;
  int reported = 0;
  for (std::size_t i = 0; i < a.slot.size(); ++i) {
    seen += a.slot[i] != IndexMap::kNoSurfel;
    if ((a.slot[i] != b.slot[i] || std::bit_cast<uint32_t>(a.depth[i]) != std::bit_cast<uint32_t>(b.depth[i])) &&
        reported++ < 5) {
      ADD_FAILURE() << what << ": pixel " << i << ": slot " << a.slot[i] << " depth " << a.depth[i] << " against slot "
                    << b.slot[i] << " depth " << b.depth[i];
    }
  }
  return seen;
}

TEST_P(TargetTest, TheIndexMapsGatherIsTheReference) {
  std::mt19937_64 rng(41);
  const int sizes[][2] = {{640, 480}, {1, 1}, {3, 3}, {5, 2}, {15, 6}, {16, 4}, {17, 5}, {31, 3}, {33, 7},
                          {63, 2}, {64, 3}, {65, 9}, {129, 5}, {3, 37}, {320, 240}};
  std::size_t seen = 0;
  const int reps = test::repetitions(3, 1);
  for (const auto& s : sizes) {
    for (int rep = 0; rep < reps; ++rep) {
      const IndexMap map = randomCentres(s[0], s[1], rng);
      const std::size_t pixels = static_cast<std::size_t>(s[0]) * static_cast<std::size_t>(s[1]);
      Gathered ref(pixels), simd(pixels);
      gatherIndexRef(map.grid(), 3.0f, 0, s[1], ref.out());
      // In two bands, as fusion calls it between safe points.
      gatherIndexSimd(map.grid(), 3.0f, 0, s[1] / 2, simd.out());
      gatherIndexSimd(map.grid(), 3.0f, s[1] / 2, s[1], simd.out());
      seen += expectSameGather(ref, simd, std::to_string(s[0]) + "x" + std::to_string(s[1]));
    }
  }
  EXPECT_GT(seen, 100000u) << "most pixels should see a surfel";
  // No centre at all: every pixel empty, at infinity.
  IndexMap empty(40, 30);
  empty.reset(40, 30);
  Gathered ref(1200), simd(1200);
  gatherIndexRef(empty.grid(), 3.0f, 0, 30, ref.out());
  gatherIndexSimd(empty.grid(), 3.0f, 0, 30, simd.out());
  EXPECT_EQ(expectSameGather(ref, simd, "empty"), 0u);
  EXPECT_EQ(ref.depth[0], std::numeric_limits<float>::infinity());
}

// The reference against the rule as a brute force states it: every centre of
// the grid whose footprint (du^2 + dv^2 <= reach^2) holds the pixel, nearest
// first, then by row and column offset; a candidate with a positive inverse
// depth replaces the held one when nearer by more than the tolerance, or within
// it at the held one's distance with a lower slot.
TEST(IndexMapGather, TheReferenceIsTheBruteForce) {
  std::mt19937_64 rng(43);
  for (int rep = 0; rep < 12; ++rep) {
    const int w = 5 + static_cast<int>(rng() % 20), h = 3 + static_cast<int>(rng() % 12);
    const IndexMap map = randomCentres(w, h, rng);
    const CentreGrid g = map.grid();
    Gathered ref(static_cast<std::size_t>(w * h)), brute(static_cast<std::size_t>(w * h));
    gatherIndexRef(g, 3.0f, 0, h, ref.out());
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        struct Candidate {
          int rsq, dv, du;
          std::size_t k;
        };
        std::vector<Candidate> candidates;
        for (int cy = -kMaxReach; cy < h + kMaxReach; ++cy) {
          for (int cx = -kMaxReach; cx < w + kMaxReach; ++cx) {
            const std::size_t k = g.at(cx, cy);
            if (g.cell[k] == CentreGrid::kEmptyCell) continue;
            const int du = x - cx, dv = y - cy, reach = static_cast<int>(g.cell[k] >> 24);
            if (du * du + dv * dv <= reach * reach) candidates.push_back({du * du + dv * dv, dv, du, k});
          }
        }
        std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
          return std::tie(a.rsq, a.dv, a.du) < std::tie(b.rsq, b.dv, b.du);
        });
        float held = std::numeric_limits<float>::infinity();
        uint32_t slot = IndexMap::kNoSurfel;
        int held_rsq = -1;
        for (const Candidate& c : candidates) {
          const float iz = (g.inv_depth[c.k] + g.grad_u[c.k] * static_cast<float>(c.du)) +
                           g.grad_v[c.k] * static_cast<float>(c.dv);
          if (!(iz > 0.0f)) continue;
          const float z = 1.0f / iz, same = 3.0f * depthSigma(z);
          const uint32_t candidate = g.cell[c.k] & CentreGrid::kSlotBits;
          if (z < held - same || (z <= held + same && c.rsq == held_rsq && candidate < slot)) {
            held = z;
            slot = candidate;
            held_rsq = c.rsq;
          }
        }
        const std::size_t i = static_cast<std::size_t>(y * w + x);
        brute.slot[i] = slot;
        brute.depth[i] = held;
      }
    }
    expectSameGather(brute, ref, "brute force " + std::to_string(w) + "x" + std::to_string(h));
  }
}

// The centre's contest: the nearer surface wins; within the tolerance the
// lower rank (the map's: the more confident surfel), and of equal ranks the first offered.
TEST(IndexMapGather, TheNearerSurfaceAndThenTheLowerRankWinsTheCell) {
  IndexMap map(4, 4);
  map.reset(4, 4);
  auto centre = [](float z, uint8_t rank) {
    IndexMap::Centre c;
    c.depth = z;
    c.inv_depth = 1.0f / z;
    c.same = 0.01f;
    c.rank = rank;
    return c;
  };
  auto winner = [&map] {
    Gathered out(16);
    gatherIndexRef(map.grid(), 3.0f, 0, 4, out.out());
    return out.slot[5];  // pixel (1, 1)
  };
  map.offerCentre(1, 1, centre(2.0f, 100), 1);
  EXPECT_EQ(winner(), 1u);
  map.offerCentre(1, 1, centre(2.005f, 50), 2);  // one surface, the lower rank
  EXPECT_EQ(winner(), 2u);
  map.offerCentre(1, 1, centre(2.0f, 50), 3);  // the same rank: the first stays
  EXPECT_EQ(winner(), 2u);
  map.offerCentre(1, 1, centre(2.5f, 0), 4);  // behind: never
  EXPECT_EQ(winner(), 2u);
  map.offerCentre(1, 1, centre(1.5f, 200), 5);  // in front: always
  EXPECT_EQ(winner(), 5u);
}

// ---- the index map's first pass: the splat plans ----------------------------

// A random frame and bricks for the plans: a rotation, bricks in front of,
// beside and behind the camera (some culled), and per pixel depths that are
// missing, near and far, with their weights.
struct PlanScene {
  static constexpr int kBricks = 64;
  int w = 0, h = 0;
  std::vector<float> brick_cam = std::vector<float>(3 * kBricks);
  std::vector<uint32_t> visible = std::vector<uint32_t>(kBricks);
  std::vector<float> depth, weight;
  SplatFrame frame;

  PlanScene(const PlanScene&) = delete;  // the frame points into this scene's arrays
  PlanScene& operator=(const PlanScene&) = delete;
  PlanScene(int width, int height, std::mt19937_64& rng) : w(width), h(height) {
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    depth.resize(static_cast<std::size_t>(w) * h);
    weight.resize(depth.size());
    for (std::size_t i = 0; i < depth.size(); ++i) {
      depth[i] = rng() % 4 == 0 ? 0.0f : 0.3f + 4.0f * unit(rng);
      weight[i] = 2.0f * unit(rng);
    }
    for (int b = 0; b < kBricks; ++b) {
      brick_cam[3 * b] = 2.0f * unit(rng) - 1.0f;
      brick_cam[3 * b + 1] = 2.0f * unit(rng) - 1.0f;
      brick_cam[3 * b + 2] = 5.0f * unit(rng) - 0.5f;  // some behind the camera
      visible[b] = rng() % 5 != 0;
    }
    const Eigen::Matrix3f r =
        Eigen::AngleAxisf(unit(rng) * 6.0f, Eigen::Vector3f(unit(rng), unit(rng), unit(rng) + 0.1f).normalized())
            .toRotationMatrix();
    for (int i = 0; i < 9; ++i) frame.r[i] = r(i / 3, i % 3);
    frame.brick_cam = brick_cam.data();
    frame.brick_visible = visible.data();
    frame.measured_z = depth.data();
    frame.weight = weight.data();
    frame.w = w, frame.h = h;
    frame.fx = 0.8f * static_cast<float>(w), frame.fy = 0.75f * static_cast<float>(w);
    frame.cx = 0.5f * static_cast<float>(w) - 0.5f, frame.cy = 0.5f * static_cast<float>(h) + 0.25f;
    frame.inv_fx = 1.0f / frame.fx, frame.inv_fy = 1.0f / frame.fy;
    frame.f = 0.5f * (frame.fx + frame.fy);
    frame.min_z = 0.1f, frame.sigmas = 3.0f, frame.carve = 0.5f;
    frame.u_lo = -0.5f - kMaxReach, frame.u_hi = static_cast<float>(w) - 0.5f + kMaxReach;
    frame.v_lo = -0.5f - kMaxReach, frame.v_hi = static_cast<float>(h) - 0.5f + kMaxReach;
    frame.frame = 1000, frame.unstable_max = 30;
  }

  // A surfel of a random brick whose centre projects to pixel (u, v) at depth z
  // (the position is then rotated into the brick's frame).
  Surfel surfelAt(float u, float v, float z, uint16_t brick) const {
    const Eigen::Vector3f p((u - frame.cx) / frame.fx * z, (v - frame.cy) / frame.fy * z, z);
    const Eigen::Matrix3f r = Eigen::Map<const Eigen::Matrix<float, 3, 3, Eigen::RowMajor>>(frame.r);
    const Eigen::Vector3f local = r.transpose() * (p - Eigen::Vector3f::Map(brick_cam.data() + 3 * brick));
    Surfel s;
    s.x = local.x(), s.y = local.y(), s.z = local.z();
    s.brick = brick;
    return s;
  }
};

// Random surfels: live and dead, stable and not and of every age, centres in
// and around the frame (many at half-integer pixels and at the depth range's
// start), every normal and radius code, every confidence.
std::vector<Surfel> randomSurfels(const PlanScene& scene, std::size_t n, std::mt19937_64& rng) {
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  std::vector<Surfel> surfels(n);
  for (Surfel& s : surfels) {
    const auto brick = static_cast<uint16_t>(rng() % PlanScene::kBricks);
    float u = (unit(rng) * 1.2f - 0.1f) * static_cast<float>(scene.w);
    float v = (unit(rng) * 1.2f - 0.1f) * static_cast<float>(scene.h);
    if (rng() % 3 == 0) u = std::round(u) + 0.5f, v = std::round(v) - 0.5f;
    const float z = rng() % 8 == 0 ? scene.frame.min_z : rng() % 8 == 0 ? -1.0f : 0.2f + 4.5f * unit(rng);
    s = scene.surfelAt(u, v, z, brick);
    if (rng() % 10 == 0) s = Surfel{unit(rng), unit(rng), unit(rng)};  // anywhere in its brick
    s.brick = brick;
    s.normal_radius = static_cast<uint32_t>(rng());
    s.confidence = static_cast<uint16_t>(rng());
    s.flags = static_cast<uint8_t>(rng() % 8);
    s.first_seen = scene.frame.frame - static_cast<uint32_t>(rng() % 40) + (rng() % 20 == 0 ? 10u : 0u);
  }
  return surfels;
}

// Lane by lane the same action and, for what the action uses, the same bits.
int expectSamePlans(const SplatPlan& a, const SplatPlan& b, std::size_t count, const std::string& what) {
  int reported = 0, splats = 0;
  auto same = [](float x, float y) { return std::bit_cast<uint32_t>(x) == std::bit_cast<uint32_t>(y); };
  for (std::size_t j = 0; j < count; ++j) {
    bool ok = a.action[j] == b.action[j];
    if (ok && a.action[j] == SplatPlan::kCarve) ok = same(a.kept[j], b.kept[j]);
    if (ok && a.action[j] == SplatPlan::kSplat) {
      ++splats;
      ok = a.centre_u[j] == b.centre_u[j] && a.centre_v[j] == b.centre_v[j] && a.reach[j] == b.reach[j] &&
           a.rank[j] == b.rank[j] && same(a.depth[j], b.depth[j]) && same(a.same[j], b.same[j]) &&
           same(a.inv_depth[j], b.inv_depth[j]) && same(a.grad_u[j], b.grad_u[j]) && same(a.grad_v[j], b.grad_v[j]);
    }
    if (!ok && reported++ < 5) {
      ADD_FAILURE() << what << ": lane " << j << ": action " << a.action[j] << " against " << b.action[j]
                    << ", centre (" << a.centre_u[j] << ", " << a.centre_v[j] << ") against (" << b.centre_u[j]
                    << ", " << b.centre_v[j] << "), depth " << a.depth[j] << " against " << b.depth[j];
    }
  }
  return splats;
}

TEST_P(TargetTest, TheSplatPlansAreTheReference) {
  std::mt19937_64 rng(47);
  int splats = 0;
  uint64_t actions[4] = {};
  const int reps = test::repetitions(40, 10);
  for (int rep = 0; rep < reps; ++rep) {
    const int w = rep % 4 == 0 ? 640 : 3 + static_cast<int>(rng() % 90), h = rep % 4 == 0 ? 480 : 2 + static_cast<int>(rng() % 70);
    const PlanScene scene(w, h, rng);
    const std::vector<Surfel> surfels = randomSurfels(scene, SplatPlan::kSize, rng);
    for (std::size_t count : {SplatPlan::kSize, std::size_t{1}, std::size_t{1} + rng() % SplatPlan::kSize}) {
      SplatPlan ref{}, simd{};
      planSplatsRef(scene.frame, surfels.data(), count, ref);
      planSplatsSimd(scene.frame, surfels.data(), count, simd);
      splats += expectSamePlans(ref, simd, count, std::to_string(w) + "x" + std::to_string(h));
      for (std::size_t j = 0; j < count; ++j) ++actions[ref.action[j]];
    }
  }
  for (int a = 0; a < 4; ++a) EXPECT_GT(actions[a], 20u) << "action " << a << " should be among the random plans";
  EXPECT_GT(splats, 12 * reps);  // about 28 a repetition
}

// Adversarial surfels: non-finite and huge positions, a centre on the depth
// range's start and on the frame's edges, normals along and across the ray
// (every fold of the octahedral code), the largest radius.
TEST_P(TargetTest, TheSplatPlansOfAdversarialSurfelsAreTheReference) {
  std::mt19937_64 rng(53);
  PlanScene scene(64, 48, rng);
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  std::vector<Surfel> surfels;
  const float edges[] = {-2.5f, -2.49f, -0.5f, 0.0f, 0.49999997f, 0.5f, 31.5f, 63.5f, 64.5f, 65.49f, 65.5f};
  for (float u : edges) {
    for (float v : {-2.5f, 0.5f, 47.5f, 49.49f}) surfels.push_back(scene.surfelAt(u, v, rng() % 2 ? 0.1f : 1.3f, 0));
  }
  for (float x : {nan, inf, -inf, 1e30f, -1e30f, 0.0f}) {
    surfels.push_back(Surfel{x, 0.1f, 0.2f});
    surfels.push_back(Surfel{0.1f, x, 0.2f});
    surfels.push_back(Surfel{0.1f, 0.2f, x});
  }
  std::size_t live = surfels.size();
  for (uint32_t code : {0u, 0xfffu, 0xfff000u, 0xffffffu, 0x7ff7ffu, 0x800800u, 0x7ff000u, 0x000fffu}) {
    for (uint32_t radius : {0u, 128u, 255u}) {
      surfels.push_back(scene.surfelAt(20.0f, 30.0f, 0.5f + 0.01f * static_cast<float>(surfels.size()), 1));
      surfels.back().normal_radius = code << 8 | radius;
    }
  }
  for (std::size_t i = 0; i < surfels.size(); ++i) {
    if (i >= live) surfels[i].brick = 1;
    surfels[i].flags = kSurfelLive | kSurfelStable;
    surfels[i].confidence = static_cast<uint16_t>(rng());
  }
  scene.visible[0] = scene.visible[1] = 1;
  int splats = 0;
  for (std::size_t b0 = 0; b0 < surfels.size(); b0 += SplatPlan::kSize) {
    const std::size_t count = std::min(SplatPlan::kSize, surfels.size() - b0);
    SplatPlan ref{}, simd{};
    planSplatsRef(scene.frame, surfels.data() + b0, count, ref);
    planSplatsSimd(scene.frame, surfels.data() + b0, count, simd);
    splats += expectSamePlans(ref, simd, count, "adversarial");
  }
  EXPECT_GT(splats, 20);
}

// Runs of surfels the kernel may skip a vector at a time (none removed, none
// live in a visible brick: a map larger than the view), each run broken at one
// random place by a surfel that must not be skipped: live in a visible brick,
// or unstable and old in an invisible one (removed wherever it is), so that a
// vector with one such lane among skippable ones is planned lane by lane.
TEST_P(TargetTest, TheSplatPlansOfRunsOutOfViewAreTheReference) {
  std::mt19937_64 rng(59);
  PlanScene scene(96, 72, rng);
  scene.visible.assign(scene.visible.size(), 0);
  scene.visible[3] = 1;
  std::vector<Surfel> surfels = randomSurfels(scene, 8 * SplatPlan::kSize, rng);
  for (std::size_t i = 0; i < surfels.size(); ++i) {
    Surfel& s = surfels[i];
    s.brick = static_cast<uint16_t>(rng() % 3);  // invisible
    s.flags = i % 7 == 0 ? 0 : kSurfelLive | kSurfelStable;  // some dead
  }
  std::size_t broken_visible = 0, broken_removed = 0;
  for (std::size_t run = 0; run + 64 <= surfels.size(); run += 64) {
    const std::size_t at = run + rng() % 64;
    if (rng() % 3 == 0) continue;  // a run left whole
    if (rng() % 2 == 0) {
      surfels[at] = scene.surfelAt(40.0f, 30.0f, 1.5f, 3);
      surfels[at].flags = kSurfelLive | kSurfelStable;
      ++broken_visible;
    } else {
      surfels[at].flags = kSurfelLive;  // unstable
      surfels[at].first_seen = scene.frame.frame - scene.frame.unstable_max - 1;
      ++broken_removed;
    }
  }
  uint64_t actions[4] = {};
  for (std::size_t b0 = 0; b0 < surfels.size(); b0 += SplatPlan::kSize) {
    SplatPlan ref{}, simd{};
    planSplatsRef(scene.frame, surfels.data() + b0, SplatPlan::kSize, ref);
    planSplatsSimd(scene.frame, surfels.data() + b0, SplatPlan::kSize, simd);
    expectSamePlans(ref, simd, SplatPlan::kSize, "runs out of view");
    for (std::size_t j = 0; j < SplatPlan::kSize; ++j) ++actions[ref.action[j]];
  }
  EXPECT_GT(broken_visible + broken_removed, 4u);
  EXPECT_EQ(actions[SplatPlan::kRemoveUnstable], broken_removed);
  EXPECT_EQ(actions[SplatPlan::kSplat], broken_visible);
  EXPECT_EQ(actions[SplatPlan::kSkip], surfels.size() - broken_visible - broken_removed);
}

// ---- the association: its plans ---------------------------------------------

// A batch's pixels and the pool they name, for the association's plans
// (pipeline/map/association_plan.h): measurements missing and without a
// normal, slots none or into the pool (several pixels naming one surfel), the
// index map's depth clearly behind, exactly at either edge of, within and in
// front of the tolerance, every normal, radius, confidence and colour in the
// pool, pixel normals near the surfel's (so that many merge) or anywhere, and
// colour images or none (grey).
struct AssociationScene {
  static constexpr int kBricks = 16;
  static constexpr std::size_t kPool = 300;
  std::vector<float> brick_cam, weight, z, nx, ny, nz, radius, seen, ray_u, normal_cos;
  std::vector<uint32_t> slot;
  std::vector<uint8_t> rgb;
  std::vector<Surfel> surfels;
  AssociationFrame frame;

  AssociationScene(const AssociationScene&) = delete;  // the frame points into this scene's arrays
  AssociationScene& operator=(const AssociationScene&) = delete;
  AssociationScene(std::size_t pixels, std::mt19937_64& rng) {
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    const Eigen::Matrix3f r =
        Eigen::AngleAxisf(unit(rng) * 6.0f, Eigen::Vector3f(unit(rng), unit(rng) - 0.5f, unit(rng) + 0.1f).normalized())
            .toRotationMatrix();
    for (int i = 0; i < 9; ++i) frame.r[i] = r(i / 3, i % 3);
    frame.sigmas = 3.0f, frame.confidence_cap = 20.0f, frame.stable_confidence = 1.5f;
    for (int b = 0; b < 3 * kBricks; ++b) brick_cam.push_back(8.0f * unit(rng) - 4.0f);
    for (int b = 0; b < 64; ++b) normal_cos.push_back(0.05f + 0.85f * unit(rng));
    surfels.resize(kPool);
    for (Surfel& s : surfels) {
      s = Surfel{unit(rng) * 0.3f, unit(rng) * 0.3f, unit(rng) * 0.3f};
      s.normal_radius = static_cast<uint32_t>(rng());
      s.confidence = static_cast<uint16_t>(rng() % 4 == 0 ? rng() : rng() % 6000);
      s.brick = static_cast<uint16_t>(rng() % kBricks);
      s.flags = kSurfelLive;
      s.red = static_cast<uint8_t>(rng()), s.green = static_cast<uint8_t>(rng()), s.blue = static_cast<uint8_t>(rng());
    }
    surfels[1].confidence = 0;  // no confidence: the pixel's measurement alone
    for (std::size_t j = 0; j < pixels; ++j) addPixel(r, rng);
    frame.brick_cam = brick_cam.data();
    frame.slot = slot.data(), frame.seen = seen.data(), frame.weight = weight.data(), frame.z = z.data();
    frame.nx = nx.data(), frame.ny = ny.data(), frame.nz = nz.data(), frame.radius = radius.data();
    frame.ray_u = ray_u.data();
    frame.ray_v = unit(rng) - 0.5f;
    for (std::size_t k = 0; k < 3 * pixels; ++k) rgb.push_back(static_cast<uint8_t>(rng()));
    frame.rgb = rng() % 4 == 0 ? nullptr : rgb.data();  // a frame without colour: grey
    frame.normal_cos = normal_cos.data();
    frame.normal_cos_size = static_cast<uint32_t>(normal_cos.size());
    frame.normal_cos_z_min = 0.3f, frame.normal_cos_per_m = 64.0f / 4.2f;
  }

  void addPixel(const Eigen::Matrix3f& r, std::mt19937_64& rng) {
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    const uint64_t pick = rng();
    weight.push_back(pick % 9 == 0 ? 0.0f : pick % 11 == 0 ? 1.0f : 1.5f * unit(rng));
    const float depth = pick % 13 == 0 ? 0.3f : 0.3f + 5.0f * unit(rng);
    z.push_back(depth);
    const uint32_t s = pick % 7 == 0 ? IndexMap::kNoSurfel : static_cast<uint32_t>(rng() % (pick % 5 == 0 ? 4 : kPool));
    slot.push_back(s);
    Eigen::Vector3f n(unit(rng) - 0.5f, unit(rng) - 0.5f, unit(rng) - 0.5f);
    if (s != IndexMap::kNoSurfel && rng() % 3 != 0) {  // near the surfel's normal, seen from the camera
      n = r.transpose() * decodeNormal(surfels[s].normal_radius >> 8) + 0.2f * n;
    }
    if (pick % 10 == 0) n.setZero();                 // no normal: an edge
    if (pick % 17 == 0) n = Eigen::Vector3f(1e-30f, 0.0f, 0.0f);  // its square underflows: none either
    nx.push_back(n.x()), ny.push_back(n.y()), nz.push_back(n.z());
    const float radii[] = {kMinRadiusM, kMaxRadiusM, 0.0f, 0.5f};
    radius.push_back(pick % 19 == 0 ? radii[rng() % 4] : 1e-4f + 0.02f * unit(rng));
    const float tolerance = frame.sigmas * depthSigma(depth);
    const float offsets[] = {-1.5f * tolerance, -tolerance, tolerance, 2.0f * tolerance, 0.0f, 0.3f * tolerance};
    const uint64_t which = rng() % 8;
    seen.push_back(which < 6 ? (which == 1 ? depth - tolerance : which == 2 ? depth + tolerance : depth + offsets[which])
                             : which == 6 ? std::numeric_limits<float>::infinity() : 6.0f * unit(rng));
    ray_u.push_back(1.4f * unit(rng) - 0.7f);
  }
};

// Lane by lane the same kind and bits, and for a merge the same bits in every field.
int expectSamePlans(const AssociationPlan& a, const AssociationPlan& b, std::size_t count, const std::string& what) {
  int reported = 0, merges = 0;
  auto same = [](float x, float y) { return std::bit_cast<uint32_t>(x) == std::bit_cast<uint32_t>(y); };
  for (std::size_t j = 0; j < count; ++j) {
    bool ok = a.kind[j] == b.kind[j] && a.bits[j] == b.bits[j];
    if (ok && a.kind[j] != AssociationPlan::kNothing) ok = a.slot[j] == b.slot[j];
    if (ok && (a.bits[j] & AssociationPlan::kMerges)) {
      ++merges;
      ok = same(a.x[j], b.x[j]) && same(a.y[j], b.y[j]) && same(a.z[j], b.z[j]) && a.rgb[j] == b.rgb[j] &&
           a.normal_radius[j] == b.normal_radius[j] && a.confidence[j] == b.confidence[j];
    }
    if (!ok && reported++ < 5) {
      ADD_FAILURE() << what << ": pixel " << j << ": kind " << a.kind[j] << " against " << b.kind[j] << ", bits "
                    << a.bits[j] << " against " << b.bits[j] << ", normal and radius " << std::hex << a.normal_radius[j]
                    << " against " << b.normal_radius[j] << std::dec << ", confidence " << a.confidence[j]
                    << " against " << b.confidence[j] << ", x " << a.x[j] << " against " << b.x[j];
    }
  }
  return merges;
}

TEST_P(TargetTest, TheAssociationPlansAreTheReference) {
  std::mt19937_64 rng(61);
  int merges = 0;
  uint64_t kinds[5] = {}, stable = 0;
  const int reps = test::repetitions(60, 15);
  for (int rep = 0; rep < reps; ++rep) {
    const AssociationScene scene(AssociationPlan::kSize, rng);
    for (std::size_t count : {AssociationPlan::kSize, std::size_t{1}, std::size_t{1} + rng() % AssociationPlan::kSize}) {
      AssociationPlan ref{}, simd{};
      planAssociationRef(scene.frame, scene.surfels.data(), count, ref);
      planAssociationSimd(scene.frame, scene.surfels.data(), count, simd);
      merges += expectSamePlans(ref, simd, count, "batch of " + std::to_string(count));
      for (std::size_t j = 0; j < count; ++j) {
        ++kinds[ref.kind[j]];
        if (ref.bits[j] & AssociationPlan::kStable) ++stable;
      }
    }
  }
  for (int k = 0; k < 5; ++k) EXPECT_GT(kinds[k], 20u * static_cast<unsigned>(reps) / 15) << "kind " << k;
  EXPECT_GT(merges, 10 * reps);
  EXPECT_GT(stable, static_cast<uint64_t>(reps));
}

// A pixel replanned at its turn (planMergeRef) from a surfel an earlier pixel
// changed: the same lane as a whole batch's plan against that surfel.
TEST(AssociationPlan, APixelPlannedAgainIsItsBatchsLane) {
  std::mt19937_64 rng(67);
  AssociationScene scene(AssociationPlan::kSize, rng);
  AssociationPlan batch{};
  planAssociationRef(scene.frame, scene.surfels.data(), AssociationPlan::kSize, batch);
  int checked = 0;
  for (std::size_t j = 0; j < AssociationPlan::kSize; ++j) {
    if (batch.kind[j] != AssociationPlan::kAtDepth || !(batch.bits[j] & AssociationPlan::kHasNormal)) continue;
    AssociationPlan again = batch;
    again.bits[j] |= AssociationPlan::kMerges | AssociationPlan::kStable;  // cleared or set anew
    planMergeRef(scene.frame, scene.surfels[batch.slot[j]], j, again);
    expectSamePlans(batch, again, AssociationPlan::kSize, "pixel " + std::to_string(j));
    ++checked;
  }
  EXPECT_GT(checked, 10);
}

// ---- whole maps --------------------------------------------------------------

::testing::AssertionResult sameMap(const SurfelMap& a, const SurfelMap& b) {
  if (a.size() != b.size() || a.slotCount() != b.slotCount() || a.brickCount() != b.brickCount()) {
    return ::testing::AssertionFailure() << "surfels " << a.size() << " vs " << b.size() << ", slots "
                                         << a.slotCount() << " vs " << b.slotCount() << ", bricks "
                                         << a.brickCount() << " vs " << b.brickCount();
  }
  for (std::size_t slot = 0; slot < a.slotCount(); ++slot) {
    if (std::memcmp(&a.surfel(slot), &b.surfel(slot), sizeof(Surfel)) != 0) {
      return ::testing::AssertionFailure() << "slot " << slot << " differs: position " << a.worldPosition(slot).transpose()
                                           << " vs " << b.worldPosition(slot).transpose();
    }
  }
  for (std::size_t brick = 0; brick < a.brickCount(); ++brick) {
    if (a.brickOrigin(static_cast<uint16_t>(brick)) != b.brickOrigin(static_cast<uint16_t>(brick))) {
      return ::testing::AssertionFailure() << "brick " << brick << " differs";
    }
  }
  return ::testing::AssertionSuccess();
}

// The mock camera's living room (orbit) and balloon scenes, fused with either kernel
// set: the same surfels in the same slots, bit for bit, and the same statistics.
TEST_P(TargetTest, MapsFusedWithEitherKernelSetAreTheSame) {
  for (const char* spec : {"mock:living-room,path=orbit,size=160x120", "mock:balloon,size=96x72"}) {
    auto camera = hal::createCamera(spec);
    ASSERT_TRUE(camera.isOk()) << camera.status().toString();
    hal::Camera& cam = *camera.value();
    ASSERT_TRUE(cam.open().isOk());
    ASSERT_TRUE(cam.start().isOk());
    const hal::CameraIntrinsics& k = cam.info().intrinsics;
    SurfelMapConfig config;
    config.max_width = k.width;
    config.max_height = k.height;
    config.max_surfels = static_cast<std::size_t>(k.width) * k.height;  // eviction too
    config.kernels = KernelSet::kRef;
    SurfelMap ref = SurfelMap::create(config).value();
    config.kernels = KernelSet::kSimd;
    SurfelMap simd = SurfelMap::create(config).value();
    hal::RgbdFrame frame(k.width, k.height);
    uint64_t merged = 0;
    const int frames = test::repetitions(12, 6);  // six where a frame costs ten times as much (sanitizers, qemu)
    for (int i = 0; i < frames; ++i) {
      ASSERT_TRUE(cam.acquire(frame, test::scaled(std::chrono::seconds(5))).isOk());
      FuseStats sr, ss;
      ASSERT_EQ(ref.fuse(frame, sr), FuseOutcome::kFused) << spec << " frame " << i;
      ASSERT_EQ(simd.fuse(frame, ss), FuseOutcome::kFused) << spec << " frame " << i;
      EXPECT_EQ(sr.pixels_valid, ss.pixels_valid) << spec << " frame " << i;
      EXPECT_EQ(sr.merged, ss.merged);
      EXPECT_EQ(sr.added, ss.added);
      EXPECT_EQ(sr.carved, ss.carved);
      EXPECT_EQ(sr.evicted, ss.evicted);
      ASSERT_TRUE(sameMap(ref, simd)) << spec << " frame " << i;
      merged += sr.merged;
    }
    EXPECT_GT(ref.size(), 0u) << spec;
    EXPECT_GT(merged, 0u) << spec;
    cam.stop();
  }
}

// A random view, frame and pose for the explained view's judgement
// (pipeline/map/view_judge.h): depths with holes, out of range and at the
// extremes; the view's raw depths near the frame's (so that both codes occur);
// a pose that turns and moves a little.
struct JudgeCase {
  std::vector<uint16_t> depth, view_raw;
  hal::RgbdFrame frame;
  ViewJudgeParams params;
  JudgeCase(int w, int h, int vw, int vh, std::mt19937_64& rng) : frame(w, h) {
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    frame.intrinsics = {w, h, 0.8 * w, 0.8 * w, 0.5 * w - 0.5, 0.5 * h - 0.5};
    frame.depth_scale_m = 0.001;
    depth.resize(static_cast<std::size_t>(w) * h);
    for (uint16_t& d : depth) {
      const uint64_t r = rng();
      d = r % 11 == 0 ? 0 : r % 13 == 0 ? 65535 : r % 17 == 0 ? 50 : static_cast<uint16_t>(800 + (r >> 20) % 2500);
    }
    view_raw.assign(static_cast<std::size_t>(vw) * vh + 1, 0);
    for (std::size_t i = 0; i + 1 < view_raw.size(); ++i) {
      const uint64_t r = rng();
      view_raw[i] = r % 7 == 0 ? 0 : static_cast<uint16_t>(800 + (r >> 20) % 2500);
    }
    DepthRange range;
    range.min_m = 0.3;
    range.max_m = 6.0;
    params.rule = PixelBackprojection(frame, range);
    params.rule.r = Eigen::AngleAxisf(0.3f * unit(rng), Eigen::Vector3f(unit(rng), unit(rng), 1.0f).normalized())
                        .toRotationMatrix();
    params.into.R = Eigen::AngleAxisf(0.2f * unit(rng), Eigen::Vector3f(1.0f, unit(rng), unit(rng)).normalized())
                        .toRotationMatrix();
    params.into.t = Eigen::Vector3f(0.1f * unit(rng), 0.1f * unit(rng), 0.05f * unit(rng));
    params.view = {view_raw.data(), vw, vh, 0.8f * vw, 0.8f * vw, 0.5f * vw - 0.5f, 0.5f * vh - 0.5f, 0.001f, 4.24f};
    params.depth = depth.data();
    params.width = w;
  }
};

// Both kernels on every row: the same code for every pixel. Returns the
// explained ones.
std::size_t expectSameJudgement(const JudgeCase& c, int h, const std::string& what) {
  std::vector<uint8_t> ref(static_cast<std::size_t>(c.params.width)), simd(ref.size());
  std::size_t explained = 0;
  for (int v = 0; v < h; ++v) {
    std::fill(simd.begin(), simd.end(), uint8_t{0xee});
    judgeRowRef(c.params, v, ref.data());
    judgeRowSimd(c.params, v, simd.data());
    for (std::size_t u = 0; u < ref.size(); ++u) {
      EXPECT_EQ(ref[u], simd[u]) << what << " pixel (" << u << ", " << v << ")";
      if (ref[u] != simd[u]) return explained;
      explained += ref[u] == kJudgedExplained ? 1 : 0;
    }
  }
  return explained;
}

TEST_P(TargetTest, TheViewsJudgementIsTheReference) {
  std::mt19937_64 rng(47);
  const int sizes[][4] = {{640, 480, 640, 480}, {1, 1, 1, 1}, {3, 5, 3, 5}, {17, 9, 17, 9}, {33, 7, 20, 9},
                          {64, 4, 64, 4},       {65, 6, 129, 5}, {100, 30, 40, 20}};
  std::size_t explained = 0;
  for (const auto& s : sizes) {
    JudgeCase c(s[0], s[1], s[2], s[3], rng);
    explained += expectSameJudgement(c, s[1], std::to_string(s[0]) + "x" + std::to_string(s[1]));
  }
  EXPECT_GT(explained, 1000u) << "the cases should explain some pixels";
  // Points landing on half pixels: the view is the frame's, moved half a pixel
  // across and down, neither turned nor moved (lround takes the halves up).
  JudgeCase halves(160, 120, 160, 120, rng);
  halves.params.rule.r.setIdentity();
  halves.params.into = {};
  halves.params.view.cx = static_cast<float>(halves.frame.intrinsics.cx) + 0.5f;
  halves.params.view.cy = static_cast<float>(halves.frame.intrinsics.cy) + 0.5f;
  halves.params.view.fx = static_cast<float>(halves.frame.intrinsics.fx);
  halves.params.view.fy = static_cast<float>(halves.frame.intrinsics.fy);
  expectSameJudgement(halves, 120, "halves");
  // Behind the view's camera and an empty view: nothing is explained.
  JudgeCase behind(70, 10, 70, 10, rng);
  behind.params.into.R = -Eigen::Matrix3f::Identity();
  EXPECT_EQ(expectSameJudgement(behind, 10, "behind"), 0u);
  JudgeCase empty(70, 10, 70, 10, rng);
  empty.params.view.width = empty.params.view.height = 0;
  EXPECT_EQ(expectSameJudgement(empty, 10, "empty view"), 0u);
}

INSTANTIATE_TEST_SUITE_P(Targets, TargetTest, ::testing::ValuesIn(simdTargetsHere()), test::simdTargetName);

}  // namespace
}  // namespace fovea::pipeline::map

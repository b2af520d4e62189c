// DepthToColourRegistration against an independent computation written here in
// double precision with Eigen (its own back-projection, transform, plumb-bob
// distortion and rounding). Colour images carry each pixel's index in its RGB
// bytes (plus one, so black is "no colour"), so an output pixel says exactly
// which colour pixel it came from.
#include "hal/camera/registration/registration.h"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "tests/support/alloc_counter.h"

namespace fovea::hal {
namespace {

constexpr double kBoundaryPx = 1e-3;  // closer than this to a rounding boundary: either pixel is right

hal::StreamCalibration camera(int w, int h, double fx, double fy, double cx, double cy) {
  hal::StreamCalibration c;
  c.intrinsics = {w, h, fx, fy, cx, cy};
  return c;
}

// A colour image whose pixel i holds i + 1 (24 bits).
std::vector<uint8_t> codedColour(int w, int h) {
  std::vector<uint8_t> rgb(static_cast<std::size_t>(w) * h * 3);
  for (std::size_t i = 0; i < rgb.size() / 3; ++i) {
    const auto code = static_cast<uint32_t>(i + 1);
    rgb[3 * i] = static_cast<uint8_t>(code);
    rgb[3 * i + 1] = static_cast<uint8_t>(code >> 8);
    rgb[3 * i + 2] = static_cast<uint8_t>(code >> 16);
  }
  return rgb;
}

// The colour pixel index an output pixel came from, or -1 for black.
int64_t decode(const uint8_t* px) {
  const uint32_t code = px[0] | (uint32_t{px[1]} << 8) | (uint32_t{px[2]} << 16);
  return static_cast<int64_t>(code) - 1;
}

// What the double computation says about one depth pixel.
struct Expected {
  int64_t index = -1;      // colour pixel, -1 for black
  bool ambiguous = false;  // within kBoundaryPx of a rounding boundary (or Z within 1e-9 m of 0)
};

Expected expectedPixel(const RegistrationParams& p, int u, int v, uint16_t raw) {
  Expected e;
  if (raw == 0) return e;
  const hal::CameraIntrinsics& d = p.depth.intrinsics;
  const hal::CameraIntrinsics& c = p.colour.intrinsics;
  const double z = raw * p.depth_scale_m;
  const Eigen::Vector3d p_depth((u - d.cx) * z / d.fx, (v - d.cy) * z / d.fy, z);
  const Eigen::Vector3d p_colour = p.T_colour_depth.R_world_cam * p_depth + p.T_colour_depth.t_world_cam;
  if (std::abs(p_colour.z()) < 1e-9) e.ambiguous = true;
  if (!(p_colour.z() > 0.0)) return e;
  double x = p_colour.x() / p_colour.z();
  double y = p_colour.y() / p_colour.z();
  if (p.colour.distortion.model == hal::Distortion::Model::kPlumbBob) {
    // OpenCV's formula, written out.
    const auto& k = p.colour.distortion.coeffs;
    const double k1 = k[0], k2 = k[1], p1 = k[2], p2 = k[3], k3 = k[4];
    const double r2 = x * x + y * y;
    const double radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
    const double xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
    const double yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
    x = xd;
    y = yd;
  }
  const double pu = c.fx * x + c.cx;
  const double pv = c.fy * y + c.cy;
  // Pixel k covers [k - 0.5, k + 0.5): boundaries at half-integers.
  auto nearBoundary = [](double q) { return std::abs(q + 0.5 - std::round(q + 0.5)) < kBoundaryPx; };
  if (nearBoundary(pu) || nearBoundary(pv)) e.ambiguous = true;
  const double iu = std::floor(pu + 0.5);
  const double iv = std::floor(pv + 0.5);
  if (iu >= 0 && iu < c.width && iv >= 0 && iv < c.height) {
    e.index = static_cast<int64_t>(iv) * c.width + static_cast<int64_t>(iu);
  }
  return e;
}

struct Comparison {
  std::size_t mismatches = 0;
  std::size_t ambiguous = 0;
  std::size_t coloured = 0;
  std::string first;
};

Comparison compareWithDouble(const RegistrationParams& p, const std::vector<uint16_t>& depth,
                             const std::vector<uint8_t>& out, const RegistrationCounts& counts) {
  Comparison r;
  const int w = p.depth.intrinsics.width;
  std::size_t with_depth = 0, coloured = 0;
  for (std::size_t i = 0; i < depth.size(); ++i) {
    const int u = static_cast<int>(i % w), v = static_cast<int>(i / w);
    const Expected e = expectedPixel(p, u, v, depth[i]);
    const int64_t got = decode(&out[3 * i]);
    with_depth += depth[i] != 0;
    coloured += got >= 0;
    if (e.ambiguous) {
      ++r.ambiguous;
      continue;
    }
    if (got != e.index) {
      if (r.mismatches++ == 0) {
        r.first = "pixel (" + std::to_string(u) + ", " + std::to_string(v) + ") depth " + std::to_string(depth[i]) +
                  ": got colour pixel " + std::to_string(got) + ", double says " + std::to_string(e.index);
      }
    }
  }
  r.coloured = coloured;
  EXPECT_EQ(counts.with_depth, with_depth);
  EXPECT_EQ(counts.coloured, coloured);
  EXPECT_EQ(counts.with_depth, counts.coloured + counts.outside_colour);
  return r;
}

std::vector<uint16_t> randomDepth(int w, int h, std::mt19937_64& rng, int lo_mm, int hi_mm) {
  std::vector<uint16_t> depth(static_cast<std::size_t>(w) * h);
  std::uniform_int_distribution<int> mm(lo_mm, hi_mm);
  for (auto& d : depth) d = (rng() % 9 == 0) ? 0 : static_cast<uint16_t>(mm(rng));
  return depth;
}

Eigen::Matrix3d smallRotation(std::mt19937_64& rng, double max_deg) {
  std::uniform_real_distribution<double> angle(-max_deg, max_deg);
  const double k = std::numbers::pi / 180.0;
  return (Eigen::AngleAxisd(angle(rng) * k, Eigen::Vector3d::UnitX()) *
          Eigen::AngleAxisd(angle(rng) * k, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(angle(rng) * k, Eigen::Vector3d::UnitZ()))
      .toRotationMatrix();
}

// Runs both kernel sets and checks each against the double computation.
void expectMatchesDouble(const RegistrationParams& p, const std::vector<uint16_t>& depth, const char* what,
                         std::size_t* ambiguous_total = nullptr) {
  Result<DepthToColourRegistration> reg = DepthToColourRegistration::create(p);
  ASSERT_TRUE(reg) << reg.status().toString();
  const std::vector<uint8_t> colour = codedColour(p.colour.intrinsics.width, p.colour.intrinsics.height);
  for (KernelSet ks : {KernelSet::kRef, KernelSet::kSimd}) {
    std::vector<uint8_t> out(depth.size() * 3, 0xEE);
    const RegistrationCounts counts = reg->apply(depth.data(), colour.data(), out.data(), ks);
    const Comparison c = compareWithDouble(p, depth, out, counts);
    EXPECT_EQ(c.mismatches, 0u) << what << " (" << kernelSetName(ks) << "): " << c.first;
    // Rare: a boundary within 1e-3 px is hit by about 2e-3 of the pixels per axis.
    EXPECT_LT(c.ambiguous, depth.size() / 100) << what;
    EXPECT_GT(c.coloured, depth.size() / 4) << what << ": the scene should mostly land in the colour image";
    if (ambiguous_total != nullptr && ks == KernelSet::kRef) *ambiguous_total += c.ambiguous;
  }
}

TEST(Registration, MatchesADoublePrecisionComputation) {
  std::mt19937_64 rng(7);
  std::size_t ambiguous = 0, pixels = 0;
  struct Sizes {
    int dw, dh, cw, ch;
  };
  // depth 640x480 -> colour 1280x720 (D435-like), colour smaller than depth, equal sizes.
  for (const Sizes s : {Sizes{640, 480, 1280, 720}, Sizes{640, 480, 320, 240}, Sizes{320, 240, 320, 240},
                        Sizes{97, 61, 203, 131}}) {
    for (int rep = 0; rep < 4; ++rep) {
      RegistrationParams p;
      std::uniform_real_distribution<double> jitter(-5.0, 5.0);
      p.depth = camera(s.dw, s.dh, 0.9 * s.dw + jitter(rng), 0.9 * s.dw + jitter(rng), s.dw / 2.0 + jitter(rng),
                       s.dh / 2.0 + jitter(rng));
      p.colour = camera(s.cw, s.ch, 0.95 * s.cw + jitter(rng), 0.95 * s.cw + jitter(rng), s.cw / 2.0 + jitter(rng),
                        s.ch / 2.0 + jitter(rng));
      if (rep % 2 == 1) {
        p.colour.distortion.model = hal::Distortion::Model::kPlumbBob;
        p.colour.distortion.coeffs = {-0.3 + 0.1 * rep / 4.0, 0.12, 1e-3, -8e-4, -0.02};
      }
      p.T_colour_depth.R_world_cam = smallRotation(rng, 3.0);
      p.T_colour_depth.t_world_cam = Eigen::Vector3d(0.015 * (rep + 1), -0.004, 0.002);
      p.depth_scale_m = (rep == 2) ? 1.0 / 5000.0 : 0.001;
      const std::vector<uint16_t> depth = randomDepth(s.dw, s.dh, rng, 300, rep == 2 ? 40000 : 8000);
      const std::string what = std::to_string(s.dw) + "x" + std::to_string(s.dh) + " -> " + std::to_string(s.cw) +
                               "x" + std::to_string(s.ch) + " rep " + std::to_string(rep);
      expectMatchesDouble(p, depth, what.c_str(), &ambiguous);
      pixels += depth.size();
    }
  }
  std::printf("pixels within %.0e px of a rounding boundary (not compared): %zu of %zu\n", kBoundaryPx, ambiguous,
              pixels);
  EXPECT_GT(ambiguous, 0u) << "the boundary rule is never exercised: the test would not notice a half-pixel shift";
}

TEST(Registration, IdentityWithEqualIntrinsicsCopiesTheColourImage) {
  RegistrationParams p;
  p.depth = camera(641, 479, 525.0, 525.0, 319.5, 239.5);
  p.colour = p.depth;
  DepthToColourRegistration reg = DepthToColourRegistration::create(p).value();
  std::mt19937_64 rng(3);
  const std::vector<uint16_t> depth = randomDepth(641, 479, rng, 1, 65535);
  std::vector<uint8_t> colour(depth.size() * 3);
  for (auto& c : colour) c = static_cast<uint8_t>(rng());
  for (KernelSet ks : {KernelSet::kRef, KernelSet::kSimd}) {
    std::vector<uint8_t> out(colour.size(), 0x55);
    const RegistrationCounts counts = reg.apply(depth.data(), colour.data(), out.data(), ks);
    std::size_t with_depth = 0;
    for (std::size_t i = 0; i < depth.size(); ++i) {
      for (int ch = 0; ch < 3; ++ch) {
        const uint8_t want = depth[i] != 0 ? colour[3 * i + ch] : 0;
        ASSERT_EQ(out[3 * i + ch], want) << kernelSetName(ks) << " pixel " << i << " depth " << depth[i];
      }
      with_depth += depth[i] != 0;
    }
    EXPECT_EQ(counts.with_depth, with_depth);
    EXPECT_EQ(counts.coloured, with_depth);
    EXPECT_EQ(counts.outside_colour, 0u);
  }
}

// A baseline b along x on a plane at depth z shifts the image by fx * b / z pixels.
TEST(Registration, ATranslationShiftsByTheDisparity) {
  const int w = 160, h = 90;
  struct Case {
    double baseline_m, z_m;
    int expected_shift_px;
  };
  // fx = 200: 0.05 m at 0.5 m is 20 px; 0.0101 m at 1 m is 2.02 px -> 2; -0.0174 at 0.4 is -8.7 -> -9.
  for (const Case c : {Case{0.05, 0.5, 20}, Case{0.0101, 1.0, 2}, Case{-0.0174, 0.4, -9}, Case{0.0, 3.0, 0}}) {
    RegistrationParams p;
    p.depth = camera(w, h, 200.0, 200.0, 80.0, 45.0);
    p.colour = p.depth;
    p.T_colour_depth.t_world_cam = Eigen::Vector3d(c.baseline_m, 0.0, 0.0);
    DepthToColourRegistration reg = DepthToColourRegistration::create(p).value();
    const std::vector<uint16_t> depth(static_cast<std::size_t>(w) * h, static_cast<uint16_t>(c.z_m * 1000.0 + 0.5));
    const std::vector<uint8_t> colour = codedColour(w, h);
    for (KernelSet ks : {KernelSet::kRef, KernelSet::kSimd}) {
      std::vector<uint8_t> out(depth.size() * 3);
      const RegistrationCounts counts = reg.apply(depth.data(), colour.data(), out.data(), ks);
      std::size_t outside = 0;
      for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
          const int cu = u + c.expected_shift_px;
          const int64_t want = (cu >= 0 && cu < w) ? int64_t{v} * w + cu : -1;
          outside += want < 0;
          ASSERT_EQ(decode(&out[3 * (static_cast<std::size_t>(v) * w + u)]), want)
              << kernelSetName(ks) << " baseline " << c.baseline_m << " at (" << u << ", " << v << ")";
        }
      }
      EXPECT_EQ(counts.outside_colour, outside);
      EXPECT_EQ(outside, static_cast<std::size_t>(std::abs(c.expected_shift_px)) * h);
    }
  }
}

TEST(Registration, DepthAndColourAtDifferentResolutions) {
  // The same optical centre and field of view, colour at twice the resolution
  // (1280x960): depth pixel (u, v) lands on colour pixel near (2u + 0.5, 2v + 0.5),
  // which rounds up to (2u + 1, 2v + 1).
  RegistrationParams p;
  p.depth = camera(640, 480, 500.0, 500.0, 319.5, 239.5);
  p.colour = camera(1280, 960, 1000.0, 1000.0, 639.5, 479.5);
  const std::vector<uint16_t> depth(640 * 480, 1500);
  const std::vector<uint8_t> colour = codedColour(1280, 960);
  DepthToColourRegistration reg = DepthToColourRegistration::create(p).value();
  // Colour pixel centres are at 2u + 0.5 exactly: the rounding boundary. Shift a
  // quarter pixel so the answer is clear: cx + 0.25.
  p.colour.intrinsics.cx += 0.25;
  p.colour.intrinsics.cy += 0.25;
  reg = DepthToColourRegistration::create(p).value();
  for (KernelSet ks : {KernelSet::kRef, KernelSet::kSimd}) {
    std::vector<uint8_t> out(depth.size() * 3);
    const RegistrationCounts counts = reg.apply(depth.data(), colour.data(), out.data(), ks);
    EXPECT_EQ(counts.coloured, depth.size());
    for (int v = 0; v < 480; v += 7) {
      for (int u = 0; u < 640; u += 5) {
        ASSERT_EQ(decode(&out[3 * (static_cast<std::size_t>(v) * 640 + u)]), int64_t{2 * v + 1} * 1280 + (2 * u + 1))
            << kernelSetName(ks) << " (" << u << ", " << v << ")";
      }
    }
  }
  // Colour smaller (and narrower in view) than depth: the edges fall outside.
  p.colour = camera(320, 240, 400.0, 400.0, 159.5, 119.5);
  reg = DepthToColourRegistration::create(p).value();
  const std::vector<uint8_t> small = codedColour(320, 240);
  std::vector<uint8_t> ref(depth.size() * 3), simd(depth.size() * 3);
  const RegistrationCounts cr = reg.registerRef(depth.data(), small.data(), ref.data());
  const RegistrationCounts cs = reg.registerSimd(depth.data(), small.data(), simd.data());
  EXPECT_EQ(ref, simd);
  EXPECT_EQ(cr.coloured, cs.coloured);
  // Depth u maps to colour (u - 319.5) * 0.8 + 159.5: colour 0..319 covers depth u
  // with |u - 319.5| * 0.8 < 160: u in 120..519 (400 columns); rows likewise 300.
  EXPECT_EQ(cr.coloured, 400u * 300u);
  EXPECT_EQ(cr.outside_colour, depth.size() - 400u * 300u);
  EXPECT_EQ(decode(&ref[3 * (240 * 640 + 320)]), 120 * 320 + 160);
}

TEST(Registration, PointsBehindTheColourCameraAreBlackAndCounted) {
  // The colour camera looks back at the depth camera (180 degrees about y, 1 m
  // ahead): points nearer than 1 m are in front of it, farther ones behind it.
  RegistrationParams p;
  p.depth = camera(64, 48, 50.0, 50.0, 31.5, 23.5);
  p.colour = p.depth;
  p.T_colour_depth.R_world_cam = Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitY()).toRotationMatrix();
  p.T_colour_depth.t_world_cam = Eigen::Vector3d(0.0, 0.0, 1.0);
  DepthToColourRegistration reg = DepthToColourRegistration::create(p).value();
  std::vector<uint16_t> depth(64 * 48);
  for (std::size_t i = 0; i < depth.size(); ++i) depth[i] = (i % 2 == 0) ? 500 : 1500;  // 0.5 m / 1.5 m
  depth[0] = 1000;  // exactly at the colour camera: Z = 0 is behind too
  const std::vector<uint8_t> colour = codedColour(64, 48);
  for (KernelSet ks : {KernelSet::kRef, KernelSet::kSimd}) {
    std::vector<uint8_t> out(depth.size() * 3, 0x77);
    const RegistrationCounts counts = reg.apply(depth.data(), colour.data(), out.data(), ks);
    EXPECT_EQ(counts.with_depth, depth.size());
    std::size_t behind = 0;
    for (std::size_t i = 0; i < depth.size(); ++i) {
      if (depth[i] >= 1000) {
        ++behind;
        EXPECT_EQ(decode(&out[3 * i]), -1) << kernelSetName(ks) << " pixel " << i;
      }
    }
    EXPECT_EQ(behind, depth.size() / 2 + 1);
    EXPECT_GE(counts.outside_colour, behind);
    const Comparison c = compareWithDouble(p, depth, out, counts);
    EXPECT_EQ(c.mismatches, 0u) << c.first;
  }
}

TEST(Registration, NoDepthIsBlackAndNotCountedAsAMeasurement) {
  RegistrationParams p;
  p.depth = camera(33, 7, 30.0, 30.0, 16.0, 3.0);
  p.colour = p.depth;
  DepthToColourRegistration reg = DepthToColourRegistration::create(p).value();
  std::vector<uint16_t> depth(33 * 7, 0);
  depth[5] = 1000;
  const std::vector<uint8_t> colour(33 * 7 * 3, 0xFF);
  for (KernelSet ks : {KernelSet::kRef, KernelSet::kSimd}) {
    std::vector<uint8_t> out(depth.size() * 3, 0x99);
    const RegistrationCounts counts = reg.apply(depth.data(), colour.data(), out.data(), ks);
    EXPECT_EQ(counts.with_depth, 1u);
    EXPECT_EQ(counts.coloured, 1u);
    EXPECT_EQ(counts.outside_colour, 0u);
    for (std::size_t i = 0; i < depth.size(); ++i) {
      const uint8_t want = i == 5 ? 0xFF : 0;
      EXPECT_EQ(out[3 * i], want);
      EXPECT_EQ(out[3 * i + 1], want);
      EXPECT_EQ(out[3 * i + 2], want);
    }
  }
}

// Every bad field is refused with a message that names it.
TEST(Registration, ValidationNamesTheField) {
  const RegistrationParams good = [] {
    RegistrationParams p;
    p.depth = camera(640, 480, 570.0, 570.0, 320.0, 240.0);
    p.colour = camera(1280, 720, 910.0, 910.0, 640.0, 360.0);
    p.T_colour_depth.t_world_cam = Eigen::Vector3d(0.015, 0.0, 0.0);
    return p;
  }();
  ASSERT_TRUE(DepthToColourRegistration::create(good));
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  constexpr double kInf = std::numeric_limits<double>::infinity();
  struct Bad {
    const char* field;
    void (*spoil)(RegistrationParams&);
  };
  const Bad cases[] = {
      {"depth.width", [](RegistrationParams& p) { p.depth.intrinsics.width = 0; }},
      {"depth.height", [](RegistrationParams& p) { p.depth.intrinsics.height = -4; }},
      {"colour.width", [](RegistrationParams& p) { p.colour.intrinsics.width = 100000; }},
      {"colour.height", [](RegistrationParams& p) { p.colour.intrinsics.height = 0; }},
      {"depth.fx", [](RegistrationParams& p) { p.depth.intrinsics.fx = 0.0; }},
      {"depth.fy", [](RegistrationParams& p) { p.depth.intrinsics.fy = kNaN; }},
      {"colour.fx", [](RegistrationParams& p) { p.colour.intrinsics.fx = -910.0; }},
      {"colour.fy", [](RegistrationParams& p) { p.colour.intrinsics.fy = kInf; }},
      {"colour.fx", [](RegistrationParams& p) { p.colour.intrinsics.fx = 1e300; }},  // finite, not as float
      {"colour.cx", [](RegistrationParams& p) { p.colour.intrinsics.cx = kNaN; }},
      {"depth.cy", [](RegistrationParams& p) { p.depth.intrinsics.cy = -kInf; }},
      {"colour.distortion.k1",
       [](RegistrationParams& p) {
         p.colour.distortion.model = hal::Distortion::Model::kPlumbBob;
         p.colour.distortion.coeffs[0] = kNaN;
       }},
      {"colour.distortion.k3",
       [](RegistrationParams& p) {
         p.colour.distortion.model = hal::Distortion::Model::kPlumbBob;
         p.colour.distortion.coeffs[4] = kInf;
       }},
      {"colour.distortion.p2", [](RegistrationParams& p) { p.colour.distortion.coeffs[3] = kNaN; }},
      {"depth.distortion",
       [](RegistrationParams& p) {
         p.depth.distortion.model = hal::Distortion::Model::kPlumbBob;
         p.depth.distortion.coeffs[0] = 0.1;
       }},
      {"T_colour_depth.R", [](RegistrationParams& p) { p.T_colour_depth.R_world_cam(0, 0) = 1.001; }},
      {"T_colour_depth.R", [](RegistrationParams& p) { p.T_colour_depth.R_world_cam(2, 2) = -1.0; }},  // reflection
      {"T_colour_depth.R", [](RegistrationParams& p) { p.T_colour_depth.R_world_cam(1, 0) = kNaN; }},
      {"T_colour_depth.R", [](RegistrationParams& p) { p.T_colour_depth.R_world_cam *= 2.0; }},
      {"T_colour_depth.t", [](RegistrationParams& p) { p.T_colour_depth.t_world_cam.y() = kInf; }},
      {"T_colour_depth.t", [](RegistrationParams& p) { p.T_colour_depth.t_world_cam.z() = kNaN; }},
      {"depth_scale_m", [](RegistrationParams& p) { p.depth_scale_m = 0.0; }},
      {"depth_scale_m", [](RegistrationParams& p) { p.depth_scale_m = -0.001; }},
      {"depth_scale_m", [](RegistrationParams& p) { p.depth_scale_m = kNaN; }},
      {"depth_scale_m", [](RegistrationParams& p) { p.depth_scale_m = 1e-50; }},  // zero as float
  };
  for (const Bad& bad : cases) {
    RegistrationParams p = good;
    bad.spoil(p);
    Result<DepthToColourRegistration> r = DepthToColourRegistration::create(p);
    ASSERT_FALSE(r) << bad.field;
    EXPECT_EQ(r.status().code(), ErrorCode::kInvalidArgument) << bad.field;
    EXPECT_NE(r.status().message().find(std::string("registration: ") + bad.field), std::string::npos)
        << "wanted '" << bad.field << "' in: " << r.status().message();
  }
  // A rotation within 1e-6 of orthonormal is accepted (a calibration file's digits).
  RegistrationParams near = good;
  near.T_colour_depth.R_world_cam = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  near.T_colour_depth.R_world_cam(0, 1) += 4e-7;
  EXPECT_TRUE(DepthToColourRegistration::create(near));
}

TEST(Registration, CallsDoNotAllocate) {
  RegistrationParams p;
  p.depth = camera(640, 480, 570.0, 570.0, 320.0, 240.0);
  p.colour = camera(1280, 720, 910.0, 910.0, 640.0, 360.0);
  p.colour.distortion.model = hal::Distortion::Model::kPlumbBob;
  p.colour.distortion.coeffs = {0.1, -0.2, 0.001, 0.001, 0.05};
  p.T_colour_depth.t_world_cam = Eigen::Vector3d(0.015, 0.0, 0.0);
  const DepthToColourRegistration reg = DepthToColourRegistration::create(p).value();
  std::mt19937_64 rng(5);
  const std::vector<uint16_t> depth = randomDepth(640, 480, rng, 200, 9000);
  const std::vector<uint8_t> colour = codedColour(1280, 720);
  std::vector<uint8_t> out(depth.size() * 3);
  (void)reg.registerSimd(depth.data(), colour.data(), out.data());  // Highway picks its target on the first call
  test::AllocationScope scope;
  RegistrationCounts c1 = reg.registerRef(depth.data(), colour.data(), out.data());
  RegistrationCounts c2 = reg.registerSimd(depth.data(), colour.data(), out.data());
  RegistrationCounts c3 = reg.apply(depth.data(), colour.data(), out.data());
  EXPECT_EQ(scope.allocations(), 0u);
  EXPECT_EQ(c1.coloured, c2.coloured);
  EXPECT_EQ(c1.coloured, c3.coloured);
  EXPECT_GT(c1.coloured, 0u);
}

TEST(Registration, CopiesKeepTheirOwnTables) {
  RegistrationParams p;
  p.depth = camera(20, 10, 20.0, 20.0, 10.0, 5.0);
  p.colour = p.depth;
  auto original = std::make_unique<DepthToColourRegistration>(DepthToColourRegistration::create(p).value());
  const DepthToColourRegistration copy = *original;
  original.reset();  // the copy must not read the original's tables
  const std::vector<uint16_t> depth(200, 1000);
  const std::vector<uint8_t> colour = codedColour(20, 10);
  std::vector<uint8_t> out(600);
  EXPECT_EQ(copy.registerSimd(depth.data(), colour.data(), out.data()).coloured, 200u);
  EXPECT_EQ(decode(&out[3 * 57]), 57);
}

}  // namespace
}  // namespace fovea::hal

#include "pipeline/pyramid_sampler.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "pipeline/acuity_levels.h"

namespace fovea::pipeline {

PyramidRule PyramidRule::fromAcuity(const AcuityConfig& config) {
  PyramidRule rule;
  rule.slope = static_cast<float>(config.slope);
  rule.margin = static_cast<float>(config.level_margin);
  rule.floor_m = static_cast<float>(config.floor_m);
  rule.floor_per_m2 = static_cast<float>(config.floor_per_m2);
  return rule;
}

Status PyramidRule::validate() const {
  const auto finite_non_negative = [](float v) { return std::isfinite(v) && v >= 0.0f; };
  if (!finite_non_negative(slope)) return {ErrorCode::kInvalidArgument, "pyramid: slope must be finite and >= 0"};
  if (!(std::isfinite(margin) && margin > 0.0f)) {
    return {ErrorCode::kInvalidArgument, "pyramid: margin must be finite and > 0"};
  }
  if (!finite_non_negative(floor_m) || !finite_non_negative(floor_per_m2)) {
    return {ErrorCode::kInvalidArgument, "pyramid: floors must be finite and >= 0"};
  }
  return Status::ok();
}

Result<PyramidSampler> PyramidSampler::create(int max_width, int max_height, int levels, KernelSet kernels) {
  if (max_width < 1 || max_height < 1 || max_width > 16384 || max_height > 16384) {
    return Status{ErrorCode::kInvalidArgument, "pyramid: frame size must be within 1..16384"};
  }
  if (levels < 1 || levels > kMaxPyramidLevels) {
    return Status{ErrorCode::kInvalidArgument,
                  "pyramid: levels must be within 1.." + std::to_string(kMaxPyramidLevels)};
  }
  return PyramidSampler(max_width, max_height, levels, kernels);
}

void PyramidSampler::Level::resize(std::size_t cells) {
  for (std::vector<float>* a : {&n, &sx, &sy, &sz, &m2, &zmax, &merge}) a->assign(cells, 0.0f);
}

PyramidSampler::PyramidSampler(int max_width, int max_height, int levels, KernelSet kernels)
    : max_width_(max_width),
      max_height_(max_height),
      levels_(levels),
      kernels_(kernels),
      pyramid_(static_cast<std::size_t>(levels)) {
  for (int k = 1; k <= levels; ++k) {
    const int w = (max_width + (1 << k) - 1) >> k;
    const int h = (max_height + (1 << k) - 1) >> k;
    pyramid_[static_cast<std::size_t>(k - 1)].resize(static_cast<std::size_t>(w + 1) * (h + 1));  // + padding
  }
  const std::size_t first_cells = pyramid_[0].n.size();
  for (std::vector<float>* a : {&pyramid_[0].cr, &pyramid_[0].cg, &pyramid_[0].cb}) a->assign(first_cells, 0.0f);
  candidates_.resize(first_cells);
  parents_.resize(first_cells);
  for (std::vector<float>& g : gathered_) g.resize(first_cells);
  verdict_.resize(first_cells);
  // Rows padded to an even width: the odd column's partner is an invalid pixel.
  const auto padded = static_cast<std::size_t>(max_width + 1);
  for (int r = 0; r < 2; ++r) {
    for (std::vector<float>* a : {&row_x_[r], &row_z_[r], &row_valid_[r]}) a->assign(padded, 0.0f);
  }
  column_xn_.assign(padded, 0.0f);
}

namespace {

// The colour sums (sr, sg, sb) of row j of level 1's cells (PyramidSampler::
// buildFirstLevel), from a w x h colour image, over the valid pixels of each 2 x 2
// square (va, vb: the validity of pixel rows 2j and 2j + 1), exact in float (at most
// 4 x 255), for the emitted cells' means. Byte loads, so a loop of its own; row b
// past the image reads row a's bytes with no valid pixel to count.
inline void sumFirstLevelColours(const uint8_t* rgb, int w, int h, int j, int cells, const float* __restrict va,
                                 const float* __restrict vb, float* __restrict sr, float* __restrict sg,
                                 float* __restrict sb) {
  const uint8_t* ca = rgb + 3 * static_cast<std::size_t>(2 * j) * w;
  const uint8_t* cb = 2 * j + 1 < h ? ca + 3 * static_cast<std::size_t>(w) : ca;
  const int pairs = w / 2;  // cells with both columns in the image
  for (int i = 0; i < pairs; ++i) {
    const int u = 2 * i;
    const uint8_t* pa = ca + 3 * u;
    const uint8_t* pb = cb + 3 * u;
    sr[i] = (va[u] * pa[0] + va[u + 1] * pa[3]) + (vb[u] * pb[0] + vb[u + 1] * pb[3]);
    sg[i] = (va[u] * pa[1] + va[u + 1] * pa[4]) + (vb[u] * pb[1] + vb[u + 1] * pb[4]);
    sb[i] = (va[u] * pa[2] + va[u + 1] * pa[5]) + (vb[u] * pb[2] + vb[u + 1] * pb[5]);
  }
  if (pairs < cells) {  // an odd width: the last cell has one column
    const int u = 2 * pairs;
    const uint8_t* pa = ca + 3 * u;
    const uint8_t* pb = cb + 3 * u;
    sr[pairs] = va[u] * pa[0] + vb[u] * pb[0];
    sg[pairs] = va[u] * pa[1] + vb[u] * pb[1];
    sb[pairs] = va[u] * pa[2] + vb[u] * pb[2];
  }
}

}  // namespace

// Level 1 straight from the depth image, two rows at a time: per row a loop over
// pixels (x, z and validity, 0 when invalid), then one over cells adding each 2 x 2
// square; both are plain loops over arrays that the compiler vectorises. y is summed
// as yn * z per row (y = yn z for every pixel of row v). m2 comes from the square's
// own mean (one division a cell), and the colour sums of level 1 (not above it: an
// emitted cell adds up its level-1 cells, Walk::meanColour).
void PyramidSampler::buildFirstLevel(const hal::RgbdFrame& frame, const RawDepthRange& raw) {
  const int w = frame.width();
  const int h = frame.height();
  Level& level = pyramid_[0];
  level.setSize((w + 1) / 2, (h + 1) / 2);
  const hal::CameraIntrinsics& k = frame.intrinsics;
  const auto scale = static_cast<float>(frame.depth_scale_m);
  const auto cx = static_cast<float>(k.cx);
  const auto cy = static_cast<float>(k.cy);
  const auto inv_fx = static_cast<float>(1.0 / k.fx);
  const auto inv_fy = static_cast<float>(1.0 / k.fy);
  float* __restrict xn = column_xn_.data();
  for (int u = 0; u < w; ++u) xn[u] = (static_cast<float>(u) - cx) * inv_fx;
  const auto raw_min = static_cast<uint32_t>(std::clamp<int64_t>(raw.min, 0, 65536));
  const auto raw_max = static_cast<uint32_t>(std::clamp<int64_t>(raw.max, -1, 65535) + 1);  // exclusive
  // Rows 2j (a) and 2j + 1 (b; all invalid past the image), padded to an even width
  // with an invalid pixel.
  const auto fill = [&](int v, float* __restrict x, float* __restrict z, float* __restrict valid) {
    x[w] = z[w] = valid[w] = 0.0f;
    if (v >= h) {
      std::fill(x, x + w, 0.0f), std::fill(z, z + w, 0.0f), std::fill(valid, valid + w, 0.0f);
      return;
    }
    const uint16_t* __restrict drow = frame.depth() + static_cast<std::size_t>(v) * w;
    for (int u = 0; u < w; ++u) {
      const uint32_t d = drow[u];
      const float ok = (d >= raw_min && d < raw_max) ? 1.0f : 0.0f;
      const float zu = static_cast<float>(d) * scale * ok;
      z[u] = zu;
      x[u] = xn[u] * zu;
      valid[u] = ok;
    }
  };
  float* __restrict xa = row_x_[0].data();
  float* __restrict za = row_z_[0].data();
  float* __restrict va = row_valid_[0].data();
  float* __restrict xb = row_x_[1].data();
  float* __restrict zb = row_z_[1].data();
  float* __restrict vb = row_valid_[1].data();
  const int cells = level.width;
  for (int j = 0; j < level.height; ++j) {
    fill(2 * j, xa, za, va);
    fill(2 * j + 1, xb, zb, vb);
    const float yna = (static_cast<float>(2 * j) - cy) * inv_fy;
    const float ynb = (static_cast<float>(2 * j + 1) - cy) * inv_fy;
    const std::size_t row0 = static_cast<std::size_t>(j) * level.stride;
    float* __restrict n = level.n.data() + row0;
    float* __restrict sx = level.sx.data() + row0;
    float* __restrict sy = level.sy.data() + row0;
    float* __restrict sz = level.sz.data() + row0;
    float* __restrict m2 = level.m2.data() + row0;
    float* __restrict zmax = level.zmax.data() + row0;
    for (int i = 0; i < cells; ++i) {
      const int u = 2 * i;
      const float a0 = za[u], a1 = za[u + 1], b0 = zb[u], b1 = zb[u + 1];
      const float count = (va[u] + va[u + 1]) + (vb[u] + vb[u + 1]);
      const float zs_a = a0 + a1, zs_b = b0 + b1;
      const float zs = zs_a + zs_b;
      const float mean = zs / std::max(count, 1.0f);
      const float d0 = a0 - mean, d1 = a1 - mean, d2 = b0 - mean, d3 = b1 - mean;
      n[i] = count;
      sx[i] = (xa[u] + xa[u + 1]) + (xb[u] + xb[u + 1]);
      sy[i] = yna * zs_a + ynb * zs_b;
      sz[i] = zs;
      m2[i] = (va[u] * (d0 * d0) + va[u + 1] * (d1 * d1)) + (vb[u] * (d2 * d2) + vb[u + 1] * (d3 * d3));
      zmax[i] = std::max(std::max(a0, a1), std::max(b0, b1));
    }
    if (frame.has_rgb) {
      sumFirstLevelColours(frame.rgb(), w, h, j, cells, va, vb, level.cr.data() + row0, level.cg.data() + row0,
                           level.cb.data() + row0);
    }
  }
  level.clearPadding();
}

// Level k (>= 2) from the 2 x 2 cells below it (the level below is padded to even
// sizes with empty cells, so every cell has four). m2 by the pairwise update:
// the children's m2 plus each child's n (mean_child - mean)^2.
void PyramidSampler::buildLevel(int k) {
  const Level& below = pyramid_[static_cast<std::size_t>(k - 2)];
  Level& level = pyramid_[static_cast<std::size_t>(k - 1)];
  level.setSize((below.width + 1) / 2, (below.height + 1) / 2);
  const std::size_t bs = below.stride;
  for (int j = 0; j < level.height; ++j) {
    const std::size_t c0 = static_cast<std::size_t>(2 * j) * bs;  // row 2j of the level below
    const std::size_t c1 = c0 + bs;
    const std::size_t row0 = static_cast<std::size_t>(j) * level.stride;
    for (int i = 0; i < level.width; ++i) {
      const std::size_t c[4] = {c0 + 2 * i, c0 + 2 * i + 1, c1 + 2 * i, c1 + 2 * i + 1};
      float count = 0.0f, sx = 0.0f, sy = 0.0f, sz = 0.0f, m2 = 0.0f, zmax = 0.0f;
      for (const std::size_t q : c) {
        count += below.n[q];
        sx += below.sx[q], sy += below.sy[q], sz += below.sz[q];
        m2 += below.m2[q];
        zmax = std::max(zmax, below.zmax[q]);
      }
      const float mean = sz / std::max(count, 1.0f);
      for (const std::size_t q : c) {
        const float d = below.sz[q] / std::max(below.n[q], 1.0f) - mean;
        m2 += below.n[q] * (d * d);
      }
      const std::size_t at = row0 + i;
      level.n[at] = count, level.sx[at] = sx, level.sy[at] = sy, level.sz[at] = sz, level.m2[at] = m2;
      level.zmax[at] = zmax;
    }
  }
  level.clearPadding();
}

void PyramidSampler::Level::setSize(int w, int h) {
  width = w;
  height = h;
  stride = (w + 1) & ~1;
  rows = (h + 1) & ~1;
}

// The empty cells that pad the level to even sizes (a frame of another size may
// have left sums there).
void PyramidSampler::Level::clearPadding() {
  for (std::vector<float>* a : {&n, &sx, &sy, &sz, &m2, &zmax}) {
    float* v = a->data();
    for (int j = 0; j < height; ++j) {
      for (int i = width; i < stride; ++i) v[static_cast<std::size_t>(j) * stride + i] = 0.0f;
    }
    for (int j = height; j < rows; ++j) {
      std::fill(v + static_cast<std::size_t>(j) * stride, v + static_cast<std::size_t>(j + 1) * stride, 0.0f);
    }
  }
}

std::size_t PyramidSampler::memoryBytes() const {
  std::size_t bytes = (candidates_.size() + parents_.size()) * sizeof(uint32_t) + verdict_.size() * sizeof(float);
  for (const std::vector<float>& g : gathered_) bytes += g.size() * sizeof(float);
  for (int r = 0; r < 2; ++r) bytes += 3 * row_x_[r].size() * sizeof(float);
  bytes += column_xn_.size() * sizeof(float);
  for (const Level& level : pyramid_) {
    bytes += (7 * level.n.size() + level.cr.size() + level.cg.size() + level.cb.size()) * sizeof(float);
  }
  return bytes;
}

void pyramidMergeRef(const kernels::PyramidMergeParams& p, const kernels::PyramidCellSums& c, std::size_t count,
                     float* merge) {
  const Eigen::Vector3f l(p.eye.l[0], p.eye.l[1], p.eye.l[2]);
  for (std::size_t i = 0; i < count; ++i) {
    const float inv_n = 1.0f / c.n[i];
    const float mx = c.sx[i] * inv_n, my = c.sy[i] * inv_n, mz = c.sz[i] * inv_n;
    const float variance = c.m2[i] * inv_n;
    const float e = std::max(p.lateral * c.zmax[i], 2.0f * std::sqrt(variance));
    const float diagonal = kernels::kPyramidSqrt3 * e;
    bool floor_merge = false;
    if (p.floors) {
      const float s2 = (mx * mx + my * my) + mz * mz;
      floor_merge = e <= p.floor_m + p.floor_per_m2 * s2;
    }
    const float vx = ((p.r[0] * mx + p.r[1] * my) + p.r[2] * mz) + p.eye.origin_minus_eye[0];
    const float vy = ((p.r[3] * mx + p.r[4] * my) + p.r[5] * mz) + p.eye.origin_minus_eye[1];
    const float vz = ((p.r[6] * mx + p.r[7] * my) + p.r[8] * mz) + p.eye.origin_minus_eye[2];
    const EyeView view = eyeViewSpec(vx, vy, vz, l, 0.0f);
    const float r_min = view.r_m - diagonal;
    const float spread = (diagonal / r_min) * kLevelsRadToDeg;
    float ecc = (view.ecc_deg - spread) - p.growth_deg;
    ecc = ecc < 0.0f ? 0.0f : ecc;
    const float allowed = p.eye.bounds.allowedM(r_min, ecc);
    const bool eye_merge = view.r_m > 2.0f * diagonal && p.margin * e <= allowed;
    merge[i] = floor_merge || eye_merge ? 1.0f : 0.0f;
  }
}

void PyramidSampler::decide(const hal::RgbdFrame& frame, const Gaze& gaze, const PyramidRule& rule,
                            PyramidStats& stats) {
  kernels::PyramidMergeParams p;
  const Eigen::Vector3d o = frame.T_world_cam.t_world_cam - gaze.origin_m;  // large parts cancel in double
  const Eigen::Vector3d l = gaze.direction.normalized();
  for (int a = 0; a < 3; ++a) {
    p.eye.origin_minus_eye[a] = static_cast<float>(o[a]);
    p.eye.l[a] = static_cast<float>(l[a]);
    for (int b = 0; b < 3; ++b) p.r[3 * a + b] = static_cast<float>(frame.T_world_cam.R_world_cam(a, b));
  }
  p.eye.bounds.slope = rule.slope;
  p.growth_deg = static_cast<float>(gaze.fovea_growth_deg);
  p.margin = rule.margin;
  p.floors = rule.floor_m > 0.0f || rule.floor_per_m2 > 0.0f;
  p.floor_m = rule.floor_m;
  p.floor_per_m2 = rule.floor_per_m2;
  const float inv_f = std::max(static_cast<float>(1.0 / frame.intrinsics.fx),
                               static_cast<float>(1.0 / frame.intrinsics.fy));
  std::size_t parents = 0;
  for (int k = levels_; k >= 1; --k) {
    Level& level = pyramid_[static_cast<std::size_t>(k - 1)];
    std::size_t count = 0;
    if (k == levels_) {
      for (int j = 0; j < level.height; ++j) {
        for (int i = 0; i < level.width; ++i) {
          const std::size_t at = static_cast<std::size_t>(j) * level.stride + i;
          if (level.n[at] != 0.0f) candidates_[count++] = static_cast<uint32_t>(at);
        }
      }
    } else {
      const Level& above = pyramid_[static_cast<std::size_t>(k)];
      for (std::size_t q = 0; q < parents; ++q) {
        const uint32_t at = parents_[q];
        if (above.merge[at] != 0.0f) continue;
        const uint32_t i = at % static_cast<uint32_t>(above.stride);
        const uint32_t j = at / static_cast<uint32_t>(above.stride);
        // Four children each (padding cells are empty).
        const uint32_t first = 2 * j * static_cast<uint32_t>(level.stride) + 2 * i;
        for (const uint32_t child : {first, first + 1, first + static_cast<uint32_t>(level.stride),
                                     first + static_cast<uint32_t>(level.stride) + 1}) {
          if (level.n[child] != 0.0f) candidates_[count++] = child;
        }
      }
    }
    const std::vector<float>* sums[6] = {&level.n, &level.sx, &level.sy, &level.sz, &level.m2, &level.zmax};
    for (int a = 0; a < 6; ++a) {
      const float* from = sums[a]->data();
      float* to = gathered_[a].data();
      for (std::size_t q = 0; q < count; ++q) to[q] = from[candidates_[q]];
    }
    p.lateral = static_cast<float>(1 << k) * inv_f;
    const kernels::PyramidCellSums cells{gathered_[0].data(), gathered_[1].data(), gathered_[2].data(),
                                         gathered_[3].data(), gathered_[4].data(), gathered_[5].data()};
    if (kernels_ == KernelSet::kSimd) {
      kernels::pyramidMergeSimd(p, cells, count, verdict_.data());
    } else {
      pyramidMergeRef(p, cells, count, verdict_.data());
    }
    for (std::size_t q = 0; q < count; ++q) level.merge[candidates_[q]] = verdict_[q];
    stats.cells_tested += static_cast<uint32_t>(count);
    std::swap(candidates_, parents_);
    parents = count;
  }
}

struct PyramidSampler::Walk {
  const hal::RgbdFrame* frame = nullptr;
  uint32_t raw_min = 0, raw_max = 0;  // raw_max exclusive
  float scale = 0.0f, cx = 0.0f, cy = 0.0f, inv_fx = 0.0f, inv_fy = 0.0f;
  float r[9] = {};  // R_world_cam
  FoveatedCloud* out = nullptr;
  std::size_t n = 0;
  std::size_t capacity = 0;  // of out
  bool full = false;         // a point did not fit: the walk stops
  PyramidStats* stats = nullptr;
  uint32_t* representative = nullptr;  // by pixel, or null

  // The rounded mean colour of the valid pixels of the 2^k square at cell (i, j),
  // from level 1's colour sums (`first`); with `representative`, those pixels get
  // output point `index`.
  uint32_t meanColour(const Level& first, int k, int i, int j, float count, uint32_t index) const {
    if (representative != nullptr) {
      const int w = frame->width();
      for (int v = j << k; v < std::min((j + 1) << k, frame->height()); ++v) {
        for (int u = i << k; u < std::min((i + 1) << k, w); ++u) {
          const std::size_t p = static_cast<std::size_t>(v) * w + u;
          const uint32_t d = frame->depth()[p];
          if (d >= raw_min && d < raw_max) representative[p] = index;
        }
      }
    }
    if (!frame->has_rgb) return 0u;
    const int shift = k - 1;
    const int i0 = i << shift, i1 = std::min((i + 1) << shift, first.width);
    const int j0 = j << shift, j1 = std::min((j + 1) << shift, first.height);
    float r = 0.0f, g = 0.0f, b = 0.0f;  // exact: below 4^7 x 255 < 2^24
    for (int cj = j0; cj < j1; ++cj) {
      const std::size_t row = static_cast<std::size_t>(cj) * first.stride;
      for (int ci = i0; ci < i1; ++ci) {
        r += first.cr[row + ci], g += first.cg[row + ci], b += first.cb[row + ci];
      }
    }
    const auto n = static_cast<uint32_t>(count);
    const auto mean = [n](float sum) { return static_cast<uint8_t>((static_cast<uint32_t>(sum) + n / 2) / n); };
    return packRgb(mean(r), mean(g), mean(b));
  }

  void emit(float cxm, float cym, float czm, uint32_t rgb, uint8_t level, uint32_t weight) {
    if (n == capacity) {
      full = true;
      return;
    }
    PointCloud& pc = out->points;
    pc.x()[n] = (r[0] * cxm + r[1] * cym) + r[2] * czm;
    pc.y()[n] = (r[3] * cxm + r[4] * cym) + r[5] * czm;
    pc.z()[n] = (r[6] * cxm + r[7] * cym) + r[8] * czm;
    pc.rgb()[n] = rgb;
    out->region[n] = level;
    if (out->hasWeights()) out->weight[n] = weight;
    ++n;
    ++stats->out_by_level[level];
  }
};

void PyramidSampler::visit(Walk& walk, int k, int i, int j) const {
  if (walk.full) return;
  if (k == 0) {
    const hal::RgbdFrame& f = *walk.frame;
    if (i >= f.width() || j >= f.height()) return;
    const std::size_t p = static_cast<std::size_t>(j) * f.width() + i;
    const uint32_t d = f.depth()[p];
    if (d < walk.raw_min || d >= walk.raw_max) return;
    // backprojectRef's expressions.
    const float z = static_cast<float>(d) * walk.scale;
    const float x = ((static_cast<float>(i) - walk.cx) * walk.inv_fx) * z;
    const float y = ((static_cast<float>(j) - walk.cy) * walk.inv_fy) * z;
    const uint8_t* c = f.rgb() + 3 * p;
    walk.emit(x, y, z, f.has_rgb ? packRgb(c[0], c[1], c[2]) : 0u, 0, 1);
    if (walk.representative != nullptr && !walk.full) walk.representative[p] = static_cast<uint32_t>(walk.n - 1);
    return;
  }
  const Level& level = pyramid_[static_cast<std::size_t>(k - 1)];
  if (i >= level.width || j >= level.height) return;
  const std::size_t at = static_cast<std::size_t>(j) * level.stride + i;
  const float count = level.n[at];
  if (count == 0.0f) return;
  if (level.merge[at] != 0.0f) {
    const float inv_n = 1.0f / count;
    const float mx = level.sx[at] * inv_n, my = level.sy[at] * inv_n, mz = level.sz[at] * inv_n;
    const uint32_t rgb = walk.meanColour(pyramid_[0], k, i, j, count, static_cast<uint32_t>(walk.n));
    walk.emit(mx, my, mz, rgb, static_cast<uint8_t>(k), static_cast<uint32_t>(count));
    return;
  }
  visit(walk, k - 1, 2 * i, 2 * j);
  visit(walk, k - 1, 2 * i + 1, 2 * j);
  visit(walk, k - 1, 2 * i, 2 * j + 1);
  visit(walk, k - 1, 2 * i + 1, 2 * j + 1);
}

Status PyramidSampler::sample(const hal::RgbdFrame& frame, const DepthRange& range, const Gaze& gaze,
                              const PyramidRule& rule, FoveatedCloud& out, PyramidStats& stats,
                              uint32_t* representative_by_pixel) {
  stats = {};
  out.points.clear();
  if (Status s = validateFrame(frame); !s) return s;
  if (Status s = range.validate(); !s) return s;
  if (Status s = rule.validate(); !s) return s;
  if (frame.width() > max_width_ || frame.height() > max_height_) {
    return {ErrorCode::kCapacityExceeded, "pyramid: frame " + std::to_string(frame.width()) + "x" +
                                              std::to_string(frame.height()) + " is larger than the sampler's " +
                                              std::to_string(max_width_) + "x" + std::to_string(max_height_)};
  }
  if (out.region.size() < out.points.capacity() || (out.hasWeights() && out.weight.size() < out.points.capacity())) {
    return {ErrorCode::kInvalidArgument, "pyramid: the output's region and weight arrays are shorter than its points"};
  }
  if (!gaze.origin_m.allFinite() || !gaze.direction.allFinite() || !std::isfinite(gaze.fovea_growth_deg)) {
    return {ErrorCode::kInvalidInput, "pyramid: gaze is not finite"};
  }
  const RawDepthRange raw = rawDepthRange(range, frame.depth_scale_m);
  buildFirstLevel(frame, raw);
  for (int k = 2; k <= levels_; ++k) buildLevel(k);

  Walk walk;
  walk.frame = &frame;
  walk.raw_min = static_cast<uint32_t>(std::clamp<int64_t>(raw.min, 0, 65536));
  walk.raw_max = static_cast<uint32_t>(std::clamp<int64_t>(raw.max, -1, 65535) + 1);
  const hal::CameraIntrinsics& k = frame.intrinsics;
  walk.scale = static_cast<float>(frame.depth_scale_m);
  walk.cx = static_cast<float>(k.cx);
  walk.cy = static_cast<float>(k.cy);
  walk.inv_fx = static_cast<float>(1.0 / k.fx);
  walk.inv_fy = static_cast<float>(1.0 / k.fy);
  const Eigen::Matrix3d& rot = frame.T_world_cam.R_world_cam;
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) walk.r[3 * a + b] = static_cast<float>(rot(a, b));
  }
  walk.out = &out;
  walk.capacity = out.points.capacity();
  walk.stats = &stats;
  walk.representative = representative_by_pixel;
  if (representative_by_pixel != nullptr) {
    std::fill(representative_by_pixel, representative_by_pixel + frame.pixelCount(), kNoRepresentative);
  }
  decide(frame, gaze, rule, stats);

  const Level& top = pyramid_[static_cast<std::size_t>(levels_ - 1)];
  uint32_t valid = 0;
  for (int j = 0; j < top.height; ++j) {
    for (int i = 0; i < top.width; ++i) {
      valid += static_cast<uint32_t>(top.n[static_cast<std::size_t>(j) * top.stride + i]);
      visit(walk, levels_, i, j);
    }
  }
  if (walk.full) {
    out.points.clear();
    return {ErrorCode::kCapacityExceeded, "pyramid: the frame needs more than the output's " +
                                              std::to_string(walk.capacity) + " points"};
  }
  out.points.origin_m = frame.T_world_cam.t_world_cam;
  out.points.has_color = frame.has_rgb;
  (void)out.points.resize(walk.n);  // walk.n <= capacity
  stats.points_in = valid;
  stats.points_out = static_cast<uint32_t>(walk.n);
  return Status::ok();
}

}  // namespace fovea::pipeline

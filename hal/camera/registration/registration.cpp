#include "hal/camera/registration/registration.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include <Eigen/Core>
#include <Eigen/LU>

namespace fovea::hal {

namespace {

// Room after the last pixel so a vector load of the tables never leaves them
// (the widest Highway vector holds 64 floats: SVE at 2048 bits).
constexpr std::size_t kTablePadding = 64;
// Image sides: float holds every pixel coordinate exactly, and an RGB index fits int32.
constexpr int kMaxSide = 16384;

Status invalid(const std::string& field, const std::string& what) {
  return {ErrorCode::kInvalidArgument, "registration: " + field + " " + what};
}

std::string number(double v) {
  char text[64];
  std::snprintf(text, sizeof text, "%.17g", v);
  return text;
}

// Finite, and finite once rounded to float (the kernels compute in float).
bool finiteAsFloat(double v) { return std::isfinite(v) && std::isfinite(static_cast<float>(v)); }

Status validateCamera(const std::string& name, const hal::StreamCalibration& cal) {
  const hal::CameraIntrinsics& k = cal.intrinsics;
  if (k.width <= 0 || k.width > kMaxSide) {
    return invalid(name + ".width", "must be 1.." + std::to_string(kMaxSide) + " pixels, got " +
                                        std::to_string(k.width) + ": check the calibration's image size");
  }
  if (k.height <= 0 || k.height > kMaxSide) {
    return invalid(name + ".height", "must be 1.." + std::to_string(kMaxSide) + " pixels, got " +
                                         std::to_string(k.height) + ": check the calibration's image size");
  }
  if (!(finiteAsFloat(k.fx) && k.fx > 0.0)) {
    return invalid(name + ".fx", "must be a finite focal length > 0 (pixels), got " + number(k.fx));
  }
  if (!(finiteAsFloat(k.fy) && k.fy > 0.0)) {
    return invalid(name + ".fy", "must be a finite focal length > 0 (pixels), got " + number(k.fy));
  }
  if (!finiteAsFloat(k.cx)) return invalid(name + ".cx", "must be finite, got " + number(k.cx));
  if (!finiteAsFloat(k.cy)) return invalid(name + ".cy", "must be finite, got " + number(k.cy));
  static const char* const kCoeffNames[5] = {"k1", "k2", "p1", "p2", "k3"};
  for (int i = 0; i < 5; ++i) {
    const double c = cal.distortion.coeffs[static_cast<std::size_t>(i)];
    if (!finiteAsFloat(c)) {
      return invalid(name + ".distortion." + kCoeffNames[i], "must be finite, got " + number(c));
    }
  }
  return Status::ok();
}

Status validate(const RegistrationParams& p) {
  if (Status s = validateCamera("depth", p.depth); !s) return s;
  if (!p.depth.distortion.isIdentity()) {
    return invalid("depth.distortion", "must be none: depth images are taken as undistorted (the device rectifies "
                                       "them); remove the depth distortion coefficients");
  }
  if (Status s = validateCamera("colour", p.colour); !s) return s;
  const Eigen::Matrix3d& R = p.T_colour_depth.R_world_cam;
  if (!R.allFinite()) return invalid("T_colour_depth.R", "has a non-finite element");
  const double orth_err = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!(orth_err <= 1e-6)) {
    return invalid("T_colour_depth.R", "is not a rotation: R^T R differs from I by " + number(orth_err) +
                                           " (more than 1e-6); give an orthonormal matrix with enough digits");
  }
  const double det = R.determinant();
  if (!(std::abs(det - 1.0) <= 1e-6)) {
    return invalid("T_colour_depth.R", "is not a rotation: its determinant is " + number(det) +
                                           ", not 1 (a reflection? check the axis convention)");
  }
  const Eigen::Vector3d& t = p.T_colour_depth.t_world_cam;
  for (int i = 0; i < 3; ++i) {
    if (!finiteAsFloat(t[i])) {
      return invalid("T_colour_depth.t", "must be finite (metres), got " + number(t[i]) + " at index " +
                                             std::to_string(i));
    }
  }
  if (!(finiteAsFloat(p.depth_scale_m) && p.depth_scale_m > 0.0 && static_cast<float>(p.depth_scale_m) > 0.0f)) {
    return invalid("depth_scale_m", "must be finite and > 0 (metres per depth unit, 0.001 for millimetres), got " +
                                        number(p.depth_scale_m));
  }
  return Status::ok();
}

}  // namespace

Result<DepthToColourRegistration> DepthToColourRegistration::create(const RegistrationParams& params) {
  if (Status s = validate(params); !s) return s;
  DepthToColourRegistration r;
  r.params_ = params;
  const hal::CameraIntrinsics& d = params.depth.intrinsics;
  const hal::CameraIntrinsics& c = params.colour.intrinsics;
  const Eigen::Matrix3d& R = params.T_colour_depth.R_world_cam;
  const Eigen::Vector3d& t = params.T_colour_depth.t_world_cam;
  Kernel& k = r.constants_;
  k.depth_width = d.width;
  k.depth_height = d.height;
  k.colour_width = c.width;
  k.colour_height = c.height;
  k.scale = static_cast<float>(params.depth_scale_m);
  k.tx = static_cast<float>(t.x());
  k.ty = static_cast<float>(t.y());
  k.tz = static_cast<float>(t.z());
  k.fx = static_cast<float>(c.fx);
  k.fy = static_cast<float>(c.fy);
  k.cx = static_cast<float>(c.cx);
  k.cy = static_cast<float>(c.cy);
  k.distort = !params.colour.distortion.isIdentity();
  const auto& dc = params.colour.distortion.coeffs;
  k.k1 = static_cast<float>(dc[0]);
  k.k2 = static_cast<float>(dc[1]);
  k.p1 = static_cast<float>(dc[2]);
  k.p2 = static_cast<float>(dc[3]);
  k.k3 = static_cast<float>(dc[4]);
  k.two_p1 = static_cast<float>(2.0 * dc[2]);
  k.two_p2 = static_cast<float>(2.0 * dc[3]);

  const std::size_t n = static_cast<std::size_t>(d.width) * static_cast<std::size_t>(d.height);
  r.ray_x_.assign(n + kTablePadding, 0.0f);
  r.ray_y_.assign(n + kTablePadding, 0.0f);
  r.ray_z_.assign(n + kTablePadding, 0.0f);
  for (int v = 0; v < d.height; ++v) {
    const double y = (v - d.cy) / d.fy;
    for (int u = 0; u < d.width; ++u) {
      const Eigen::Vector3d q = R * Eigen::Vector3d((u - d.cx) / d.fx, y, 1.0);
      const std::size_t i = static_cast<std::size_t>(v) * d.width + u;
      r.ray_x_[i] = static_cast<float>(q.x());
      r.ray_y_[i] = static_cast<float>(q.y());
      r.ray_z_[i] = static_cast<float>(q.z());
    }
  }
  return r;
}

DepthToColourRegistration::Kernel DepthToColourRegistration::kernel() const {
  Kernel k = constants_;
  k.qx = ray_x_.data();
  k.qy = ray_y_.data();
  k.qz = ray_z_.data();
  return k;
}

RegistrationCounts DepthToColourRegistration::registerRef(const uint16_t* depth, const uint8_t* colour_rgb,
                                                          uint8_t* out_rgb) const {
  const Kernel k = kernel();
  const std::size_t n = static_cast<std::size_t>(k.depth_width) * static_cast<std::size_t>(k.depth_height);
  const auto width_f = static_cast<float>(k.colour_width);
  const auto height_f = static_cast<float>(k.colour_height);
  RegistrationCounts counts;
  for (std::size_t i = 0; i < n; ++i) {
    uint8_t* out = out_rgb + 3 * i;
    const uint16_t raw = depth[i];
    if (raw == 0) {
      out[0] = out[1] = out[2] = 0;
      continue;
    }
    ++counts.with_depth;
    // The header's arithmetic, one operation per step.
    const float z = static_cast<float>(raw) * k.scale;
    const float X = k.qx[i] * z + k.tx;
    const float Y = k.qy[i] * z + k.ty;
    const float Z = k.qz[i] * z + k.tz;
    bool inside = Z > 0.0f;
    if (inside) {
      float a = X / Z;
      float b = Y / Z;
      if (k.distort) {
        const float aa = a * a;
        const float bb = b * b;
        const float ab = a * b;
        const float r2 = aa + bb;
        const float radial = ((k.k3 * r2 + k.k2) * r2 + k.k1) * r2 + 1.0f;
        const float da = a * radial + (k.two_p1 * ab + k.p2 * (r2 + (aa + aa)));
        const float db = b * radial + (k.p1 * (r2 + (bb + bb)) + k.two_p2 * ab);
        a = da;
        b = db;
      }
      const float hu = (k.fx * a + k.cx) + 0.5f;
      const float hv = (k.fy * b + k.cy) + 0.5f;
      inside = hu >= 0.0f && hu < width_f && hv >= 0.0f && hv < height_f;
      if (inside) {
        const auto cu = static_cast<std::size_t>(static_cast<int32_t>(hu));
        const auto cv = static_cast<std::size_t>(static_cast<int32_t>(hv));
        const uint8_t* px = colour_rgb + 3 * (cv * static_cast<std::size_t>(k.colour_width) + cu);
        out[0] = px[0];
        out[1] = px[1];
        out[2] = px[2];
        ++counts.coloured;
      }
    }
    if (!inside) {
      out[0] = out[1] = out[2] = 0;
      ++counts.outside_colour;
    }
  }
  return counts;
}

RegistrationCounts DepthToColourRegistration::registerSimd(const uint16_t* depth, const uint8_t* colour_rgb,
                                                           uint8_t* out_rgb) const {
  return kernels::registerSimdDispatch(kernel(), depth, colour_rgb, out_rgb);
}

RegistrationCounts DepthToColourRegistration::apply(const uint16_t* depth, const uint8_t* colour_rgb,
                                                    uint8_t* out_rgb, KernelSet kernels) const {
  return kernels == KernelSet::kRef ? registerRef(depth, colour_rgb, out_rgb)
                                    : registerSimd(depth, colour_rgb, out_rgb);
}

}  // namespace fovea::hal

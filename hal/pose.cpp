#include "hal/pose.h"

#include <cmath>
#include <cstdio>

namespace fovea::hal {

namespace {

std::string number(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.9g", v);
  return text;
}

}  // namespace

bool normalisedQuaternion(double x, double y, double z, double w, Eigen::Quaterniond& out) {
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z) || !std::isfinite(w)) return false;
  const Eigen::Quaterniond q(w, x, y, z);
  const double norm = q.norm();
  if (!(norm > 0.5 && norm < 1.5)) return false;
  out = q.normalized();
  return true;
}

Result<Eigen::Quaterniond> quaternionFromXyzw(std::span<const double> xyzw, std::string_view what) {
  using R = Result<Eigen::Quaterniond>;
  if (xyzw.size() != 4) {
    return R(ErrorCode::kInvalidArgument, std::string(what) + ": a quaternion is 4 numbers x, y, z, w (got " +
                                              std::to_string(xyzw.size()) + ")");
  }
  Eigen::Quaterniond q;
  if (!normalisedQuaternion(xyzw[0], xyzw[1], xyzw[2], xyzw[3], q)) {
    const double norm = std::sqrt(xyzw[0] * xyzw[0] + xyzw[1] * xyzw[1] + xyzw[2] * xyzw[2] + xyzw[3] * xyzw[3]);
    return R(ErrorCode::kInvalidArgument,
             std::string(what) + ": not a rotation quaternion (x, y, z, w with length near 1; got length " +
                 number(norm) + "; the identity is [0, 0, 0, 1])");
  }
  return q;
}

Status checkRotation(const Eigen::Matrix3d& R, std::string_view what, double tolerance) {
  if (!R.allFinite()) return {ErrorCode::kInvalidArgument, std::string(what) + ": not finite"};
  const double orthogonality = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  const double det = R.determinant();
  if (orthogonality > tolerance) {
    return {ErrorCode::kInvalidArgument, std::string(what) + ": not a rotation (R^T R differs from I by " +
                                             number(orthogonality) + ", tolerance " + number(tolerance) +
                                             "; write it with more digits or as a quaternion)"};
  }
  if (std::abs(det - 1.0) > tolerance) {
    return {ErrorCode::kInvalidArgument, std::string(what) + ": not a rotation (determinant " + number(det) +
                                             ", a reflection when -1: check the axis order)"};
  }
  return Status::ok();
}

Result<Eigen::Vector3d> translationFromList(std::span<const double> xyz, std::string_view what) {
  using R = Result<Eigen::Vector3d>;
  if (xyz.size() != 3) {
    return R(ErrorCode::kInvalidArgument,
             std::string(what) + ": a translation is 3 numbers x, y, z in metres (got " + std::to_string(xyz.size()) + ")");
  }
  const Eigen::Vector3d t(xyz[0], xyz[1], xyz[2]);
  if (!t.allFinite()) return R(ErrorCode::kInvalidArgument, std::string(what) + ": not finite");
  return t;
}

Pose poseFromQuaternion(const Eigen::Vector3d& t, const Eigen::Quaterniond& q) {
  Pose p;
  p.R_world_cam = q.toRotationMatrix();
  p.t_world_cam = t;
  return p;
}

std::size_t formatTumPose(int64_t stamp_ns, const Pose& pose, char* out, std::size_t size) {
  Eigen::Quaterniond q(pose.R_world_cam);
  q.normalize();
  if (q.w() < 0) q.coeffs() = -q.coeffs();  // one of the two: w >= 0, as TUM's files mostly have it
  const bool negative = stamp_ns < 0;
  const uint64_t magnitude = negative ? 0 - static_cast<uint64_t>(stamp_ns) : static_cast<uint64_t>(stamp_ns);
  const uint64_t us = (magnitude + 500) / 1000;  // rounded to the microsecond
  const int n = std::snprintf(out, size, "%s%llu.%06llu %.6f %.6f %.6f %.7f %.7f %.7f %.7f\n", negative ? "-" : "",
                              static_cast<unsigned long long>(us / 1'000'000),
                              static_cast<unsigned long long>(us % 1'000'000), pose.t_world_cam.x(),
                              pose.t_world_cam.y(), pose.t_world_cam.z(), q.x(), q.y(), q.z(), q.w());
  return n > 0 && static_cast<std::size_t>(n) < size ? static_cast<std::size_t>(n) : 0;
}

Pose interpolateBetween(const StampedPose& a, const StampedPose& b, int64_t stamp_ns) {
  const int64_t span = b.stamp_ns - a.stamp_ns;
  const double alpha = span > 0 ? static_cast<double>(stamp_ns - a.stamp_ns) / static_cast<double>(span) : 0.0;
  return poseFromQuaternion(a.t_world_cam + (b.t_world_cam - a.t_world_cam) * alpha,
                            a.q_world_cam.slerp(alpha, b.q_world_cam));
}

}  // namespace fovea::hal

// Timestamped camera poses and their interpolation: one place for what the TUM
// recordings, the board profile's fixed mount and the robot's pose socket
// (hal/pose_source.h) all need. Convention of hal::Pose: p_world = R * p_cam + t,
// OpenCV camera axes (x right, y down, z forward).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include <Eigen/Geometry>

#include "core/result.h"
#include "hal/frame.h"

namespace fovea::hal {

struct StampedPose {
  int64_t stamp_ns = 0;
  Eigen::Vector3d t_world_cam = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q_world_cam = Eigen::Quaterniond::Identity();  // normalised
};

// A quaternion given as x, y, z, w (ROS and TUM order), normalised. False when
// a component is not finite or its norm is outside 0.5 .. 1.5: a sender that
// rounds (TUM writes 4 decimals) is forgiven, a zero or garbage one is not.
[[nodiscard]] bool normalisedQuaternion(double x, double y, double z, double w, Eigen::Quaterniond& out);

// The same for a configuration or calibration value: 4 numbers, x y z w.
// kInvalidArgument naming `what` otherwise.
Result<Eigen::Quaterniond> quaternionFromXyzw(std::span<const double> xyzw, std::string_view what);

// OK when R is a rotation: finite, R^T R = I and det R = +1 within tolerance
// (1e-6 by default). kInvalidArgument naming `what` and how far off it is.
Status checkRotation(const Eigen::Matrix3d& R, std::string_view what, double tolerance = 1e-6);

// A translation of 3 finite numbers (metres), kInvalidArgument naming `what` otherwise.
Result<Eigen::Vector3d> translationFromList(std::span<const double> xyz, std::string_view what);

Pose poseFromQuaternion(const Eigen::Vector3d& t, const Eigen::Quaterniond& q);

// One line of a trajectory in the TUM RGB-D benchmark's format,
// "timestamp tx ty tz qx qy qz qw\n" (seconds with 6 decimals, exactly from the
// nanoseconds; metres and the unit quaternion with 6 and 7 decimals), what
// groundtruth.txt holds and the benchmark's evaluate_ate.py reads. Written into
// out (no allocation); returns its length, 0 when it does not fit.
std::size_t formatTumPose(int64_t stamp_ns, const Pose& pose, char* out, std::size_t size);

// The pose between a and b at a's stamp + alpha * (b's - a's): translation
// linearly, rotation by slerp (the shorter arc: q and -q are one rotation).
Pose interpolateBetween(const StampedPose& a, const StampedPose& b, int64_t stamp_ns);

// The pose at stamp_ns from `count` poses with increasing stamps, the i-th
// given by at(i) (a vector, or a ring's slots in age order): interpolated
// between the two samples around it; the end pose within clamp_ns outside the
// span; false when farther out or when count is 0 (out is then untouched).
template <typename At>
bool interpolatePoseAt(std::size_t count, At&& at, int64_t stamp_ns, int64_t clamp_ns, Pose& out) {
  if (count == 0) return false;
  const StampedPose& first = at(std::size_t{0});
  const StampedPose& last = at(count - 1);
  if (stamp_ns <= first.stamp_ns) {
    if (first.stamp_ns - stamp_ns > clamp_ns) return false;
    out = poseFromQuaternion(first.t_world_cam, first.q_world_cam);
    return true;
  }
  if (stamp_ns >= last.stamp_ns) {
    if (stamp_ns - last.stamp_ns > clamp_ns) return false;
    out = poseFromQuaternion(last.t_world_cam, last.q_world_cam);
    return true;
  }
  // Binary search keeping at(lo) <= stamp_ns < at(hi).
  std::size_t lo = 0, hi = count - 1;
  while (hi - lo > 1) {
    const std::size_t mid = lo + (hi - lo) / 2;
    if (at(mid).stamp_ns <= stamp_ns) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  out = interpolateBetween(at(lo), at(hi), stamp_ns);
  return true;
}

inline bool interpolatePose(std::span<const StampedPose> poses, int64_t stamp_ns, int64_t clamp_ns, Pose& out) {
  return interpolatePoseAt(
      poses.size(), [&poses](std::size_t i) -> const StampedPose& { return poses[i]; }, stamp_ns, clamp_ns, out);
}

}  // namespace fovea::hal

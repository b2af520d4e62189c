// The eye's angular speed and the fovea growth it calls for (Preset::kAcuity,
// Gaze::fovea_growth_deg; firmware/gaze_policy.h applies it to the operator's
// gaze, fovea-error-report's coverage figure to a scripted one).
//
// The eye moves on while a gaze sample travels to the robot and the frame it
// steers travels back, so the fovea is widened by the eye's speed between its
// last two samples, measured on the sender's clock (the receiver's adds network
// jitter), times the sample's age plus the frame's expected time to the display
// (lead), up to a bound: a fixating eye gets none, a saccade in flight (some
// hundreds of degrees per second) the bound, so that where it lands is sharp.
#pragma once

#include <cstdint>

#include <Eigen/Core>

namespace fovea::pipeline {

// Faster than any saccade: a larger figure comes from clock jitter between two
// samples stamped close together.
inline constexpr double kMaxEyeSpeedDegS = 1000.0;

class EyeSpeed {
 public:
  // A sample: its direction (any non-zero length) and its stamp on the sender's
  // clock. A repeated stamp is the same sample (ignored); a stamp that goes back,
  // or a non-finite direction, restarts the measurement (speed 0).
  void observe(const Eigen::Vector3d& direction, int64_t stamp_ns);
  void reset();
  double speedDegS() const { return speed_deg_s_; }

 private:
  bool have_previous_ = false;
  Eigen::Vector3d previous_ = Eigen::Vector3d::UnitZ();
  int64_t previous_stamp_ns_ = 0;
  double speed_deg_s_ = 0.0;
};

// min(max_deg, speed * (age + lead)); a negative age counts as 0.
double foveaGrowthDeg(double speed_deg_s, int64_t age_ns, int64_t lead_ns, double max_deg);

}  // namespace fovea::pipeline

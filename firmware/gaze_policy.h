// Which gaze and which foveation a streamed frame uses (issue 4's robot side).
//
// The operator's newest valid gaze sample drives the foveation while it is
// fresh. With none yet, or one older than the timeout (default 100 ms: a few
// eye-tracker periods; a saccade lands in about 50 ms), the service cannot
// know where the operator looks, so it falls back to a uniform lattice: every
// point is sampled with voxels of fallback_voxel_m (default 5 cm) around the
// camera's optical axis, which keeps the stream bounded and shows the whole
// scene evenly rather than placing a sharp fovea where the operator may not be
// looking. The fallback is FREF's "no foveation" at a safe voxel size.
// docs/protocol.md ("Gaze fallback") documents it for operators.
//
// A fresh gaze also carries how far the fovea must reach beyond it, for the
// ACUITY preset: the eye's speed between the operator's samples times the
// sample's age plus lead, up to growth_max_deg (pipeline/eye_speed.h).
#pragma once

#include <cstdint>
#include <string_view>

#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/eye_speed.h"
#include "pipeline/foveator.h"

namespace fovea::firmware {

struct GazePolicyConfig {
  int64_t timeout_ns = 100'000'000;
  double fallback_voxel_m = 0.05;
  // The fovea's growth (ACUITY): bound, and the capture-to-display time it looks
  // ahead (the stream's capture-to-decoded p50 is about 13 ms on loopback, plus a
  // display refresh; docs/acuity-levels.md). growth_max_deg = 0 disables it.
  double growth_max_deg = 10.0;
  int64_t lead_ns = 30'000'000;

  Status validate() const;
};

enum class GazeSource { kOperator, kNoGazeYet, kStale };
std::string_view gazeSourceName(GazeSource source);

// The operator's newest gaze sample as the robot holds it (the send thread hands
// it to the foveation thread).
struct OperatorGaze {
  bool valid = false;       // a session with a valid sample
  pipeline::Gaze gaze;      // with the head's forward axis (view_known) from the HMD pose
  int64_t received_ns = 0;  // robot's clock
  int64_t stamp_ns = 0;     // operator's clock (the eye's speed between samples)
};

// The foveation configuration that samples every point on one uniform lattice
// of voxel_m: a one-bound custom model whose inner region (within 0.001 deg of
// the axis, at most a pixel) stays whole and whose outer region spans the rest,
// with d0 fixed so that region's voxel (Eq. 5-6) is voxel_m.
pipeline::FoveationConfig uniformFoveationConfig(double voxel_m);

class GazePolicy {
 public:
  GazePolicy(const GazePolicyConfig& config, const pipeline::FoveationConfig& operator_config);

  struct Decision {
    GazeSource source = GazeSource::kNoGazeYet;
    pipeline::Gaze gaze;
    const pipeline::FoveationConfig* foveation = nullptr;
    bool changed = false;  // source differs from the previous decision (log it once)
    int64_t age_ns = -1;   // of the operator's sample; -1 when there is none
    double eye_speed_deg_s = 0.0;  // between the operator's last two samples
  };

  // newest: the operator's newest sample (valid false: none yet); camera: the
  // frame's pose, for the fallback's gaze along the optical axis.
  Decision decide(const OperatorGaze& newest, int64_t now_ns, const hal::Pose& camera);

  // A new operator-side configuration (SIGHUP, issue 5); the fallback stays.
  void setOperatorConfig(const pipeline::FoveationConfig& config) { operator_config_ = config; }
  const pipeline::FoveationConfig& fallbackConfig() const { return fallback_config_; }

 private:
  GazePolicyConfig config_;
  pipeline::FoveationConfig operator_config_;
  pipeline::FoveationConfig fallback_config_;
  bool first_ = true;
  GazeSource last_ = GazeSource::kNoGazeYet;
  pipeline::EyeSpeed eye_speed_;  // between the operator's samples
};

}  // namespace fovea::firmware

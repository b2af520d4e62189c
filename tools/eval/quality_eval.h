// fovea-eval's objective stand-in for the paper's user study: for one frame
// and one HMD position, every condition's cloud (foveated with the position's
// gaze, through the stream's codec and back) drawn from the eye by the splat
// renderer, against FREF's drawing from the same eye: PSNR and SSIM per
// eccentricity ring and weighted by acuity, and the share of points displaced
// by more than the eye resolves (pipeline/error_metrics.h).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/result.h"
#include "hal/frame.h"
#include "firmware/frame_foveator.h"
#include "tools/eval/plan.h"
#include "tools/eval/quality/image_quality.h"
#include "tools/operator/held_cloud.h"

namespace fovea::tools::eval {

struct QualityOptions {
  int width = 1440, height = 1600;  // one eye of a VR headset
  double horizontal_fov_deg = 100.0;
  std::vector<double> ring_edges_deg = {0, 2.5, 5, 10, 20, 30, 40, 50, 70};
  double slope = 0.022;            // the eye whose MAR weighs the rings and judges the displacements
  std::string image_path_prefix;   // "": no side-by-side images; else <prefix>_<condition>.png
  int image_scale = 4;
};

struct QualityRow {
  std::string dataset, condition;
  int position = 0;
  int frame = -1;              // the dataset's frame (the camera's sequence number) drawn
  // false: nothing to measure (MAP-DELTA without what the operator held at the
  // frame: never decoded, lost, or before the operator's hello); every figure NaN.
  bool measured = true;
  FoveatedQuality quality;     // against FREF's image
  // Input points displaced by more than their MAR: against their representative;
  // for a cloud the operator held (MAP-DELTA), against the nearest point drawn,
  // over the input points inside the eye's image (heldShareAboveMar, quality/held_error.h);
  // NaN when no input point is in the image.
  double above_mar_share = 0;
  uint32_t points = 0;         // decoded points drawn
  std::string image;           // the side-by-side PNG written, if any
};

class QualityEvaluator {
 public:
  static Result<std::unique_ptr<QualityEvaluator>> create(std::size_t max_points);
  ~QualityEvaluator();

  // FREF is always drawn as the reference (and reported as a row: PSNR +inf, SSIM 1).
  // A condition with source "map" foveates `map` instead of the frame: the map
  // source's stage that fused the dataset's frames up to and including `frame`
  // (its cloud the frame's unexplained points); kInvalidArgument without one.
  // max_points (create) must then hold FrameFoveator::cloudCapacity.
  // A condition with map_delta (MAP-DELTA) is not foveated here: it draws `held`,
  // what fovea-operator --save-held wrote at this frame (its live points and the
  // bricks it held), sized as the viewer sizes them; without it, the row is not
  // measured (measured = false, NaN figures).
  Result<std::vector<QualityRow>> evaluate(const hal::RgbdFrame& frame, const Dataset& dataset,
                                           const HmdPosition& position, const std::vector<Condition>& conditions,
                                           const QualityOptions& options, firmware::FrameFoveator* map = nullptr,
                                           const tools::HeldCloud* held = nullptr);

 private:
  struct State;
  explicit QualityEvaluator(std::unique_ptr<State> state);
  std::unique_ptr<State> s_;
};

// The eye camera of a position: at the eye, looking at its first fixation (the
// scene's centre), the world's up kept up.
EyeCamera eyeCamera(const HmdPosition& position, const Eigen::Vector3d& up, const QualityOptions& options);

}  // namespace fovea::tools::eval

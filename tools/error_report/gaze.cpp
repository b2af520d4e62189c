// fovea-error-report's eye on each frame, and the report's words for it.
#include "tools/error_report/gaze.h"

#include <cstdio>
#include <numbers>

#include <Eigen/Geometry>

namespace fovea::tools {

std::string describeGaze(const Options& options, const hal::CameraInfo& info) {
  char gaze_text[320];
  char eye_text[96] = "the camera";
  if (!options.eye_offset_cam.isZero()) {
    std::snprintf(eye_text, sizeof eye_text, "an eye at (%.2f, %.2f, %.2f) m from the camera (its x right, y down, z forward)",
                  options.eye_offset_cam.x(), options.eye_offset_cam.y(), options.eye_offset_cam.z());
  }
  if (info.focus_point_m.has_value()) {
    std::snprintf(gaze_text, sizeof gaze_text, "from %s towards the scene's focus point (%.2f, %.2f, %.2f) m", eye_text,
                  info.focus_point_m->x(), info.focus_point_m->y(), info.focus_point_m->z());
  } else {
    std::snprintf(gaze_text, sizeof gaze_text, "from %s along the camera's optical axis (the camera has no focus point)",
                  eye_text);
  }
  return gaze_text;
}

pipeline::Gaze gazeOn(const hal::RgbdFrame& frame, const Options& options, const hal::CameraInfo& info) {
  pipeline::Gaze gaze;
  gaze.origin_m = frame.T_world_cam.t_world_cam + frame.T_world_cam.R_world_cam * options.eye_offset_cam;
  gaze.direction = info.focus_point_m.has_value() ? Eigen::Vector3d(*info.focus_point_m - gaze.origin_m)
                                                  : Eigen::Vector3d(frame.T_world_cam.R_world_cam.col(2));
  gaze.view_known = true;
  gaze.view_forward = Eigen::AngleAxisd(-options.head_turn_deg * std::numbers::pi / 180.0,
                                        Eigen::Vector3d(-frame.T_world_cam.R_world_cam.col(1))) *
                      gaze.direction;
  return gaze;
}

}  // namespace fovea::tools

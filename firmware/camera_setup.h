// The camera's calibration and pose from the configuration ([camera]
// calibration_file, [camera.extrinsics], [camera.pose]): the one place that
// both the service (firmware/service*.cpp) and `fovead run` use.
#pragma once

#include <memory>
#include <string>

#include "core/result.h"
#include "firmware/options.h"
#include "firmware/service_config.h"
#include "hal/calibration.h"
#include "hal/camera.h"
#include "hal/pose_source.h"
#include "pipeline/map/pose_tracking.h"

namespace fovea::firmware {

// The extrinsics and pose keys alone (sizes, rotations, the socket path when
// source = "socket"), for config validation. The message starts with the key:
// "camera.pose.rotation_xyzw: not a rotation quaternion ...".
Status checkCameraGeometry(const CameraSettings& settings);

// The calibration configured: the file (if any), then the inline extrinsics
// over it. Empty (calibration.empty()) when nothing is configured.
Result<hal::CameraCalibration> loadCameraCalibration(const CameraSettings& settings);

// Loads the calibration and hands it to the camera; call before open(). A
// camera that takes none (mock, tum) with a calibration configured is an error
// naming the key. Returns the line to log ("" when nothing is configured).
Result<std::string> applyCameraCalibration(hal::Camera& camera, const CameraSettings& settings);

// What camera.pose.source takes, and --pose: for the messages and the help.
inline constexpr const char* kPoseSourceChoices =
    "camera.pose.source: must be none, fixed, socket, track, track+fixed, track+socket or track+camera";
inline constexpr const char* kPoseFlagForms =
    "none, fixed:X,Y,Z[,QX,QY,QZ,QW], socket:PATH, track, track+fixed:X,Y,Z[,...], track+socket:PATH or track+camera";

// The outside pose source camera.pose.source names (track: none; track+X: X).
// The tracking part is pipeline::map::parsePoseSourceChoice's.
Result<hal::PoseSourceConfig> poseSourceConfig(const CameraSettings& settings);
// The pose line for the log: the pose source's own description, or what the
// tracker does with it ("track: the map tracks the camera ...").
std::string describePose(const CameraSettings& settings, const hal::PoseSource& source);

// Whether and how the map tracks the camera (kOff for a source that is not valid:
// checkCameraGeometry() says why).
pipeline::map::PoseTracking poseTracking(const CameraSettings& settings);
// The pose source the configuration asks for (binds the socket for "socket").
Result<std::unique_ptr<hal::PoseSource>> createPoseSource(const CameraSettings& settings);

// [camera] settings from the command line: --camera SPEC (default the mock
// living room), --calibration FILE, --pose none|fixed:X,Y,Z[,QX,QY,QZ,QW]|socket:PATH
// and --pose-max-age-ms MS (fovead run and fovead map take these flags).
inline const std::vector<std::string> kCameraFlags = {"--camera", "--calibration", "--pose", "--pose-max-age-ms"};
Result<CameraSettings> cameraSettingsFromArgs(const Args& args);

// A camera opened as the service opens one: calibration before open(), then
// its pose source. Members in this order so that the pose source goes before
// the camera it serves.
struct OpenedCamera {
  std::unique_ptr<hal::Camera> camera;
  std::string calibrated;  // what the calibration set, "" for none
  std::unique_ptr<hal::PoseSource> pose_source;
};
// kInvalidArgument for what was asked wrong (the spec, the calibration, the
// pose settings); otherwise the failure of the machine, a device that would not
// open ("camera NAME: why") never kInvalidArgument.
Result<OpenedCamera> openConfiguredCamera(const CameraSettings& settings);

}  // namespace fovea::firmware

// The camera's calibration and pose from the configuration ([camera]
// calibration_file, [camera.extrinsics], [camera.pose]): the one place that
// both the service (firmware/service.cpp) and `fovead run` use.
#pragma once

#include <memory>
#include <string>

#include "core/result.h"
#include "firmware/service_config.h"
#include "hal/calibration.h"
#include "hal/camera.h"
#include "hal/pose_source.h"

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

Result<hal::PoseSourceConfig> poseSourceConfig(const CameraSettings& settings);
// The pose source the configuration asks for (binds the socket for "socket").
Result<std::unique_ptr<hal::PoseSource>> createPoseSource(const CameraSettings& settings);

}  // namespace fovea::firmware

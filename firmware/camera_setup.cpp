#include "firmware/camera_setup.h"

#include "hal/calibration_file.h"
#include "hal/pose.h"

namespace fovea::firmware {

namespace {

// The inline extrinsics, when given.
Result<std::optional<hal::Pose>> inlineExtrinsics(const CameraSettings& s) {
  using R = Result<std::optional<hal::Pose>>;
  const bool has_rotation = !s.extrinsics_rotation_xyzw.empty();
  const bool has_translation = !s.extrinsics_translation_m.empty();
  if (!has_rotation && !has_translation) return std::optional<hal::Pose>();
  if (has_rotation != has_translation) {
    return R(invalidArgument(
        std::string(has_rotation ? "camera.extrinsics.translation_m" : "camera.extrinsics.rotation_xyzw") +
        ": give camera.extrinsics.rotation_xyzw and translation_m together (or neither)"));
  }
  Result<Eigen::Quaterniond> q = hal::quaternionFromXyzw(s.extrinsics_rotation_xyzw, "camera.extrinsics.rotation_xyzw");
  if (!q) return q.status();
  Result<Eigen::Vector3d> t = hal::translationFromList(s.extrinsics_translation_m, "camera.extrinsics.translation_m");
  if (!t) return t.status();
  return std::optional<hal::Pose>(hal::poseFromQuaternion(t.value(), q.value()));
}

Result<hal::Pose> posePose(const PoseSettings& p) {
  Result<Eigen::Quaterniond> q = hal::quaternionFromXyzw(p.rotation_xyzw, "camera.pose.rotation_xyzw");
  if (!q) return q.status();
  Result<Eigen::Vector3d> t = hal::translationFromList(p.translation_m, "camera.pose.translation_m");
  if (!t) return t.status();
  return hal::poseFromQuaternion(t.value(), q.value());
}

}  // namespace

Status checkCameraGeometry(const CameraSettings& settings) {
  if (Result<std::optional<hal::Pose>> e = inlineExtrinsics(settings); !e) return e.status();
  if (Result<hal::Pose> p = posePose(settings.pose); !p) return p.status();
  if (settings.pose.source == "socket" && settings.pose.socket.empty()) {
    return invalidArgument("camera.pose.socket: must name the socket's path with camera.pose.source = \"socket\"");
  }
  return Status::ok();
}

Result<hal::CameraCalibration> loadCameraCalibration(const CameraSettings& settings) {
  hal::CameraCalibration calibration;
  if (!settings.calibration_file.empty()) {
    Result<hal::CameraCalibration> loaded = hal::loadCalibrationFile(settings.calibration_file);
    if (!loaded) return Status(loaded.status().code(), "camera.calibration_file: " + loaded.status().message());
    calibration = std::move(loaded.value());
  }
  Result<std::optional<hal::Pose>> extrinsics = inlineExtrinsics(settings);
  if (!extrinsics) return extrinsics.status();
  if (*extrinsics) {
    calibration.T_colour_depth = **extrinsics;
    calibration.source += std::string(calibration.source.empty() ? "" : " + ") + "camera.extrinsics";
  }
  return calibration;
}

Result<std::string> applyCameraCalibration(hal::Camera& camera, const CameraSettings& settings) {
  Result<hal::CameraCalibration> calibration = loadCameraCalibration(settings);
  if (!calibration) return calibration.status();
  if (calibration->empty()) return std::string();
  if (Status s = camera.setCalibration(calibration.value()); !s) {
    return Status(s.code(), s.message() + ": remove the calibration (camera.calibration_file, camera.extrinsics, --calibration) for this camera");
  }
  return "calibration from " + calibration->source + ": " + hal::describeCalibration(calibration.value());
}

Result<hal::PoseSourceConfig> poseSourceConfig(const CameraSettings& settings) {
  if (Status s = checkCameraGeometry(settings); !s) return s;
  const PoseSettings& p = settings.pose;
  hal::PoseSourceConfig config;
  if (p.source == "none") {
    config.kind = hal::PoseSourceConfig::Kind::kNone;
  } else if (p.source == "fixed") {
    config.kind = hal::PoseSourceConfig::Kind::kFixed;
  } else if (p.source == "socket") {
    config.kind = hal::PoseSourceConfig::Kind::kSocket;
  } else {
    return Status(ErrorCode::kInvalidArgument, "camera.pose.source: must be none, fixed or socket (got '" + p.source + "')");
  }
  config.pose = posePose(p).value();
  config.socket_path = p.socket;
  config.max_age_ns = p.max_age_ms * 1'000'000;
  config.capacity = static_cast<std::size_t>(p.buffer_poses);
  return config;
}

Result<std::unique_ptr<hal::PoseSource>> createPoseSource(const CameraSettings& settings) {
  Result<hal::PoseSourceConfig> config = poseSourceConfig(settings);
  if (!config) return config.status();
  Result<std::unique_ptr<hal::PoseSource>> source = hal::PoseSource::create(config.value());
  if (!source) return Status(source.status().code(), "camera.pose: " + source.status().message());
  return source;
}

}  // namespace fovea::firmware

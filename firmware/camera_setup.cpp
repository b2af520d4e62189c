#include "firmware/camera_setup.h"

#include "firmware/mcap_camera.h"
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
  const std::optional<pipeline::map::PoseSourceChoice> choice = pipeline::map::parsePoseSourceChoice(settings.pose.source);
  if (!choice) return invalidArgument(std::string(kPoseSourceChoices) + " (got '" + settings.pose.source + "')");
  if (choice->outside == "socket" && settings.pose.socket.empty()) {
    return invalidArgument("camera.pose.socket: must name the socket's path with camera.pose.source = \"" +
                           settings.pose.source + "\"");
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
  const std::string_view outside = pipeline::map::parsePoseSourceChoice(p.source)->outside;  // checked above
  hal::PoseSourceConfig config;
  if (outside == "none") {
    config.kind = hal::PoseSourceConfig::Kind::kNone;
  } else if (outside == "fixed") {
    config.kind = hal::PoseSourceConfig::Kind::kFixed;
  } else {
    config.kind = hal::PoseSourceConfig::Kind::kSocket;
  }
  config.pose = posePose(p).value();
  config.socket_path = p.socket;
  config.max_age_ns = p.max_age_ms * 1'000'000;
  config.capacity = static_cast<std::size_t>(p.buffer_poses);
  return config;
}

std::string describePose(const CameraSettings& settings, const hal::PoseSource& source) {
  switch (poseTracking(settings)) {
    case pipeline::map::PoseTracking::kAlone:
      return "track: the map tracks the camera (docs/tracking.md); the world is the first frame's camera frame";
    case pipeline::map::PoseTracking::kRefine:
      return settings.pose.source + ": the map's tracker refines the outside pose, " + source.describe();
    case pipeline::map::PoseTracking::kOff: break;
  }
  return source.describe();
}

pipeline::map::PoseTracking poseTracking(const CameraSettings& settings) {
  const std::optional<pipeline::map::PoseSourceChoice> choice = pipeline::map::parsePoseSourceChoice(settings.pose.source);
  return choice ? choice->tracking : pipeline::map::PoseTracking::kOff;
}

Result<std::unique_ptr<hal::PoseSource>> createPoseSource(const CameraSettings& settings) {
  Result<hal::PoseSourceConfig> config = poseSourceConfig(settings);
  if (!config) return config.status();
  Result<std::unique_ptr<hal::PoseSource>> source = hal::PoseSource::create(config.value());
  if (!source) return Status(source.status().code(), "camera.pose: " + source.status().message());
  return source;
}

// [camera] settings from --camera, --calibration, --pose and --pose-max-age-ms.
Result<CameraSettings> cameraSettingsFromArgs(const Args& args) {
  CameraSettings settings;
  settings.spec = args.getOr("--camera", "mock:living-room");
  settings.calibration_file = args.getOr("--calibration", "");
  std::string pose = args.getOr("--pose", "none");
  // track, track+fixed:..., track+socket:PATH, track+camera: the tracker, alone or
  // refining the outside pose (track+camera: the camera's own, as `none` gives it).
  const bool track = pose == "track" || pose.rfind("track+", 0) == 0;
  const bool own = pose == "track+camera";
  if (pose == "track" || own) {
    pose = "none";
  } else if (track) {
    pose.erase(0, 6);
  }
  if (pose == "none") {
    settings.pose.source = "none";
  } else if (pose.rfind("fixed:", 0) == 0) {
    Result<std::vector<double>> values = parseDoubleList("--pose fixed:", pose.substr(6));
    if (!values) return values.status();
    if (values->size() != 3 && values->size() != 7) {
      return Result<CameraSettings>(ErrorCode::kInvalidArgument, "--pose fixed: expects X,Y,Z or X,Y,Z,QX,QY,QZ,QW");
    }
    settings.pose.source = "fixed";
    settings.pose.translation_m.assign(values->begin(), values->begin() + 3);
    if (values->size() == 7) settings.pose.rotation_xyzw.assign(values->begin() + 3, values->end());
  } else if (pose.rfind("socket:", 0) == 0 && pose.size() > 7) {
    settings.pose.source = "socket";
    settings.pose.socket = pose.substr(7);
  } else {
    return Result<CameraSettings>(ErrorCode::kInvalidArgument,
                                  "--pose: '" + args.getOr("--pose", "") + "' is not " + kPoseFlagForms);
  }
  if (track) {
    settings.pose.source = own ? "track+camera" : settings.pose.source == "none" ? "track" : "track+" + settings.pose.source;
  }
  if (const std::string* v = args.get("--pose-max-age-ms")) {
    Result<long> ms = parseInteger("--pose-max-age-ms", *v, 1, 60'000);
    if (!ms) return ms.status();
    settings.pose.max_age_ms = ms.value();
  }
  if (Status s = checkCameraGeometry(settings); !s) return s;
  return settings;
}

Result<OpenedCamera> openConfiguredCamera(const CameraSettings& settings) {
  Result<std::unique_ptr<hal::Camera>> created = createCamera(settings.spec);
  if (!created) return Result<OpenedCamera>(invalidArgument(created.status().message()));
  hal::Camera& camera = *created.value();
  Result<std::string> calibrated = applyCameraCalibration(camera, settings);
  if (!calibrated) return Result<OpenedCamera>(invalidArgument(calibrated.status().message()));
  Result<std::unique_ptr<hal::PoseSource>> pose_source = createPoseSource(settings);
  if (!pose_source) return pose_source.status();
  if (Status s = camera.open(); !s) {
    const ErrorCode code = s.code() == ErrorCode::kInvalidArgument ? ErrorCode::kUnavailable : s.code();
    return Result<OpenedCamera>(code, "camera " + camera.info().name + ": " + s.message());
  }
  OpenedCamera out;
  out.camera = std::move(created.value());
  out.calibrated = std::move(calibrated.value());
  out.pose_source = std::move(pose_source.value());
  return out;
}

}  // namespace fovea::firmware

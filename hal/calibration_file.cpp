#include "hal/calibration_file.h"

#include <yaml-cpp/yaml.h>

#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "hal/pose.h"

namespace fovea::hal {

namespace {

constexpr int kMaxImageSide = 16384;
constexpr double kMaxUnitlessBaselineM = 1.0;  // an RGB-D baseline is centimetres

// Thrown inside this file only and caught at its boundary with yaml-cpp's own:
// the parser is a few nested readers, and an error in any of them ends it.
struct CalibrationError {
  std::string message;
};

[[noreturn]] void fail(const std::string& where, const std::string& what) { throw CalibrationError{where + ": " + what}; }

std::string number(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.6g", v);
  return text;
}

std::string join(const std::string& prefix, const char* key) { return prefix.empty() ? key : prefix + "." + key; }

// Where a field is: "file.yaml: colour.camera_matrix".
struct Place {
  std::string file;
  std::string field;
  std::string at() const { return field.empty() ? file : file + ": " + field; }
  Place operator/(const char* key) const { return {file, join(field, key)}; }
};

double scalarNumber(const YAML::Node& node, const Place& place) {
  if (!node.IsScalar()) fail(place.at(), "expected a number");
  std::string_view text = node.Scalar();
  while (!text.empty() && (text.front() == ' ')) text.remove_prefix(1);
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  double v = 0.0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (text.empty() || ec != std::errc() || end != text.data() + text.size()) {
    fail(place.at(), "'" + node.Scalar() + "' is not a number");
  }
  if (!std::isfinite(v)) fail(place.at(), "'" + node.Scalar() + "' is not finite");
  return v;
}

int scalarInt(const YAML::Node& node, const Place& place) {
  const double v = scalarNumber(node, place);
  if (v != std::floor(v) || std::abs(v) > 1e9) fail(place.at(), "expected an integer, got " + number(v));
  return static_cast<int>(v);
}

bool has(const YAML::Node& map, const char* key) {
  if (!map.IsMap()) return false;
  const YAML::Node n = map[key];
  return n.IsDefined() && !n.IsNull();
}

YAML::Node required(const YAML::Node& map, const char* key, const Place& place) {
  if (!has(map, key)) fail((place / key).at(), "missing");
  return map[key];
}

// A flat list of numbers from a sequence, possibly nested one level ([[1,2],[3,4]]).
void flatten(const YAML::Node& node, const Place& place, std::vector<double>& out, int depth = 0) {
  if (out.size() > 64) fail(place.at(), "too many numbers for a calibration matrix");
  if (node.IsSequence() && depth < 2) {
    for (std::size_t i = 0; i < node.size(); ++i) flatten(node[i], place, out, depth + 1);
    return;
  }
  out.push_back(scalarNumber(node, place));
}

// A rows x cols matrix, row-major: a mapping {rows, cols, data} (ROS, and
// OpenCV's !!opencv-matrix with dt) or a plain list. `cols_alternatives` lets a
// vector be written as 1xN or Nx1.
std::vector<double> readMatrix(const YAML::Node& node, const Place& place, int rows, int cols, bool vector = false) {
  std::vector<double> data;
  if (node.IsMap()) {
    const int r = scalarInt(required(node, "rows", place), place / "rows");
    const int c = scalarInt(required(node, "cols", place), place / "cols");
    if (has(node, "dt")) {
      const YAML::Node dt = node["dt"];
      if (!dt.IsScalar() || (dt.Scalar() != "d" && dt.Scalar() != "f")) {
        fail((place / "dt").at(), "expected d or f (a matrix of doubles or floats)");
      }
    }
    flatten(required(node, "data", place), place / "data", data);
    if (static_cast<std::size_t>(r) * static_cast<std::size_t>(std::max(c, 0)) != data.size() || r <= 0 || c <= 0) {
      fail(place.at(), "rows x cols = " + std::to_string(r) + "x" + std::to_string(c) + " but data holds " +
                           std::to_string(data.size()) + " numbers");
    }
    const bool shape_ok = vector ? (r * c == rows * cols && (r == 1 || c == 1)) : (r == rows && c == cols);
    if (!shape_ok) {
      fail(place.at(), "expected " + std::to_string(rows) + "x" + std::to_string(cols) + (vector ? " (or its transpose)" : "") +
                           ", got " + std::to_string(r) + "x" + std::to_string(c));
    }
  } else if (node.IsSequence()) {
    flatten(node, place, data);
    if (data.size() != static_cast<std::size_t>(rows * cols)) {
      fail(place.at(), "expected " + std::to_string(rows * cols) + " numbers (" + std::to_string(rows) + "x" +
                           std::to_string(cols) + "), got " + std::to_string(data.size()));
    }
  } else {
    fail(place.at(), "expected a matrix (rows, cols, data) or a list of numbers");
  }
  return data;
}

// Distortion coefficients as a vector of any of OpenCV's lengths.
std::vector<double> readCoefficients(const YAML::Node& node, const Place& place) {
  std::vector<double> data;
  if (node.IsMap()) {
    const int r = scalarInt(required(node, "rows", place), place / "rows");
    const int c = scalarInt(required(node, "cols", place), place / "cols");
    flatten(required(node, "data", place), place / "data", data);
    if (r <= 0 || c < 0 || static_cast<std::size_t>(r) * static_cast<std::size_t>(c) != data.size()) {
      fail(place.at(), "rows x cols = " + std::to_string(r) + "x" + std::to_string(c) + " but data holds " +
                           std::to_string(data.size()) + " numbers");
    }
    if (r != 1 && c != 1 && !data.empty()) fail(place.at(), "expected a vector (1xN or Nx1)");
  } else if (node.IsSequence()) {
    flatten(node, place, data);
  } else {
    fail(place.at(), "expected a list of coefficients");
  }
  return data;
}

constexpr const char* kKnownModels = "plumb_bob (k1 k2 p1 p2 k3, also called radtan or brown_conrady), none";

Distortion distortionFrom(std::string model, const std::vector<double>& coeffs, const Place& place) {
  for (char& ch : model) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  Distortion d;
  if (model.empty() || model == "none") {
    for (double c : coeffs) {
      if (c != 0.0) fail(place.at(), "distortion model none with non-zero coefficients (say plumb_bob)");
    }
    return d;
  }
  if (model != "plumb_bob" && model != "radtan" && model != "brown_conrady" && model != "opencv") {
    fail(place.at(), "distortion model '" + model + "' is not supported (known: " + kKnownModels +
                         "); undistort the images or calibrate with the plumb_bob model");
  }
  const std::size_t n = coeffs.size();
  if (n != 0 && n != 4 && n != 5 && n != 8 && n != 12 && n != 14) {
    fail(place.at(), "plumb_bob takes 5 coefficients (k1 k2 p1 p2 k3; OpenCV also writes 4, 8, 12 or 14), got " +
                         std::to_string(n));
  }
  for (std::size_t i = 5; i < n; ++i) {
    if (coeffs[i] != 0.0) {
      fail(place.at(), "coefficient " + std::to_string(i + 1) + " of " + std::to_string(n) +
                           " is not zero: that is OpenCV's rational/thin-prism model, not supported (known: " +
                           kKnownModels + ")");
    }
  }
  d.model = Distortion::Model::kPlumbBob;
  for (std::size_t i = 0; i < std::min<std::size_t>(n, 5); ++i) d.coeffs[i] = coeffs[i];
  return d;
}

CameraIntrinsics intrinsicsFrom(const std::vector<double>& K, int width, int height, const Place& place) {
  if (width <= 0 || height <= 0 || width > kMaxImageSide || height > kMaxImageSide) {
    fail(place.file + ": " + (place.field.empty() ? "" : place.field + ".") + "image_width/image_height",
         "must be within 1 .. " + std::to_string(kMaxImageSide) + " (got " + std::to_string(width) + "x" +
             std::to_string(height) + ")");
  }
  const Place k = place / "camera_matrix";
  CameraIntrinsics in{width, height, K[0], K[4], K[2], K[5]};
  if (!(in.fx > 0.0)) fail(k.at(), "fx must be positive (got " + number(in.fx) + ")");
  if (!(in.fy > 0.0)) fail(k.at(), "fy must be positive (got " + number(in.fy) + ")");
  if (K[3] != 0.0 || K[6] != 0.0 || K[7] != 0.0 || std::abs(K[8] - 1.0) > 1e-9) {
    fail(k.at(), "not a camera matrix [fx 0 cx; 0 fy cy; 0 0 1] (got " + number(K[3]) + ", " + number(K[6]) + ", " +
                     number(K[7]) + ", " + number(K[8]) + " in the lower rows)");
  }
  if (std::abs(K[1]) > 1e-6 * in.fx) fail(k.at(), "skew " + number(K[1]) + " is not supported (must be 0)");
  if (!(in.cx >= 0.0 && in.cx <= width && in.cy >= 0.0 && in.cy <= height)) {
    fail(k.at(), "principal point (" + number(in.cx) + ", " + number(in.cy) + ") lies outside the " +
                     std::to_string(width) + "x" + std::to_string(height) +
                     " image: is image_width/image_height the calibrated resolution?");
  }
  return in;
}

// One camera in camera_info form (ROS) or OpenCV's single-camera form.
StreamCalibration readCamera(const YAML::Node& node, const Place& place) {
  if (!node.IsMap()) fail(place.at(), "expected a camera (image_width, image_height, camera_matrix, ...)");
  const int width = scalarInt(required(node, "image_width", place), place / "image_width");
  const int height = scalarInt(required(node, "image_height", place), place / "image_height");
  const std::vector<double> K = readMatrix(required(node, "camera_matrix", place), place / "camera_matrix", 3, 3);
  StreamCalibration cam;
  cam.intrinsics = intrinsicsFrom(K, width, height, place);
  std::vector<double> coeffs;
  if (has(node, "distortion_coefficients")) {
    coeffs = readCoefficients(node["distortion_coefficients"], place / "distortion_coefficients");
  }
  std::string model = coeffs.empty() ? "none" : "plumb_bob";  // OpenCV names no model
  if (has(node, "distortion_model")) {
    const YAML::Node m = node["distortion_model"];
    if (!m.IsScalar()) fail((place / "distortion_model").at(), "expected a name (" + std::string(kKnownModels) + ")");
    model = m.Scalar();
  }
  cam.distortion = distortionFrom(model, coeffs, place / "distortion_model");
  if (has(node, "rectification_matrix")) {
    const std::vector<double> r = readMatrix(node["rectification_matrix"], place / "rectification_matrix", 3, 3);
    const Eigen::Matrix3d R = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(r.data());
    if (Status s = checkRotation(R, (place / "rectification_matrix").at()); !s) throw CalibrationError{s.message()};
  }
  if (has(node, "projection_matrix")) {
    // Checked for shape only: fovea projects with camera_matrix (the
    // unrectified camera), which is what a depth-to-colour registration needs.
    (void)readMatrix(node["projection_matrix"], place / "projection_matrix", 3, 4);
  }
  return cam;
}

Eigen::Matrix3d rotationFrom(const std::vector<double>& r, const Place& place) {
  const Eigen::Matrix3d R = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(r.data());
  if (Status s = checkRotation(R, place.at()); !s) throw CalibrationError{s.message()};
  return R;
}

double unitScale(const YAML::Node& root, const Place& place) {
  if (!has(root, "translation_unit")) return 1.0;
  const YAML::Node u = root["translation_unit"];
  const std::string unit = u.IsScalar() ? u.Scalar() : "";
  if (unit == "m") return 1.0;
  if (unit == "cm") return 0.01;
  if (unit == "mm") return 0.001;
  fail((place / "translation_unit").at(), "expected m, cm or mm (the unit of T: the calibration target's)");
}

Pose extrinsicsFrom(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  Pose p;
  p.R_world_cam = R;
  p.t_world_cam = t;
  return p;
}

std::pair<int, int> imageSize(const YAML::Node& root, const char* key, const Place& place) {
  const std::vector<double> s = readMatrix(root[key], place / key, 1, 2, true);
  if (s[0] != std::floor(s[0]) || s[1] != std::floor(s[1]) || std::abs(s[0]) > 1e6 || std::abs(s[1]) > 1e6) {
    fail((place / key).at(), "expected two integers [width, height]");
  }
  return {static_cast<int>(s[0]), static_cast<int>(s[1])};
}

void readStereo(const YAML::Node& root, const Place& place, CameraCalibration& out) {
  std::pair<int, int> size{0, 0};
  if (has(root, "image_width") || has(root, "image_height")) {
    size = {scalarInt(required(root, "image_width", place), place / "image_width"),
            scalarInt(required(root, "image_height", place), place / "image_height")};
  } else if (has(root, "image_size")) {
    size = imageSize(root, "image_size", place);
  } else if (has(root, "imageSize")) {
    size = imageSize(root, "imageSize", place);
  }
  for (int cam = 1; cam <= 2; ++cam) {
    const std::string k_name = has(root, cam == 1 ? "K1" : "K2") ? (cam == 1 ? "K1" : "K2") : (cam == 1 ? "M1" : "M2");
    const std::string d_name = cam == 1 ? "D1" : "D2";
    const std::string size_name = cam == 1 ? "image_size_1" : "image_size_2";
    std::pair<int, int> cam_size = has(root, size_name.c_str()) ? imageSize(root, size_name.c_str(), place) : size;
    if (cam_size.first == 0 && cam_size.second == 0) {
      fail(place.at(), "image_width/image_height (or image_size: [w, h]) missing: OpenCV's stereo output does not "
                       "say the resolution it was calibrated at; add it");
    }
    const Place at{place.file, k_name};
    const std::vector<double> K = readMatrix(required(root, k_name.c_str(), place), at, 3, 3);
    StreamCalibration s;
    s.intrinsics = intrinsicsFrom(K, cam_size.first, cam_size.second, Place{place.file, ""});
    std::vector<double> coeffs;
    if (has(root, d_name.c_str())) coeffs = readCoefficients(root[d_name], Place{place.file, d_name});
    s.distortion = distortionFrom(coeffs.empty() ? "none" : "plumb_bob", coeffs, Place{place.file, d_name});
    (cam == 1 ? out.depth : out.colour) = s;
  }
  const Eigen::Matrix3d R = rotationFrom(readMatrix(required(root, "R", place), place / "R", 3, 3), place / "R");
  const std::vector<double> t = readMatrix(required(root, "T", place), place / "T", 3, 1, true);
  const bool unit_given = has(root, "translation_unit");
  const Eigen::Vector3d T = Eigen::Vector3d(t[0], t[1], t[2]) * unitScale(root, place);
  if (!unit_given && T.norm() > kMaxUnitlessBaselineM) {
    fail((place / "T").at(), "length " + number(T.norm()) +
                                 " m is no RGB-D baseline: OpenCV's T is in the calibration target's unit; add "
                                 "translation_unit: mm (or cm, m)");
  }
  out.T_colour_depth = extrinsicsFrom(R, T);
}

std::string readWholeFile(const std::string& path, ErrorCode& code) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    code = ErrorCode::kNotFound;
    return "calibration file " + path + " does not exist";
  }
  if (std::filesystem::is_directory(path, ec)) {
    code = ErrorCode::kIoError;
    return "calibration file " + path + " is a directory";
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    code = ErrorCode::kIoError;
    return "cannot read calibration file " + path + ": " + std::strerror(errno);
  }
  std::ostringstream text;
  text << in.rdbuf();
  code = ErrorCode::kOk;
  return text.str();
}

YAML::Node parseYaml(std::string_view text, const std::string& name) {
  // OpenCV writes "%YAML:1.0", which YAML 1.2 parsers (yaml-cpp) reject as a
  // directive: it is dropped (and YAML 1.0 reads the same here).
  std::string body(text);
  if (body.rfind("%YAML:", 0) == 0) {
    const std::size_t eol = body.find('\n');
    body = eol == std::string::npos ? std::string() : body.substr(eol + 1);
  }
  try {
    return YAML::Load(body);
  } catch (const YAML::Exception& e) {
    // The line as the user counts it (yaml-cpp counts from 0, after the dropped line).
    const int line = e.mark.line + 1 + (body.size() != text.size() ? 1 : 0);
    throw CalibrationError{name + ":" + std::to_string(line) + ": not valid YAML: " + e.msg};
  }
}

StreamCalibration readCameraRef(const YAML::Node& node, const Place& place, const std::string& base_dir) {
  if (node.IsScalar()) {
    const std::filesystem::path ref(node.Scalar());
    const std::string path = ref.is_absolute() ? ref.string() : (std::filesystem::path(base_dir) / ref).string();
    ErrorCode code;
    const std::string text = readWholeFile(path, code);
    if (code != ErrorCode::kOk) fail(place.at(), text);
    const YAML::Node root = parseYaml(text, path);
    return readCamera(root, Place{path, ""});
  }
  return readCamera(node, place);
}

void readCombined(const YAML::Node& root, const Place& place, const std::string& base_dir, CameraCalibration& out) {
  for (const auto& item : root) {
    const std::string key = item.first.IsScalar() ? item.first.Scalar() : "?";
    if (key != "depth" && key != "colour" && key != "color" && key != "T_colour_depth" && key != "depth_scale_m") {
      fail(place.at(), "unknown key '" + key + "' (known: depth, colour, T_colour_depth, depth_scale_m)");
    }
  }
  if (has(root, "depth")) out.depth = readCameraRef(root["depth"], place / "depth", base_dir);
  if (has(root, "colour") && has(root, "color")) fail(place.at(), "colour and color both given: keep one");
  if (has(root, "colour")) out.colour = readCameraRef(root["colour"], place / "colour", base_dir);
  if (has(root, "color")) out.colour = readCameraRef(root["color"], place / "color", base_dir);
  if (has(root, "T_colour_depth")) {
    const YAML::Node e = root["T_colour_depth"];
    const Place at = place / "T_colour_depth";
    if (!e.IsMap()) fail(at.at(), "expected rotation (or rotation_xyzw) and translation_m");
    Eigen::Matrix3d R;
    if (has(e, "rotation") && has(e, "rotation_xyzw")) fail(at.at(), "rotation and rotation_xyzw both given: keep one");
    if (has(e, "rotation")) {
      R = rotationFrom(readMatrix(e["rotation"], at / "rotation", 3, 3), at / "rotation");
    } else if (has(e, "rotation_xyzw")) {
      const std::vector<double> q = readMatrix(e["rotation_xyzw"], at / "rotation_xyzw", 1, 4, true);
      Result<Eigen::Quaterniond> quaternion = quaternionFromXyzw(q, (at / "rotation_xyzw").at());
      if (!quaternion) throw CalibrationError{quaternion.status().message()};
      R = quaternion->toRotationMatrix();
    } else {
      fail((at / "rotation").at(), "missing (9 numbers row-major, or rotation_xyzw: [x, y, z, w])");
    }
    const std::vector<double> t = readMatrix(required(e, "translation_m", at), at / "translation_m", 3, 1, true);
    out.T_colour_depth = extrinsicsFrom(R, Eigen::Vector3d(t[0], t[1], t[2]));
  }
  if (has(root, "depth_scale_m")) {
    const double scale = scalarNumber(root["depth_scale_m"], place / "depth_scale_m");
    if (!(scale > 0.0 && scale <= 1.0)) {
      fail((place / "depth_scale_m").at(), "must be within 0 .. 1 metres per unit (got " + number(scale) + ")");
    }
    out.depth_scale_m = scale;
  }
  if (out.empty()) fail(place.at(), "says nothing (give depth, colour, T_colour_depth or depth_scale_m)");
}

}  // namespace

Result<CameraCalibration> parseCalibration(std::string_view text, std::string_view name_for_errors,
                                           std::string_view base_dir) {
  const std::string name(name_for_errors);
  CameraCalibration out;
  out.source = name;
  try {
    const YAML::Node root = parseYaml(text, name);
    const Place place{name, ""};
    if (!root.IsMap()) {
      fail(name, "not a calibration file (expected a YAML mapping: a ROS camera_info, an OpenCV FileStorage or a "
                 "fovea calibration; see docs/calibration.md)");
    }
    if (has(root, "depth") || has(root, "colour") || has(root, "color") || has(root, "T_colour_depth")) {
      readCombined(root, place, std::string(base_dir), out);
    } else if (has(root, "K1") || has(root, "M1")) {
      readStereo(root, place, out);
    } else if (has(root, "camera_matrix")) {
      out.colour = readCamera(root, Place{name, ""});
    } else {
      fail(name, "not a calibration file: expected a ROS camera_info (image_width, camera_matrix, ...), an OpenCV "
                 "FileStorage (camera_matrix, or K1 D1 K2 D2 R T) or a fovea calibration (depth, colour, "
                 "T_colour_depth); see docs/calibration.md");
    }
  } catch (const CalibrationError& e) {
    return Result<CameraCalibration>(ErrorCode::kParseError, e.message);
  } catch (const YAML::Exception& e) {
    return Result<CameraCalibration>(ErrorCode::kParseError, name + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg);
  } catch (const std::exception& e) {
    return Result<CameraCalibration>(ErrorCode::kParseError, name + ": " + e.what());
  }
  return out;
}

Result<CameraCalibration> loadCalibrationFile(const std::string& path) {
  ErrorCode code;
  const std::string text = readWholeFile(path, code);
  if (code != ErrorCode::kOk) return Result<CameraCalibration>(code, text);
  const std::string dir = std::filesystem::path(path).parent_path().string();
  return parseCalibration(text, path, dir.empty() ? "." : dir);
}

std::string describeCalibration(const CameraCalibration& c) {
  std::string out;
  auto add = [&out](const std::string& part) { out += (out.empty() ? "" : ", ") + part; };
  auto stream = [](const char* name, const StreamCalibration& s) {
    char text[160];
    std::snprintf(text, sizeof text, "%s %dx%d fx %.1f fy %.1f cx %.1f cy %.1f%s", name, s.intrinsics.width,
                  s.intrinsics.height, s.intrinsics.fx, s.intrinsics.fy, s.intrinsics.cx, s.intrinsics.cy,
                  s.distortion.isIdentity() ? "" : " plumb_bob");
    return std::string(text);
  };
  if (c.depth) add(stream("depth", *c.depth));
  if (c.colour) add(stream("colour", *c.colour));
  if (c.T_colour_depth) {
    char text[96];
    const Eigen::AngleAxisd aa(c.T_colour_depth->R_world_cam);
    std::snprintf(text, sizeof text, "depth to colour %.1f mm, %.2f deg", c.T_colour_depth->t_world_cam.norm() * 1e3,
                  aa.angle() * 180.0 / M_PI);
    add(text);
  }
  if (c.depth_scale_m) add("depth scale " + number(*c.depth_scale_m) + " m");
  return out.empty() ? "nothing" : out;
}

}  // namespace fovea::hal

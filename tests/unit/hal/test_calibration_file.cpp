// Calibration files (hal/calibration_file.h): real-world shaped examples of
// each format, every error with the message the user sees, and truncations of
// a valid file (an error or a result, never a crash).
#include "hal/calibration_file.h"

#include <cmath>
#include <fstream>
#include <limits>
#include <string>

#include <gtest/gtest.h>

#include "tests/support/process.h"

namespace fovea::hal {
namespace {

using test::TempDir;

// What realsense-ros publishes on /camera/color/camera_info for a D435 at
// 640x480, written out by camera_calibration_parsers (ROS camera_info YAML).
const char* kRealSenseColour = R"(image_width: 640
image_height: 480
camera_name: d435_color
camera_matrix:
  rows: 3
  cols: 3
  data: [615.9, 0, 319.5, 0, 616.1, 240.6, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0, 0, 0, 0, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [615.9, 0, 319.5, 0, 0, 616.1, 240.6, 0, 0, 0, 1, 0]
)";

// cv::FileStorage output of a stereo calibration (IR camera 1, colour camera 2),
// T in millimetres as the chessboard's squares were given in mm.
const char* kOpenCvStereo = R"(%YAML:1.0
---
image_width: 640
image_height: 480
translation_unit: mm
K1: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 5.7735e+02, 0., 3.1950e+02, 0., 5.7735e+02, 2.3950e+02, 0., 0., 1. ]
D1: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ -1.2e-02, 3.1e-02, 0., 0., 0. ]
K2: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 5.2500e+02, 0., 3.1950e+02, 0., 5.2500e+02, 2.3950e+02, 0., 0., 1. ]
D2: !!opencv-matrix
   rows: 1
   cols: 8
   dt: d
   data: [ 2.6e-01, -8.4e-01, -1.0e-03, 2.0e-03, 9.1e-01, 0., 0., 0. ]
R: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 0.9999500004166653, -0.009999833334166664, 0., 0.009999833334166664, 0.9999500004166653, 0., 0., 0., 1. ]
T: !!opencv-matrix
   rows: 3
   cols: 1
   dt: d
   data: [ -25.0, 0.1, -0.3 ]
E: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 0., 0., 0., 0., 0., 0., 0., 0., 0. ]
)";

std::string parseError(const std::string& text) {
  Result<CameraCalibration> c = parseCalibration(text, "cal.yaml");
  return c ? "(parsed)" : c.status().message();
}

std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

TEST(CalibrationFile, RosCameraInfoIsTheColourCamera) {
  Result<CameraCalibration> c = parseCalibration(kRealSenseColour, "d435_color.yaml");
  ASSERT_TRUE(c.isOk()) << c.status().message();
  ASSERT_TRUE(c->colour.has_value());
  EXPECT_FALSE(c->depth.has_value());
  EXPECT_FALSE(c->T_colour_depth.has_value());
  const CameraIntrinsics& k = c->colour->intrinsics;
  EXPECT_EQ(k.width, 640);
  EXPECT_EQ(k.height, 480);
  EXPECT_DOUBLE_EQ(k.fx, 615.9);
  EXPECT_DOUBLE_EQ(k.fy, 616.1);
  EXPECT_DOUBLE_EQ(k.cx, 319.5);
  EXPECT_DOUBLE_EQ(k.cy, 240.6);
  EXPECT_EQ(c->colour->distortion.model, Distortion::Model::kPlumbBob);
  EXPECT_TRUE(c->colour->distortion.isIdentity());
  EXPECT_EQ(c->source, "d435_color.yaml");
}

TEST(CalibrationFile, OpenCvStereoGivesBothCamerasAndTheExtrinsicsInMetres) {
  Result<CameraCalibration> c = parseCalibration(kOpenCvStereo, "stereo.yml");
  ASSERT_TRUE(c.isOk()) << c.status().message();
  ASSERT_TRUE(c->depth && c->colour && c->T_colour_depth);
  EXPECT_DOUBLE_EQ(c->depth->intrinsics.fx, 577.35);
  EXPECT_DOUBLE_EQ(c->colour->intrinsics.fx, 525.0);
  EXPECT_EQ(c->depth->distortion.model, Distortion::Model::kPlumbBob);
  EXPECT_DOUBLE_EQ(c->depth->distortion.coeffs[0], -0.012);
  EXPECT_DOUBLE_EQ(c->colour->distortion.coeffs[4], 0.91);  // 8 coefficients, the last 3 zero
  EXPECT_NEAR(c->T_colour_depth->t_world_cam.x(), -0.025, 1e-15);
  EXPECT_NEAR(c->T_colour_depth->t_world_cam.z(), -0.0003, 1e-15);
  EXPECT_NEAR(c->T_colour_depth->R_world_cam(1, 0), 0.009999833334166664, 1e-15);
  EXPECT_NE(describeCalibration(c.value()).find("depth to colour 25.0 mm"), std::string::npos)
      << describeCalibration(c.value());
}

TEST(CalibrationFile, OpenCvSingleCameraSample) {
  // What OpenCV's camera calibration sample writes (Brown-Conrady, 5 terms).
  const std::string text = "%YAML:1.0\n---\ncalibration_time: \"Mon 01 Jan\"\nimage_width: 1280\nimage_height: 720\n"
                           "camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
                           "   data: [ 9.1e+02, 0., 6.4e+02, 0., 9.1e+02, 3.6e+02, 0., 0., 1. ]\n"
                           "distortion_coefficients: !!opencv-matrix\n   rows: 5\n   cols: 1\n   dt: d\n"
                           "   data: [ 0.1, -0.2, 0., 0., 0.05 ]\navg_reprojection_error: 0.21\n";
  Result<CameraCalibration> c = parseCalibration(text, "cam.yml");
  ASSERT_TRUE(c.isOk()) << c.status().message();
  EXPECT_EQ(c->colour->intrinsics.width, 1280);
  EXPECT_DOUBLE_EQ(c->colour->distortion.coeffs[4], 0.05);
}

TEST(CalibrationFile, CombinedFileWithReferencedAndInlineCameras) {
  TempDir dir;
  std::ofstream(dir.file("colour.yaml")) << kRealSenseColour;
  const std::string combined =
      "# fovea calibration\n"
      "colour: colour.yaml\n"
      "depth:\n"
      "  image_width: 848\n"
      "  image_height: 480\n"
      "  camera_matrix: {rows: 3, cols: 3, data: [421.0, 0, 424.0, 0, 421.0, 240.0, 0, 0, 1]}\n"
      "  distortion_model: none\n"
      "T_colour_depth:\n"
      "  rotation_xyzw: [0, 0, 0, 2]\n"  // normalised to the identity
      "  translation_m: [0.015, 0.0, 0.0]\n"
      "depth_scale_m: 0.001\n";
  std::ofstream(dir.file("fovea-cal.yaml")) << combined;
  Result<CameraCalibration> c = loadCalibrationFile(dir.file("fovea-cal.yaml"));
  ASSERT_FALSE(c.isOk());  // norm 2 is not "near unit length": refused, not silently normalised
  EXPECT_NE(c.status().message().find("T_colour_depth.rotation_xyzw: not a rotation quaternion"), std::string::npos)
      << c.status().message();
  std::ofstream(dir.file("fovea-cal.yaml")) << replaced(combined, "[0, 0, 0, 2]", "[0, 0, 0, 1.0001]");
  c = loadCalibrationFile(dir.file("fovea-cal.yaml"));
  ASSERT_TRUE(c.isOk()) << c.status().message();
  EXPECT_EQ(c->colour->intrinsics.width, 640);
  EXPECT_EQ(c->depth->intrinsics.width, 848);
  EXPECT_EQ(c->depth->distortion.model, Distortion::Model::kNone);
  EXPECT_TRUE(c->T_colour_depth->R_world_cam.isApprox(Eigen::Matrix3d::Identity(), 1e-15));
  EXPECT_DOUBLE_EQ(c->T_colour_depth->t_world_cam.x(), 0.015);
  EXPECT_DOUBLE_EQ(*c->depth_scale_m, 0.001);
  // A rotation as 9 numbers.
  const std::string nine = replaced(combined, "rotation_xyzw: [0, 0, 0, 2]", "rotation: [0, -1, 0, 1, 0, 0, 0, 0, 1]");
  std::ofstream(dir.file("nine.yaml")) << nine;
  c = loadCalibrationFile(dir.file("nine.yaml"));
  ASSERT_TRUE(c.isOk()) << c.status().message();
  EXPECT_EQ(c->T_colour_depth->R_world_cam(0, 1), -1.0);
  // A referenced file that is missing is named.
  std::ofstream(dir.file("missing-ref.yaml")) << "colour: nowhere.yaml\n";
  c = loadCalibrationFile(dir.file("missing-ref.yaml"));
  ASSERT_FALSE(c.isOk());
  EXPECT_NE(c.status().message().find("colour: calibration file " + dir.file("nowhere.yaml") + " does not exist"),
            std::string::npos)
      << c.status().message();
}

TEST(CalibrationFile, MissingFileAndDirectory) {
  Result<CameraCalibration> c = loadCalibrationFile("/nonexistent/cal.yaml");
  ASSERT_FALSE(c.isOk());
  EXPECT_EQ(c.status().code(), ErrorCode::kNotFound);
  EXPECT_EQ(c.status().message(), "calibration file /nonexistent/cal.yaml does not exist");
  TempDir dir;
  c = loadCalibrationFile(dir.path());
  ASSERT_FALSE(c.isOk());
  EXPECT_EQ(c.status().code(), ErrorCode::kIoError);
}

TEST(CalibrationFile, NotYamlNamesTheLine) {
  EXPECT_EQ(parseError("image_width: 640\ncamera_matrix: [1, 2\n"),
            "cal.yaml:3: not valid YAML: end of sequence flow not found");
  EXPECT_EQ(parseError("just text"), "cal.yaml: not a calibration file (expected a YAML mapping: a ROS camera_info, an "
                                     "OpenCV FileStorage or a fovea calibration; see docs/calibration.md)");
  EXPECT_NE(parseError("a: 1\n").find("not a calibration file: expected a ROS camera_info"), std::string::npos);
  EXPECT_NE(parseError("").find("not a calibration file"), std::string::npos);
  EXPECT_NE(parseError(std::string("\0\x01\xff", 3)).find("cal.yaml"), std::string::npos);
}

TEST(CalibrationFile, MissingField) {
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "image_height: 480\n", "")), "cal.yaml: image_height: missing");
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "  data: [615.9, 0, 319.5, 0, 616.1, 240.6, 0, 0, 1]\n", "")),
            "cal.yaml: camera_matrix.data: missing");
  EXPECT_EQ(parseError(replaced(kOpenCvStereo, "R: !!opencv", "Rx: !!opencv")), "cal.yaml: R: missing");
  EXPECT_NE(parseError(replaced(kOpenCvStereo, "image_width: 640\nimage_height: 480\n", ""))
                .find("image_width/image_height (or image_size: [w, h]) missing"),
            std::string::npos);
}

TEST(CalibrationFile, WrongShape) {
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "  rows: 3\n  cols: 3\n  data: [615.9", "  rows: 2\n  cols: 3\n  data: [615.9")),
            "cal.yaml: camera_matrix: rows x cols = 2x3 but data holds 9 numbers");
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "cols: 4\n  data: [615.9, 0, 319.5, 0, 0,", "cols: 4\n  data: [615.9, 0, 319.5, 0,")),
            "cal.yaml: projection_matrix: rows x cols = 3x4 but data holds 11 numbers");
  EXPECT_EQ(parseError(replaced(kOpenCvStereo, "   rows: 3\n   cols: 1\n", "   rows: 1\n   cols: 1\n")),
            "cal.yaml: T: rows x cols = 1x1 but data holds 3 numbers");
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "data: [0, 0, 0, 0, 0]", "data: [0, 0, 0]")),
            "cal.yaml: distortion_coefficients: rows x cols = 1x5 but data holds 3 numbers");
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "cols: 5\n  data: [0, 0, 0, 0, 0]", "cols: 6\n  data: [0, 0, 0, 0, 0, 0]")),
            "cal.yaml: distortion_model: plumb_bob takes 5 coefficients (k1 k2 p1 p2 k3; OpenCV also writes 4, 8, 12 "
            "or 14), got 6");
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "camera_matrix:\n  rows: 3", "camera_matrix: 7\nx:\n  rows: 3")),
            "cal.yaml: camera_matrix: expected a matrix (rows, cols, data) or a list of numbers");
}

TEST(CalibrationFile, NotANumberNaNAndZeroFocalLength) {
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "615.9, 0, 319.5", ".nan, 0, 319.5")),
            "cal.yaml: camera_matrix.data: '.nan' is not a number");
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "615.9, 0, 319.5", "nan, 0, 319.5")),
            "cal.yaml: camera_matrix.data: 'nan' is not finite");
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "615.9, 0, 319.5", "0, 0, 319.5")),
            "cal.yaml: camera_matrix: fx must be positive (got 0)");
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "616.1, 240.6", "-616.1, 240.6")),
            "cal.yaml: camera_matrix: fy must be positive (got -616.1)");
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "image_width: 640", "image_width: zero")),
            "cal.yaml: image_width: 'zero' is not a number");
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "image_width: 640", "image_width: 0")),
            "cal.yaml: image_width/image_height: must be within 1 .. 16384 (got 0x480)");
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "image_width: 640", "image_width: 640.5")),
            "cal.yaml: image_width: expected an integer, got 640.5");
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "image_width: 640", "image_width: 300")),
            "cal.yaml: camera_matrix: principal point (319.5, 240.6) lies outside the 300x480 image: is "
            "image_width/image_height the calibrated resolution?");
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "0, 616.1", "3, 616.1")),
            "cal.yaml: camera_matrix: not a camera matrix [fx 0 cx; 0 fy cy; 0 0 1] (got 3, 0, 0, 1 in the lower rows)");
}

TEST(CalibrationFile, NonRotationsAndUnits) {
  EXPECT_NE(parseError(replaced(kOpenCvStereo, "0.9999500004166653, -0.0099", "0.99, -0.0099"))
                .find("cal.yaml: R: not a rotation (R^T R differs from I by"),
            std::string::npos);
  EXPECT_NE(parseError(replaced(kOpenCvStereo, "0., 0., 1. ]\nT:", "0., 0., -1. ]\nT:"))
                .find("cal.yaml: R: not a rotation (determinant -1, a reflection"),
            std::string::npos);
  EXPECT_EQ(parseError(replaced(kOpenCvStereo, "translation_unit: mm\n", "")),
            "cal.yaml: T: length 25.002 m is no RGB-D baseline: OpenCV's T is in the calibration target's unit; add "
            "translation_unit: mm (or cm, m)");
  EXPECT_EQ(parseError(replaced(kOpenCvStereo, "translation_unit: mm", "translation_unit: inch")),
            "cal.yaml: translation_unit: expected m, cm or mm (the unit of T: the calibration target's)");
  const std::string combined = "T_colour_depth:\n  rotation_xyzw: [0, 0, 0, 0]\n  translation_m: [0.01, 0, 0]\n";
  EXPECT_EQ(parseError(combined),
            "cal.yaml: T_colour_depth.rotation_xyzw: not a rotation quaternion (x, y, z, w with length near 1; got "
            "length 0; the identity is [0, 0, 0, 1])");
  EXPECT_EQ(parseError("T_colour_depth:\n  translation_m: [0.01, 0, 0]\n"),
            "cal.yaml: T_colour_depth.rotation: missing (9 numbers row-major, or rotation_xyzw: [x, y, z, w])");
  EXPECT_EQ(parseError("T_colour_depth:\n  rotation_xyzw: [0, 0, 0, 1]\n  translation_m: [0.01, 0]\n"),
            "cal.yaml: T_colour_depth.translation_m: expected 3 numbers (3x1), got 2");
  EXPECT_EQ(parseError("colour: x.yaml\nextra: 1\n"),
            "cal.yaml: unknown key 'extra' (known: depth, colour, T_colour_depth, depth_scale_m)");
  EXPECT_EQ(parseError("depth_scale_m: 0.001\ncolour: {image_width: 0}\n"),
            "cal.yaml: colour.image_height: missing");
}

TEST(CalibrationFile, UnknownDistortionModelsListTheKnownOnes) {
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "plumb_bob", "equidistant")),
            "cal.yaml: distortion_model: distortion model 'equidistant' is not supported (known: plumb_bob (k1 k2 p1 "
            "p2 k3, also called radtan or brown_conrady), none); undistort the images or calibrate with the plumb_bob "
            "model");
  EXPECT_NE(parseError(replaced(kOpenCvStereo, "9.1e-01, 0., 0., 0. ]", "9.1e-01, 0.3, 0., 0. ]"))
                .find("coefficient 6 of 8 is not zero: that is OpenCV's rational/thin-prism model"),
            std::string::npos);
  EXPECT_EQ(parseError(replaced(kRealSenseColour, "distortion_model: plumb_bob", "distortion_model: none")),
            "(parsed)");  // none with zero coefficients
}

// Every prefix of a valid file parses or fails with a message: never a crash,
// never an exception out of the parser.
TEST(CalibrationFile, TruncationsNeverCrash) {
  for (const char* text : {kRealSenseColour, kOpenCvStereo}) {
    const std::string full(text);
    std::size_t parsed = 0;
    for (std::size_t n = 0; n <= full.size(); ++n) {
      Result<CameraCalibration> c = parseCalibration(full.substr(0, n), "cut.yaml");
      if (c) {
        ++parsed;
      } else {
        EXPECT_FALSE(c.status().message().empty());
        EXPECT_EQ(c.status().message().rfind("cut.yaml", 0), 0u) << c.status().message();
      }
    }
    EXPECT_GT(parsed, 0u);  // the whole file, at least
  }
}

}  // namespace
}  // namespace fovea::hal

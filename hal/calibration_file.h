// Calibration files: what hal::CameraCalibration (hal/calibration.h) is read
// from. Three formats, told apart by their keys (docs/calibration.md):
//
//  - ROS camera_info YAML (camera_calibration_parsers, `rs-enumerate-devices -c`
//    turned into it, ROS camera_calibration's ost.yaml): image_width,
//    image_height, camera_matrix {rows, cols, data}, distortion_model
//    (plumb_bob, or none/empty), distortion_coefficients, rectification_matrix,
//    projection_matrix. One camera per file: alone, it is the COLOUR camera
//    (the depth camera's intrinsics usually come from the device).
//  - OpenCV FileStorage YAML (`%YAML:1.0`, `!!opencv-matrix` nodes with rows,
//    cols, dt, data): one camera (camera_matrix, distortion_coefficients,
//    image_width, image_height: the colour camera, as above) or a stereo
//    calibration (K1 or M1, D1, K2 or M2, D2, R, T; camera 1 is the depth (IR)
//    camera, camera 2 the colour camera, so p_2 = R p_1 + T is T_colour_depth)
//    with image_width/image_height or image_size [w, h] for both (image_size_1,
//    image_size_2 per camera). OpenCV's T is in the unit of the calibration
//    target's squares: `translation_unit: mm` (m, cm, mm) says which; without
//    it T is taken as metres and a T longer than 1 m is refused as a likely
//    millimetre value.
//  - fovea's own YAML, the combined form: `depth:` and `colour:` (or `color:`),
//    each a file name (relative to this file; a single-camera file of either
//    format above) or an inline camera_info mapping; `T_colour_depth:` with
//    `rotation: [9 numbers, row-major]` or `rotation_xyzw: [x, y, z, w]` and
//    `translation_m: [x, y, z]`; `depth_scale_m:`.
//
// Validation names the file and field: sizes positive (up to 16384), fx and fy
// positive and finite, principal point inside the image (an error: it is
// always a wrong size or swapped fields), camera matrix of the form
// [fx 0 cx; 0 fy cy; 0 0 1], matrix shapes, rotations that are rotations
// (R^T R = I and det +1 within 1e-6; a quaternion is normalised, a zero one
// refused), finite translations. Distortion models other than plumb_bob
// (k1 k2 p1 p2 k3; OpenCV's 4, or 8/12/14 whose extra terms are zero) and
// none are refused with the list of known ones. Nothing throws (yaml-cpp's
// exceptions are caught here).
#pragma once

#include <string>
#include <string_view>

#include "core/result.h"
#include "hal/calibration.h"

namespace fovea::hal {

// Reads and parses a calibration file. kNotFound when it does not exist,
// kIoError when unreadable, kParseError naming the file (and line for YAML
// syntax) and field otherwise.
Result<CameraCalibration> loadCalibrationFile(const std::string& path);

// Parses calibration text. File names inside a combined file are taken
// relative to base_dir. The result's source is name_for_errors.
Result<CameraCalibration> parseCalibration(std::string_view text, std::string_view name_for_errors,
                                           std::string_view base_dir = ".");

// A one-line description for the log: "colour 1280x720 fx 908.3 ..., depth to
// colour 15.0 mm" (what is set, nothing when empty).
std::string describeCalibration(const CameraCalibration& calibration);

}  // namespace fovea::hal

// The mock RGB-D camera: ray-casts a built-in scene (hal/camera/mock/scene.h)
// and adds Kinect-like depth artefacts. An ordinary backend: spec
// "mock:SCENE[,key=value...]", see mockCameraHelp().
//
// Sensor model (noise=on):
//  - Intrinsics: Kinect v1 nominal pinhole, fx = fy = 525 * width / 640 (square
//    pixels), cx = (width - 1) / 2, cy = (height - 1) / 2, no distortion.
//  - Depth: z along the optical axis in uint16 millimetres (depth_scale_m 0.001),
//    valid from 0.4 m to 8 m (0 outside). Axial noise after Nguyen, Izadi and
//    Lovell (3DIMPVT 2012): sigma_z = 0.0012 + 0.0019 (z - 0.4)^2
//    + 0.0001 / sqrt(z) * theta^2 / (pi/2 - theta)^2 m, theta the incidence angle
//    (capped at 80 degrees in that term). Missing pixels (0): with a probability
//    ramping from 0 at 75 degrees incidence to 1 at 85 degrees; on the far side of
//    depth discontinuities (the pixels next to a nearer surface always, the second
//    pixel to the left of its left edge half of the time: the IR projector's
//    shadow); per material (black screen, glass); and 0.3 % at random.
//  - RGB: texture colour with Lambertian shading from the scene's point light,
//    registered to depth, plus uniform noise of +-4 levels per channel.
//  - Every random draw is a hash of (seed, pixel, frame) (frame fixed at 0 when
//    temporal_noise=off), so frames are reproducible and independent of threads.
// noise=off gives the ideal sensor: exact z rounded to the nearest millimetre,
// still cut to 0.4..8 m, no missing pixels otherwise, RGB without noise.
//
// Time: frame `sequence` (0, 1, 2... from the first acquire) shows the scene
// and the camera path at t = sequence / fps, and stamp_ns = round(sequence *
// 1e9 / fps): deterministic, whatever realtime says. realtime=on only paces
// acquire() to the wall clock (and skips sequence numbers the consumer was too
// slow for, as a real sensor drops frames).
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "hal/camera.h"
#include "hal/camera/mock/faults.h"
#include "hal/camera/mock/scene.h"

namespace fovea::hal::mock {

enum class PathKind {
  kStatic,     // the scene's default pose
  kPan,        // default eye, yaw swinging +-pan_amplitude_rad (period pan_period_s)
  kOrbit,      // around the focus point at orbit_radius_m, orbit_height_m, looking at it
  kDolly,      // default view, moving forward up to dolly_distance_m and back
  kKeyframes,  // linear interpolation of eye and target, clamped at the ends
};

struct Keyframe {
  double t_s = 0.0;
  Eigen::Vector3d eye_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d target_m = Eigen::Vector3d::UnitY();
};

struct CameraPath {
  PathKind kind = PathKind::kStatic;
  std::vector<Keyframe> keyframes;  // kKeyframes: at least one, times increasing
};

// Camera pose on `path` at time_s (paths start at t = 0). Allocation-free.
Pose cameraPoseAt(const CameraPath& path, const SceneInfo& scene, double time_s);

struct MockCameraOptions {
  std::string scene = "living-room";
  uint64_t seed = 1;
  int width = 640;
  int height = 480;
  double fps = 30.0;
  CameraPath path;
  bool noise = true;
  bool temporal_noise = true;
  bool realtime = false;
  std::vector<FaultSpec> faults;  // fault=..., see hal/camera/mock/faults.h
  // A static scene seen from a path that moves every frame (orbit, pan, dolly)
  // is rendered row by row into the frame (three rows of scratch: the
  // noiseless image would be re-rendered whole every frame anyway, and is 19
  // bytes a pixel); false keeps the whole image as the other paths do (tests
  // compare the two bit for bit).
  bool stream_rows = true;
};

// Parses "SCENE[,key=value...]" (the spec after "mock:"). Keys: seed=UINT,
// size=WxH, fps=F, path=static|pan|orbit|dolly|keyframes:t,x,y,z,tx,ty,tz;...,
// noise=on|off, temporal_noise=on|off, realtime=on|off,
// fault=none|KIND[:DURATION]@FRAME[:N];... (faults.h). A comma-separated piece
// without '=' continues the previous value (the keyframe lists contain commas).
// kInvalidArgument naming the key and its accepted values on any error.
Result<MockCameraOptions> parseMockCameraOptions(std::string_view args);

// The help line for cameraSpecHelp().
std::string mockCameraHelp();

class MockCamera final : public Camera {
 public:
  // Never fails: options come from parseMockCameraOptions() (an unknown scene
  // name gives an empty scene). open() allocates every buffer.
  explicit MockCamera(MockCameraOptions options);
  // The backend-table entry: parses the options, constructs, does not open.
  static Result<std::unique_ptr<Camera>> create(std::string_view args);

  Status open() override;
  Status start() override;
  Status acquire(RgbdFrame& slot, std::chrono::nanoseconds timeout) override;
  void stop() override;

  const CameraInfo& info() const override { return info_; }
  CameraCounters counters() const override { return counters_.snapshot(); }

  const MockCameraOptions& options() const { return options_; }
  // The clock the injected faults' durations run on (not owned; nullptr: the
  // steady clock). Tests pass a ManualClock so a 2 s stall takes no time.
  void setClock(MockClock* clock) { clock_ = clock != nullptr ? clock : &steadyMockClock(); }
  // scene().info().focus_point_m (also in info().focus_point_m) is where the
  // service aims the gaze.
  const Scene& scene() const { return scene_; }

 private:
  // The noiseless image the sensor model starts from, one entry per pixel:
  // the whole image, or a ring of `rows` rows (row y at y % rows).
  struct CleanImage {
    int width = 0;
    int rows = 0;  // 0: the whole image
    std::size_t at(int x, int y) const {
      return static_cast<std::size_t>(rows > 0 ? y % rows : y) * static_cast<std::size_t>(width) +
             static_cast<std::size_t>(x);
    }
    std::vector<double> depth_m;   // z along the optical axis; 0: the ray hit nothing
    std::vector<float> sigma_m;    // axial noise
    std::vector<float> drop_prob;  // incidence, material and random dropout; in work_, with the discontinuity bands (updateDropouts)
    std::vector<uint8_t> rgb;      // shaded colour, 3 bytes per pixel
    void resize(int image_width, int image_height, int ring_rows);
  };
  struct PixelRect {  // half-open [x0, x1) x [y0, y1); empty when x0 >= x1 or y0 >= y1
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    bool empty() const { return x0 >= x1 || y0 >= y1; }
  };

  // acquire()'s steps; ok means go on, anything else is what acquire() returns.
  Status waitUntilDue(std::chrono::nanoseconds timeout);
  Status applyFaults(std::chrono::nanoseconds timeout);
  // The renderer (render.cpp).
  void renderClean(const Pose& pose, double time_s);
  void renderRect(const Pose& pose, double time_s, SceneLayer layer, const PixelRect& rect,
                  CleanImage& out);
  // renderRect()'s steps: the culling set-up, then per row the ray cast (its
  // hits into row_hits_) and the noise model over those hits.
  void sortShapeRects(const Pose& pose);
  std::size_t castRow(const Pose& pose, double time_s, int y, const PixelRect& rect,
                      bool static_layer, bool dynamic_layer, CleanImage& out);
  void modelRowNoise(int y, std::size_t hit_count, CleanImage& out);
  PixelRect projectBox(const Pose& pose, const Eigen::Vector3d& min_m,
                       const Eigen::Vector3d& max_m) const;
  void copyRect(const CleanImage& from, const PixelRect& rect, CleanImage& to) const;
  PixelRect dynamicRect(const Pose& pose, double time_s) const;
  void updateDropouts(const PixelRect& rect);
  float* nearRow(int y);  // near_row_min_m_'s row for image row y
  void fillNearRow(int y, int x0, int x1);
  void finishDropoutRow(int y, int x0, int x1);
  void writeFrame(RgbdFrame& slot, uint64_t sequence) const;
  void writeRows(RgbdFrame& slot, uint64_t sequence, int y0, int y1) const;
  // The row-by-row path (rows_only_): each row ray-cast, then the row above
  // it finished (its dropout bands need the rows either side) and written.
  void renderAndWriteRows(const Pose& pose, double time_s, RgbdFrame& slot, uint64_t sequence);
  void writeGarbage(RgbdFrame& slot, uint64_t sequence) const;
  // Fires the faults due at sequence_; kNotFound when a disconnect fired.
  Status fireFaults();
  PixelRect fullRect() const { return {0, 0, options_.width, options_.height}; }
  PixelRect unite(const PixelRect& a, const PixelRect& b) const;
  PixelRect grow(const PixelRect& r, int pixels) const;

  MockCameraOptions options_;
  Scene scene_;
  CameraInfo info_;

  bool opened_ = false;
  bool started_ = false;
  uint64_t sequence_ = 0;
  uint64_t start_sequence_ = 0;
  std::chrono::steady_clock::time_point start_time_;

  // Scratch, sized in open(). For a static scene `work_` is the whole render and
  // is kept while the pose stays the same (on an orbit, a pan or a dolly, three
  // rows of it: renderAndWriteRows). For a dynamic scene `background_`
  // holds the static layer for `rendered_pose_`, and each frame re-renders only
  // the dynamic shapes' screen rectangle (restoring last frame's from background_).
  std::vector<double> ray_x_;  // (u - cx) / fx per column
  std::vector<double> ray_y_;  // (v - cy) / fy per row
  CleanImage background_;
  CleanImage work_;
  bool rows_only_ = false;  // work_ is a ring of three rows (MockCameraOptions::stream_rows)
  std::vector<float> near_row_min_m_;   // the dropout bands' horizontal pass: three rows (nearRow)
  // Screen-space culling: each static shape's projected bounds, the shapes in
  // order of their first column, those covering the current row and pixel.
  std::vector<PixelRect> shape_rects_;
  std::vector<uint16_t> shape_order_;
  std::vector<uint16_t> row_shapes_;
  std::vector<uint16_t> active_shapes_;
  // One row's hits, for the sensor model's second pass (see modelRowNoise()).
  struct RowHit {
    int x;
    float n_dot_d;    // |normal . dir|
    float d_squared;  // |dir|^2
    float ir_dropout;
  };
  std::vector<RowHit> row_hits_;
  bool have_render_ = false;
  Pose rendered_pose_;
  PixelRect dynamic_rect_;  // where work_ differs from background_

  CameraCounterSet counters_;

  // Fault injection (options_.faults): which have fired, and what stands.
  MockClock* clock_ = &steadyMockClock();
  std::vector<bool> fault_fired_;
  bool connected_ = true;           // false from a disconnect until a successful open()
  int64_t gone_until_ns_ = 0;       // open() fails before this (clock_ time)
  bool stalling_ = false;
  int64_t stall_until_ns_ = 0;      // while stalling_, acquire() delivers nothing before this
  uint64_t wrong_size_pending_ = 0;
  uint64_t garbage_pending_ = 0;
};

}  // namespace fovea::hal::mock

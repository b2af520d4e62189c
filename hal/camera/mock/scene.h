// Ray-cast scenes for the mock RGB-D camera: a few analytic shapes (boxes,
// spheres, vertical cylinders, planes) with procedural textures. No meshes, no
// files, no global state: the same ray at the same time gives the same bits.
//
// World frame of every mock scene: right-handed, z up, metres, floor at z = 0.
// The living room spans x 0..6 (west to east), y 0..4.5 (south to north),
// z 0..2.7. Cameras use the OpenCV frame (x right, y down, z forward) and a Pose
// maps camera coordinates to world coordinates (see hal/frame.h).
#pragma once

#include <cstdint>
#include <limits>
#include <numbers>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "core/result.h"
#include "hal/frame.h"

namespace fovea::hal::mock {

// The mock's constants, for scene.cpp and mock_camera.cpp alike.
inline constexpr double kInf = std::numeric_limits<double>::infinity();
inline constexpr double kTwoPi = 2.0 * std::numbers::pi;

enum class TextureKind {
  kSolid,    // color_a
  kChecker,  // squares of scale_m
  kStripes,  // bands of width scale_m across u
  kWood,     // planks along u with wavy grain lines scale_m apart
  kNoise,    // two octaves of value noise with cells of scale_m
};

// Colours are linear RGB in [0, 1]. Textures are evaluated in surface
// coordinates (u, v) in metres, so a pattern keeps its size on every face.
struct Material {
  TextureKind texture = TextureKind::kSolid;
  Eigen::Vector3f color_a = Eigen::Vector3f(0.8f, 0.8f, 0.8f);
  Eigen::Vector3f color_b = Eigen::Vector3f(0.5f, 0.5f, 0.5f);
  double scale_m = 0.1;
  bool swap_uv = false;     // turns the pattern by 90 degrees on the surface
  bool emissive = false;    // lamps and windows: the colour is not shaded
  float ir_dropout = 0.0f;  // extra chance the depth sensor misses it (black screen, glass)
  uint32_t salt = 0;        // decorrelates the noise of materials sharing a texture
};

// Smooth periodic motion of a dynamic shape around its rest position:
// offset = amplitude_m * sin(2 pi frequency_hz t + phase_rad), per axis. Every
// term has zero mean over its period, so the rest position is the mean position.
struct Motion {
  Eigen::Vector3d amplitude_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d frequency_hz = Eigen::Vector3d::Zero();
  Eigen::Vector3d phase_rad = Eigen::Vector3d::Zero();
  // From this time on the shape is gone: it left the scene (the map's ghost test).
  double gone_from_s = std::numeric_limits<double>::infinity();

  Eigen::Vector3d offsetAt(double time_s) const;
  bool presentAt(double time_s) const { return time_s < gone_from_s; }
};

enum class ShapeKind {
  kBox,   // axis-aligned, one material
  kRoom,  // axis-aligned box meant to be seen from inside, one material per face
  kSphere,
  kCylinder,  // axis along world z, capped
  kPlane,
};

struct Shape {
  ShapeKind kind = ShapeKind::kBox;
  int material = 0;
  // Room: materials of the faces at min x, max x, min y, max y, min z (floor), max z.
  int face_material[6] = {0, 0, 0, 0, 0, 0};
  // Box and room: their corners. Sphere and cylinder: their bounds at rest.
  Eigen::Vector3d min_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d max_m = Eigen::Vector3d::Zero();
  // Sphere: centre at rest. Cylinder (axis along world z): x, y of the axis; the
  // caps are at min_m.z() and max_m.z().
  Eigen::Vector3d center_m = Eigen::Vector3d::Zero();
  double radius_m = 0.0;
  // Plane: the points p with normal . p == offset_m; texture axes u_axis, v_axis.
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double offset_m = 0.0;
  Eigen::Vector3d u_axis = Eigen::Vector3d::UnitX();
  Eigen::Vector3d v_axis = Eigen::Vector3d::UnitY();
  // Dynamic shapes (spheres and boxes) move with `motion`, their bounds and
  // centre being those at rest.
  Motion motion;
};

// The nearest surface along a ray origin + t * dir (dir need not be unit).
struct Hit {
  double t = 0.0;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit, facing the ray origin
  const Shape* shape = nullptr;
  int material = 0;
  int face_axis = -1;  // box, room: axis of the face hit; cylinder: 2 on a cap, -1 on the side
  // The hit point in the shape's own frame, where its texture is fixed: the
  // world point for a static shape, less its offset for a moving one, in the
  // camera's frame for a carried one.
  Eigen::Vector3d local_m = Eigen::Vector3d::Zero();
};

// What a camera path and the service need to know about a scene.
struct SceneInfo {
  std::string name;
  // Where the service aims the gaze: the living room's centre, the balloon's
  // mean position.
  Eigen::Vector3d focus_point_m = Eigen::Vector3d::Zero();
  // Default camera: its position and the point it looks at.
  Eigen::Vector3d default_eye_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d default_target_m = Eigen::Vector3d::UnitY();
  // Lighting: one point light plus ambient, Lambertian, no shadows.
  Eigen::Vector3d light_m = Eigen::Vector3d(0.0, 0.0, 2.5);
  float ambient = 0.3f;
  // Built-in camera paths (see MockCamera): yaw swing about the default eye;
  // circle or arc around focus_point_m; back-and-forth along the view direction.
  double pan_amplitude_rad = 0.5;
  double pan_period_s = 8.0;
  double orbit_radius_m = 1.4;
  double orbit_height_m = 1.5;
  double orbit_sweep_rad = 0.0;  // 0: full circles; else swing +- this about the default azimuth
  double orbit_period_s = 24.0;
  double dolly_distance_m = 1.0;
  double dolly_period_s = 10.0;
};

enum class SceneLayer { kStatic, kDynamic, kAll };

class Scene {
 public:
  Scene() = default;  // empty: every ray misses

  // A name of names(); kInvalidArgument naming the accepted names otherwise.
  static Result<Scene> create(std::string_view name);
  // "living-room|balloon|...", for help texts and error messages.
  static std::string names();
  static bool isKnown(std::string_view name);

  const SceneInfo& info() const { return info_; }
  // The default camera pose: default_eye_m looking at default_target_m.
  Pose defaultPose() const;
  // Whether anything moves: a shape with a motion or one carried with the camera.
  bool isDynamic() const { return !dynamic_shapes_.empty() || !carried_shapes_.empty(); }
  std::size_t shapeCount() const {
    return shapes_.size() + dynamic_shapes_.size() + carried_shapes_.size();
  }

  // Nearest hit with t in (kMinT, t_max) among the shapes of `layer` at time_s.
  // Allocation-free and const: safe to call from several threads.
  bool intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double time_s,
                 SceneLayer layer, double t_max, Hit& hit) const;

  // Shaded colour (linear RGB in [0, 1]) of a hit returned by intersect().
  Eigen::Vector3f shade(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir,
                        const Hit& hit) const;
  // The material's extra depth dropout probability at a hit.
  float irDropout(const Hit& hit) const { return materials_[hit.material].ir_dropout; }

  // intersect() culls static shapes by the bounds of their group (a piece of
  // furniture, a shelf of books). A pinhole renderer culls better by projecting
  // each static shape's bounds into the image and testing only the shapes that
  // cover a pixel.
  std::size_t staticShapeCount() const { return shapes_.size(); }
  // False for a shape that every ray must test (a plane or a room).
  bool staticShapeBounds(std::size_t shape, Eigen::Vector3d& min_m, Eigen::Vector3d& max_m) const;
  // Nearest hit with t in (kMinT, t_max) among the listed static shapes only.
  bool intersectShapes(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir,
                       const uint16_t* shapes, std::size_t shape_count, double t_max,
                       Hit& hit) const;

  // Bounds of every dynamic shape at time_s; false when the scene has none.
  bool dynamicBounds(double time_s, Eigen::Vector3d& min_m, Eigen::Vector3d& max_m) const;

  // Shapes carried with the camera (a block in a robot's gripper): boxes fixed
  // in the camera's frame, seen the same in every frame whatever the path.
  // Nearest hit with t in (kMinT, t_max) of the ray from the camera at `camera`
  // along dir (world frame; t is the same in either frame).
  bool intersectCarried(const Pose& camera, const Eigen::Vector3d& dir, double t_max,
                        Hit& hit) const;
  // Bounds of every carried shape in the camera's frame; false when none.
  bool carriedBounds(Eigen::Vector3d& min_cam_m, Eigen::Vector3d& max_cam_m) const;

  static constexpr double kMinT = 1e-6;

 private:
  struct Group {
    Eigen::Vector3d min_m;
    Eigen::Vector3d max_m;
    bool bounded = true;  // false when it holds a plane or a room
    int first = 0;
    int count = 0;
  };

  bool intersectShape(const Shape& shape, const Eigen::Vector3d& origin, const Eigen::Vector3d& dir,
                      const Eigen::Vector3d& inv_dir, double& t_best, Hit& hit) const;
  // The built-in scenes (built_in_scenes.cpp).
  static Scene livingRoom();
  static Scene balloon(double gone_from_s = std::numeric_limits<double>::infinity());
  // The living room with a person walking through it, or a block carried with
  // the camera (issue 42's movers).
  static Scene walker(double gone_from_s = std::numeric_limits<double>::infinity());
  static Scene carried();
  // livingRoom()'s pieces, added in this order: a material's noise salt is its
  // index, and the order of the shapes and groups is part of the scene's bits.
  struct LivingRoomMaterials;
  LivingRoomMaterials addLivingRoomMaterials();
  void addLivingRoomShell(const LivingRoomMaterials& m);
  void addSofaAndPicture(const LivingRoomMaterials& m);
  void addRugAndCoffeeTable(const LivingRoomMaterials& m);
  void addBookshelf(const LivingRoomMaterials& m);
  void addBooks(const LivingRoomMaterials& m);
  void addCabinetTvWindowAndDoor(const LivingRoomMaterials& m);
  void addLampAndPlant(const LivingRoomMaterials& m);

  int addMaterial(const Material& material);
  // Static shapes are added to the open group; groups are culled by their bounds.
  void beginGroup();
  void endGroup();
  void addBox(const Eigen::Vector3d& min_m, const Eigen::Vector3d& max_m, int material);
  void addRoom(const Eigen::Vector3d& min_m, const Eigen::Vector3d& max_m,
               const int (&face_material)[6]);
  void addSphere(const Eigen::Vector3d& center_m, double radius_m, int material);
  void addCylinder(double x_m, double y_m, double radius_m, double z_min_m, double z_max_m,
                   int material);
  void addPlane(const Eigen::Vector3d& normal, double offset_m, const Eigen::Vector3d& u_axis,
                int material);
  void addMovingSphere(const Eigen::Vector3d& center_m, double radius_m, const Motion& motion,
                       int material);
  void addMovingBox(const Eigen::Vector3d& min_m, const Eigen::Vector3d& max_m,
                    const Motion& motion, int material);
  // A box in the camera's frame (OpenCV axes: x right, y down, z forward).
  void addCarriedBox(const Eigen::Vector3d& min_cam_m, const Eigen::Vector3d& max_cam_m,
                     int material);
  void addShape(const Shape& shape);

  Eigen::Vector3f albedo(const Material& material, double u, double v) const;

  SceneInfo info_;
  std::vector<Material> materials_;
  std::vector<Shape> shapes_;  // static, contiguous per group
  std::vector<Group> groups_;
  std::vector<Shape> dynamic_shapes_;
  std::vector<Shape> carried_shapes_;  // boxes, in the camera's frame
  bool group_open_ = false;
};

// Camera-to-world pose of a camera at eye_m looking at target_m with world z up
// (image x to the right, y down, no roll). Looking straight up or down, where
// "no roll" is undefined, world +y plays the part of "up".
Pose lookAtPose(const Eigen::Vector3d& eye_m, const Eigen::Vector3d& target_m);

}  // namespace fovea::hal::mock

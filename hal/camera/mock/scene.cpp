#include "hal/camera/mock/scene.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include <Eigen/Geometry>

#include "hal/camera/mock/hash.h"

namespace fovea::hal::mock {

namespace {

using Eigen::Vector3d;
using Eigen::Vector3f;

// Entry and exit of the ray through an axis-aligned box, and the axes of the
// slabs crossed there; false when it misses. A direction component of exactly
// zero is handled apart (0 * inf would be NaN).
bool slabs(const Vector3d& o, const Vector3d& d, const Vector3d& inv, const Vector3d& lo,
           const Vector3d& hi, double& t_enter, double& t_exit, int& axis_enter, int& axis_exit) {
  t_enter = -kInf;
  t_exit = kInf;
  axis_enter = 0;
  axis_exit = 0;
  for (int k = 0; k < 3; ++k) {
    if (d[k] == 0.0) {
      if (o[k] < lo[k] || o[k] > hi[k]) return false;
      continue;
    }
    double ta = (lo[k] - o[k]) * inv[k];
    double tb = (hi[k] - o[k]) * inv[k];
    if (ta > tb) std::swap(ta, tb);
    if (ta > t_enter) {
      t_enter = ta;
      axis_enter = k;
    }
    if (tb < t_exit) {
      t_exit = tb;
      axis_exit = k;
    }
  }
  return t_enter <= t_exit;
}

// Whether the ray can meet the box before t_best: a conservative test for
// culling. Where 0 * inf gives NaN the comparisons fail and that slab is ignored.
inline bool hitsBounds(const Vector3d& o, const Vector3d& inv, const Vector3d& lo,
                       const Vector3d& hi, double t_best) {
  double t0 = Scene::kMinT;
  double t1 = t_best;
  for (int k = 0; k < 3; ++k) {
    const double ta = (lo[k] - o[k]) * inv[k];
    const double tb = (hi[k] - o[k]) * inv[k];
    const double near = ta < tb ? ta : tb;
    const double far = ta < tb ? tb : ta;
    if (near > t0) t0 = near;
    if (far < t1) t1 = far;
  }
  return !(t0 > t1);
}

// A box is seen from outside (furniture), a room from inside; either way the
// first crossing beyond kMinT counts.
bool intersectBox(const Shape& s, const Vector3d& o, const Vector3d& d, const Vector3d& inv,
                  double& t_best, Hit& hit) {
  double t_enter, t_exit;
  int axis_enter, axis_exit;
  if (!slabs(o, d, inv, s.min_m, s.max_m, t_enter, t_exit, axis_enter, axis_exit)) return false;
  double t;
  int axis;
  bool max_side;  // the face at max_m[axis]
  if (t_enter > Scene::kMinT) {
    t = t_enter;
    axis = axis_enter;
    max_side = d[axis] < 0.0;
  } else if (t_exit > Scene::kMinT) {
    t = t_exit;
    axis = axis_exit;
    max_side = d[axis] > 0.0;
  } else {
    return false;
  }
  if (t >= t_best) return false;
  t_best = t;
  hit.t = t;
  hit.normal = Vector3d::Zero();
  hit.normal[axis] = d[axis] > 0.0 ? -1.0 : 1.0;
  hit.shape = &s;
  hit.material =
      s.kind == ShapeKind::kRoom ? s.face_material[2 * axis + (max_side ? 1 : 0)] : s.material;
  hit.face_axis = axis;
  return true;
}

bool intersectSphere(const Shape& s, const Vector3d& o, const Vector3d& d, double& t_best, Hit& hit) {
  const Vector3d oc = o - s.center_m;
  const double a = d.squaredNorm();
  const double b = oc.dot(d);
  const double c = oc.squaredNorm() - s.radius_m * s.radius_m;
  const double disc = b * b - a * c;
  if (disc < 0.0) return false;
  const double sq = std::sqrt(disc);
  double t = (-b - sq) / a;
  if (t <= Scene::kMinT) t = (-b + sq) / a;
  if (t <= Scene::kMinT || t >= t_best) return false;
  Vector3d n = (oc + t * d) / s.radius_m;
  if (n.dot(d) > 0.0) n = -n;
  t_best = t;
  hit.t = t;
  hit.normal = n.normalized();
  hit.shape = &s;
  hit.material = s.material;
  hit.face_axis = -1;
  return true;
}

bool intersectCylinder(const Shape& s, const Vector3d& o, const Vector3d& d, double& t_best,
                       Hit& hit) {
  const double ox = o.x() - s.center_m.x();
  const double oy = o.y() - s.center_m.y();
  const double r2 = s.radius_m * s.radius_m;
  const double z_min = s.min_m.z();
  const double z_max = s.max_m.z();
  double best = t_best;
  bool found = false;
  Vector3d n = Vector3d::Zero();
  int face = -1;
  const double a = d.x() * d.x() + d.y() * d.y();
  if (a > 0.0) {
    const double b = ox * d.x() + oy * d.y();
    const double c = ox * ox + oy * oy - r2;
    const double disc = b * b - a * c;
    if (disc >= 0.0) {
      const double sq = std::sqrt(disc);
      for (const double t : {(-b - sq) / a, (-b + sq) / a}) {
        if (t <= Scene::kMinT || t >= best) continue;
        const double z = o.z() + t * d.z();
        if (z < z_min || z > z_max) continue;
        best = t;
        found = true;
        face = -1;
        n = Vector3d(ox + t * d.x(), oy + t * d.y(), 0.0);
        break;
      }
    }
  }
  if (d.z() != 0.0) {
    for (const double z_cap : {z_min, z_max}) {
      const double t = (z_cap - o.z()) / d.z();
      if (t <= Scene::kMinT || t >= best) continue;
      const double x = ox + t * d.x();
      const double y = oy + t * d.y();
      if (x * x + y * y > r2) continue;
      best = t;
      found = true;
      face = 2;
      n = Vector3d::UnitZ();
    }
  }
  if (!found) return false;
  n.normalize();
  if (n.dot(d) > 0.0) n = -n;
  t_best = best;
  hit.t = best;
  hit.normal = n;
  hit.shape = &s;
  hit.material = s.material;
  hit.face_axis = face;
  return true;
}

bool intersectPlane(const Shape& s, const Vector3d& o, const Vector3d& d, double& t_best,
                    Hit& hit) {
  const double denom = s.normal.dot(d);
  if (std::abs(denom) < 1e-12) return false;
  const double t = (s.offset_m - s.normal.dot(o)) / denom;
  if (t <= Scene::kMinT || t >= t_best) return false;
  t_best = t;
  hit.t = t;
  hit.normal = denom > 0.0 ? Vector3d(-s.normal) : s.normal;
  hit.shape = &s;
  hit.material = s.material;
  hit.face_axis = -1;
  return true;
}

// floor() without the libm call (x86-64 without SSE4.1 has no inline floor).
// Texture coordinates stay far inside the int64_t range.
int64_t floorToInt(double x) {
  const auto i = static_cast<int64_t>(x);  // truncates towards zero
  return i - (static_cast<double>(i) > x ? 1 : 0);
}

// Value noise in [0, 1): smoothstep interpolation of lattice values from a
// fixed 128 x 128 table of 8-bit hashes. 16 KB stay in L1 (a 256 KB float
// table made texturing a third of the frame time); the pattern repeats every
// 128 cells, metres away at the cell sizes used. Computed at compile time.
constexpr int kLatticeBits = 7;
constexpr int kLatticeSize = 1 << kLatticeBits;
constexpr uint64_t kLatticeMask = kLatticeSize - 1;

struct LatticeTable {
  uint8_t values[kLatticeSize * kLatticeSize] = {};
  constexpr LatticeTable() {
    for (int i = 0; i < kLatticeSize * kLatticeSize; ++i) {
      values[i] = static_cast<uint8_t>(mix64(static_cast<uint64_t>(i) ^ 0x5EED1A771CE5ull) >> 56);
    }
  }
};

constexpr LatticeTable kLattice;

const uint8_t* latticeValues() { return kLattice.values; }

// One lattice value in [0, 1): a per-plank or per-cell random number.
float latticeValue(int64_t iu, int64_t iv, uint32_t salt) {
  const uint64_t u = (static_cast<uint64_t>(iu) + salt) & kLatticeMask;
  const uint64_t v =
      (static_cast<uint64_t>(iv) + salt * 7u + (salt >> kLatticeBits)) & kLatticeMask;
  return static_cast<float>(latticeValues()[u + (v << kLatticeBits)]) * (1.0f / 256.0f);
}

float valueNoise(double u, double v, uint32_t salt) {
  const uint8_t* lattice = latticeValues();
  const int64_t iu = floorToInt(u);
  const int64_t iv = floorToInt(v);
  auto smooth = [](double s) { return static_cast<float>(s * s * (3.0 - 2.0 * s)); };
  const float su = smooth(u - static_cast<double>(iu));
  const float sv = smooth(v - static_cast<double>(iv));
  // The salt shifts the table so that materials do not share a pattern.
  const uint64_t u0 = (static_cast<uint64_t>(iu) + salt) & kLatticeMask;
  const uint64_t v0 =
      (static_cast<uint64_t>(iv) + salt * 7u + (salt >> kLatticeBits)) & kLatticeMask;
  const uint64_t u1 = (u0 + 1) & kLatticeMask;
  const uint64_t v1 = (v0 + 1) & kLatticeMask;
  const auto a = static_cast<float>(lattice[u0 + (v0 << kLatticeBits)]);
  const auto b = static_cast<float>(lattice[u1 + (v0 << kLatticeBits)]);
  const auto c = static_cast<float>(lattice[u0 + (v1 << kLatticeBits)]);
  const auto e = static_cast<float>(lattice[u1 + (v1 << kLatticeBits)]);
  const float top = a + (b - a) * su;
  const float bottom = c + (e - c) * su;
  return (top + (bottom - top) * sv) * (1.0f / 256.0f);
}

Vector3f mix(const Vector3f& a, const Vector3f& b, float w) { return a + (b - a) * w; }

// A box from its corners; its centre for the shapes that move (their texture's frame).
Shape boxShape(const Vector3d& min_m, const Vector3d& max_m, int material) {
  Shape s;
  s.kind = ShapeKind::kBox;
  s.material = material;
  s.min_m = min_m;
  s.max_m = max_m;
  s.center_m = 0.5 * (min_m + max_m);
  return s;
}

}  // namespace

Vector3d Motion::offsetAt(double time_s) const {
  Vector3d offset;
  for (int k = 0; k < 3; ++k) {
    offset[k] = amplitude_m[k] * std::sin(kTwoPi * frequency_hz[k] * time_s + phase_rad[k]);
  }
  return offset;
}

Pose lookAtPose(const Vector3d& eye_m, const Vector3d& target_m) {
  Pose pose;
  Vector3d forward = target_m - eye_m;
  const double length = forward.norm();
  forward = length > 0.0 ? Vector3d(forward / length) : Vector3d::UnitY();
  Vector3d right = forward.cross(Vector3d::UnitZ());
  if (right.norm() < 1e-9) right = forward.cross(Vector3d::UnitY());
  right.normalize();
  const Vector3d down = forward.cross(right);
  pose.R_world_cam.col(0) = right;
  pose.R_world_cam.col(1) = down;
  pose.R_world_cam.col(2) = forward;
  pose.t_world_cam = eye_m;
  return pose;
}

Pose Scene::defaultPose() const { return lookAtPose(info_.default_eye_m, info_.default_target_m); }

int Scene::addMaterial(const Material& material) {
  materials_.push_back(material);
  return static_cast<int>(materials_.size()) - 1;
}

void Scene::beginGroup() {
  Group group;
  group.min_m = Vector3d::Constant(kInf);
  group.max_m = Vector3d::Constant(-kInf);
  group.first = static_cast<int>(shapes_.size());
  groups_.push_back(group);
  group_open_ = true;
}

void Scene::endGroup() { group_open_ = false; }

void Scene::addShape(const Shape& shape) {
  const bool singleton = !group_open_;
  if (singleton) beginGroup();
  Group& group = groups_.back();
  shapes_.push_back(shape);
  ++group.count;
  if (shape.kind == ShapeKind::kPlane || shape.kind == ShapeKind::kRoom) {
    group.bounded = false;  // a room's bounds would only cull rays from outside the room
  } else {
    group.min_m = group.min_m.cwiseMin(shape.min_m);
    group.max_m = group.max_m.cwiseMax(shape.max_m);
  }
  if (singleton) endGroup();
}

void Scene::addBox(const Vector3d& min_m, const Vector3d& max_m, int material) {
  addShape(boxShape(min_m, max_m, material));
}

void Scene::addRoom(const Vector3d& min_m, const Vector3d& max_m, const int (&face_material)[6]) {
  Shape s;
  s.kind = ShapeKind::kRoom;
  s.material = face_material[0];
  std::copy(std::begin(face_material), std::end(face_material), std::begin(s.face_material));
  s.min_m = min_m;
  s.max_m = max_m;
  addShape(s);
}

void Scene::addSphere(const Vector3d& center_m, double radius_m, int material) {
  Shape s;
  s.kind = ShapeKind::kSphere;
  s.material = material;
  s.center_m = center_m;
  s.radius_m = radius_m;
  s.min_m = center_m - Vector3d::Constant(radius_m);
  s.max_m = center_m + Vector3d::Constant(radius_m);
  addShape(s);
}

void Scene::addCylinder(double x_m, double y_m, double radius_m, double z_min_m, double z_max_m,
                        int material) {
  Shape s;
  s.kind = ShapeKind::kCylinder;
  s.material = material;
  s.center_m = Vector3d(x_m, y_m, 0.5 * (z_min_m + z_max_m));
  s.radius_m = radius_m;
  s.min_m = Vector3d(x_m - radius_m, y_m - radius_m, z_min_m);
  s.max_m = Vector3d(x_m + radius_m, y_m + radius_m, z_max_m);
  addShape(s);
}

void Scene::addPlane(const Vector3d& normal, double offset_m, const Vector3d& u_axis,
                     int material) {
  Shape s;
  s.kind = ShapeKind::kPlane;
  s.material = material;
  s.normal = normal.normalized();
  s.offset_m = offset_m;
  s.u_axis = u_axis.normalized();
  s.v_axis = s.normal.cross(s.u_axis);
  addShape(s);
}

void Scene::addMovingSphere(const Vector3d& center_m, double radius_m, const Motion& motion,
                            int material) {
  Shape s;
  s.kind = ShapeKind::kSphere;
  s.material = material;
  s.center_m = center_m;
  s.radius_m = radius_m;
  s.min_m = center_m - Vector3d::Constant(radius_m);
  s.max_m = center_m + Vector3d::Constant(radius_m);
  s.motion = motion;
  dynamic_shapes_.push_back(s);
}

void Scene::addMovingBox(const Vector3d& min_m, const Vector3d& max_m, const Motion& motion,
                         int material) {
  Shape s = boxShape(min_m, max_m, material);
  s.motion = motion;
  dynamic_shapes_.push_back(s);
}

void Scene::addCarriedBox(const Vector3d& min_cam_m, const Vector3d& max_cam_m, int material) {
  carried_shapes_.push_back(boxShape(min_cam_m, max_cam_m, material));
}

bool Scene::intersectShape(const Shape& s, const Vector3d& origin, const Vector3d& dir,
                           const Vector3d& inv_dir, double& t_best, Hit& hit) const {
  switch (s.kind) {
    case ShapeKind::kBox:
    case ShapeKind::kRoom: return intersectBox(s, origin, dir, inv_dir, t_best, hit);
    case ShapeKind::kSphere: return intersectSphere(s, origin, dir, t_best, hit);
    case ShapeKind::kCylinder: return intersectCylinder(s, origin, dir, t_best, hit);
    case ShapeKind::kPlane: return intersectPlane(s, origin, dir, t_best, hit);
  }
  return false;
}

bool Scene::intersect(const Vector3d& origin, const Vector3d& dir, double time_s, SceneLayer layer,
                      double t_max, Hit& hit) const {
  const Vector3d inv_dir = dir.cwiseInverse();  // +-inf where a component is 0; see slabs()
  double t_best = t_max;
  bool found = false;
  Vector3d hit_origin = origin;  // the ray's origin in the frame of the best hit's shape
  if (layer != SceneLayer::kDynamic) {
    for (const Group& group : groups_) {
      if (group.bounded && !hitsBounds(origin, inv_dir, group.min_m, group.max_m, t_best)) continue;
      const Shape* end = shapes_.data() + group.first + group.count;
      for (const Shape* s = shapes_.data() + group.first; s != end; ++s) {
        found |= intersectShape(*s, origin, dir, inv_dir, t_best, hit);
      }
    }
  }
  if (layer != SceneLayer::kStatic) {
    for (const Shape& s : dynamic_shapes_) {
      if (!s.motion.presentAt(time_s)) continue;
      // The ray in the shape's rest frame: a moving shape only translates.
      const Vector3d rest_origin = origin - s.motion.offsetAt(time_s);
      if (intersectShape(s, rest_origin, dir, inv_dir, t_best, hit)) {
        found = true;
        hit_origin = rest_origin;
      }
    }
  }
  if (found) hit.local_m = hit_origin + hit.t * dir;
  return found;
}

bool Scene::intersectCarried(const Pose& camera, const Vector3d& dir, double t_max, Hit& hit) const {
  const Vector3d dir_cam = camera.R_world_cam.transpose() * dir;
  const Vector3d inv_dir = dir_cam.cwiseInverse();
  double t_best = t_max;
  bool found = false;
  for (const Shape& s : carried_shapes_) {
    found |= intersectShape(s, Vector3d::Zero(), dir_cam, inv_dir, t_best, hit);
  }
  if (!found) return false;
  hit.normal = camera.R_world_cam * hit.normal;
  hit.local_m = hit.t * dir_cam;
  return true;
}

bool Scene::carriedBounds(Vector3d& min_cam_m, Vector3d& max_cam_m) const {
  if (carried_shapes_.empty()) return false;
  min_cam_m = Vector3d::Constant(kInf);
  max_cam_m = Vector3d::Constant(-kInf);
  for (const Shape& s : carried_shapes_) {
    min_cam_m = min_cam_m.cwiseMin(s.min_m);
    max_cam_m = max_cam_m.cwiseMax(s.max_m);
  }
  return true;
}

bool Scene::intersectShapes(const Vector3d& origin, const Vector3d& dir, const uint16_t* shapes,
                            std::size_t shape_count, double t_max, Hit& hit) const {
  const Vector3d inv_dir = dir.cwiseInverse();
  double t_best = t_max;
  bool found = false;
  for (std::size_t i = 0; i < shape_count; ++i) {
    found |= intersectShape(shapes_[shapes[i]], origin, dir, inv_dir, t_best, hit);
  }
  if (found) hit.local_m = origin + hit.t * dir;
  return found;
}

bool Scene::staticShapeBounds(std::size_t shape, Vector3d& min_m, Vector3d& max_m) const {
  const Shape& s = shapes_[shape];
  min_m = s.min_m;
  max_m = s.max_m;
  return s.kind != ShapeKind::kPlane && s.kind != ShapeKind::kRoom;
}

bool Scene::dynamicBounds(double time_s, Vector3d& min_m, Vector3d& max_m) const {
  min_m = Vector3d::Constant(kInf);
  max_m = Vector3d::Constant(-kInf);
  bool any = false;
  for (const Shape& s : dynamic_shapes_) {
    if (!s.motion.presentAt(time_s)) continue;
    const Vector3d offset = s.motion.offsetAt(time_s);
    min_m = min_m.cwiseMin(s.min_m + offset);
    max_m = max_m.cwiseMax(s.max_m + offset);
    any = true;
  }
  return any;
}

Vector3f Scene::albedo(const Material& m, double u, double v) const {
  if (m.swap_uv) std::swap(u, v);
  const double s = m.scale_m;
  switch (m.texture) {
    case TextureKind::kSolid: return m.color_a;
    case TextureKind::kChecker:
      return ((floorToInt(u / s) + floorToInt(v / s)) & 1) != 0 ? m.color_b : m.color_a;
    case TextureKind::kStripes: return (floorToInt(u / s) & 1) != 0 ? m.color_b : m.color_a;
    case TextureKind::kWood: {
      // Planks 12 grain spacings wide run along u; each plank gets its own grain
      // offset and tone; wavy grain lines follow u; dark seams between planks.
      const double plank_w = 12.0 * s;
      const double pv = v / plank_w;
      const int64_t plank = floorToInt(pv);
      const double across = pv - static_cast<double>(plank);
      const double shift_m = 40.0 * latticeValue(plank, 0, m.salt);
      const float tone = 0.85f + 0.3f * latticeValue(plank, 1, m.salt);
      const double g = v / s + 1.5 * valueNoise((u + shift_m) / (8.0 * s), v / (3.0 * s), m.salt);
      // Grain lines: a smoothed triangle wave of g, peaking (dark) once per unit.
      const double f = g - static_cast<double>(floorToInt(g));
      const auto tri = static_cast<float>(1.0 - std::abs(2.0 * f - 1.0));
      const float ring = tri * tri * (3.0f - 2.0f * tri);
      Vector3f c = mix(m.color_a, m.color_b, ring * ring * ring) * tone;
      if (across < 0.03 || across > 0.97) c *= 0.55f;
      return c;
    }
    case TextureKind::kNoise: {
      const float n = 0.65f * valueNoise(u / s, v / s, m.salt) +
                      0.35f * valueNoise(2.0 * u / s, 2.0 * v / s, m.salt + 1u);
      return mix(m.color_a, m.color_b, n);
    }
  }
  return m.color_a;
}

Vector3f Scene::shade(const Vector3d& origin, const Vector3d& dir, const Hit& hit) const {
  const Shape& s = *hit.shape;
  const Material& m = materials_[hit.material];
  const Vector3d& q = hit.local_m;  // texture coordinates move with the shape
  double u = 0.0;
  double v = 0.0;
  switch (s.kind) {
    case ShapeKind::kBox:
    case ShapeKind::kRoom:
      u = hit.face_axis == 0 ? q.y() : q.x();
      v = hit.face_axis == 2 ? q.y() : q.z();
      break;
    case ShapeKind::kSphere: {
      const Vector3d r = q - s.center_m;
      u = std::atan2(r.y(), r.x()) * s.radius_m;
      v = r.z();
      break;
    }
    case ShapeKind::kCylinder:
      if (hit.face_axis == 2) {
        u = q.x();
        v = q.y();
      } else {
        u = std::atan2(q.y() - s.center_m.y(), q.x() - s.center_m.x()) * s.radius_m;
        v = q.z();
      }
      break;
    case ShapeKind::kPlane:
      u = q.dot(s.u_axis);
      v = q.dot(s.v_axis);
      break;
  }
  const Vector3f base = albedo(m, u, v);
  if (m.emissive) return base;
  const Vector3d p = origin + hit.t * dir;
  const Vector3d to_light = (info_.light_m - p).normalized();
  const auto lambert = static_cast<float>(std::max(0.0, hit.normal.dot(to_light)));
  return base * (info_.ambient + (1.0f - info_.ambient) * lambert);
}

}  // namespace fovea::hal::mock

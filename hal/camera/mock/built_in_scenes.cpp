// The mock camera's built-in scenes, the living room, the balloon and the
// living room's movers, and the table of their names: what each scene holds, apart from the ray casting and
// shading of scene.cpp that every scene shares.
#include "hal/camera/mock/scene.h"

#include <cmath>
#include <cstdint>
#include <numbers>
#include <string>

#include "hal/camera/mock/hash.h"

namespace fovea::hal::mock {

namespace {

using Eigen::Vector3d;
using Eigen::Vector3f;

Vector3d v3(double x, double y, double z) { return Vector3d(x, y, z); }
Vector3f rgb(float r, float g, float b) { return Vector3f(r, g, b); }

// The living room's bookshelf against the west wall: its extent in x and y,
// for the shelf and the books on it.
constexpr double kShelfX0 = 0.02, kShelfX1 = 0.36, kShelfY0 = 1.2, kShelfY1 = 2.4;

// The living room's camera, light and camera paths.
SceneInfo livingRoomInfo() {
  SceneInfo info;
  info.name = "living-room";
  info.focus_point_m = v3(3.0, 2.25, 1.35);
  info.default_eye_m = v3(3.0, 0.35, 1.55);
  info.default_target_m = v3(3.0, 3.5, 0.9);
  info.light_m = v3(3.0, 2.0, 2.55);
  info.ambient = 0.35f;
  info.pan_amplitude_rad = 0.5;
  info.pan_period_s = 8.0;
  info.orbit_radius_m = 1.4;
  info.orbit_height_m = 1.5;
  info.orbit_sweep_rad = 0.0;
  info.orbit_period_s = 24.0;
  info.dolly_distance_m = 1.0;
  info.dolly_period_s = 10.0;
  return info;
}

// A living-room material; `index` is the index it will have in the scene,
// which salts its noise so that materials sharing a texture differ.
Material livingRoomMaterial(TextureKind texture, Vector3f a, Vector3f b, double scale_m, std::size_t index) {
  Material m;
  m.texture = texture;
  m.color_a = a;
  m.color_b = b;
  m.scale_m = scale_m;
  m.salt = static_cast<uint32_t>(index) * 7919u + 17u;
  return m;
}

}  // namespace

Result<Scene> Scene::create(std::string_view name) {
  if (name == "living-room") return livingRoom();
  if (name == "balloon") return balloon();
  // The balloon leaves after 2 s (frame 60 at 30 fps): what the map keeps of it after.
  if (name == "balloon-leaves") return balloon(2.0);
  if (name == "walker") return walker();
  // The walker leaves after 3 s (frame 90): the map 30 frames after it left.
  if (name == "walker-leaves") return walker(3.0);
  if (name == "carried") return carried();
  return Result<Scene>(ErrorCode::kInvalidArgument,
                       "scene: unknown name '" + std::string(name) + "'; accepted: " + names());
}

std::string Scene::names() {
  return "living-room|balloon|balloon-leaves|walker|walker-leaves|carried";
}

bool Scene::isKnown(std::string_view name) {
  return name == "living-room" || name == "balloon" || name == "balloon-leaves" ||
         name == "walker" || name == "walker-leaves" || name == "carried";
}

// The living room's materials, by what they cover.
struct Scene::LivingRoomMaterials {
  int wall, wallpaper, ceiling, floor, rug;
  int fabric, cushion, table_wood, dark_wood, shelf_wood, cabinet, screen, frame, canvas;
  int metal, lamp, pot, foliage, door, window;
  int books[8];
};

// The living room, after the synthetic "LIV" room: floor, four walls and a
// ceiling (one room box seen from inside), a sofa against the north wall
// with a picture above it, a coffee table with legs on a rug, a bookshelf with
// books against the west wall, a cabinet and a TV against the east wall, a
// window, a door, a floor lamp and a plant.
Scene Scene::livingRoom() {
  Scene scene;
  scene.info_ = livingRoomInfo();
  const LivingRoomMaterials m = scene.addLivingRoomMaterials();
  scene.addLivingRoomShell(m);
  scene.addSofaAndPicture(m);
  scene.addRugAndCoffeeTable(m);
  scene.addBookshelf(m);
  scene.addBooks(m);
  scene.addCabinetTvWindowAndDoor(m);
  scene.addLampAndPlant(m);
  return scene;
}

Scene::LivingRoomMaterials Scene::addLivingRoomMaterials() {
  const auto material = [&](TextureKind texture, Vector3f a, Vector3f b, double scale_m) {
    return livingRoomMaterial(texture, a, b, scale_m, materials_.size());
  };
  LivingRoomMaterials m;
  m.wall = addMaterial(
      material(TextureKind::kNoise, rgb(0.85f, 0.82f, 0.74f), rgb(0.74f, 0.71f, 0.62f), 0.25));
  m.wallpaper = addMaterial(
      material(TextureKind::kStripes, rgb(0.76f, 0.81f, 0.71f), rgb(0.66f, 0.73f, 0.62f), 0.12));
  m.ceiling = addMaterial(
      material(TextureKind::kSolid, rgb(0.93f, 0.93f, 0.92f), rgb(0.93f, 0.93f, 0.92f), 1.0));
  m.floor = addMaterial(
      material(TextureKind::kWood, rgb(0.58f, 0.40f, 0.23f), rgb(0.38f, 0.24f, 0.13f), 0.02));
  m.rug = addMaterial(
      material(TextureKind::kChecker, rgb(0.62f, 0.16f, 0.15f), rgb(0.86f, 0.79f, 0.60f), 0.2));
  m.fabric = addMaterial(
      material(TextureKind::kNoise, rgb(0.22f, 0.34f, 0.58f), rgb(0.12f, 0.21f, 0.40f), 0.04));
  m.cushion = addMaterial(
      material(TextureKind::kStripes, rgb(0.90f, 0.55f, 0.15f), rgb(0.95f, 0.88f, 0.70f), 0.05));
  m.table_wood = addMaterial(
      material(TextureKind::kWood, rgb(0.64f, 0.45f, 0.28f), rgb(0.44f, 0.29f, 0.16f), 0.015));
  m.dark_wood = addMaterial(
      material(TextureKind::kSolid, rgb(0.25f, 0.18f, 0.12f), rgb(0.25f, 0.18f, 0.12f), 1.0));
  m.shelf_wood = addMaterial(
      material(TextureKind::kWood, rgb(0.78f, 0.62f, 0.42f), rgb(0.60f, 0.45f, 0.28f), 0.02));
  Material cabinet_material =
      material(TextureKind::kStripes, rgb(0.90f, 0.90f, 0.87f), rgb(0.72f, 0.72f, 0.69f), 0.28);
  cabinet_material.swap_uv = true;  // horizontal bands: drawer fronts
  m.cabinet = addMaterial(cabinet_material);
  Material screen_material =
      material(TextureKind::kSolid, rgb(0.03f, 0.03f, 0.04f), rgb(0.03f, 0.03f, 0.04f), 1.0);
  screen_material.ir_dropout = 0.5f;  // black glossy screens return little IR
  m.screen = addMaterial(screen_material);
  m.frame = addMaterial(
      material(TextureKind::kSolid, rgb(0.16f, 0.11f, 0.06f), rgb(0.16f, 0.11f, 0.06f), 1.0));
  m.canvas = addMaterial(
      material(TextureKind::kChecker, rgb(0.92f, 0.62f, 0.12f), rgb(0.10f, 0.40f, 0.72f), 0.11));
  m.metal = addMaterial(
      material(TextureKind::kSolid, rgb(0.60f, 0.60f, 0.62f), rgb(0.60f, 0.60f, 0.62f), 1.0));
  Material lamp_material =
      material(TextureKind::kSolid, rgb(1.0f, 0.95f, 0.80f), rgb(1.0f, 0.95f, 0.80f), 1.0);
  lamp_material.emissive = true;
  m.lamp = addMaterial(lamp_material);
  m.pot = addMaterial(
      material(TextureKind::kStripes, rgb(0.66f, 0.34f, 0.20f), rgb(0.54f, 0.26f, 0.15f), 0.04));
  m.foliage = addMaterial(
      material(TextureKind::kNoise, rgb(0.16f, 0.46f, 0.12f), rgb(0.06f, 0.25f, 0.06f), 0.04));
  Material door_material =
      material(TextureKind::kWood, rgb(0.52f, 0.34f, 0.20f), rgb(0.36f, 0.22f, 0.12f), 0.02);
  door_material.swap_uv = true;  // vertical grain
  m.door = addMaterial(door_material);
  Material window_material =
      material(TextureKind::kSolid, rgb(0.72f, 0.86f, 0.97f), rgb(0.72f, 0.86f, 0.97f), 1.0);
  window_material.emissive = true;  // daylight
  window_material.ir_dropout = 0.3f;
  m.window = addMaterial(window_material);
  const Vector3f book_palette[8] = {rgb(0.60f, 0.10f, 0.10f), rgb(0.10f, 0.30f, 0.55f),
                                    rgb(0.15f, 0.45f, 0.20f), rgb(0.85f, 0.75f, 0.30f),
                                    rgb(0.30f, 0.20f, 0.40f), rgb(0.90f, 0.90f, 0.85f),
                                    rgb(0.10f, 0.10f, 0.12f), rgb(0.75f, 0.40f, 0.15f)};
  for (int i = 0; i < 8; ++i) {
    m.books[i] = addMaterial(material(TextureKind::kSolid, book_palette[i], book_palette[i], 1.0));
  }
  return m;
}

// The shell first: every ray from inside hits it, which then culls the
// furniture groups behind the hit.
void Scene::addLivingRoomShell(const LivingRoomMaterials& m) {
  const int shell[6] = {m.wall, m.wall, m.wall, m.wallpaper, m.floor, m.ceiling};  // W, E, S, N, floor, ceiling
  addRoom(v3(0.0, 0.0, 0.0), v3(6.0, 4.5, 2.7), shell);
}

// Sofa against the north wall, two cushions, the picture above it.
void Scene::addSofaAndPicture(const LivingRoomMaterials& m) {
  beginGroup();
  addBox(v3(1.6, 3.6, 0.0), v3(3.8, 4.45, 0.42), m.fabric);
  addBox(v3(1.6, 4.15, 0.42), v3(3.8, 4.45, 0.88), m.fabric);
  addBox(v3(1.6, 3.6, 0.42), v3(1.8, 4.15, 0.62), m.fabric);
  addBox(v3(3.6, 3.6, 0.42), v3(3.8, 4.15, 0.62), m.fabric);
  addBox(v3(1.9, 4.0, 0.42), v3(2.4, 4.15, 0.78), m.cushion);
  addBox(v3(3.0, 4.0, 0.42), v3(3.5, 4.15, 0.78), m.cushion);
  endGroup();
  beginGroup();
  addBox(v3(2.2, 4.46, 1.25), v3(3.2, 4.5, 1.95), m.frame);
  addBox(v3(2.26, 4.45, 1.31), v3(3.14, 4.46, 1.89), m.canvas);
  endGroup();
}

// Rug, coffee table with four legs.
void Scene::addRugAndCoffeeTable(const LivingRoomMaterials& m) {
  addBox(v3(1.6, 2.0, 0.0), v3(4.0, 3.45, 0.008), m.rug);
  beginGroup();
  addBox(v3(2.25, 2.45, 0.40), v3(3.35, 3.05, 0.45), m.table_wood);
  for (const double x : {2.29, 3.26}) {
    for (const double y : {2.49, 2.96})
      addBox(v3(x, y, 0.0), v3(x + 0.05, y + 0.05, 0.40), m.dark_wood);
  }
  endGroup();
}

// Bookshelf against the west wall: sides, back, top, bottom, three shelves.
void Scene::addBookshelf(const LivingRoomMaterials& m) {
  beginGroup();
  addBox(v3(kShelfX0, kShelfY0, 0.0), v3(kShelfX1, kShelfY0 + 0.03, 2.0), m.shelf_wood);
  addBox(v3(kShelfX0, kShelfY1 - 0.03, 0.0), v3(kShelfX1, kShelfY1, 2.0), m.shelf_wood);
  addBox(v3(kShelfX0, kShelfY0, 0.0), v3(0.04, kShelfY1, 2.0), m.shelf_wood);
  addBox(v3(kShelfX0, kShelfY0, 1.97), v3(kShelfX1, kShelfY1, 2.0), m.shelf_wood);
  addBox(v3(0.04, kShelfY0, 0.0), v3(kShelfX1, kShelfY1, 0.08), m.shelf_wood);
  constexpr double kBoardZ[3] = {0.52, 0.99, 1.46};
  for (const double z : kBoardZ) {
    addBox(v3(0.04, kShelfY0 + 0.03, z), v3(kShelfX1, kShelfY1 - 0.03, z + 0.025), m.shelf_wood);
  }
  endGroup();
}

// Books: one group per shelf, sizes and colours from a fixed hash.
void Scene::addBooks(const LivingRoomMaterials& m) {
  constexpr double kRowZ[4] = {0.08, 0.545, 1.015, 1.485};
  uint64_t book = 0;
  for (const double z0 : kRowZ) {
    beginGroup();
    double y = kShelfY0 + 0.04;
    while (true) {
      const uint64_t h = hash2(book++, 0xB00C5ull);
      const double width_m = 0.02 + 0.04 * unitFromHash(h);
      const double height_m = 0.18 + 0.16 * unitFromHash(mix64(h ^ 1u));
      const double depth_m = 0.17 + 0.10 * unitFromHash(mix64(h ^ 2u));
      if (y + width_m > kShelfY1 - 0.04) break;
      if ((h & 15u) == 0u) {  // a gap now and then
        y += 0.08;
        continue;
      }
      addBox(v3(0.04, y, z0), v3(0.04 + depth_m, y + width_m, z0 + height_m), m.books[(h >> 8) & 7u]);
      y += width_m + 0.002;
    }
    endGroup();
  }
}

// Cabinet with a TV above it against the east wall; a window further north.
// The door in the south wall, slightly proud of it.
void Scene::addCabinetTvWindowAndDoor(const LivingRoomMaterials& m) {
  beginGroup();
  addBox(v3(5.55, 1.5, 0.0), v3(5.98, 2.7, 0.85), m.cabinet);
  addBox(v3(5.52, 1.48, 0.85), v3(5.99, 2.72, 0.88), m.dark_wood);
  addBox(v3(5.9, 1.6, 1.05), v3(5.97, 2.6, 1.65), m.screen);
  endGroup();
  addBox(v3(5.985, 3.1, 1.0), v3(6.0, 4.1, 2.1), m.window);
  addBox(v3(4.5, 0.0, 0.0), v3(5.4, 0.03, 2.05), m.door);
}

// Floor lamp in the north-east corner, plant in the north-west corner.
void Scene::addLampAndPlant(const LivingRoomMaterials& m) {
  beginGroup();
  addCylinder(5.4, 4.05, 0.16, 0.0, 0.03, m.metal);
  addCylinder(5.4, 4.05, 0.015, 0.03, 1.45, m.metal);
  addSphere(v3(5.4, 4.05, 1.6), 0.17, m.lamp);
  endGroup();
  beginGroup();
  addCylinder(0.45, 4.05, 0.17, 0.0, 0.38, m.pot);
  addSphere(v3(0.45, 4.05, 0.75), 0.32, m.foliage);
  endGroup();
}

// The balloon, after the synthetic "BAL" sequence: a striped sphere of radius
// 0.3 m drifting on a Lissajous path (periods 4 s, 8 s and 2 s along x, y, z;
// 8 s in all) in front of a plastered wall (the plane y = 3.5) over a tiled floor
// (z = 0). Its mean position, the focus point, is its rest position.
Scene Scene::balloon(double gone_from_s) {
  Scene scene;
  SceneInfo& info = scene.info_;
  info.name = std::isinf(gone_from_s) ? "balloon" : "balloon-leaves";
  const Vector3d rest_m = v3(0.0, 2.0, 1.15);
  info.focus_point_m = rest_m;
  info.default_eye_m = v3(0.0, 0.0, 1.2);
  info.default_target_m = v3(0.0, 3.5, 0.95);
  info.light_m = v3(-1.0, 0.3, 2.5);
  info.ambient = 0.3f;
  info.pan_amplitude_rad = 0.35;
  info.pan_period_s = 8.0;
  info.orbit_radius_m = 2.0;
  info.orbit_height_m = 1.2;
  info.orbit_sweep_rad = 0.6;
  info.orbit_period_s = 12.0;
  info.dolly_distance_m = 0.8;
  info.dolly_period_s = 10.0;

  Material plaster;
  plaster.texture = TextureKind::kNoise;
  plaster.color_a = rgb(0.82f, 0.80f, 0.74f);
  plaster.color_b = rgb(0.62f, 0.60f, 0.53f);
  plaster.scale_m = 0.15;
  plaster.salt = 101u;
  Material tiles;
  tiles.texture = TextureKind::kChecker;
  tiles.color_a = rgb(0.58f, 0.57f, 0.52f);
  tiles.color_b = rgb(0.30f, 0.30f, 0.28f);
  tiles.scale_m = 0.3;
  Material skin;
  skin.texture = TextureKind::kStripes;
  skin.color_a = rgb(0.85f, 0.12f, 0.10f);
  skin.color_b = rgb(0.95f, 0.80f, 0.15f);
  constexpr double kRadius = 0.3;
  skin.scale_m = kTwoPi * kRadius / 8.0;  // eight segments around the equator
  const int wall = scene.addMaterial(plaster);
  const int floor = scene.addMaterial(tiles);
  const int balloon = scene.addMaterial(skin);

  scene.addPlane(Vector3d::UnitY(), 3.5, Vector3d::UnitX(), wall);
  scene.addPlane(Vector3d::UnitZ(), 0.0, Vector3d::UnitX(), floor);
  Motion motion;
  motion.amplitude_m = v3(0.6, 0.3, 0.25);
  motion.frequency_hz = v3(0.25, 0.125, 0.5);
  motion.phase_rad = v3(0.0, std::numbers::pi / 2.0, 0.0);
  motion.gone_from_s = gone_from_s;
  scene.addMovingSphere(rest_m, kRadius, motion, balloon);
  return scene;
}

// The living room with a person walking through it (issue 42's large mover):
// a person-sized box (0.55 m wide, 0.3 m deep, 1.75 m tall, in a checked
// shirt) walking east and back along y = 1.9 m, between the orbit's start and
// the focus point, 1.3 m either way of x = 3 m in 8 s (1 m/s at the middle).
// It starts at the west end and crosses the middle at 2 s, where the orbit's
// camera sees it at about 1.1 m, over a third of the view.
Scene Scene::walker(double gone_from_s) {
  Scene scene = livingRoom();
  scene.info_.name = std::isinf(gone_from_s) ? "walker" : "walker-leaves";
  Material shirt;
  shirt.texture = TextureKind::kChecker;
  shirt.color_a = rgb(0.20f, 0.32f, 0.62f);
  shirt.color_b = rgb(0.78f, 0.76f, 0.70f);
  shirt.scale_m = 0.09;
  const int person = scene.addMaterial(shirt);
  Motion walk;
  walk.amplitude_m = v3(1.3, 0.0, 0.0);
  walk.frequency_hz = v3(0.125, 0.0, 0.0);
  walk.phase_rad = v3(-std::numbers::pi / 2.0, 0.0, 0.0);
  walk.gone_from_s = gone_from_s;
  scene.addMovingBox(v3(2.725, 1.75, 0.0), v3(3.275, 2.05, 1.75), walk, person);
  return scene;
}

// The living room with a block carried with the camera (issue 42's carried
// mover, a robot's gripper holding a box): a cardboard box 0.6 to 0.9 m in
// front of the camera over the lower left of the view, about 28 % of it.
Scene Scene::carried() {
  Scene scene = livingRoom();
  scene.info_.name = "carried";
  Material cardboard;
  cardboard.texture = TextureKind::kNoise;
  cardboard.color_a = rgb(0.72f, 0.55f, 0.34f);
  cardboard.color_b = rgb(0.45f, 0.32f, 0.18f);
  cardboard.scale_m = 0.03;
  cardboard.salt = 211u;
  const int box = scene.addMaterial(cardboard);
  scene.addCarriedBox(v3(-0.45, -0.15, 0.6), v3(-0.10, 0.45, 0.9), box);
  return scene;
}

}  // namespace fovea::hal::mock

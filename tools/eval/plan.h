// What fovea-eval runs (issue 14, docs/eval.md): datasets, conditions, and the
// seeded HMD positions with their gaze scripts, as in the paper's section IV:
// five positions at varying distances from the scene's centre, each watching a
// fixation-and-saccade sequence around it.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/result.h"

namespace fovea::tools::eval {

struct Dataset {
  std::string name;         // "living-room" (LIV), "balloon" (BAL), "tum", "balloon-orbit", "tum-track"
  std::string paper_name;   // "LIV", "BAL", "" (not in the paper)
  std::string camera_spec;  // for fovead serve --camera (paced in real time)
  // --set settings of the conditions foveating the map on this dataset.
  std::vector<std::string> map_settings = {};
  bool by_default = true;  // run without --datasets naming it
};

// living-room and balloon from the mock camera; tum when tum_path is not empty;
// balloon-orbit (the balloon with the camera orbiting, the map's conditions
// tracking it with track+camera so that the balloon is found moving: issue 42)
// and tum-track (TUM played forwards and backwards, the map's conditions
// tracking it: issue 41's TUM target), only when --datasets names them.
std::vector<Dataset> defaultDatasets(const std::string& tum_path);

struct Condition {
  std::string name;    // F1, F2, F3, FREF, ACUITY, ACUITY-2MM, ACUITY-REFINED, MAP, MAP-DELTA
  std::string preset;  // fovead --preset
  // ACUITY's distance floor (foveation.floor_per_m2, m per m^2 of distance); 0: none.
  double floor_per_m2 = 0.0;
  // ACUITY's level margin (foveation.level_margin; 0: the default) and refinement
  // passes (foveation.refine_passes).
  double level_margin = 0.0;
  int refine_passes = 0;
  // What is foveated (foveation.source): "" the frame (fovead's default), "map"
  // the fused surfel map (docs/map.md).
  std::string source = {};
  // With the map: false, the map's surfels the eye sees sent with every frame
  // (map.delta = false, MAP); true, the map streamed as bricks the operator keeps
  // and each frame's live points (map.delta = true, MAP-DELTA, docs/map-delta.md),
  // whose quality is measured from what the operator holds (fovea-operator --save-held).
  bool map_delta = false;
};
// The paper's F1, F2, F3 and FREF, and ACUITY (the mode beyond the paper), also with a
// distance floor of 2 mm x s^2 (as fast as F1 on the mock room) and refined (margin
// 0.3, one pass; docs/acuity-levels.md).
std::vector<Condition> defaultConditions();
// Every condition --conditions may name: the default ones, then MAP (ACUITY
// foveating the fused surfel map, foveation.source = map, map.delta = false) and
// MAP-DELTA (the same map streamed as bricks, map.delta = true); neither is a
// default: the service fuses every frame, 60 to 140 ms a 640x480 frame on the
// 2-core host (docs/eval.md).
std::vector<Condition> allConditions();
// What a condition sets beyond its preset, as `fovead --set` takes it, in this order:
// foveation.floor_per_m2, foveation.level_margin, foveation.refine_passes,
// foveation.source and, with the map, map.delta (those set).
std::vector<std::string> conditionSettings(const Condition& c);
// A run's settings: its condition's, and the dataset's for the map's conditions.
std::vector<std::string> runSettings(const Dataset& d, const Condition& c);
// The quality frame (the camera's sequence number) when --quality-frame is not
// given: 30, or 90 when a condition streams the map as bricks (MAP-DELTA): its
// operator must hold the map by then, and the map's bricks come only once its
// surfels settled, 1 to 3 s after the start on the 2-core host (docs/eval.md).
inline constexpr int kDefaultQualityFrame = 30;
inline constexpr int kMapDeltaQualityFrame = 90;
int defaultQualityFrame(const std::vector<Condition>& conditions);
// A setting's number as `fovead --set` takes it: the shortest decimal that reads back
// as the same double (0.002, not 0.0020000000000000000416).
std::string shortestDecimal(double value);
// Picks names out of allConditions() (comma list); errors name the unknown one.
Result<std::vector<Condition>> selectConditions(const std::string& names);
Result<std::vector<Dataset>> selectDatasets(const std::vector<Dataset>& all, const std::string& names);

// Where the scene is, from the camera's first frame: its centre (the camera's
// focus point, or the median of the first frame's points), the camera's position
// and the world's up (minus the camera's y axis).
struct SceneGeometry {
  Eigen::Vector3d centre_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d camera_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
};

struct HmdPosition {
  int index = 0;                           // 1-based
  Eigen::Vector3d eye_m;                   // the HMD (the eye between the lenses)
  double distance_m = 0.0;                 // to the scene's centre
  std::vector<Eigen::Vector3d> targets_m;  // fixations, in order; the first is the centre
};

// `count` positions, seeded (the same seed gives the same positions): distances
// spread from 0.6 to 1.4 times the camera's distance to the centre (in order, with
// a seeded jitter), each on the camera's side of the scene within 30 degrees of
// its bearing, at the camera's height within 0.15 m; five fixations per position,
// the centre and four seeded points within 0.5 m of it across the view.
std::vector<HmdPosition> makePositions(const SceneGeometry& scene, int count, uint64_t seed);

// fovea-operator --gaze for a position: scan:EYE>T1;T2;...@DWELL/SACCADE.
std::string gazeScript(const HmdPosition& position, int dwell_ms, int saccade_ms);

// A run's directory name under the output's runs/: "living-room_F1_p3".
std::string runName(const Dataset& d, const Condition& c, const HmdPosition& p);

}  // namespace fovea::tools::eval

#include "tools/eval/plan.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <random>
#include <sstream>

#include <Eigen/Geometry>

namespace fovea::tools::eval {

std::vector<Dataset> defaultDatasets(const std::string& tum_path) {
  std::vector<Dataset> d = {{"living-room", "LIV", "mock:living-room,realtime=on"},
                            {"balloon", "BAL", "mock:balloon,realtime=on"}};
  if (!tum_path.empty()) d.push_back({"tum", "", "tum:" + tum_path + ",realtime=on,loop=on"});
  d.push_back({"balloon-orbit", "", "mock:balloon,realtime=on,path=orbit", {"camera.pose.source=track+camera"}, false});
  if (!tum_path.empty()) {
    // TUM with the map tracking the camera (issue 41's TUM target), played
    // forwards and backwards: a restart would jump the camera back to the first
    // pose, where the tracker loses it.
    d.push_back({"tum-track", "", "tum:" + tum_path + ",realtime=on,loop=bounce", {"camera.pose.source=track+camera"}, false});
  }
  return d;
}

std::vector<Condition> defaultConditions() {
  return {{"F1", "F1"},         {"F2", "F2"},         {"F3", "F3"},
          {"FREF", "FREF"},     {"ACUITY", "ACUITY"}, {"ACUITY-2MM", "ACUITY", 0.002},
          {"ACUITY-REFINED", "ACUITY", 0.0, 0.3, 1}};
}

std::vector<Condition> allConditions() {
  std::vector<Condition> all = defaultConditions();
  all.push_back({"MAP", "ACUITY", 0.0, 0.0, 0, "map", false});
  all.push_back({"MAP-DELTA", "ACUITY", 0.0, 0.0, 0, "map", true});
  return all;
}

std::vector<std::string> conditionSettings(const Condition& c) {
  std::vector<std::string> out;
  if (c.floor_per_m2 > 0.0) out.push_back("foveation.floor_per_m2=" + shortestDecimal(c.floor_per_m2));
  if (c.level_margin > 0.0) out.push_back("foveation.level_margin=" + shortestDecimal(c.level_margin));
  if (c.refine_passes > 0) out.push_back("foveation.refine_passes=" + std::to_string(c.refine_passes));
  if (!c.source.empty()) out.push_back("foveation.source=" + c.source);
  // MAP is the map foveated as the eye sees it with every frame; MAP-DELTA the
  // stream of the map's bricks (fovead's default with the map since issue 26),
  // said explicitly so that the run does not depend on the default.
  if (c.source == "map") out.push_back(c.map_delta ? "map.delta=true" : "map.delta=false");
  return out;
}

std::vector<std::string> runSettings(const Dataset& d, const Condition& c) {
  std::vector<std::string> out = conditionSettings(c);
  if (c.source == "map") out.insert(out.end(), d.map_settings.begin(), d.map_settings.end());
  return out;
}

int defaultQualityFrame(const std::vector<Condition>& conditions) {
  const bool delta = std::any_of(conditions.begin(), conditions.end(), [](const Condition& c) { return c.map_delta; });
  return delta ? kMapDeltaQualityFrame : kDefaultQualityFrame;
}

std::string shortestDecimal(double value) {
  char text[32];
  for (int digits = 1; digits <= 17; ++digits) {
    std::snprintf(text, sizeof text, "%.*g", digits, value);
    if (std::strtod(text, nullptr) == value) break;
  }
  return text;
}

namespace {
std::vector<std::string> splitComma(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}
}  // namespace

Result<std::vector<Condition>> selectConditions(const std::string& names) {
  const std::vector<Condition> all = allConditions();
  std::vector<Condition> out;
  for (const std::string& n : splitComma(names)) {
    auto it = std::find_if(all.begin(), all.end(), [&](const Condition& c) { return c.name == n; });
    if (it == all.end()) return Result<std::vector<Condition>>(ErrorCode::kInvalidArgument, "--conditions: unknown '" + n + "' (F1, F2, F3, FREF, ACUITY, ACUITY-2MM, ACUITY-REFINED, MAP, MAP-DELTA)");
    out.push_back(*it);
  }
  if (out.empty()) return Result<std::vector<Condition>>(ErrorCode::kInvalidArgument, "--conditions: none given");
  return out;
}

Result<std::vector<Dataset>> selectDatasets(const std::vector<Dataset>& all, const std::string& names) {
  std::vector<Dataset> out;
  for (const std::string& n : splitComma(names)) {
    auto it = std::find_if(all.begin(), all.end(), [&](const Dataset& d) { return d.name == n; });
    if (it == all.end()) {
      return Result<std::vector<Dataset>>(ErrorCode::kInvalidArgument,
                                          "--datasets: unknown or unavailable '" + n + "' (living-room, balloon, balloon-orbit, tum and tum-track with --tum PATH, recording with --mcap FILE)");
    }
    out.push_back(*it);
  }
  if (out.empty()) return Result<std::vector<Dataset>>(ErrorCode::kInvalidArgument, "--datasets: none given");
  return out;
}

std::vector<HmdPosition> makePositions(const SceneGeometry& scene, int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const Eigen::Vector3d up = scene.up.normalized();
  Eigen::Vector3d toward = scene.camera_m - scene.centre_m;  // the camera's bearing, from the centre
  const double height = toward.dot(up);
  toward -= height * up;
  const double ground = toward.norm();
  const Eigen::Vector3d bearing = ground > 1e-9 ? Eigen::Vector3d(toward / ground) : up.unitOrthogonal();
  const double base = std::max(0.5, (scene.camera_m - scene.centre_m).norm());
  std::vector<HmdPosition> out;
  for (int k = 0; k < count; ++k) {
    const double spread = count > 1 ? static_cast<double>(k) / (count - 1) : 0.5;
    const double distance = base * (0.6 + 0.8 * spread + 0.05 * unit(rng));
    const double azimuth = 30.0 * unit(rng) * std::numbers::pi / 180.0;
    const double dh = 0.15 * unit(rng);
    const Eigen::Vector3d dir = Eigen::AngleAxisd(azimuth, up) * bearing;
    // The eye keeps the camera's height above the centre (plus jitter); the
    // horizontal distance makes the straight-line distance the chosen one.
    const double h = height + dh;
    const double horizontal = std::sqrt(std::max(0.01, distance * distance - h * h));
    HmdPosition p;
    p.index = k + 1;
    p.eye_m = scene.centre_m + horizontal * dir + h * up;
    p.distance_m = (p.eye_m - scene.centre_m).norm();
    const Eigen::Vector3d across = up.cross(dir).normalized();
    p.targets_m.push_back(scene.centre_m);
    for (int t = 0; t < 4; ++t) p.targets_m.push_back(scene.centre_m + 0.5 * unit(rng) * across + 0.3 * unit(rng) * up);
    out.push_back(std::move(p));
  }
  return out;
}

std::string gazeScript(const HmdPosition& position, int dwell_ms, int saccade_ms) {
  char buf[96];
  const auto v = [&](const Eigen::Vector3d& x) {
    std::snprintf(buf, sizeof buf, "%.4f,%.4f,%.4f", x.x(), x.y(), x.z());
    return std::string(buf);
  };
  std::string s = "scan:" + v(position.eye_m) + ">";
  for (std::size_t i = 0; i < position.targets_m.size(); ++i) s += (i ? ";" : "") + v(position.targets_m[i]);
  return s + "@" + std::to_string(dwell_ms) + "/" + std::to_string(saccade_ms);
}

std::string runName(const Dataset& d, const Condition& c, const HmdPosition& p) {
  return d.name + "_" + c.name + "_p" + std::to_string(p.index);
}

}  // namespace fovea::tools::eval

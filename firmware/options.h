// Command-line parsing shared by fovead's commands. Every parser returns a
// Status naming the flag and the accepted values; nothing throws.
#pragma once

#include <map>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "core/result.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"

namespace fovea::firmware {

struct MapSettings;  // firmware/frame_foveator.h

// "--name value" and "--name=value" pairs, plus bare "--flag" switches.
class Args {
 public:
  // Parses argv[first..argc). `switches` take no value. Unknown flags are errors.
  static Result<Args> parse(int argc, char** argv, int first, const std::vector<std::string>& value_flags,
                            const std::vector<std::string>& switches);
  bool has(const std::string& flag) const { return values_.count(flag) > 0; }
  const std::string* get(const std::string& flag) const;
  std::string getOr(const std::string& flag, const std::string& fallback) const;

 private:
  std::map<std::string, std::string> values_;
};

Result<double> parseDouble(std::string_view flag, std::string_view text);
Result<long> parseInteger(std::string_view flag, std::string_view text, long min, long max);
// --duration S: seconds in (0, 3.2e7], or 0 when the flag is absent (no limit).
Result<double> durationFromArgs(const Args& args);
// --depth-min M and --depth-max M over `base` (each optional), validated.
Result<pipeline::DepthRange> depthRangeFromArgs(const Args& args, pipeline::DepthRange base = {});
// The map's flags (fovead map, fovead run): --max-surfels N, --brick-size M; and
// for run --source frame|map (foveation.source). The depth range is the caller's.
inline const std::vector<std::string> kMapFlags = {"--max-surfels", "--brick-size"};
Result<MapSettings> mapSettingsFromArgs(const Args& args);
// "X,Y,Z", each a finite number.
Result<Eigen::Vector3d> parseVector3(std::string_view flag, std::string_view text);
// "a,b,c" of finite numbers.
Result<std::vector<double>> parseDoubleList(std::string_view flag, std::string_view text);

// ACUITY's own flags (the configuration keys of the same names), refused with
// another preset.
inline const std::vector<std::string> kAcuityFlags = {"--level-voxel-m", "--floor-m",      "--floor-per-m2",
                                                      "--level-margin",  "--refine-passes", "--view-cull",
                                                      "--view-cull-deg"};
// The foveation flags every command shares: --preset, --bounds, --m, --far-ecc,
// --fixation hit|centroid|fixed:D0, and kAcuityFlags.
inline const std::vector<std::string> kFoveationFlags = [] {
  std::vector<std::string> flags = {"--preset", "--bounds", "--m", "--far-ecc", "--fixation"};
  flags.insert(flags.end(), kAcuityFlags.begin(), kAcuityFlags.end());
  return flags;
}();
// Starts from `base` (for fovead serve: the board profile, the configuration file and
// --set) and changes only what the flags name, so that --preset ACUITY keeps a floor
// or a level margin set there.
Result<pipeline::FoveationConfig> foveationConfigFromArgs(const Args& args, pipeline::FoveationConfig base = {});
std::string foveationFlagsHelp();

// One-line description: "F1 (m 0.022, far periphery at 90 deg), fixation hit"; ACUITY's
// distance floors follow its name when set ("ACUITY floor 2 mm x s^2 (m 0.022, ...").
std::string describeFoveation(const pipeline::FoveationConfig& config);

}  // namespace fovea::firmware

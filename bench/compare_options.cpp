// fovea-compare's command line: the options, their checks and the usage text.
#include "bench/compare_options.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <iterator>
#include <string_view>

#include "bench/compare_methods.h"

namespace fovea::bench::compare {
namespace {

bool parseVector(const std::string& text, Eigen::Vector3d& out) {
  double v[3];
  if (std::sscanf(text.c_str(), "%lf,%lf,%lf", &v[0], &v[1], &v[2]) != 3) return false;
  out = Eigen::Vector3d(v[0], v[1], v[2]);
  return out.allFinite();
}

// --methods A,B,...: every name must be a row of the table.
std::optional<int> parseMethodList(const char* v, CompareOptions& options) {
  options.only_methods = std::string(",") + v + ",";
  const std::span<const MethodEntry> table = methodTable();
  std::size_t begin = 1;
  while (begin < options.only_methods.size()) {
    const std::size_t end = options.only_methods.find(',', begin);
    const std::string name = options.only_methods.substr(begin, end - begin);
    const bool known = std::any_of(table.begin(), table.end(), [&](const MethodEntry& e) { return name == e.name; });
    if (!known) return usage(("--methods: no method named '" + name + "'").c_str());
    begin = end + 1;
  }
  return std::nullopt;
}

// One option and its value.
std::optional<int> parseOption(std::string_view arg, const char* v, CompareOptions& options) {
  if (arg == "--runs") {
    options.runs = std::atoi(v);
    if (options.runs < 1 || options.runs > 100000) return usage("--runs: expected a count in 1..100000");
  } else if (arg == "--pyramid-margin") {
    char* end = nullptr;
    options.pyramid_margin = std::strtod(v, &end);
    if (end == v || *end != '\0' || !(options.pyramid_margin > 0.0 && options.pyramid_margin <= 100.0)) {
      return usage("--pyramid-margin: expected a margin in (0, 100]");
    }
  } else if (arg == "--methods") {
    return parseMethodList(v, options);
  } else if (arg == "--tum") {
    options.tum_path = v;
  } else if (arg == "--frame") {
    options.frame_index = std::atoi(v);
    if (options.frame_index < 0) return usage("--frame: expected an index >= 0");
  } else if (arg == "--ply") {
    options.ply_path = v;
  } else if (arg == "--preset") {
    options.preset_name = v;
  } else if (arg == "--acuity-floor") {
    char* end = nullptr;
    options.acuity_floor_mm = std::strtod(v, &end);
    if (end == v || *end != '\0' || !(options.acuity_floor_mm > 0.0 && options.acuity_floor_mm <= 1000.0)) {
      return usage("--acuity-floor: expected mm per m^2 in (0, 1000]");
    }
  } else if (arg == "--gaze-origin" || arg == "--gaze-dir") {
    Eigen::Vector3d vec;
    if (!parseVector(v, vec)) return usage((std::string(arg) + ": expected X,Y,Z").c_str());
    (arg == "--gaze-origin" ? options.gaze_origin : options.gaze_dir) = vec;
  } else {
    return usage(("unknown option " + std::string(arg)).c_str());
  }
  return std::nullopt;
}

// The options that go together or not, then the preset's name.
std::optional<int> checkOptions(CompareOptions& options) {
  if (!options.tum_path.empty() && !options.ply_path.empty()) return usage("--tum and --ply exclude each other");
  if (options.frame_index != 0 && options.tum_path.empty()) return usage("--frame needs --tum");
  if (!options.ply_path.empty() && (!options.gaze_origin || !options.gaze_dir)) {
    return usage("--ply needs --gaze-origin and --gaze-dir");
  }
  Result<pipeline::Preset> parsed_preset = pipeline::parsePreset(options.preset_name);
  if (!parsed_preset) return usage(parsed_preset.status().message().c_str());
  options.preset = parsed_preset.value();
  return std::nullopt;
}

}  // namespace

int usage(const char* message) {
  if (message) std::fprintf(stderr, "fovea-compare: %s\n", message);
  std::fprintf(stderr,
               "usage: fovea-compare [--runs N] [--preset F1|F2|F3|FREF] [--acuity-floor MM] [--methods A,B,...]\n"
               "                     [--tum PATH [--frame N] | --ply FILE --gaze-origin X,Y,Z --gaze-dir X,Y,Z]\n"
               "Runs the foveation methods on one input (default: the mock living-room frame, 640x480)\n"
               "and prints a table and one `method=... ms_median=...` line per method.\n"
               "  --acuity-floor MM  distance floor of the acuity-floor and acuity-features methods, mm per m^2\n"
               "                     of distance (foveation.floor_per_m2 x 1000; default 1: F1's bytes on the\n"
               "                     mock room)\n"
               "  --methods A,B,...  run only these rows (by name; the table lists them all)\n"
               "  --pyramid-margin M the pyramid rows' margin (default ACUITY's level_margin, 0.5): smaller keeps\n"
               "                     fewer points, with more above the MAR\n");
  return 2;
}

std::optional<int> parseOptions(int argc, char** argv, CompareOptions& options) {
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      usage(nullptr);
      return 0;
    }
    const char* v = i + 1 < argc ? argv[++i] : nullptr;
    if (v == nullptr) return usage(("missing value after " + std::string(arg)).c_str());
    if (std::optional<int> stop = parseOption(arg, v, options)) return stop;
  }
  return checkOptions(options);
}

}  // namespace fovea::bench::compare

// fovea-error-report's command line: the --help text and the parser, a group of
// flags per step (what is measured, ACUITY's rows, the eye, the figures over time).
#include "tools/error_report/options.h"

#include <cmath>
#include <cstdlib>
#include <optional>
#include <string_view>

namespace fovea::tools {

const char* const kHelp =
    "usage: fovea-error-report [--camera SPEC] [--frames N] [--out-dir DIR] [--presets LIST] [--slopes LIST]\n"
    "                          [--reference-m M] [--sources LIST] [--map-warmup N] [--no-plot] [--replot-from DIR]\n"
    "\n"
    "Foveates the same camera frames with every preset and slope m, side by side, and reports per\n"
    "configuration the output points, bytes on the wire (fovea's chunk codec), median time per frame (back-projection\n"
    "through sampled output, scalar reference kernels) and the error against the full cloud: the\n"
    "distance from each input point to its representative (RMS, max, per region, / voxel size) and the\n"
    "share of points displaced, seen from the eye, by more than the MAR at their eccentricity (Eq. 1).\n"
    "The gaze goes from the camera towards the scene's focus point (the camera's optical axis when it\n"
    "has none), as `fovead run` does by default.\n"
    "\n"
    "  --camera SPEC     camera (default mock:living-room); e.g. mock:living-room,size=160x120\n"
    "  --frames N        frames to average over (default 30)\n"
    "  --out-dir DIR     where report.md, report.csv, report.gp, report_plot.dat, report.png go\n"
    "                    (default docs/report; created if missing)\n"
    "  --presets LIST    comma-separated presets (default F1,F2,F3,FREF,ACUITY)\n"
    "  --slopes LIST     comma-separated slopes m of MAR = m E + 1 arcmin (default 0.022,0.028,0.034)\n"
    "  --acuity-margins LIST  ACUITY's level margins k, a row each (default 1.732,0.7,0.5,0.42;\n"
    "                    docs/acuity-levels.md)\n"
    "  --acuity-refined LIST  ACUITY's refined rows, K:PASSES each (level margin, refinement passes;\n"
    "                    default 0.3:1,0.12:2,0.15:7; none for none)\n"
    "  --acuity-floors LIST  ACUITY's sensor floors in mm, 0 for none (default 0); a row each margin x floor\n"
    "  --acuity-noise-floors LIST  ACUITY's distance-dependent floors, mm per square metre of distance\n"
    "                    (foveation.floor_per_m2 x 1000); a row each margin x floor besides (default none)\n"
    "  --view-culls LIST  ACUITY's view cull (off, coarsest, drop; foveation.view_cull_deg 70), a row each\n"
    "                    (default off)\n"
    "  --head-turn-deg D  the operator's head faces D degrees right of the gaze, about the camera's up axis\n"
    "                    (default 0: the head faces the gaze)\n"
    "  --eye-offset X,Y,Z  the eye relative to the camera, metres in the camera's frame (x right, y down,\n"
    "                    z forward; default 0,0,0): an operator's head is rarely where the camera is, and\n"
    "                    depth noise along the camera's rays is visible only from elsewhere\n"
    "  --reference-m M   slope of a fixed observer every configuration is also judged by (default 0.022)\n"
    "  --sources LIST    what is foveated, comma-separated: frame (each frame's own cloud) and map (the\n"
    "                    frame fused into the surfel map, the map's stable surfels the eye sees and the\n"
    "                    frame's unexplained points: foveation.source = map, docs/map.md); default frame.\n"
    "                    With map, every row (frame's too) is also judged against the true surface by the\n"
    "                    nearest sent point (docs/report/README.md), and the report compares the sources\n"
    "  --map-warmup N    frames fused into the map before the measured frames (default 60; with map only)\n"
    "  --dynamics-frames N  frames of the temporal-stability figure, after the measured ones (default 30;\n"
    "                    0 skips it and the latency-corrected coverage; both use the first slope)\n"
    "  --down-ms MS      capture to display for the coverage figure (default 13: the stream's p50 on loopback)\n"
    "  --up-ms MS        operator to robot for the coverage figure (default 1)\n"
    "  --coverage-seconds S  length of the scripted scan the coverage figure replays (default 3.6: two rounds)\n"
    "  --growth-max-deg D  ACUITY's fovea growth bound in the coverage figure (default 10, the service's)\n"
    "  --growth-lead-ms T  ACUITY's fovea growth lead in the coverage figure (default 30, the service's)\n"
    "  --no-plot         do not run gnuplot (report.gp and report_acuity.gp are still written)\n"
    "  --replot-from DIR  measure nothing: rewrite DIR's plot data and scripts from the report.csv and\n"
    "                    report.md an earlier run wrote there, and draw them (unless --no-plot)\n"
    "\n"
    "With a mock camera, the same scene without sensor noise (noise=off, same seed and path) is the true\n"
    "surface: every configuration is also judged against it (the columns 'true surface'), so that noise the\n"
    "output keeps counts as error, not as detail.\n";

namespace {

std::vector<std::string> splitCommas(std::string_view text) {
  std::vector<std::string> parts;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = text.find(',', start);
    parts.emplace_back(text.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return parts;
}

Result<double> parseNumber(const std::string& flag, const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(v)) {
    return Result<double>(ErrorCode::kInvalidArgument, flag + ": '" + text + "' is not a finite number");
  }
  return v;
}

// Each group below takes one flag with its value into options: nullopt when the
// flag is not the group's, else what taking it gave (kInvalidArgument naming the
// flag when the value does not fit).

// What is measured and where the report goes: the camera, frames, presets,
// slopes, sources, the fixed observer and the output.
std::optional<Status> applyRunFlag(const std::string& flag, const std::string& value, Options& options) {
  if (flag == "--no-plot") {
    options.plot = false;
  } else if (flag == "--replot-from") {
    if (value.empty()) return invalidArgument("--replot-from: must not be empty");
    options.replot_from = value;
  } else if (flag == "--camera") {
    options.camera = value;
  } else if (flag == "--out-dir") {
    if (value.empty()) return invalidArgument("--out-dir: must not be empty");
    options.out_dir = value;
  } else if (flag == "--frames") {
    Result<double> n = parseNumber(flag, value);
    if (!n) return n.status();
    if (*n < 1 || *n > 100000 || std::floor(*n) != *n) {
      return invalidArgument("--frames: '" + value + "' is not an integer in [1, 100000]");
    }
    options.frames = static_cast<long>(*n);
  } else if (flag == "--presets") {
    options.presets.clear();
    for (const std::string& name : splitCommas(value)) {
      Result<pipeline::Preset> p = pipeline::parsePreset(name);
      if (!p || p.value() == pipeline::Preset::kCustom) {
        return invalidArgument("--presets: '" + name + "' is not F1, F2, F3, FREF or ACUITY");
      }
      options.presets.push_back(p.value());
    }
  } else if (flag == "--reference-m") {
    Result<double> m = parseNumber(flag, value);
    if (!m) return m.status();
    if (*m < 0.0) return invalidArgument("--reference-m: '" + value + "' is negative");
    options.reference_slope = *m;
  } else if (flag == "--sources") {
    options.sources.clear();
    for (const std::string& name : splitCommas(value)) {
      const std::optional<firmware::FoveationSource> source = firmware::parseFoveationSource(name);
      if (!source) return invalidArgument("--sources: '" + name + "' is not frame or map");
      if (std::find(options.sources.begin(), options.sources.end(), *source) != options.sources.end()) {
        return invalidArgument("--sources: '" + name + "' is named twice");
      }
      options.sources.push_back(*source);
    }
  } else if (flag == "--map-warmup") {
    Result<double> n = parseNumber(flag, value);
    if (!n) return n.status();
    if (*n < 0 || *n > 100000 || std::floor(*n) != *n) {
      return invalidArgument(flag + ": '" + value + "' is not an integer in [0, 100000]");
    }
    options.map_warmup = static_cast<long>(*n);
  } else if (flag == "--slopes") {
    options.slopes.clear();
    for (const std::string& text : splitCommas(value)) {
      Result<double> m = parseNumber("--slopes", text);
      if (!m) return m.status();
      if (*m < 0.0) return invalidArgument("--slopes: '" + text + "' is negative");
      options.slopes.push_back(*m);
    }
  } else {
    return std::nullopt;
  }
  return Status::ok();
}

// ACUITY's rows: its level margins, refined rows, floors and view culls.
std::optional<Status> applyAcuityFlag(const std::string& flag, const std::string& value, Options& options) {
  if (flag == "--acuity-margins") {
    options.acuity_margins.clear();
    for (const std::string& text : splitCommas(value)) {
      Result<double> k = parseNumber(flag, text);
      if (!k) return k.status();
      if (*k < 0.1 || *k > 10.0) return invalidArgument("--acuity-margins: '" + text + "' is outside [0.1, 10]");
      options.acuity_margins.push_back(*k);
    }
  } else if (flag == "--acuity-refined") {
    options.acuity_refined.clear();
    for (const std::string& text : splitCommas(value)) {
      if (text == "none") continue;
      const std::size_t colon = text.find(':');
      Result<double> k = parseNumber(flag, text.substr(0, colon));
      if (!k) return k.status();
      if (*k < 0.1 || *k > 10.0) return invalidArgument(flag + ": '" + text + "': k is outside [0.1, 10]");
      char* end = nullptr;
      const std::string passes = colon == std::string::npos ? "" : text.substr(colon + 1);
      const long p = std::strtol(passes.c_str(), &end, 10);
      if (passes.empty() || end != passes.c_str() + passes.size() || p < 1 || p > pipeline::kMaxRefinePasses) {
        return invalidArgument(flag + ": '" + text + "' is not K:PASSES with PASSES in [1, " +
                               std::to_string(pipeline::kMaxRefinePasses) + "]");
      }
      options.acuity_refined.emplace_back(*k, static_cast<int>(p));
    }
  } else if (flag == "--view-culls") {
    options.view_culls.clear();
    for (const std::string& text : splitCommas(value)) {
      Result<pipeline::ViewCull> c = pipeline::parseViewCull(text);
      if (!c) return invalidArgument(flag + ": " + c.status().message());
      options.view_culls.push_back(c.value());
    }
  } else if (flag == "--acuity-noise-floors") {
    options.acuity_noise_floors_mm.clear();
    for (const std::string& text : splitCommas(value)) {
      Result<double> mm = parseNumber(flag, text);
      if (!mm) return mm.status();
      if (*mm <= 0.0 || *mm > 1000.0) return invalidArgument(flag + ": '" + text + "' is outside (0, 1000] mm per m^2");
      options.acuity_noise_floors_mm.push_back(*mm);
    }
  } else if (flag == "--acuity-floors") {
    options.acuity_floors_mm.clear();
    for (const std::string& text : splitCommas(value)) {
      Result<double> mm = parseNumber(flag, text);
      if (!mm) return mm.status();
      if (*mm < 0.0 || *mm > 1000.0) return invalidArgument("--acuity-floors: '" + text + "' is outside [0, 1000] mm");
      options.acuity_floors_mm.push_back(*mm);
    }
  } else {
    return std::nullopt;
  }
  return Status::ok();
}

// Where the operator's eye and head are: away from the camera, turned from the gaze.
std::optional<Status> applyEyeFlag(const std::string& flag, const std::string& value, Options& options) {
  if (flag == "--head-turn-deg") {
    Result<double> d = parseNumber(flag, value);
    if (!d) return d.status();
    if (std::fabs(*d) > 180.0) return invalidArgument(flag + ": '" + value + "' is outside [-180, 180]");
    options.head_turn_deg = *d;
  } else if (flag == "--eye-offset") {
    const std::vector<std::string> parts = splitCommas(value);
    if (parts.size() != 3) return invalidArgument(flag + ": '" + value + "' is not X,Y,Z");
    for (int a = 0; a < 3; ++a) {
      Result<double> v = parseNumber(flag, parts[a]);
      if (!v) return v.status();
      if (std::fabs(*v) > 100.0) return invalidArgument(flag + ": '" + parts[a] + "' is beyond 100 m");
      options.eye_offset_cam[a] = *v;
    }
  } else {
    return std::nullopt;
  }
  return Status::ok();
}

// The figures over time (dynamics.h): their frames, the scan, the link's delays
// and ACUITY's fovea growth.
std::optional<Status> applyDynamicsFlag(const std::string& flag, const std::string& value, Options& options) {
  if (flag == "--dynamics-frames") {
    Result<double> n = parseNumber(flag, value);
    if (!n) return n.status();
    if (*n < 0 || *n > 10000 || std::floor(*n) != *n) {
      return invalidArgument(flag + ": '" + value + "' is not an integer in [0, 10000]");
    }
    options.dynamics.stability_frames = static_cast<int>(*n);
  } else if (flag == "--coverage-seconds") {
    Result<double> t = parseNumber(flag, value);
    if (!t) return t.status();
    if (*t < 0.1 || *t > 3600.0) return invalidArgument(flag + ": '" + value + "' is outside [0.1, 3600] s");
    options.dynamics.coverage_seconds = *t;
  } else if (flag == "--growth-max-deg") {
    Result<double> g = parseNumber(flag, value);
    if (!g) return g.status();
    if (*g < 0.0 || *g > 90.0) return invalidArgument(flag + ": '" + value + "' is outside [0, 90]");
    options.dynamics.growth_max_deg = *g;
  } else if (flag == "--growth-lead-ms") {
    Result<double> t = parseNumber(flag, value);
    if (!t) return t.status();
    if (*t < 0.0 || *t > 1000.0) return invalidArgument(flag + ": '" + value + "' is outside [0, 1000] ms");
    options.dynamics.lead_ms = *t;
  } else if (flag == "--down-ms" || flag == "--up-ms") {
    Result<double> ms = parseNumber(flag, value);
    if (!ms) return ms.status();
    if (*ms < 0.0 || *ms > 10000.0) return invalidArgument(flag + ": '" + value + "' is outside [0, 10000] ms");
    (flag == "--down-ms" ? options.dynamics.down_ms : options.dynamics.up_ms) = *ms;
  } else {
    return std::nullopt;
  }
  return Status::ok();
}

// One flag (not --help) and its value into options, by whichever group takes it.
Status applyFlag(const std::string& flag, const std::string& value, Options& options) {
  for (const auto apply : {applyRunFlag, applyAcuityFlag, applyEyeFlag, applyDynamicsFlag}) {
    if (std::optional<Status> taken = apply(flag, value, options)) return *taken;
  }
  return invalidArgument("unknown argument '" + flag + "' (see --help)");
}

}  // namespace

Result<Options> parseArgs(int argc, char** argv, bool& help) {
  Options options;
  help = false;
  for (int i = 1; i < argc; ++i) {
    std::string flag = argv[i];
    std::string value;
    const bool takes_value = flag != "--help" && flag != "-h" && flag != "--no-plot";
    if (const std::size_t eq = flag.find('='); flag.rfind("--", 0) == 0 && eq != std::string::npos) {
      value = flag.substr(eq + 1);
      flag = flag.substr(0, eq);
    } else if (takes_value) {
      if (i + 1 >= argc) return Result<Options>(ErrorCode::kInvalidArgument, flag + " needs a value");
      value = argv[++i];
    }
    if (flag == "--help" || flag == "-h") {
      help = true;
    } else if (Status s = applyFlag(flag, value, options); !s) {
      return s;
    }
  }
  return options;
}

}  // namespace fovea::tools

#include "firmware/options.h"

#include "firmware/frame_foveator.h"
#include "pipeline/map/surfel_links.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <utility>

namespace fovea::firmware {

namespace {

Status badValue(std::string_view flag, std::string_view text, std::string_view expected) {
  return {ErrorCode::kInvalidArgument,
          std::string(flag) + ": '" + std::string(text) + "' is not " + std::string(expected)};
}

std::vector<std::string_view> splitCommas(std::string_view text) {
  std::vector<std::string_view> parts;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = text.find(',', start);
    parts.push_back(text.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return parts;
}

}  // namespace

Result<Args> Args::parse(int argc, char** argv, int first, const std::vector<std::string>& value_flags,
                         const std::vector<std::string>& switches) {
  Args args;
  for (int i = first; i < argc; ++i) {
    std::string token = argv[i];
    std::string value;
    bool inline_value = false;
    if (const std::size_t eq = token.find('='); token.rfind("--", 0) == 0 && eq != std::string::npos) {
      value = token.substr(eq + 1);
      token = token.substr(0, eq);
      inline_value = true;
    }
    const bool is_value_flag = std::find(value_flags.begin(), value_flags.end(), token) != value_flags.end();
    const bool is_switch = std::find(switches.begin(), switches.end(), token) != switches.end();
    if (!is_value_flag && !is_switch) {
      return Result<Args>(ErrorCode::kInvalidArgument, "unknown argument '" + token + "' (see --help)");
    }
    if (is_switch) {
      if (inline_value) return Result<Args>(ErrorCode::kInvalidArgument, token + " takes no value");
      args.values_[token] = "";
      continue;
    }
    if (!inline_value) {
      if (i + 1 >= argc) return Result<Args>(ErrorCode::kInvalidArgument, token + " needs a value");
      value = argv[++i];
    }
    args.values_[token] = value;
  }
  return args;
}

const std::string* Args::get(const std::string& flag) const {
  auto it = values_.find(flag);
  return it == values_.end() ? nullptr : &it->second;
}

std::string Args::getOr(const std::string& flag, const std::string& fallback) const {
  const std::string* v = get(flag);
  return v ? *v : fallback;
}

Result<double> parseDouble(std::string_view flag, std::string_view text) {
  const std::string s(text);
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (s.empty() || end != s.c_str() + s.size() || !std::isfinite(v)) return badValue(flag, text, "a finite number");
  return v;
}

Result<long> parseInteger(std::string_view flag, std::string_view text, long min, long max) {
  long v = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || ptr != text.data() + text.size() || v < min || v > max) {
    return badValue(flag, text, "an integer in [" + std::to_string(min) + ", " + std::to_string(max) + "]");
  }
  return v;
}

Result<std::vector<double>> parseDoubleList(std::string_view flag, std::string_view text) {
  std::vector<double> values;
  for (std::string_view part : splitCommas(text)) {
    Result<double> v = parseDouble(flag, part);
    if (!v) return v.status();
    values.push_back(v.value());
  }
  return values;
}

Result<double> durationFromArgs(const Args& args) {
  const std::string* v = args.get("--duration");
  if (v == nullptr) return 0.0;
  Result<double> d = parseDouble("--duration", *v);
  if (!d) return d.status();
  // Up to a year, so start + duration stays far inside int64 nanoseconds.
  if (!(d.value() > 0.0 && d.value() <= 3.2e7)) {
    return Result<double>(ErrorCode::kInvalidArgument, "--duration: must be within 0 .. 3.2e7 s (a year)");
  }
  return d.value();
}

Result<pipeline::DepthRange> depthRangeFromArgs(const Args& args, pipeline::DepthRange range) {
  for (const auto& [flag, value] : {std::pair{"--depth-min", &range.min_m}, std::pair{"--depth-max", &range.max_m}}) {
    if (const std::string* v = args.get(flag)) {
      Result<double> d = parseDouble(flag, *v);
      if (!d) return d.status();
      *value = d.value();
    }
  }
  if (Status s = range.validate(); !s) return s;
  return range;
}

Result<MapSettings> mapSettingsFromArgs(const Args& args) {
  MapSettings settings;
  if (const std::string* v = args.get("--source")) {
    const std::optional<FoveationSource> source = parseFoveationSource(*v);
    if (!source) return badValue("--source", *v, "frame, map or pyramid");
    settings.source = *source;
  }
  if (const std::string* v = args.get("--max-surfels")) {
    Result<long> n = parseInteger("--max-surfels", *v, 1, pipeline::map::SurfelLinks::kMaxSlots);
    if (!n) return n.status();
    settings.map.max_surfels = static_cast<std::size_t>(n.value());
  }
  if (const std::string* v = args.get("--brick-size")) {
    Result<double> d = parseDouble("--brick-size", *v);
    if (!d) return d.status();
    settings.map.brick_size_m = d.value();
  }
  if (Status s = settings.map.validate(); !s) return s;
  return settings;
}

Result<Eigen::Vector3d> parseVector3(std::string_view flag, std::string_view text) {
  Result<std::vector<double>> values = parseDoubleList(flag, text);
  if (!values) return values.status();
  if (values->size() != 3) return badValue(flag, text, "three comma-separated numbers X,Y,Z");
  return Eigen::Vector3d((*values)[0], (*values)[1], (*values)[2]);
}

namespace {

// --preset, --bounds (a custom region list), --m and --far-ecc.
Status applyRegionFlags(const Args& args, pipeline::AcuityConfig& acuity) {
  if (const std::string* preset = args.get("--preset")) {
    Result<pipeline::Preset> p = pipeline::parsePreset(*preset);
    if (!p) return p.status();
    acuity.preset = p.value();
  }
  if (const std::string* bounds = args.get("--bounds")) {
    if (args.has("--preset") && acuity.preset != pipeline::Preset::kCustom) {
      return Status(ErrorCode::kInvalidArgument,
                    "--bounds: defines a custom region list; drop --preset or say --preset custom");
    }
    Result<std::vector<double>> list = parseDoubleList("--bounds", *bounds);
    if (!list) return list.status();
    acuity.preset = pipeline::Preset::kCustom;
    acuity.custom_bounds_deg = list.value();
  } else if (acuity.preset == pipeline::Preset::kCustom && acuity.custom_bounds_deg.empty()) {
    return Status(ErrorCode::kInvalidArgument, "--preset custom: needs --bounds E1,E2,...");
  }
  if (const std::string* m = args.get("--m")) {
    Result<double> v = parseDouble("--m", *m);
    if (!v) return v.status();
    acuity.slope = v.value();
  }
  if (const std::string* far = args.get("--far-ecc")) {
    Result<double> v = parseDouble("--far-ecc", *far);
    if (!v) return v.status();
    acuity.far_ecc_deg = v.value();
  }
  return Status::ok();
}

// --fixation hit|centroid|fixed:D0.
Status applyFixationFlag(const Args& args, pipeline::FixationConfig& fixation_config) {
  const std::string* fixation = args.get("--fixation");
  if (fixation == nullptr) return Status::ok();
  if (fixation->rfind("fixed:", 0) == 0) {
    Result<double> d0 = parseDouble("--fixation fixed:D0", fixation->substr(6));
    if (!d0) return d0.status();
    fixation_config.mode = pipeline::FixationMode::kFixed;
    fixation_config.fixed_m = d0.value();
  } else {
    Result<pipeline::FixationMode> mode = pipeline::parseFixationMode(*fixation);
    if (!mode) return mode.status();
    if (mode.value() == pipeline::FixationMode::kFixed) {
      return Status(ErrorCode::kInvalidArgument, "--fixation fixed: say fixed:D0 with D0 in metres");
    }
    fixation_config.mode = mode.value();
  }
  return Status::ok();
}

// ACUITY's own settings (the configuration keys of the same names); with
// another preset they would silently do nothing, so they are refused.
Status applyAcuityFlags(const Args& args, pipeline::AcuityConfig& acuity) {
  const auto acuityDouble = [&](const char* flag, double& field) -> Status {
    const std::string* text = args.get(flag);
    if (text == nullptr) return Status();
    Result<double> v = parseDouble(flag, *text);
    if (!v) return v.status();
    field = v.value();
    return Status();
  };
  if (Status s = acuityDouble("--level-voxel-m", acuity.level_voxel_m); !s) return s;
  if (Status s = acuityDouble("--floor-m", acuity.floor_m); !s) return s;
  if (Status s = acuityDouble("--floor-per-m2", acuity.floor_per_m2); !s) return s;
  if (Status s = acuityDouble("--level-margin", acuity.level_margin); !s) return s;
  if (const std::string* passes = args.get("--refine-passes")) {
    Result<long> v = parseInteger("--refine-passes", *passes, 0, pipeline::kMaxRefinePasses);
    if (!v) return v.status();
    acuity.refine_passes = static_cast<int>(v.value());
  }
  if (const std::string* cull = args.get("--view-cull")) {
    Result<pipeline::ViewCull> v = pipeline::parseViewCull(*cull);
    if (!v) return v.status();
    acuity.view_cull = v.value();
  }
  if (Status s = acuityDouble("--view-cull-deg", acuity.view_cull_deg); !s) return s;
  std::string named;  // the ACUITY flags given
  for (const std::string& flag : kAcuityFlags) {
    if (args.get(flag) != nullptr) named += (named.empty() ? "" : ", ") + flag;
  }
  if (!named.empty() && acuity.preset != pipeline::Preset::kAcuity) {
    return Status(ErrorCode::kInvalidArgument, named + ": ACUITY's settings: say --preset ACUITY (the foveation is " +
                                                   std::string(pipeline::presetName(acuity.preset)) + ")");
  }
  return Status::ok();
}

}  // namespace

Result<pipeline::FoveationConfig> foveationConfigFromArgs(const Args& args, pipeline::FoveationConfig base) {
  pipeline::FoveationConfig config = std::move(base);
  if (Status s = applyRegionFlags(args, config.acuity); !s) return s;
  if (Status s = applyFixationFlag(args, config.fixation); !s) return s;
  if (Status s = applyAcuityFlags(args, config.acuity); !s) return s;
  // Validate here so that the error names the flags, before any work starts.
  Result<pipeline::RegionModel> model = pipeline::RegionModel::create(config.acuity);
  if (!model) return model.status();
  if (Status s = config.fixation.validate(); !s) return s;
  return config;
}

std::string foveationFlagsHelp() {
  return "  --preset F1|F2|F3|FREF   regions of the paper's section III (default F1); ACUITY: each point on\n"
         "                           the coarsest lattice level its own acuity allows (docs/acuity-levels.md)\n"
         "  --bounds E1,E2,...       custom region bounds in degrees, strictly increasing in (0, 180)\n"
         "  --m SLOPE                slope of MAR(E) = m E + 1 arcmin (default 0.022; the paper: 0.022..0.034)\n"
         "  --far-ecc DEG            eccentricity whose MAR sizes the outermost region (default 90)\n"
         "  --fixation MODE          d0: hit (first surface along the gaze, default), centroid (the paper's\n"
         "                           fovea centroid) or fixed:D0 (metres)\n"
         "  ACUITY only (the configuration keys foveation.floor_m and so on; docs/acuity-levels.md):\n"
         "  --level-voxel-m V        the finest level's voxel edge in metres (default 0.002)\n"
         "  --floor-m M              no voxel finer than M metres (default 0)\n"
         "  --floor-per-m2 Q         no voxel finer than Q x distance^2 (the depth noise's floor; default 0)\n"
         "  --level-margin K         a level's voxel may displace a point by K x its MAR (default 0.5)\n"
         "  --refine-passes N        error-driven refinement passes, 0 to 7 (default 0)\n"
         "  --view-cull MODE         points outside the HMD's view: off (default), coarsest or drop\n"
         "  --view-cull-deg D        the view's half angle around the head's forward axis (default 70)\n";
}

std::string describeFoveation(const pipeline::FoveationConfig& config) {
  char buffer[160];
  std::snprintf(buffer, sizeof buffer, "%s (m %.3f, far periphery at %g deg), fixation %s",
                std::string(pipeline::presetName(config.acuity.preset)).c_str(), config.acuity.slope,
                config.acuity.far_ecc_deg, std::string(pipeline::fixationModeName(config.fixation.mode)).c_str());
  std::string text = buffer;
  if (config.acuity.preset == pipeline::Preset::kAcuity) {
    // Floors change what ACUITY sends several-fold (docs/acuity-levels.md): say them.
    std::string floors;
    if (config.acuity.floor_m > 0.0) {
      std::snprintf(buffer, sizeof buffer, " floor %g mm", config.acuity.floor_m * 1e3);
      floors += buffer;
    }
    if (config.acuity.floor_per_m2 > 0.0) {
      std::snprintf(buffer, sizeof buffer, " floor %g mm x s^2", config.acuity.floor_per_m2 * 1e3);
      floors += buffer;
    }
    if (config.acuity.level_margin != pipeline::AcuityConfig{}.level_margin) {
      std::snprintf(buffer, sizeof buffer, " margin %g", config.acuity.level_margin);
      floors += buffer;
    }
    if (config.acuity.refine_passes > 0) {
      std::snprintf(buffer, sizeof buffer, " refined %d pass%s", config.acuity.refine_passes,
                    config.acuity.refine_passes == 1 ? "" : "es");
      floors += buffer;
    }
    text.insert(pipeline::presetName(config.acuity.preset).size(), floors);
  }
  if (config.fixation.mode == pipeline::FixationMode::kFixed) text += " " + std::to_string(config.fixation.fixed_m) + " m";
  return text;
}

}  // namespace fovea::firmware

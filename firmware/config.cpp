#include "firmware/config.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <type_traits>
#include <variant>

#include <toml.hpp>

#include "core/kernel_set.h"
#include "firmware/camera_setup.h"
#include "hal/camera.h"
#include "hal/gpio.h"
#include "net/codec.h"
#include "net/udp_socket.h"
#include "net/wire.h"
#include "pipeline/acuity.h"
#include "pipeline/fixation.h"

#ifndef FOVEA_BOARD_DIR
#define FOVEA_BOARD_DIR "board"
#endif
#ifndef FOVEA_INSTALLED_BOARD_DIR
#define FOVEA_INSTALLED_BOARD_DIR "share/fovea/board"  // relative to the installation prefix
#endif

namespace fovea::firmware {

namespace {

using Value = std::variant<bool, int64_t, double, std::string, std::vector<double>>;
enum class Kind { kBool, kInt, kFloat, kString, kChoice, kFloatList };

// One setting: its "section.key" name, its TOML type and range (in the file's
// units: ms, MB/s), and how it maps onto ServiceConfig.
struct Field {
  const char* path;
  Kind kind;
  double min = 0.0;  // kInt, kFloat, each element of kFloatList: inclusive
  double max = 0.0;
  std::vector<std::string> choices;  // kChoice
  Value (*get)(const ServiceConfig&) = nullptr;
  void (*set)(ServiceConfig&, const Value&) = nullptr;
  // An extra check of a kString value: an error message, or "" when fine.
  std::string (*check)(const std::string&) = nullptr;
};

template <typename T>
using Plain = std::remove_cvref_t<T>;

// The table: every field of ServiceConfig but stream.link.key (read from
// stream.key_file at start-up) and stream.codec.max_payload (follows each
// session's MTU). Within a section, plain keys come before sub-sections.
#define FOVEA_BOOL(PATH, MEMBER)                                                                      \
  Field {                                                                                             \
    PATH, Kind::kBool, 0, 0, {}, [](const ServiceConfig& c) -> Value { return bool(c.MEMBER); },      \
        [](ServiceConfig& c, const Value& v) { c.MEMBER = std::get<bool>(v); }                         \
  }
#define FOVEA_INT(PATH, MEMBER, LO, HI)                                                                    \
  Field {                                                                                                  \
    PATH, Kind::kInt, LO, HI, {}, [](const ServiceConfig& c) -> Value { return static_cast<int64_t>(c.MEMBER); }, \
        [](ServiceConfig& c, const Value& v) { c.MEMBER = static_cast<Plain<decltype(c.MEMBER)>>(std::get<int64_t>(v)); } \
  }
// A duration kept in nanoseconds, written in milliseconds.
#define FOVEA_NS_AS_MS(PATH, MEMBER, LO, HI)                                                                 \
  Field {                                                                                                    \
    PATH, Kind::kInt, LO, HI, {}, [](const ServiceConfig& c) -> Value { return int64_t(c.MEMBER / 1'000'000); }, \
        [](ServiceConfig& c, const Value& v) { c.MEMBER = std::get<int64_t>(v) * 1'000'000; }                \
  }
#define FOVEA_FLOAT(PATH, MEMBER, LO, HI)                                                              \
  Field {                                                                                              \
    PATH, Kind::kFloat, LO, HI, {}, [](const ServiceConfig& c) -> Value { return double(c.MEMBER); },  \
        [](ServiceConfig& c, const Value& v) { c.MEMBER = std::get<double>(v); }                        \
  }
#define FOVEA_STRING(PATH, MEMBER, CHECK)                                                             \
  Field {                                                                                             \
    PATH, Kind::kString, 0, 0, {}, [](const ServiceConfig& c) -> Value { return c.MEMBER; },           \
        [](ServiceConfig& c, const Value& v) { c.MEMBER = std::get<std::string>(v); }, CHECK           \
  }
#define FOVEA_FLOAT_LIST(PATH, MEMBER, LO, HI)                                                         \
  Field {                                                                                              \
    PATH, Kind::kFloatList, LO, HI, {}, [](const ServiceConfig& c) -> Value { return c.MEMBER; },      \
        [](ServiceConfig& c, const Value& v) { c.MEMBER = std::get<std::vector<double>>(v); }           \
  }
#define FOVEA_THREAD(PATH, MEMBER)                                                     \
  FOVEA_INT(PATH ".core", MEMBER.core, -1, 1023),                                      \
      FOVEA_INT(PATH ".realtime_priority", MEMBER.realtime_priority, 0, 99)

std::string checkSpec(const std::string& spec) {
  if (spec.empty() || spec.front() == ':') return "must name a backend, as backend[:args]";
  return "";
}

std::string checkListen(const std::string& listen) {
  if (listen.empty()) return "";
  Result<net::Endpoint> endpoint = net::Endpoint::parse(listen);
  return endpoint ? std::string() : endpoint.status().message() + " (or \"\" not to listen)";
}

std::string checkNonEmpty(const std::string& text) { return text.empty() ? "must not be empty" : ""; }

const std::vector<Field>& fields() {
  static const std::vector<Field> table = {
      FOVEA_STRING("board", board, &checkNonEmpty),
      // [camera]
      FOVEA_STRING("camera.spec", camera.spec, &checkSpec),
      FOVEA_FLOAT("camera.depth_min_m", camera.depth.min_m, 0.0, 1000.0),
      FOVEA_FLOAT("camera.depth_max_m", camera.depth.max_m, 0.001, 1000.0),
      FOVEA_INT("camera.retry_initial_ms", camera.retry_initial_ms, 1, 60'000),
      FOVEA_INT("camera.retry_max_ms", camera.retry_max_ms, 1, 3'600'000),
      FOVEA_INT("camera.stall_timeout_ms", camera.stall_timeout_ms, 0, 600'000),
      FOVEA_STRING("camera.calibration_file", camera.calibration_file, nullptr),
      // [camera.extrinsics]
      FOVEA_FLOAT_LIST("camera.extrinsics.rotation_xyzw", camera.extrinsics_rotation_xyzw, -2.0, 2.0),
      FOVEA_FLOAT_LIST("camera.extrinsics.translation_m", camera.extrinsics_translation_m, -10.0, 10.0),
      // [camera.pose]
      Field{"camera.pose.source", Kind::kChoice, 0, 0, {"none", "fixed", "socket", "track", "track+fixed", "track+socket"},
            [](const ServiceConfig& c) -> Value { return c.camera.pose.source; },
            [](ServiceConfig& c, const Value& v) { c.camera.pose.source = std::get<std::string>(v); }},
      FOVEA_FLOAT_LIST("camera.pose.translation_m", camera.pose.translation_m, -1e7, 1e7),
      FOVEA_FLOAT_LIST("camera.pose.rotation_xyzw", camera.pose.rotation_xyzw, -2.0, 2.0),
      FOVEA_STRING("camera.pose.socket", camera.pose.socket, nullptr),
      FOVEA_INT("camera.pose.max_age_ms", camera.pose.max_age_ms, 1, 60'000),
      FOVEA_INT("camera.pose.buffer_poses", camera.pose.buffer_poses, 2, 100'000),
      // [pipeline]
      FOVEA_INT("pipeline.max_points", pipeline.max_points, 1, 50'000'000),
      FOVEA_INT("pipeline.max_voxels", pipeline.max_voxels, 1, 50'000'000),
      FOVEA_INT("pipeline.max_output_points", max_output_points, 0, 50'000'000),
      Field{"pipeline.kernels", Kind::kChoice, 0, 0, {"ref", "simd"},
            [](const ServiceConfig& c) -> Value { return std::string(fovea::kernelSetName(c.pipeline.kernels)); },
            [](ServiceConfig& c, const Value& v) {
              c.pipeline.kernels = *fovea::parseKernelSet(std::get<std::string>(v));
            }},
      FOVEA_INT("pipeline.threads", pipeline.threads, 1, 64),
      // [foveation]
      Field{"foveation.preset", Kind::kChoice, 0, 0, {"F1", "F2", "F3", "FREF", "ACUITY", "custom"},
            [](const ServiceConfig& c) -> Value { return std::string(pipeline::presetName(c.foveation.acuity.preset)); },
            [](ServiceConfig& c, const Value& v) {
              const std::string& name = std::get<std::string>(v);
              c.foveation.acuity.preset =
                  name == "custom" ? pipeline::Preset::kCustom : pipeline::parsePreset(name).value();
            }},
      Field{"foveation.custom_bounds_deg", Kind::kFloatList, 0.0, 180.0, {},
            [](const ServiceConfig& c) -> Value { return c.foveation.acuity.custom_bounds_deg; },
            [](ServiceConfig& c, const Value& v) {
              c.foveation.acuity.custom_bounds_deg = std::get<std::vector<double>>(v);
            }},
      FOVEA_FLOAT("foveation.slope", foveation.acuity.slope, 0.0001, 1.0),
      FOVEA_FLOAT("foveation.far_ecc_deg", foveation.acuity.far_ecc_deg, 0.01, 180.0),
      // preset ACUITY (docs/acuity-levels.md)
      FOVEA_FLOAT("foveation.level_voxel_m", foveation.acuity.level_voxel_m, 0.0001, 1.0),
      FOVEA_FLOAT("foveation.floor_m", foveation.acuity.floor_m, 0.0, 1.0),
      FOVEA_FLOAT("foveation.floor_per_m2", foveation.acuity.floor_per_m2, 0.0, 1.0),
      FOVEA_FLOAT("foveation.level_margin", foveation.acuity.level_margin, 0.1, 10.0),
      FOVEA_INT("foveation.refine_passes", foveation.acuity.refine_passes, 0, pipeline::kMaxRefinePasses),
      Field{"foveation.view_cull", Kind::kChoice, 0, 0, {"off", "coarsest", "drop"},
            [](const ServiceConfig& c) -> Value {
              return std::string(pipeline::viewCullName(c.foveation.acuity.view_cull));
            },
            [](ServiceConfig& c, const Value& v) {
              c.foveation.acuity.view_cull = pipeline::parseViewCull(std::get<std::string>(v)).value();
            }},
      FOVEA_FLOAT("foveation.view_cull_deg", foveation.acuity.view_cull_deg, 0.001, 180.0),
      // The map source (docs/map.md); not reloadable: it allocates the map.
      Field{"foveation.source", Kind::kChoice, 0, 0, {"frame", "map", "pyramid"},
            [](const ServiceConfig& c) -> Value { return std::string(foveationSourceName(c.map.source)); },
            [](ServiceConfig& c, const Value& v) {
              c.map.source = parseFoveationSource(std::get<std::string>(v)).value();
            }},
      // [foveation.fixation]
      Field{"foveation.fixation.mode", Kind::kChoice, 0, 0, {"hit", "centroid", "fixed"},
            [](const ServiceConfig& c) -> Value {
              return std::string(pipeline::fixationModeName(c.foveation.fixation.mode));
            },
            [](ServiceConfig& c, const Value& v) {
              c.foveation.fixation.mode = pipeline::parseFixationMode(std::get<std::string>(v)).value();
            }},
      FOVEA_FLOAT("foveation.fixation.fixed_m", foveation.fixation.fixed_m, 0.001, 10'000.0),
      FOVEA_FLOAT("foveation.fixation.hit_cone_deg", foveation.fixation.hit_cone_deg, 0.001, 89.0),
      FOVEA_FLOAT("foveation.fixation.hit_percentile", foveation.fixation.hit_percentile, 0.0, 1.0),
      FOVEA_FLOAT("foveation.fixation.fallback_m", foveation.fixation.fallback_m, 0.001, 10'000.0),
      FOVEA_FLOAT("foveation.fixation.min_m", foveation.fixation.min_m, 0.001, 100.0),
      // [map] (with foveation.source = "map"; pipeline/map/surfel_map.h says what each is)
      FOVEA_INT("map.max_surfels", map.map.max_surfels, 1, 1 << 30),
      FOVEA_INT("map.max_bricks", map.map.max_bricks, 1, 65535),
      FOVEA_FLOAT("map.brick_size_m", map.map.brick_size_m, 0.05, 16.0),
      FOVEA_FLOAT("map.depth_tolerance_sigmas", map.map.depth_tolerance_sigmas, 0.1, 100.0),
      FOVEA_FLOAT("map.normal_tolerance_deg", map.map.normal_tolerance_deg, 1.0, 180.0),
      FOVEA_FLOAT("map.confidence_cap", map.map.confidence_cap, 1.0, 255.0),
      FOVEA_FLOAT("map.stable_confidence", map.map.stable_confidence, 0.01, 255.0),
      FOVEA_INT("map.unstable_max_frames", map.map.unstable_max_frames, 1, 1'000'000),
      FOVEA_INT("map.settle_frames", map.map.settle_frames, 0, 1'000'000),
      // The map streamed as bricks the operator keeps (docs/map-delta.md); false:
      // the map's surfels the eye sees go with every frame.
      FOVEA_BOOL("map.delta", map.delta),
      FOVEA_FLOAT("map.change_fraction", map.delta_config.change_fraction, 0.0, 1.0),
      FOVEA_INT("map.max_brick_surfels", map.max_brick_surfels, 1, 1 << 24),
      FOVEA_INT("map.max_frame_brick_points", map.max_frame_brick_points, 1, 1 << 26),
      FOVEA_FLOAT("map.carve_weight", map.map.carve_weight, 0.0, 100.0),
      FOVEA_FLOAT("map.max_pose_jump_m", map.map.max_pose_jump_m, 0.001, 1000.0),
      FOVEA_INT("map.eye_face_cells", map.eye.face_cells, 8, 2048),
      FOVEA_FLOAT("map.occlusion_margin", map.eye.occlusion_margin, 0.0, 10.0),
      // [stream]
      FOVEA_STRING("stream.listen", stream.link.listen, &checkListen),
      FOVEA_STRING("stream.key_file", key_file, nullptr),
      FOVEA_BOOL("stream.insecure", stream.link.insecure),
      FOVEA_INT("stream.max_mtu_bytes", stream.link.max_mtu_bytes, static_cast<double>(net::kMinMtu),
                static_cast<double>(net::kMaxMtu)),
      Field{"stream.budget_mbps", Kind::kFloat, 0.01, 10'000.0, {},
            [](const ServiceConfig& c) -> Value {
              return static_cast<double>(c.stream.link.max_budget_bytes_per_s) / 1e6;
            },
            [](ServiceConfig& c, const Value& v) {
              c.stream.link.max_budget_bytes_per_s = static_cast<uint64_t>(std::llround(std::get<double>(v) * 1e6));
            }},
      FOVEA_NS_AS_MS("stream.session_timeout_ms", stream.link.session_timeout_ns, 100, 600'000),
      FOVEA_FLOAT("stream.burst_ms", stream.burst_ms, 0.0, 1000.0),
      FOVEA_NS_AS_MS("stream.gaze_timeout_ms", stream.gaze.timeout_ns, 1, 60'000),
      FOVEA_FLOAT("stream.fallback_voxel_m", stream.gaze.fallback_voxel_m, 0.001, 1.0),
      FOVEA_FLOAT("stream.gaze_growth_max_deg", stream.gaze.growth_max_deg, 0.0, 90.0),
      FOVEA_NS_AS_MS("stream.gaze_lead_ms", stream.gaze.lead_ns, 0, 10'000),
      FOVEA_FLOAT("stream.fovea_step_m", stream.codec.fovea_step_m, 1e-6, 1.0),
      FOVEA_FLOAT("stream.periphery_step_ratio", stream.codec.periphery_step_ratio, 1.0 / 1024, 1.0),
      Field{"stream.chroma", Kind::kChoice, 0, 0, {"full", "half"},
            [](const ServiceConfig& c) -> Value {
              return std::string(c.stream.codec.halve_peripheral_chroma ? "half" : "full");
            },
            [](ServiceConfig& c, const Value& v) {
              c.stream.codec.halve_peripheral_chroma = std::get<std::string>(v) == "half";
            }},
      FOVEA_BOOL("stream.entropy", stream.codec.entropy_coding),
      FOVEA_INT("stream.zstd_level", stream.codec.zstd_level, -7, 9),
      // [gpio]
      FOVEA_STRING("gpio.spec", gpio.spec, &checkSpec),
      FOVEA_INT("gpio.heartbeat_line", gpio.lines.heartbeat_line, -1, 1023),
      FOVEA_INT("gpio.streaming_line", gpio.lines.streaming_line, -1, 1023),
      FOVEA_INT("gpio.fault_line", gpio.lines.fault_line, -1, 1023),
      FOVEA_INT("gpio.privacy_line", gpio.lines.privacy_line, -1, 1023),
      FOVEA_BOOL("gpio.privacy_active_low", gpio.lines.privacy_active_low),
      FOVEA_NS_AS_MS("gpio.heartbeat_period_ms", gpio.lines.heartbeat_period_ns, 10, 60'000),
      FOVEA_STRING("gpio.consumer", gpio.lines.consumer, &checkNonEmpty),
      // [runtime]
      FOVEA_INT("runtime.ring_depth", runtime.ring_depth, 1, 64),
      FOVEA_BOOL("runtime.memory_lock", runtime.memory_lock),
      Field{"runtime.log_level", Kind::kChoice, 0, 0, {"error", "warning", "notice", "info", "debug"},
            [](const ServiceConfig& c) -> Value { return std::string(logLevelName(c.runtime.log_level)); },
            [](ServiceConfig& c, const Value& v) {
              c.runtime.log_level = parseLogLevel(std::get<std::string>(v)).value();
            }},
      FOVEA_INT("runtime.status_interval_ms", runtime.status_interval_ms, 100, 3'600'000),
      FOVEA_BOOL("runtime.systemd_notify", runtime.systemd_notify),
      FOVEA_THREAD("runtime.capture_thread", runtime.capture_thread),
      FOVEA_THREAD("runtime.foveation_thread", runtime.foveation_thread),
      FOVEA_THREAD("runtime.send_thread", runtime.send_thread),
  };
  return table;
}

#undef FOVEA_BOOL
#undef FOVEA_INT
#undef FOVEA_NS_AS_MS
#undef FOVEA_FLOAT
#undef FOVEA_STRING
#undef FOVEA_THREAD
#undef FOVEA_FLOAT_LIST

const Field* findField(std::string_view path) {
  for (const Field& field : fields()) {
    if (field.path == path) return &field;
  }
  return nullptr;
}

std::string sectionOf(std::string_view path) {
  const std::size_t dot = path.rfind('.');
  return dot == std::string_view::npos ? std::string() : std::string(path.substr(0, dot));
}

// Every section and sub-section ("camera", "foveation", "foveation.fixation").
const std::set<std::string>& sections() {
  static const std::set<std::string> names = [] {
    std::set<std::string> s;
    for (const Field& field : fields()) {
      for (std::string section = sectionOf(field.path); !section.empty(); section = sectionOf(section)) {
        s.insert(section);
      }
    }
    return s;
  }();
  return names;
}

// Shortest text that reads back as the same double.
std::string formatNumber(double v) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, v);
  return std::string(buffer, result.ptr);
}

// As a TOML float: "100" would read back as an integer.
std::string formatFloat(double v) {
  std::string text = formatNumber(v);
  if (text.find_first_of(".eEn") == std::string::npos) text += ".0";
  return text;
}

std::string quote(std::string_view text) {
  std::string out = "\"";
  for (const char ch : text) {
    const auto c = static_cast<unsigned char>(ch);
    if (ch == '"' || ch == '\\') {
      out += '\\';
      out += ch;
    } else if (c < 0x20 || c == 0x7f) {
      char escaped[8];
      std::snprintf(escaped, sizeof escaped, "\\u%04x", c);
      out += escaped;
    } else {
      out += ch;
    }
  }
  return out + "\"";
}

std::string formatValue(const Value& value) {
  if (const bool* b = std::get_if<bool>(&value)) return *b ? "true" : "false";
  if (const int64_t* i = std::get_if<int64_t>(&value)) return std::to_string(*i);
  if (const double* d = std::get_if<double>(&value)) return formatFloat(*d);
  if (const std::string* s = std::get_if<std::string>(&value)) return quote(*s);
  std::string out = "[";
  for (const double d : std::get<std::vector<double>>(value)) {
    if (out.size() > 1) out += ", ";
    out += formatFloat(d);
  }
  return out + "]";
}

// What is wrong with a string value's bytes ("" when nothing). A TOML file is
// UTF-8, so formatServiceConfig could not print anything else loadably (--set's
// bare text is not parsed as TOML, so it can carry any bytes: fuzz_config found
// it); a control character (a NUL cuts a path short) is always a mistake here.
std::string checkText(std::string_view text) {
  for (std::size_t i = 0; i < text.size();) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c < 0x20 || c == 0x7f) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "0x%02x", c);
      return "must not contain control characters (byte " + std::to_string(i) + " is " + hex + ")";
    }
    // RFC 3629: the length from the lead byte, continuation bytes 10xxxxxx, no
    // overlong forms, no surrogates, nothing above U+10FFFF.
    std::size_t length = 1;
    unsigned char lo = 0x80, hi = 0xbf;  // the range of the second byte
    if (c >= 0xc2 && c <= 0xdf) {
      length = 2;
    } else if (c >= 0xe0 && c <= 0xef) {
      length = 3;
      if (c == 0xe0) lo = 0xa0;
      if (c == 0xed) hi = 0x9f;
    } else if (c >= 0xf0 && c <= 0xf4) {
      length = 4;
      if (c == 0xf0) lo = 0x90;
      if (c == 0xf4) hi = 0x8f;
    } else if (c >= 0x80) {
      return "must be UTF-8 text (byte " + std::to_string(i) + " is not)";
    }
    for (std::size_t k = 1; k < length; ++k) {
      const auto b = i + k < text.size() ? static_cast<unsigned char>(text[i + k]) : 0;
      if (b < (k == 1 ? lo : 0x80) || b > (k == 1 ? hi : 0xbf)) {
        return "must be UTF-8 text (byte " + std::to_string(i) + " is not)";
      }
    }
    i += length;
  }
  return "";
}

// What is wrong with a value of the right type ("" when nothing).
std::string checkValue(const Field& field, const Value& value) {
  auto outside = [&field](double v) { return !(v >= field.min && v <= field.max); };
  auto bound = [&field](double v) {
    return field.kind == Kind::kInt ? std::to_string(static_cast<int64_t>(v)) : formatNumber(v);
  };
  auto range = [&](const std::string& got) {
    return "must be within " + bound(field.min) + " .. " + bound(field.max) + " (got " + got + ")";
  };
  switch (field.kind) {
    case Kind::kBool: return "";
    case Kind::kInt: {
      const int64_t v = std::get<int64_t>(value);
      return outside(static_cast<double>(v)) ? range(std::to_string(v)) : "";
    }
    case Kind::kFloat: {
      const double v = std::get<double>(value);
      return outside(v) ? range(formatNumber(v)) : "";
    }
    case Kind::kString: {
      const std::string& v = std::get<std::string>(value);
      if (std::string error = checkText(v); !error.empty()) return error;
      return field.check ? field.check(v) : "";
    }
    case Kind::kChoice: {
      const std::string& v = std::get<std::string>(value);
      if (std::string error = checkText(v); !error.empty()) return error;
      if (std::find(field.choices.begin(), field.choices.end(), v) != field.choices.end()) return "";
      std::string list;
      for (const std::string& choice : field.choices) list += (list.empty() ? "" : ", ") + quote(choice);
      return "must be one of " + list + " (got " + quote(v) + ")";
    }
    case Kind::kFloatList:
      for (const double v : std::get<std::vector<double>>(value)) {
        if (outside(v)) return "each must be within " + formatNumber(field.min) + " .. " + formatNumber(field.max) +
                               " (got " + formatNumber(v) + ")";
      }
      return "";
  }
  return "";
}

const char* typeName(const toml::value& v) {
  switch (v.type()) {
    case toml::value_t::boolean: return "a boolean";
    case toml::value_t::integer: return "an integer";
    case toml::value_t::floating: return "a float";
    case toml::value_t::string: return "a string";
    case toml::value_t::array: return "an array";
    case toml::value_t::table: return "a table";
    case toml::value_t::empty: return "nothing";
    default: return "a date or time";
  }
}

const char* expectedName(Kind kind) {
  switch (kind) {
    case Kind::kBool: return "a boolean";
    case Kind::kInt: return "an integer";
    case Kind::kFloat: return "a number";
    case Kind::kString:
    case Kind::kChoice: return "a string";
    case Kind::kFloatList: return "an array of numbers";
  }
  return "?";
}

// The TOML value as the field's type, or the message why not.
std::variant<Value, std::string> convert(const Field& field, const toml::value& v) {
  const std::string wrong = std::string("expected ") + expectedName(field.kind) + ", got " + typeName(v);
  switch (field.kind) {
    case Kind::kBool:
      if (v.is_boolean()) return Value(v.as_boolean());
      return wrong;
    case Kind::kInt:
      if (v.is_integer()) return Value(static_cast<int64_t>(v.as_integer()));
      return wrong;
    case Kind::kFloat:
      if (v.is_floating()) return Value(static_cast<double>(v.as_floating()));
      if (v.is_integer()) return Value(static_cast<double>(v.as_integer()));
      return wrong;
    case Kind::kString:
    case Kind::kChoice:
      if (v.is_string()) return Value(v.as_string().str);
      return wrong;
    case Kind::kFloatList: {
      if (!v.is_array()) return wrong;
      std::vector<double> list;
      for (const toml::value& element : v.as_array()) {
        if (element.is_floating()) {
          list.push_back(element.as_floating());
        } else if (element.is_integer()) {
          list.push_back(static_cast<double>(element.as_integer()));
        } else {
          return std::string("expected an array of numbers, got an array holding ") + typeName(element);
        }
      }
      return Value(std::move(list));
    }
  }
  return wrong;
}

// Optimal string alignment distance (a transposition counts as one edit).
std::size_t editDistance(std::string_view a, std::string_view b) {
  std::vector<std::vector<std::size_t>> d(a.size() + 1, std::vector<std::size_t>(b.size() + 1));
  for (std::size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
  for (std::size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t cost = a[i - 1] == b[j - 1] ? 0 : 1;
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1]) d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
    }
  }
  return d[a.size()][b.size()];
}

// " (did you mean 'camera.spec'?)" for a near name, else "".
std::string suggestion(std::string_view name, bool section) {
  std::string best;
  std::size_t best_distance = std::max<std::size_t>(2, name.size() / 4) + 1;
  auto consider = [&](std::string_view candidate) {
    // A name without its unit or suffix ("stream.budget") is one edit away.
    const bool prefix = candidate.size() > name.size() && candidate.substr(0, name.size()) == name &&
                        candidate[name.size()] == '_';
    const std::size_t distance = prefix ? 1 : editDistance(name, candidate);
    if (distance < best_distance) {
      best_distance = distance;
      best = candidate;
    }
  };
  if (section) {
    for (const std::string& s : sections()) consider(s);
  } else {
    for (const Field& field : fields()) consider(field.path);
  }
  return best.empty() ? std::string() : " (did you mean '" + best + "'?)";
}

// Where each field got its value ("board/rpi5.toml:12", "--set").
using Origins = std::map<std::string, std::string>;

// A field's value from a TOML value: type, range, then set.
Status assign(ServiceConfig& config, const Field& field, const toml::value& v, const std::string& where) {
  std::variant<Value, std::string> converted = convert(field, v);
  if (const std::string* error = std::get_if<std::string>(&converted)) {
    return invalidArgument(where + ": " + field.path + ": " + *error);
  }
  const Value& value = std::get<Value>(converted);
  if (std::string error = checkValue(field, value); !error.empty()) {
    return invalidArgument(where + ": " + field.path + ": " + error);
  }
  field.set(config, value);
  return Status::ok();
}

Result<std::string> readFile(const std::string& path) {
  std::FILE* file = std::fopen(path.c_str(), "rb");
  if (!file) return Result<std::string>(ErrorCode::kNotFound, "cannot open '" + path + "': " + std::strerror(errno));
  std::string text;
  char buffer[4096];
  std::size_t n;
  while ((n = std::fread(buffer, 1, sizeof buffer, file)) > 0) text.append(buffer, n);
  const bool failed = std::ferror(file) != 0;
  const int error = errno;
  std::fclose(file);
  if (failed) return Result<std::string>(ErrorCode::kIoError, "cannot read '" + path + "': " + std::strerror(error));
  return text;
}

// The first line of a toml11 message, without its "[error] " tag.
std::string firstLine(std::string_view what) {
  std::string_view line = what.substr(0, what.find('\n'));
  if (line.rfind("[error] ", 0) == 0) line.remove_prefix(8);
  return std::string(line);
}

Result<toml::value> parseToml(const std::string& text, const std::string& name) {
  try {
    std::istringstream in(text);
    return toml::parse(in, name);
  } catch (const toml::syntax_error& e) {
    return Result<toml::value>(ErrorCode::kParseError, name + ":" + std::to_string(e.location().line()) +
                                                           ": syntax error: " + firstLine(e.what()));
  } catch (const std::exception& e) {
    return Result<toml::value>(ErrorCode::kParseError, name + ": " + firstLine(e.what()));
  }
}

struct Entry {
  std::size_t line = 0;
  std::string path;
  const toml::value* value = nullptr;
};

// Every key of a parsed file: fields as entries, unknown names and misplaced
// tables as errors (each at its line).
void collect(const toml::value& table, const std::string& prefix, std::vector<Entry>& entries,
             std::vector<std::pair<std::size_t, std::string>>& errors) {
  for (const auto& [key, value] : table.as_table()) {
    const std::string path = prefix.empty() ? key : prefix + "." + key;
    const std::size_t line = value.location().line();
    const Field* field = findField(path);
    if (value.is_table() && !field) {
      if (sections().count(path)) {
        collect(value, path, entries, errors);
      } else {
        errors.emplace_back(line, "unknown section '" + path + "'" + suggestion(path, true));
      }
    } else if (field) {
      entries.push_back({line, path, &value});
    } else if (sections().count(path)) {
      errors.emplace_back(line, path + ": expected a table (a [" + path + "] section), got " + typeName(value));
    } else {
      errors.emplace_back(line, "unknown key '" + path + "'" + suggestion(path, false));
    }
  }
}

// Applies a file's text over `config`: field by field in the file's order,
// each checked alone (validate() checks the rules between fields). path names
// the file in messages.
Status loadTextInto(const std::string& text, const std::string& path, ServiceConfig& config, Origins& origins) {
  Result<toml::value> root = parseToml(text, path);
  if (!root) return root.status();
  std::vector<Entry> entries;
  std::vector<std::pair<std::size_t, std::string>> errors;
  collect(root.value(), "", entries, errors);
  std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) { return a.line < b.line; });
  std::sort(errors.begin(), errors.end());
  const std::size_t first_error_line = errors.empty() ? SIZE_MAX : errors.front().first;
  for (const Entry& entry : entries) {
    if (entry.line > first_error_line) break;
    const std::string where = path + ":" + std::to_string(entry.line);
    if (Status s = assign(config, *findField(entry.path), *entry.value, where); !s) return s;
    origins[entry.path] = where;
  }
  if (!errors.empty()) {
    return invalidArgument(path + ":" + std::to_string(errors.front().first) + ": " + errors.front().second);
  }
  return Status::ok();
}

Status loadInto(const std::string& path, ServiceConfig& config, Origins& origins) {
  Result<std::string> text = readFile(path);
  if (!text) return text.status();
  return loadTextInto(text.value(), path, config, origins);
}

struct FieldError {
  std::string field;
  std::string message;
  std::vector<std::string> related;  // fields whose origin locates the error if field has none
};

std::optional<FieldError> findError(const ServiceConfig& c) {
  for (const Field& field : fields()) {
    if (std::string error = checkValue(field, field.get(c)); !error.empty()) return FieldError{field.path, error, {}};
  }
  if (!(c.camera.depth.max_m > c.camera.depth.min_m)) {
    return FieldError{"camera.depth_max_m",
                      "must be more than camera.depth_min_m (got " + formatNumber(c.camera.depth.max_m) + " <= " +
                          formatNumber(c.camera.depth.min_m) + ")",
                      {"camera.depth_min_m"}};
  }
  if (c.camera.retry_max_ms < c.camera.retry_initial_ms) {
    return FieldError{"camera.retry_max_ms",
                      "must be at least camera.retry_initial_ms (got " + std::to_string(c.camera.retry_max_ms) + " < " +
                          std::to_string(c.camera.retry_initial_ms) + ")",
                      {"camera.retry_initial_ms"}};
  }
  if (Status s = checkCameraGeometry(c.camera); !s) {
    const std::string& m = s.message();
    const std::size_t colon = m.find(':');
    return FieldError{m.substr(0, colon), m.substr(colon + 2),
                      {"camera.extrinsics.rotation_xyzw", "camera.extrinsics.translation_m", "camera.pose.source"}};
  }
  if (c.camera.pose.source.rfind("track", 0) == 0 && c.map.source != FoveationSource::kMap) {
    return FieldError{"camera.pose.source",
                      "\"" + c.camera.pose.source + "\" tracks the camera against the map: needs foveation.source = \"map\"",
                      {"foveation.source"}};
  }
  if (c.pipeline.max_voxels > c.pipeline.max_points) {
    return FieldError{"pipeline.max_voxels",
                      "must be at most pipeline.max_points (got " + std::to_string(c.pipeline.max_voxels) + " > " +
                          std::to_string(c.pipeline.max_points) + ")",
                      {"pipeline.max_points"}};
  }
  if (c.max_output_points > c.pipeline.max_points) {
    return FieldError{"pipeline.max_output_points",
                      "must be at most pipeline.max_points (got " + std::to_string(c.max_output_points) + " > " +
                          std::to_string(c.pipeline.max_points) + ")",
                      {"pipeline.max_points"}};
  }
  const bool custom = c.foveation.acuity.preset == pipeline::Preset::kCustom;
  if (!custom && !c.foveation.acuity.custom_bounds_deg.empty()) {
    return FieldError{"foveation.custom_bounds_deg", "only with foveation.preset = \"custom\" (clear it, or set the preset)",
                      {"foveation.preset"}};
  }
  if (Result<pipeline::RegionModel> model = pipeline::RegionModel::create(c.foveation.acuity); !model) {
    return FieldError{custom ? "foveation.custom_bounds_deg" : "foveation.preset", model.status().message(),
                      {"foveation.preset", "foveation.slope", "foveation.far_ecc_deg"}};
  }
  if (Status s = c.foveation.fixation.validate(); !s) {
    return FieldError{"foveation.fixation", s.message(), {"foveation.fixation.mode"}};
  }
  if (c.map.map.stable_confidence > c.map.map.confidence_cap) {
    return FieldError{"map.stable_confidence",
                      "must be at most map.confidence_cap (got " + formatNumber(c.map.map.stable_confidence) + " > " +
                          formatNumber(c.map.map.confidence_cap) + ")",
                      {"map.confidence_cap"}};
  }
  // Status lines: distinct, whatever is used.
  const std::pair<const char*, int> lines[] = {{"gpio.heartbeat_line", c.gpio.lines.heartbeat_line},
                                               {"gpio.streaming_line", c.gpio.lines.streaming_line},
                                               {"gpio.fault_line", c.gpio.lines.fault_line},
                                               {"gpio.privacy_line", c.gpio.lines.privacy_line}};
  for (std::size_t i = 0; i < std::size(lines); ++i) {
    for (std::size_t j = 0; j < i; ++j) {
      if (lines[i].second >= 0 && lines[i].second == lines[j].second) {
        return FieldError{lines[i].first,
                          "line " + std::to_string(lines[i].second) + " is already used by " + lines[j].first,
                          {lines[j].first}};
      }
    }
  }
  if (!c.stream.link.listen.empty() && c.key_file.empty() && !c.stream.link.insecure) {
    return FieldError{"stream.key_file",
                      "needed when stream.listen is set (fovead keygen FILE makes one), or stream.insecure = true "
                      "on a trusted test host, or stream.listen = \"\" not to stream",
                      {"stream.listen"}};
  }
  if (c.stream.link.insecure && !c.key_file.empty()) {
    return FieldError{"stream.insecure", "not together with stream.key_file (set stream.key_file = \"\")",
                      {"stream.key_file"}};
  }
  if (Status s = c.stream.gaze.validate(); !s) return FieldError{"stream.gaze_timeout_ms", s.message(), {}};
  net::CodecConfig codec = c.stream.codec;
  codec.max_payload = c.stream.link.max_mtu_bytes - net::kDatagramOverhead;
  if (Status s = net::validate(codec); !s) return FieldError{"stream", s.message(), {}};
  return std::nullopt;
}

// What one setting implies for another nobody set: tracking the camera
// (camera.pose.source = track...) needs the map, so the map is the source then
// unless foveation.source was set (to something else: validation says so).
void applyImpliedSettings(ServiceConfig& config, Origins& origins) {
  if (config.camera.pose.source.rfind("track", 0) == 0 && origins.count("foveation.source") == 0) {
    config.map.source = FoveationSource::kMap;
    origins["foveation.source"] = "implied by camera.pose.source";
  }
}

Status validateWithOrigins(const ServiceConfig& config, const Origins& origins) {
  std::optional<FieldError> error = findError(config);
  if (!error) return Status::ok();
  std::string where;
  if (auto it = origins.find(error->field); it != origins.end()) where = it->second;
  for (auto name = error->related.begin(); where.empty() && name != error->related.end(); ++name) {
    if (auto it = origins.find(*name); it != origins.end()) where = it->second;
  }
  return invalidArgument((where.empty() ? "" : where + ": ") + error->field + ": " + error->message);
}

Status applyOverrideTracked(ServiceConfig& config, std::string_view assignment, Origins& origins) {
  const std::size_t eq = assignment.find('=');
  if (eq == std::string_view::npos || eq == 0) {
    return invalidArgument("--set: '" + std::string(assignment) + "' is not section.key=value");
  }
  std::string path(assignment.substr(0, eq));
  const std::string text(assignment.substr(eq + 1));
  const Field* field = findField(path);
  if (!field && path.find('.') != std::string::npos) {
    // A key short of its outer section, when only one key ends so
    // (pose.source = camera.pose.source): what the docs' prose says.
    const Field* only = nullptr;
    int matches = 0;
    for (const Field& f : fields()) {
      const std::string_view full = f.path;
      if (full.size() > path.size() && full.substr(full.size() - path.size()) == path &&
          full[full.size() - path.size() - 1] == '.') {
        only = &f;
        ++matches;
      }
    }
    if (matches == 1) {
      field = only;
      path = only->path;
    }
  }
  if (!field) {
    if (sections().count(path)) return invalidArgument("--set: '" + path + "' is a section; set one of its keys");
    return invalidArgument("--set: unknown key '" + path + "'" + suggestion(path, false));
  }
  const bool stringy = field->kind == Kind::kString || field->kind == Kind::kChoice;
  if (stringy && (text.empty() || (text.front() != '"' && text.front() != '\''))) {
    // Bare text for a string: camera.spec=mock:balloon.
    const toml::value value(text);
    if (Status s = assign(config, *field, value, "--set"); !s) return s;
  } else {
    Result<toml::value> root = parseToml("v = " + text + "\n", "--set");
    if (!root) return invalidArgument("--set: " + path + ": '" + text + "' is not a TOML value");
    if (Status s = assign(config, *field, root->as_table().at("v"), "--set"); !s) return s;
  }
  origins[path] = "--set";
  return Status::ok();
}

}  // namespace

Result<ServiceConfig> loadServiceConfig(const std::string& path, const ServiceConfig& base) {
  Result<std::string> text = readFile(path);
  if (!text) return text.status();
  return parseServiceConfig(text.value(), path, base);
}

Result<ServiceConfig> parseServiceConfig(std::string_view text, const std::string& name, const ServiceConfig& base) {
  ServiceConfig config = base;
  Origins origins;
  if (Status s = loadTextInto(std::string(text), name, config, origins); !s) return s;
  applyImpliedSettings(config, origins);
  if (Status s = validateWithOrigins(config, origins); !s) return s;
  return config;
}

Status applyOverride(ServiceConfig& config, std::string_view assignment) {
  Origins origins;
  return applyOverrideTracked(config, assignment, origins);
}

Status validate(const ServiceConfig& config) { return validateWithOrigins(config, {}); }

std::string formatServiceConfig(const ServiceConfig& config) {
  std::string out = "# fovead configuration (fovead --print-config); the keys: board/README.md\n";
  std::string section;
  for (const Field& field : fields()) {
    const std::string field_section = sectionOf(field.path);
    if (field_section != section) {
      section = field_section;
      out += "\n[" + section + "]\n";
    }
    const std::string key = section.empty() ? field.path : std::string(field.path).substr(section.size() + 1);
    out += key + " = " + formatValue(field.get(config)) + "\n";
  }
  return out;
}

std::vector<std::string> missingBackends(const ServiceConfig& config) {
  std::vector<std::string> missing;
  auto check = [&missing](const char* field, const std::string& spec, const std::vector<std::string_view>& built) {
    const std::string name = spec.substr(0, spec.find(':'));
    if (std::find(built.begin(), built.end(), name) != built.end()) return;
    std::string list;
    for (std::string_view b : built) list += (list.empty() ? "" : ", ") + std::string(b);
    missing.push_back(std::string(field) + ": backend '" + name + "' is not in this build (built: " + list + ")");
  };
  check("camera.spec", config.camera.spec, hal::cameraBackendNames());
  check("gpio.spec", config.gpio.spec, hal::gpioBackendNames());
  return missing;
}

std::string boardDirectory() {
  if (const char* env = std::getenv("FOVEA_BOARD_DIR"); env && *env) return env;
  // Installed: PREFIX/bin/fovead beside PREFIX/share/fovea/board (wherever PREFIX is).
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const std::filesystem::path installed = exe.parent_path().parent_path() / FOVEA_INSTALLED_BOARD_DIR;
    if (std::filesystem::is_regular_file(installed / (std::string(kDefaultBoard) + ".toml"), ec)) {
      return installed.lexically_normal().string();
    }
  }
  return FOVEA_BOARD_DIR;
}

Result<ServiceConfig> resolveServiceConfig(std::optional<std::string> board, std::optional<std::string> config_file,
                                           std::span<const std::string> overrides) {
  Origins origins;
  // The config file may name its board: read it once to see.
  std::string board_name = board.value_or(std::string(kDefaultBoard));
  if (config_file) {
    ServiceConfig peek;
    Origins peek_origins;
    if (Status s = loadInto(*config_file, peek, peek_origins); !s) return s;
    if (auto it = peek_origins.find("board"); it != peek_origins.end()) {
      if (board && *board != peek.board) {
        return invalidArgument(it->second + ": board: the file is for '" + peek.board + "', --board says '" + *board +
                               "'");
      }
      board_name = peek.board;
    }
  }
  if (board_name.empty() || board_name.find('/') != std::string::npos) {
    return invalidArgument("board: '" + board_name + "' is not a board name (use --config FILE for a file elsewhere)");
  }
  const std::string dir = boardDirectory();
  const std::string board_path = dir + "/" + board_name + ".toml";
  std::error_code ec;
  if (!std::filesystem::exists(board_path, ec)) {
    std::vector<std::string> names;
    for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
      if (entry.path().extension() == ".toml") names.push_back(entry.path().stem().string());
    }
    std::sort(names.begin(), names.end());
    std::string list;
    for (const std::string& name : names) list += (list.empty() ? "" : ", ") + name;
    return Result<ServiceConfig>(ErrorCode::kNotFound, "unknown board '" + board_name + "': no " + board_name +
                                                           ".toml in " + dir + " (boards: " +
                                                           (list.empty() ? "none: set FOVEA_BOARD_DIR to the profiles' directory"
                                                                         : list) +
                                                           ")");
  }
  ServiceConfig config;
  config.board = board_name;
  if (Status s = loadInto(board_path, config, origins); !s) return s;
  if (config.board != board_name) {
    return invalidArgument(origins["board"] + ": board: '" + config.board + "' in " + board_name +
                           ".toml (they must match)");
  }
  if (config_file) {
    if (Status s = loadInto(*config_file, config, origins); !s) return s;
  }
  for (const std::string& assignment : overrides) {
    // A profile is picked before anything else; renaming it afterwards would only mislabel the result.
    if (assignment.rfind("board=", 0) == 0) return invalidArgument("--set: board: pick a profile with --board NAME");
    if (Status s = applyOverrideTracked(config, assignment, origins); !s) return s;
  }
  // FOVEA_FORCE_KERNEL beats any file, as everywhere (core/kernel_set.h).
  if (const char* force = std::getenv("FOVEA_FORCE_KERNEL"); force && *force) {
    config.pipeline.kernels = fovea::defaultKernelSet();
  }
  applyImpliedSettings(config, origins);
  if (Status s = validateWithOrigins(config, origins); !s) return s;
  return config;
}

Result<ConfigSources> takeConfigSources(std::vector<std::string>& tokens) {
  ConfigSources sources;
  std::vector<std::string> rest;
  for (std::size_t i = 0; i < tokens.size(); ++i) {
    std::string flag = tokens[i];
    std::optional<std::string> value;
    if (const std::size_t eq = flag.find('='); flag.rfind("--", 0) == 0 && eq != std::string::npos) {
      value = flag.substr(eq + 1);
      flag.resize(eq);
    }
    if (flag != "--board" && flag != "--config" && flag != "--set") {
      rest.push_back(tokens[i]);
      continue;
    }
    if (!value) {
      if (i + 1 >= tokens.size()) return invalidArgument(flag + " needs a value");
      value = tokens[++i];
    }
    if (flag == "--set") {
      sources.overrides.push_back(*value);
    } else if (std::optional<std::string>& slot = flag == "--board" ? sources.board : sources.config_file; slot) {
      return invalidArgument(flag + " given twice");
    } else {
      slot = *value;
    }
  }
  tokens = std::move(rest);
  return sources;
}

}  // namespace fovea::firmware

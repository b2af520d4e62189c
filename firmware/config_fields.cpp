// The table of configuration fields (config_fields.h), one function a section
// in the order formatServiceConfig prints them, and the lookups by name.
#include "firmware/config_fields.h"

#include <cmath>
#include <iterator>
#include <type_traits>

#include "core/kernel_set.h"
#include "net/udp_socket.h"
#include "net/wire.h"
#include "pipeline/acuity.h"
#include "pipeline/fixation.h"
#include "pipeline/map/surfel_links.h"

namespace fovea::firmware::config_detail {

namespace {

template <typename T>
using Plain = std::remove_cvref_t<T>;

// A row of the table by the member it maps onto. Within a section, plain keys
// come before sub-sections.
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
      FOVEA_INT(PATH ".realtime_priority", MEMBER.realtime_priority, 0, 99),           \
      FOVEA_INT(PATH ".nice", MEMBER.nice, -20, 19)

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

// The keys outside any section.
std::vector<Field> topLevelFields() { return {FOVEA_STRING("board", board, &checkNonEmpty)}; }

std::vector<Field> cameraFields() {
  return {
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
    Field{"camera.pose.source", Kind::kChoice, 0, 0, {"none", "fixed", "socket", "track", "track+fixed", "track+socket", "track+camera"},
          [](const ServiceConfig& c) -> Value { return c.camera.pose.source; },
          [](ServiceConfig& c, const Value& v) { c.camera.pose.source = std::get<std::string>(v); }},
    FOVEA_FLOAT_LIST("camera.pose.translation_m", camera.pose.translation_m, -1e7, 1e7),
    FOVEA_FLOAT_LIST("camera.pose.rotation_xyzw", camera.pose.rotation_xyzw, -2.0, 2.0),
    FOVEA_STRING("camera.pose.socket", camera.pose.socket, nullptr),
    FOVEA_INT("camera.pose.max_age_ms", camera.pose.max_age_ms, 1, 60'000),
    FOVEA_INT("camera.pose.buffer_poses", camera.pose.buffer_poses, 2, 100'000),
  };
}

std::vector<Field> pipelineFields() {
  return {
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
    FOVEA_INT("pipeline.max_coarsenings", pipeline.max_coarsenings, 0, 16),
  };
}

std::vector<Field> foveationFields() {
  return {
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
  };
}

std::vector<Field> mapFields() {
  return {
    // [map] (with foveation.source = "map"; pipeline/map/surfel_map.h says what each is)
    FOVEA_INT("map.max_surfels", map.map.max_surfels, 1, pipeline::map::SurfelLinks::kMaxSlots),
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
    FOVEA_FLOAT("map.growth_fraction", map.delta_config.growth_fraction, 0.0, 1.0),
    FOVEA_FLOAT("map.churn_fraction", map.delta_config.churn_fraction, 0.0, 1.0),
    // A pixel is left out of the live points only by surfels the operator holds.
    FOVEA_BOOL("map.explain_held_only", map.delta_config.explain_held_only),
    FOVEA_INT("map.max_brick_surfels", map.max_brick_surfels, 1, 1 << 24),
    // 0: what the link's largest budget pays for in a frame (frameBrickPoints()).
    FOVEA_INT("map.max_frame_brick_points", map.max_frame_brick_points, 0, 1 << 26),
    // With bricks, a frame's live points at most; 0: an eighth of the pixels (liveFramePoints()).
    FOVEA_INT("map.max_live_points", map.max_live_points, 0, 1 << 26),
    // Fusion's average time a frame at most; the rest go without what the last
    // fused frame explained (0: fuse all).
    FOVEA_FLOAT("map.fuse_budget_ms", map.fuse_budget_ms, 0.0, 10000.0),
    // Fusion on a thread of its own (runtime.map_thread); false: on the foveation stage's.
    FOVEA_BOOL("map.fusion_thread", map.fusion_thread),
    FOVEA_FLOAT("map.carve_weight", map.map.carve_weight, 0.0, 100.0),
    FOVEA_FLOAT("map.max_pose_jump_m", map.map.max_pose_jump_m, 0.001, 1000.0),
    FOVEA_INT("map.eye_face_cells", map.eye.face_cells, 8, 2048),
    FOVEA_FLOAT("map.occlusion_margin", map.eye.occlusion_margin, 0.0, 10.0),
  };
}

std::vector<Field> streamFields() {
  return {
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
  };
}

std::vector<Field> gpioFields() {
  return {
    // [gpio]
    FOVEA_STRING("gpio.spec", gpio.spec, &checkSpec),
    FOVEA_INT("gpio.heartbeat_line", gpio.lines.heartbeat_line, -1, 1023),
    FOVEA_INT("gpio.streaming_line", gpio.lines.streaming_line, -1, 1023),
    FOVEA_INT("gpio.fault_line", gpio.lines.fault_line, -1, 1023),
    FOVEA_INT("gpio.privacy_line", gpio.lines.privacy_line, -1, 1023),
    FOVEA_BOOL("gpio.privacy_active_low", gpio.lines.privacy_active_low),
    FOVEA_NS_AS_MS("gpio.heartbeat_period_ms", gpio.lines.heartbeat_period_ns, 10, 60'000),
    FOVEA_STRING("gpio.consumer", gpio.lines.consumer, &checkNonEmpty),
  };
}

std::vector<Field> runtimeFields() {
  return {
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
    FOVEA_THREAD("runtime.map_thread", runtime.map_thread),
  };
}

#undef FOVEA_BOOL
#undef FOVEA_INT
#undef FOVEA_NS_AS_MS
#undef FOVEA_FLOAT
#undef FOVEA_STRING
#undef FOVEA_THREAD
#undef FOVEA_FLOAT_LIST

}  // namespace

const std::vector<Field>& fields() {
  static const std::vector<Field> table = [] {
    std::vector<Field> all;
    // In the order formatServiceConfig prints them.
    for (std::vector<Field> (*section)() : {&topLevelFields, &cameraFields, &pipelineFields, &foveationFields,
                                            &mapFields, &streamFields, &gpioFields, &runtimeFields}) {
      std::vector<Field> rows = section();
      all.insert(all.end(), std::make_move_iterator(rows.begin()), std::make_move_iterator(rows.end()));
    }
    return all;
  }();
  return table;
}

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

}  // namespace fovea::firmware::config_detail

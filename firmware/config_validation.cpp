// The rules between configuration fields (config_validation.h), one function a
// section, checked in the table's order: the first error found is the one reported.
#include "firmware/config_validation.h"

#include <iterator>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "firmware/camera_setup.h"
#include "firmware/config_values.h"
#include "net/codec.h"
#include "net/wire.h"
#include "pipeline/acuity.h"
#include "pipeline/fixation.h"

namespace fovea::firmware::config_detail {

namespace {

struct FieldError {
  std::string field;
  std::string message;
  std::vector<std::string> related;  // fields whose origin locates the error if field has none
};

// Each field alone: its range or choices.
std::optional<FieldError> fieldRangeError(const ServiceConfig& c) {
  for (const Field& field : fields()) {
    if (std::string error = checkValue(field, field.get(c)); !error.empty()) return FieldError{field.path, error, {}};
  }
  return std::nullopt;
}

std::optional<FieldError> cameraRuleError(const ServiceConfig& c) {
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
  return std::nullopt;
}

std::optional<FieldError> pipelineRuleError(const ServiceConfig& c) {
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
  return std::nullopt;
}

std::optional<FieldError> foveationRuleError(const ServiceConfig& c) {
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
  return std::nullopt;
}

std::optional<FieldError> mapRuleError(const ServiceConfig& c) {
  if (c.map.map.stable_confidence > c.map.map.confidence_cap) {
    return FieldError{"map.stable_confidence",
                      "must be at most map.confidence_cap (got " + formatNumber(c.map.map.stable_confidence) + " > " +
                          formatNumber(c.map.map.confidence_cap) + ")",
                      {"map.confidence_cap"}};
  }
  return std::nullopt;
}

// Status lines: distinct, whatever is used.
std::optional<FieldError> gpioRuleError(const ServiceConfig& c) {
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
  return std::nullopt;
}

std::optional<FieldError> streamRuleError(const ServiceConfig& c) {
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

// The first error: each field alone, then the rules between fields section by section.
std::optional<FieldError> findError(const ServiceConfig& c) {
  for (std::optional<FieldError> (*rules)(const ServiceConfig&) :
       {&fieldRangeError, &cameraRuleError, &pipelineRuleError, &foveationRuleError, &mapRuleError, &gpioRuleError,
        &streamRuleError}) {
    if (std::optional<FieldError> error = rules(c)) return error;
  }
  return std::nullopt;
}

}  // namespace

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

}  // namespace fovea::firmware::config_detail

#include "firmware/serve_options.h"

#include <optional>
#include <utility>

#include "firmware/stream_options.h"

namespace fovea::firmware {

const std::vector<std::string>& serveFlags() {
  // Built on first use, not during static initialisation: it reads kFoveationFlags
  // and kStreamFlags of other translation units, whose initialisation order is
  // unspecified (ASan's check_initialization_order caught this one in a unity build).
  static const std::vector<std::string> flags = [] {
    std::vector<std::string> f = {"--camera",     "--frames",    "--duration",  "--gpio",      "--gpio-lines",
                                  "--ring-depth", "--status-interval-ms",       "--threads",   "--depth-min",
                                  "--depth-max",  "--log-level", "--timing-log",
                                  "--record",     "--record-slots", "--record-cloud"};
    f.insert(f.end(), kFoveationFlags.begin(), kFoveationFlags.end());
    f.insert(f.end(), kStreamFlags.begin(), kStreamFlags.end());
    return f;
  }();
  return flags;
}
const std::vector<std::string> kServeSwitches = {"--insecure", "--memory-lock", "--record-frames"};

namespace {

// --gpio-lines heartbeat,streaming,fault[,privacy].
Status applyGpioLinesFlag(const Args& args, StatusLinesConfig& lines_config) {
  const std::string* v = args.get("--gpio-lines");
  if (v == nullptr) return Status::ok();
  Result<std::vector<double>> lines = parseDoubleList("--gpio-lines", *v);
  if (!lines) return lines.status();
  if (lines->size() < 3 || lines->size() > 4) {
    return Status(ErrorCode::kInvalidArgument, "--gpio-lines: expected heartbeat,streaming,fault[,privacy] line offsets");
  }
  int* fields[4] = {&lines_config.heartbeat_line, &lines_config.streaming_line, &lines_config.fault_line,
                    &lines_config.privacy_line};
  for (std::size_t i = 0; i < lines->size(); ++i) {
    const double line = (*lines)[i];
    if (line != static_cast<int>(line) || line < -1 || line > 1023) {
      return Status(ErrorCode::kInvalidArgument, "--gpio-lines: line offsets are integers within -1 .. 1023");
    }
    *fields[i] = static_cast<int>(line);
  }
  return Status::ok();
}

// The foveation flags over the configuration's foveation (only when one is
// given), and the streaming flags (with --listen).
Status applyFoveationAndStreamFlags(const Args& args, ServiceConfig& config) {
  bool foveation_flags = false;
  for (const std::string& flag : kFoveationFlags) foveation_flags = foveation_flags || args.has(flag);
  if (foveation_flags) {
    Result<pipeline::FoveationConfig> foveation = foveationConfigFromArgs(args, config.foveation);
    if (!foveation) return foveation.status();
    config.foveation = foveation.value();
  }
  // Over the configuration's stream section: --set stream.gaze_timeout_ms (or
  // the profile's budget) with --listen used to fall back to the defaults.
  Result<std::optional<StreamConfig>> stream = streamConfigFromArgs(args, config.stream);
  if (!stream) return stream.status();
  if (stream->has_value()) {
    config.stream = **stream;
    if (const std::string* v = args.get("--key-file")) config.key_file = *v;
  }
  return Status::ok();
}

// --timing-log FILE and the session recording: --record, --record-frames,
// --record-cloud, --record-slots.
Status applyRecordFlags(const Args& args, RuntimeSettings& runtime) {
  if (const std::string* v = args.get("--timing-log")) {
    if (v->empty()) return Status(ErrorCode::kInvalidArgument, "--timing-log: expected a file path");
    runtime.timing_log = *v;
  }
  if (const std::string* v = args.get("--record")) {
    if (v->empty()) return Status(ErrorCode::kInvalidArgument, "--record: expected a file path (FILE.mcap)");
    runtime.record.path = *v;
  }
  if (args.has("--record-frames")) {
    if (runtime.record.path.empty()) return Status(ErrorCode::kInvalidArgument, "--record-frames: only with --record FILE.mcap");
    runtime.record.frames = true;
  }
  if (const std::string* v = args.get("--record-cloud")) {
    if (*v != "on" && *v != "off") return Status(ErrorCode::kInvalidArgument, "--record-cloud: expected on or off, got '" + *v + "'");
    runtime.record.foxglove_cloud = *v == "on";
  }
  if (const std::string* v = args.get("--record-slots")) {
    Result<long> slots = parseInteger("--record-slots", *v, 16, 1 << 20);
    if (!slots) return slots.status();
    runtime.record.send_slots = static_cast<std::size_t>(slots.value());
  }
  return Status::ok();
}

// --ring-depth, --status-interval-ms and --threads.
Status applyRuntimeFlags(const Args& args, ServiceConfig& config) {
  if (const std::string* v = args.get("--ring-depth")) {
    Result<long> depth = parseInteger("--ring-depth", *v, 1, 64);
    if (!depth) return depth.status();
    config.runtime.ring_depth = static_cast<int>(depth.value());
  }
  if (const std::string* v = args.get("--status-interval-ms")) {
    Result<long> ms = parseInteger("--status-interval-ms", *v, 10, 3'600'000);
    if (!ms) return ms.status();
    config.runtime.status_interval_ms = ms.value();
  }
  if (const std::string* v = args.get("--threads")) {
    Result<long> threads = parseInteger("--threads", *v, 1, 64);
    if (!threads) return threads.status();
    config.pipeline.threads = static_cast<int>(threads.value());
  }
  return Status::ok();
}

}  // namespace

Result<ServiceConfig> serviceConfigFromArgs(const Args& args, ServiceConfig base) {
  using R = Result<ServiceConfig>;
  ServiceConfig config = std::move(base);
  if (const std::string* v = args.get("--camera")) config.camera.spec = *v;
  if (const std::string* v = args.get("--gpio")) config.gpio.spec = *v;
  if (Status s = applyGpioLinesFlag(args, config.gpio.lines); !s) return s;
  if (Status s = applyFoveationAndStreamFlags(args, config); !s) return s;
  if (Status s = applyRecordFlags(args, config.runtime); !s) return s;
  if (Status s = applyRuntimeFlags(args, config); !s) return s;
  Result<pipeline::DepthRange> depth = depthRangeFromArgs(args, config.camera.depth);
  if (!depth) return depth.status();
  config.camera.depth = depth.value();
  if (const std::string* v = args.get("--log-level")) {
    Result<LogLevel> level = parseLogLevel(*v);
    if (!level) return R(level.status().code(), "--log-level: " + level.status().message());
    config.runtime.log_level = level.value();
  }
  if (args.has("--memory-lock")) config.runtime.memory_lock = true;
  return config;
}

}  // namespace fovea::firmware

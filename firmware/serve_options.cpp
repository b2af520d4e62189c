#include "firmware/serve_options.h"

#include <optional>

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

Result<ServiceConfig> serviceConfigFromArgs(const Args& args, ServiceConfig base) {
  using R = Result<ServiceConfig>;
  ServiceConfig config = std::move(base);
  if (const std::string* v = args.get("--camera")) config.camera.spec = *v;
  if (const std::string* v = args.get("--gpio")) config.gpio.spec = *v;
  if (const std::string* v = args.get("--gpio-lines")) {
    Result<std::vector<double>> lines = parseDoubleList("--gpio-lines", *v);
    if (!lines) return lines.status();
    if (lines->size() < 3 || lines->size() > 4) {
      return R(ErrorCode::kInvalidArgument, "--gpio-lines: expected heartbeat,streaming,fault[,privacy] line offsets");
    }
    int* fields[4] = {&config.gpio.lines.heartbeat_line, &config.gpio.lines.streaming_line,
                      &config.gpio.lines.fault_line, &config.gpio.lines.privacy_line};
    for (std::size_t i = 0; i < lines->size(); ++i) {
      const double line = (*lines)[i];
      if (line != static_cast<int>(line) || line < -1 || line > 1023) {
        return R(ErrorCode::kInvalidArgument, "--gpio-lines: line offsets are integers within -1 .. 1023");
      }
      *fields[i] = static_cast<int>(line);
    }
  }
  bool foveation_flags = false;
  for (const std::string& flag : kFoveationFlags) foveation_flags = foveation_flags || args.has(flag);
  if (foveation_flags) {
    Result<pipeline::FoveationConfig> foveation = foveationConfigFromArgs(args, config.foveation);
    if (!foveation) return foveation.status();
    config.foveation = foveation.value();
  }
  Result<std::optional<StreamConfig>> stream = streamConfigFromArgs(args);
  if (!stream) return stream.status();
  if (stream->has_value()) {
    config.stream = **stream;
    if (const std::string* v = args.get("--key-file")) config.key_file = *v;
  }
  if (const std::string* v = args.get("--timing-log")) {
    if (v->empty()) return R(ErrorCode::kInvalidArgument, "--timing-log: expected a file path");
    config.runtime.timing_log = *v;
  }
  if (const std::string* v = args.get("--record")) {
    if (v->empty()) return R(ErrorCode::kInvalidArgument, "--record: expected a file path (FILE.mcap)");
    config.runtime.record.path = *v;
  }
  if (args.has("--record-frames")) {
    if (config.runtime.record.path.empty()) return R(ErrorCode::kInvalidArgument, "--record-frames: only with --record FILE.mcap");
    config.runtime.record.frames = true;
  }
  if (const std::string* v = args.get("--record-cloud")) {
    if (*v != "on" && *v != "off") return R(ErrorCode::kInvalidArgument, "--record-cloud: expected on or off, got '" + *v + "'");
    config.runtime.record.foxglove_cloud = *v == "on";
  }
  if (const std::string* v = args.get("--record-slots")) {
    Result<long> slots = parseInteger("--record-slots", *v, 16, 1 << 20);
    if (!slots) return slots.status();
    config.runtime.record.send_slots = static_cast<std::size_t>(slots.value());
  }
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
  if (const std::string* v = args.get("--depth-min")) {
    Result<double> d = parseDouble("--depth-min", *v);
    if (!d) return d.status();
    config.camera.depth.min_m = d.value();
  }
  if (const std::string* v = args.get("--depth-max")) {
    Result<double> d = parseDouble("--depth-max", *v);
    if (!d) return d.status();
    config.camera.depth.max_m = d.value();
  }
  if (Status s = config.camera.depth.validate(); !s) return s;
  if (const std::string* v = args.get("--log-level")) {
    Result<LogLevel> level = parseLogLevel(*v);
    if (!level) return R(level.status().code(), "--log-level: " + level.status().message());
    config.runtime.log_level = level.value();
  }
  if (args.has("--memory-lock")) config.runtime.memory_lock = true;
  return config;
}

}  // namespace fovea::firmware

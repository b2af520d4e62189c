#include "firmware/stream_options.h"

#include <cstdio>

#include "net/key.h"

namespace fovea::firmware {

const std::vector<std::string> kStreamFlags = {"--listen", "--key-file", "--budget", "--max-mtu", "--gaze-timeout-ms",
                                               "--fallback-voxel", "--fovea-step", "--chroma", "--entropy"};

// The streaming options, or nullopt without --listen.
Result<std::optional<StreamConfig>> streamConfigFromArgs(const Args& args, const StreamConfig& base) {
  using R = Result<std::optional<StreamConfig>>;
  if (!args.has("--listen")) {
    for (const std::string& flag : kStreamFlags) {
      if (args.has(flag)) return R(ErrorCode::kInvalidArgument, flag + ": only with --listen");
    }
    if (args.has("--insecure")) return R(ErrorCode::kInvalidArgument, "--insecure: only with --listen");
    return std::optional<StreamConfig>();
  }
  StreamConfig config = base;
  config.link.listen = *args.get("--listen");
  if (const std::string* path = args.get("--key-file")) {
    if (args.has("--insecure")) return R(ErrorCode::kInvalidArgument, "--insecure: not together with --key-file");
    Result<net::LoadedKey> key = net::loadKeyFile(*path);
    if (!key) return R(key.status().code(), "--key-file: " + key.status().message());
    if (!key->warning.empty()) std::fprintf(stderr, "fovead: warning: %s\n", key->warning.c_str());
    config.link.key = key->key;
  } else if (args.has("--insecure")) {
    config.link.insecure = true;
  } else {
    return R(ErrorCode::kInvalidArgument,
             "--listen: needs --key-file FILE (fovead keygen FILE makes one), or --insecure for a trusted test host");
  }
  if (const std::string* v = args.get("--budget")) {
    Result<double> mbps = parseDouble("--budget", *v);
    if (!mbps) return mbps.status();
    if (!(mbps.value() >= 0.01 && mbps.value() <= 10000.0)) {
      return R(ErrorCode::kInvalidArgument, "--budget: must be within 0.01 .. 10000 MB/s");
    }
    config.link.max_budget_bytes_per_s = static_cast<uint64_t>(mbps.value() * 1e6);
  }
  if (const std::string* v = args.get("--max-mtu")) {
    Result<long> mtu = parseInteger("--max-mtu", *v, static_cast<long>(net::kMinMtu), static_cast<long>(net::kMaxMtu));
    if (!mtu) return mtu.status();
    config.link.max_mtu_bytes = static_cast<uint32_t>(mtu.value());
  }
  if (const std::string* v = args.get("--gaze-timeout-ms")) {
    Result<long> ms = parseInteger("--gaze-timeout-ms", *v, 1, 60000);
    if (!ms) return ms.status();
    config.gaze.timeout_ns = ms.value() * 1'000'000;
  }
  if (const std::string* v = args.get("--fallback-voxel")) {
    Result<double> m = parseDouble("--fallback-voxel", *v);
    if (!m) return m.status();
    config.gaze.fallback_voxel_m = m.value();
  }
  if (const std::string* v = args.get("--fovea-step")) {
    Result<double> m = parseDouble("--fovea-step", *v);
    if (!m) return m.status();
    config.codec.fovea_step_m = m.value();
  }
  const std::string chroma = args.getOr("--chroma", "full");
  if (chroma != "full" && chroma != "half") return R(ErrorCode::kInvalidArgument, "--chroma: '" + chroma + "' is not full or half");
  config.codec.halve_peripheral_chroma = chroma == "half";
  const std::string entropy = args.getOr("--entropy", "off");
  if (entropy != "on" && entropy != "off") return R(ErrorCode::kInvalidArgument, "--entropy: '" + entropy + "' is not on or off");
  config.codec.entropy_coding = entropy == "on";
  if (Status s = config.gaze.validate(); !s) return R(s.code(), "--gaze-timeout-ms/--fallback-voxel: " + s.message());
  if (Status s = net::validate(config.codec); !s) return R(s.code(), "--fovea-step: " + s.message());
  return std::optional<StreamConfig>(config);
}

}  // namespace fovea::firmware

// fovea-lossy-relay: a UDP relay between one client and one server that drops
// a share of the datagrams in each direction and reorders a few, from a seed,
// so that a stream can be tested on a lossy link on one machine
// (toolchain/soak puts it between fovea-operator and fovead serve).
#include <algorithm>
#include <climits>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string>

#include "core/clock.h"
#include "tools/lossy_relay/lossy_relay.h"

namespace {

using namespace fovea;

constexpr int kExitOk = 0, kExitFailure = 1, kExitUsage = 2;

const char* kHelp =
    "usage: fovea-lossy-relay --to HOST:PORT [--listen HOST:PORT] [--loss SHARE] [--loss-up SHARE]\n"
    "                         [--loss-down SHARE] [--reorder SHARE] [--duplicate SHARE] [--loss-seconds S]\n"
    "                         [--seed N] [--stats-interval SECONDS]\n"
    "\n"
    "Relays UDP datagrams between one client (whoever last sent to --listen) and the\n"
    "server at --to, dropping a share of them in each direction and holding back a\n"
    "share so that each arrives after the next one (at most 20 ms late). The decisions\n"
    "come from the seed: the same seed drops the same datagrams.\n"
    "\n"
    "  --to HOST:PORT          the server (fovead serve --listen)\n"
    "  --listen HOST:PORT      where the client connects (default 127.0.0.1:0: any free port;\n"
    "                          the first line printed gives the address)\n"
    "  --loss SHARE            the share dropped in both directions, 0..1 (default 0.02)\n"
    "  --loss-up SHARE         client -> server only (default --loss)\n"
    "  --loss-down SHARE       server -> client only (default --loss)\n"
    "  --reorder SHARE         the share reordered in each direction (default 0.001)\n"
    "  --duplicate SHARE       the share forwarded twice in each direction (default 0)\n"
    "  --loss-seconds S        after S seconds the link recovers: nothing is dropped, reordered or\n"
    "                          duplicated any more (default: never; the line 'relay: loss stopped' says when)\n"
    "  --seed N                the decisions' seed (default 1)\n"
    "  --stats-interval S      print the counters every S seconds (default 60; 0: only at the end)\n"
    "\n"
    "SIGINT or SIGTERM stops it; it prints the counters and exits 0.\n";

volatile std::sig_atomic_t g_stop = 0;
extern "C" void onStopSignal(int) { g_stop = 1; }

bool parseShare(const char* flag, const char* text, double& out) {
  char* end = nullptr;
  const double v = std::strtod(text, &end);
  if (end == text || *end != '\0' || !(v >= 0.0 && v <= 1.0)) {
    std::fprintf(stderr, "fovea-lossy-relay: %s: '%s' is not a share within 0..1\n", flag, text);
    return false;
  }
  out = v;
  return true;
}

void printCounters(const char* what, const tools::LossyRelay& relay) {
  const auto line = [](const char* dir, const tools::RelayDirectionCounters& c) {
    std::printf(" | %s received %llu forwarded %llu dropped %llu reordered %llu duplicated %llu send-failures %llu", dir,
                static_cast<unsigned long long>(c.received), static_cast<unsigned long long>(c.forwarded),
                static_cast<unsigned long long>(c.dropped), static_cast<unsigned long long>(c.reordered),
                static_cast<unsigned long long>(c.duplicated), static_cast<unsigned long long>(c.send_failures));
  };
  std::printf("relay: %s", what);
  line("up", relay.up());
  line("down", relay.down());
  std::printf("\n");
  std::fflush(stdout);
}

// The command line's values (kHelp gives the defaults).
struct RelayOptions {
  std::string listen = "127.0.0.1:0", to;
  double loss = 0.02, reorder = 0.001, loss_up = -1, loss_down = -1, stats_interval_s = 60, duplicate = 0.0,
         loss_seconds = -1;
  unsigned long long seed = 1;
};

// One option and its value; false (said on stderr) when the value is bad or the
// option unknown.
bool takeOption(const std::string& flag, const char* value, RelayOptions& o) {
  bool ok = true;
  if (flag == "--to") {
    o.to = value;
  } else if (flag == "--listen") {
    o.listen = value;
  } else if (flag == "--loss") {
    ok = parseShare("--loss", value, o.loss);
  } else if (flag == "--loss-up") {
    ok = parseShare("--loss-up", value, o.loss_up);
  } else if (flag == "--loss-down") {
    ok = parseShare("--loss-down", value, o.loss_down);
  } else if (flag == "--reorder") {
    ok = parseShare("--reorder", value, o.reorder);
  } else if (flag == "--duplicate") {
    ok = parseShare("--duplicate", value, o.duplicate);
  } else if (flag == "--loss-seconds") {
    char* end = nullptr;
    o.loss_seconds = std::strtod(value, &end);
    ok = end != value && *end == '\0' && o.loss_seconds >= 0.0 && o.loss_seconds <= 1e6;
    if (!ok) std::fprintf(stderr, "fovea-lossy-relay: --loss-seconds: '%s' is not a number of seconds\n", value);
  } else if (flag == "--seed" || flag == "--stats-interval") {
    char* end = nullptr;
    const double v = std::strtod(value, &end);
    ok = end != value && *end == '\0' && v >= 0 && v <= 1.8e19;
    if (!ok) std::fprintf(stderr, "fovea-lossy-relay: %s: '%s' is not a non-negative number\n", flag.c_str(), value);
    if (flag == "--seed") {
      o.seed = std::strtoull(value, nullptr, 10);
    } else {
      o.stats_interval_s = v;
    }
  } else {
    std::fprintf(stderr, "fovea-lossy-relay: unknown argument '%s' (see --help)\n", flag.c_str());
    return false;
  }
  return ok;
}

// Reads the command line in order (--help where it stands); an exit code when
// the program ends here, nullopt to run.
std::optional<int> parseOptions(int argc, char** argv, RelayOptions& o) {
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--help" || flag == "-h") {
      std::fputs(kHelp, stdout);
      return kExitOk;
    }
    if (i + 1 >= argc) {
      std::fprintf(stderr, "fovea-lossy-relay: %s: unknown, or needs a value (see --help)\n", flag.c_str());
      return kExitUsage;
    }
    const char* value = argv[++i];
    if (!takeOption(flag, value, o)) return kExitUsage;
  }
  if (o.to.empty()) {
    std::fprintf(stderr, "fovea-lossy-relay: --to HOST:PORT is required\n");
    return kExitUsage;
  }
  return std::nullopt;
}

// The relay's configuration from the options, or why an address does not parse.
Result<tools::LossyRelayConfig> relayConfig(const RelayOptions& o) {
  tools::LossyRelayConfig config;
  Result<net::Endpoint> listen_ep = net::Endpoint::parse(o.listen);
  Result<net::Endpoint> to_ep = net::Endpoint::parse(o.to);
  if (!listen_ep || !to_ep) return (!listen_ep ? listen_ep : to_ep).status();
  config.listen = listen_ep.value();
  config.server = to_ep.value();
  config.up = {o.loss_up >= 0 ? o.loss_up : o.loss, o.reorder, o.duplicate};
  config.down = {o.loss_down >= 0 ? o.loss_down : o.loss, o.reorder, o.duplicate};
  config.seed = o.seed;
  return config;
}

// Relays until SIGINT or SIGTERM: the counters every --stats-interval, and the
// loss stopped after --loss-seconds.
void relayUntilStopped(tools::LossyRelay& relay, const RelayOptions& o) {
  const int64_t interval_ns = static_cast<int64_t>(o.stats_interval_s * 1e9);
  const int64_t started_ns = monotonicNs();
  int64_t next_stats_ns = started_ns + interval_ns;
  int64_t recover_ns = o.loss_seconds >= 0 ? started_ns + static_cast<int64_t>(o.loss_seconds * 1e9) : INT64_MAX;
  while (!g_stop) {
    relay.pump(recover_ns == INT64_MAX ? 100 : static_cast<int>(std::clamp<int64_t>((recover_ns - monotonicNs()) / 1'000'000, 0, 100)));
    if (monotonicNs() >= recover_ns) {
      (void)relay.setShares({}, {});
      recover_ns = INT64_MAX;
      printCounters("loss stopped", relay);
      std::fflush(stdout);
    }
    if (interval_ns > 0 && monotonicNs() >= next_stats_ns) {
      printCounters("counters", relay);
      next_stats_ns += interval_ns;
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  RelayOptions options;
  if (const std::optional<int> exit_code = parseOptions(argc, argv, options)) return *exit_code;
  Result<tools::LossyRelayConfig> config = relayConfig(options);
  if (!config) {
    std::fprintf(stderr, "fovea-lossy-relay: %s\n", config.status().message().c_str());
    return kExitUsage;
  }
  Result<tools::LossyRelay> created = tools::LossyRelay::create(config.value());
  if (!created) {
    std::fprintf(stderr, "fovea-lossy-relay: %s\n", created.status().message().c_str());
    return created.status().code() == ErrorCode::kInvalidArgument ? kExitUsage : kExitFailure;
  }
  tools::LossyRelay& relay = created.value();
  std::signal(SIGINT, onStopSignal);
  std::signal(SIGTERM, onStopSignal);
  std::printf("relay: listening on %s, forwarding to %s, loss up %.4f down %.4f, reorder %.4f, seed %llu\n",
              relay.localEndpoint().toString().c_str(), config->server.toString().c_str(), config->up.drop,
              config->down.drop, options.reorder, options.seed);
  std::fflush(stdout);
  relayUntilStopped(relay, options);
  relay.flush();
  printCounters("stopped", relay);
  return kExitOk;
}

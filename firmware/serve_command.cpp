// fovead serve: the service (firmware/service.h) until SIGINT or SIGTERM.
#include <signal.h>

#include <cstdio>
#include <string>
#include <vector>

#include "firmware/commands.h"
#include "firmware/config.h"
#include "firmware/mcap_camera.h"
#include "firmware/options.h"
#include "firmware/serve_options.h"
#include "firmware/service.h"
#include "hal/camera.h"

namespace fovea::firmware {

namespace {

const char* kServeHelp =
    "usage: fovead serve [--board NAME] [--config FILE] [--set SECTION.KEY=VALUE ...]\n"
    "                    [--listen ADDR:PORT (--key-file FILE | --insecure) [stream options]]\n"
    "                    [--camera SPEC] [--frames N] [--duration S] [--gpio SPEC] [--gpio-lines H,S,F[,P]]\n"
    "                    [--preset F1|F2|F3|FREF|ACUITY] [--m SLOPE] ... [--ring-depth N] [--status-interval-ms MS]\n"
    "                    [--threads N] [--memory-lock] [--log-level LEVEL] [--timing-log FILE]\n"
    "                    [--record FILE.mcap [--record-frames] [--record-cloud on|off] [--record-slots N]]\n"
    "\n"
    "Runs fovead as a service: capture, foveation and sending in their own threads joined\n"
    "by latest-wins rings, all memory allocated at start-up (printed), status GPIO lines,\n"
    "a status log line, systemd notifications (READY, STATUS, WATCHDOG) under systemd.\n"
    "SIGINT/SIGTERM stop it (exit 0); SIGHUP reads the configuration again and applies the\n"
    "foveation parameters and the budget.\n"
    "\n"
    "The configuration: the board profile, then the --config file, then each --set\n"
    "(fovead print-config shows the result), then the flags below.\n"
    "  --board NAME             board profile in the board directory (default host-mock, or the file's board key)\n"
    "  --config FILE            a configuration file (TOML, board/README.md), read again on SIGHUP\n"
    "  --set SECTION.KEY=VALUE  one setting (repeatable), e.g. --set stream.budget_mbps=25\n"
    "  --camera SPEC            camera backend (default mock:living-room,realtime=on)\n"
    "  --frames N               stop after N frames captured and passed on (default 0: until a signal)\n"
    "  --duration S             stop after S seconds (default: until a signal)\n"
    "  --gpio SPEC              status lines chip: mock (default), gpiod:gpiochip0\n"
    "  --gpio-lines H,S,F[,P]   heartbeat, streaming, fault [and privacy input] line offsets (-1: none)\n"
    "  --ring-depth N           frames queued between stages, latest wins (default 2)\n"
    "  --status-interval-ms MS  the status log line's period (default 5000)\n"
    "  --threads N              threads per frame for back-projection and partition (default 1)\n"
    "  --depth-min M, --depth-max M   valid depth range (default 0.1 .. 10 m)\n"
    "  --memory-lock            mlockall after start-up\n"
    "  --log-level LEVEL        error, warning, notice, info (default), debug\n"
    "  --timing-log FILE        one CSV line per frame sent: its time in each stage, in microseconds\n"
    "                           (acquire, queue, back-projection, partition, sampling, hand-off, encoding,\n"
    "                           pacing and sending; docs/eval.md)\n"
    "  --record FILE.mcap       record the run as MCAP (docs/recording.md): the chunks as sent (with --listen;\n"
    "                           without an operator every frame's chunks as the encoder makes them), the gaze\n"
    "                           received, each frame's camera pose, the status lines; never blocks the stages:\n"
    "                           a full ring or disk drops and counts (the stop line says how many)\n"
    "  --record-cloud on|off    with --record: the foveated cloud as foxglove.PointCloud on /fovea/cloud (default\n"
    "                           on; 16 bytes a point a frame, about 1 GB a minute at 30 fps; off keeps the\n"
    "                           chunks, which fovea-operator --replay draws)\n"
    "  --record-frames          with --record: every captured frame too, raw (depth, colour, intrinsics, pose;\n"
    "                           about 1.5 MB a 640x480 frame before the file's zstd), so the recording is a\n"
    "                           camera: fovead run --camera mcap:FILE.mcap replays it bit for bit\n"
    "  --record-slots N         datagrams the send stage may queue for the recording's writer (default 4096)\n"

    "  stream options as for fovead run: --budget, --max-mtu, --gaze-timeout-ms, --fallback-voxel,\n"
    "                           --fovea-step, --chroma, --entropy\n";

Service* g_service = nullptr;

extern "C" void onServeSignal(int signal_number) {
  Service* service = g_service;
  if (service == nullptr) return;
  if (signal_number == SIGHUP) {
    service->requestReload();
  } else {
    service->requestStop();
  }
}

// serve's own flags, once --board, --config and --set are taken out (into `sources`).
Result<Args> parseServeFlags(std::vector<std::string> tokens, ConfigSources& sources) {
  Result<ConfigSources> taken = takeConfigSources(tokens);
  if (!taken) return taken.status();
  sources = std::move(taken.value());
  std::vector<char*> argv;
  for (std::string& t : tokens) argv.push_back(t.data());
  return Args::parse(static_cast<int>(argv.size()), argv.data(), 0, serveFlags(), kServeSwitches);
}

// The effective configuration: board, file and --set (firmware/config.h), then
// serve's own flags over them. Run at start-up and again on SIGHUP.
Result<ServiceConfig> resolveServeConfig(const std::vector<std::string>& tokens) {
  ConfigSources sources;
  Result<Args> args = parseServeFlags(tokens, sources);
  if (!args) return args.status();
  Result<ServiceConfig> base = resolveServiceConfig(sources);
  if (!base) return base.status();
  return serviceConfigFromArgs(args.value(), std::move(base.value()));
}

}  // namespace

int serveCommand(int argc, char** argv) {
  const std::vector<std::string> tokens(argv + 2, argv + argc);
  for (const std::string& t : tokens) {
    if (t == "--help" || t == "-h") {
      std::printf("%s%s\ncameras:\n%s\n", kServeHelp, foveationFlagsHelp().c_str(), cameraSpecHelp().c_str());
      return kExitOk;
    }
  }
  auto usage = [](const Status& s) {
    std::fprintf(stderr, "fovead serve: %s\n", s.message().c_str());
    return kExitUsage;
  };
  ConfigSources sources;
  Result<Args> args = parseServeFlags(tokens, sources);  // --frames, --duration: this run's, not the config's
  if (!args) return usage(args.status());
  Result<ServiceConfig> config = resolveServeConfig(tokens);
  if (!config) return usage(config.status());
  Result<long> frames = parseInteger("--frames", args->getOr("--frames", "0"), 0, 100000000);
  if (!frames) return usage(frames.status());
  Result<double> duration = durationFromArgs(args.value());
  if (!duration) return usage(duration.status());
  const double duration_s = duration.value();
  logger().setLevel(config->runtime.log_level);

  Service::Environment environment;
  // SIGHUP: the profile and the configuration file as they are now, and the same flags.
  environment.reloader = [tokens]() -> Result<ServiceConfig> { return resolveServeConfig(tokens); };
  Result<std::unique_ptr<Service>> created = Service::create(config.value(), std::move(environment));
  if (!created) {
    std::fprintf(stderr, "fovead serve: %s\n", created.status().message().c_str());
    return created.status().code() == ErrorCode::kInvalidArgument ? kExitUsage : kExitFailure;
  }
  Service& service = *created.value();
  std::printf("fovead serve: board %s, camera %s, foveation %s, ring depth %d\n", config->board.c_str(),
              config->camera.spec.c_str(), describeFoveation(config->foveation).c_str(), config->runtime.ring_depth);
  std::printf("%s", service.memory().breakdown().c_str());  // the summary line is logged
  if (service.streaming()) {
    std::printf("streaming: listening on %s (%s), budget up to %.2f MB/s\n", service.localEndpoint().toString().c_str(),
                config->stream.link.insecure ? "INSECURE" : "authenticated",
                static_cast<double>(config->stream.link.max_budget_bytes_per_s) / 1e6);
  }
  std::fflush(stdout);

  g_service = &service;
  struct sigaction action {};
  action.sa_handler = onServeSignal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  sigaction(SIGHUP, &action, nullptr);
  if (Status s = service.start(); !s) {
    g_service = nullptr;
    std::fprintf(stderr, "fovead serve: %s\n", s.message().c_str());
    return kExitFailure;
  }
  std::printf("fovead serve: running (SIGTERM or SIGINT stops, SIGHUP reloads)\n");
  std::fflush(stdout);
  service.run(static_cast<uint64_t>(frames.value()), static_cast<int64_t>(duration_s * 1e9));
  g_service = nullptr;
  const ServiceStats stats = service.stats();
  std::printf("fovead serve: stopped after %llu frames foveated, %llu sent\n",
              static_cast<unsigned long long>(stats.frames_foveated), static_cast<unsigned long long>(stats.frames_sent));
  return kExitOk;
}

}  // namespace fovea::firmware

// fovea-operator: the operator station without the headset. Says hello to a
// fovead stream, sends gaze from a script, receives and decodes the foveated
// frames, and measures what an operator would feel: frames per second, bytes on
// the wire, end-to-end latency, losses. The decoding is fovea::net's library
// (ChunkEncoder's counterpart), which a VR front end links the same way.
#include <algorithm>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "net/codec.h"
#include "net/key.h"
#include "net/operator_link.h"
#include "pipeline/io/ply.h"
#include "tools/operator/gaze_script.h"
#include "tools/operator/operator_stats.h"

namespace {

using namespace fovea;

constexpr int kExitOk = 0, kExitFailure = 1, kExitUsage = 2;

const char* kHelp =
    "usage: fovea-operator --connect HOST:PORT (--key-file FILE | --insecure) --gaze SCRIPT\n"
    "                      [--duration SECONDS] [--summary FILE.json] [--save-ply DIR]\n"
    "                      [--name NAME] [--budget MBPS] [--mtu BYTES] [--gaze-hz HZ] [--max-points N]\n"
    "                      [--clock auto|shared|estimated] [--quiet]\n"
    "\n"
    "Connects to fovead run --listen, sends gaze samples from a script, receives and\n"
    "decodes the foveated frames, and prints once a second: frames per second, MB/s\n"
    "on the wire, end-to-end latency from capture to decoded (p50, p99), datagrams lost,\n"
    "points per region.\n"
    "\n"
    "  --connect HOST:PORT   the robot: 127.0.0.1:7000, [::1]:7000, robot.local:7000\n"
    "  --key-file FILE       the pre-shared key the robot has (fovead keygen FILE)\n"
    "  --insecure            the all-zero key of a robot started with --insecure\n"
    "  --gaze SCRIPT         fixed:EYE>TARGET | scan:EYE>T1;T2;...[@DWELL_MS[/SACCADE_MS]] | csv:FILE\n"
    "                        (world metres; csv lines t_s,ox,oy,oz,dx,dy,dz)\n"
    "  --duration SECONDS    stop after this long (default: until SIGINT/SIGTERM or the robot's bye)\n"
    "  --summary FILE.json   write the whole run's figures as JSON at the end\n"
    "  --save-ply DIR        write every decoded frame as DIR/frame_ID.ply (world coordinates, region)\n"
    "  --name NAME           the name the robot shows (default fovea-operator)\n"
    "  --budget MBPS         the bandwidth to ask for, MB/s (default: what the robot allows)\n"
    "  --mtu BYTES           the largest UDP payload to ask for (default 1200)\n"
    "  --gaze-hz HZ          gaze samples per second (default 120, up to 200)\n"
    "  --max-points N        the largest frame to decode, in points (default 307200 = 640x480)\n"
    "  --clock MODE          how capture stamps (robot clock) compare with arrival (this host's):\n"
    "                        shared: one CLOCK_MONOTONIC (same host); estimated: the robot's clock\n"
    "                        estimated from its status stamps and the round trip it measures\n"
    "                        (RTT/2 each way); auto (default): shared on a loopback address\n"
    "  --quiet               no live lines\n";

volatile std::sig_atomic_t g_stop = 0;
extern "C" void onStopSignal(int) { g_stop = 1; }

int64_t monotonicNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

struct Options {
  std::string connect;
  std::optional<std::string> key_file;
  bool insecure = false;
  std::string gaze;
  double duration_s = 0.0;
  std::string summary_path;
  std::string ply_dir;
  std::string name = "fovea-operator";
  double budget_mbps = 0.0;
  long mtu = static_cast<long>(net::kDefaultMtu);
  double gaze_hz = 120.0;
  bool quiet = false;
  long max_points = 640 * 480;
  std::string clock = "auto";
};

Result<double> number(const std::string& flag, const char* text) {
  char* end = nullptr;
  const double v = std::strtod(text, &end);
  if (end == text || *end != '\0' || !std::isfinite(v)) {
    return Result<double>(ErrorCode::kInvalidArgument, flag + ": '" + text + "' is not a number");
  }
  return v;
}

Result<Options> parseOptions(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--insecure") { o.insecure = true; continue; }
    if (flag == "--quiet") { o.quiet = true; continue; }
    if (i + 1 >= argc) return Result<Options>(ErrorCode::kInvalidArgument, flag + ": unknown, or needs a value (see --help)");
    const char* value = argv[++i];
    if (flag == "--connect") {
      o.connect = value;
    } else if (flag == "--key-file") {
      o.key_file = value;
    } else if (flag == "--gaze") {
      o.gaze = value;
    } else if (flag == "--summary") {
      o.summary_path = value;
    } else if (flag == "--save-ply") {
      o.ply_dir = value;
    } else if (flag == "--name") {
      o.name = value;
    } else if (flag == "--clock") {
      o.clock = value;
      if (o.clock != "auto" && o.clock != "shared" && o.clock != "estimated") {
        return Result<Options>(ErrorCode::kInvalidArgument, "--clock: '" + o.clock + "' is not auto, shared or estimated");
      }
    } else if (flag == "--max-points") {
      Result<double> v = number(flag, value);
      if (!v) return v.status();
      if (!(v.value() >= 1 && v.value() <= 1e8)) return Result<Options>(ErrorCode::kInvalidArgument, "--max-points: must be within 1 .. 1e8");
      o.max_points = static_cast<long>(v.value());
    } else if (flag == "--duration" || flag == "--budget" || flag == "--mtu" || flag == "--gaze-hz") {
      Result<double> v = number(flag, value);
      if (!v) return v.status();
      if (flag == "--duration") {
        if (!(v.value() > 0 && v.value() <= 3.2e7)) {
          return Result<Options>(ErrorCode::kInvalidArgument, "--duration: must be within 0 .. 3.2e7 s (a year)");
        }
        o.duration_s = v.value();
      } else if (flag == "--budget") {
        if (!(v.value() >= 0.01 && v.value() <= 10000.0)) {
          return Result<Options>(ErrorCode::kInvalidArgument, "--budget: must be within 0.01 .. 10000 MB/s");
        }
        o.budget_mbps = v.value();
      } else if (flag == "--mtu") {
        if (v.value() < static_cast<double>(net::kMinMtu) || v.value() > static_cast<double>(net::kMaxMtu)) {
          return Result<Options>(ErrorCode::kInvalidArgument, "--mtu: must be within " + std::to_string(net::kMinMtu) +
                                                                  " .. " + std::to_string(net::kMaxMtu));
        }
        o.mtu = static_cast<long>(v.value());
      } else {
        if (!(v.value() >= 1 && v.value() <= 200)) return Result<Options>(ErrorCode::kInvalidArgument, "--gaze-hz: must be within 1 .. 200");
        o.gaze_hz = v.value();
      }
    } else {
      return Result<Options>(ErrorCode::kInvalidArgument, "unknown argument '" + flag + "' (see --help)");
    }
  }
  if (o.connect.empty()) return Result<Options>(ErrorCode::kInvalidArgument, "--connect HOST:PORT is required");
  if (o.gaze.empty()) return Result<Options>(ErrorCode::kInvalidArgument, "--gaze SCRIPT is required");
  if (o.key_file && o.insecure) return Result<Options>(ErrorCode::kInvalidArgument, "--insecure: not together with --key-file");
  if (!o.key_file && !o.insecure) {
    return Result<Options>(ErrorCode::kInvalidArgument, "--key-file FILE is required (or --insecure for a robot started with --insecure)");
  }
  return o;
}

std::string vec3Json(const Eigen::Vector3d& v) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "[%.9g, %.9g, %.9g]", v.x(), v.y(), v.z());
  return buf;
}

}  // namespace

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) {
      std::fputs(kHelp, stdout);
      return kExitOk;
    }
  }
  Result<Options> parsed = parseOptions(argc, argv);
  if (!parsed) {
    std::fprintf(stderr, "fovea-operator: %s\n", parsed.status().message().c_str());
    return kExitUsage;
  }
  const Options& opt = parsed.value();
  Result<tools::GazeScript> script = tools::GazeScript::parse(opt.gaze);
  if (!script) {
    std::fprintf(stderr, "fovea-operator: %s\n", script.status().message().c_str());
    return script.status().code() == ErrorCode::kInvalidArgument ? kExitUsage : kExitFailure;
  }
  net::OperatorLinkConfig link_config;
  if (opt.key_file) {
    Result<net::LoadedKey> key = net::loadKeyFile(*opt.key_file);
    if (!key) {
      std::fprintf(stderr, "fovea-operator: --key-file: %s\n", key.status().message().c_str());
      return kExitFailure;
    }
    if (!key->warning.empty()) std::fprintf(stderr, "fovea-operator: warning: %s\n", key->warning.c_str());
    link_config.key = key->key;
  }
  link_config.insecure = opt.insecure;
  link_config.name = opt.name;
  link_config.budget_bytes_per_s = static_cast<uint64_t>(opt.budget_mbps * 1e6);
  link_config.mtu_bytes = static_cast<uint32_t>(opt.mtu);
  if (!opt.ply_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(opt.ply_dir, ec);
    if (ec) {
      std::fprintf(stderr, "fovea-operator: --save-ply: cannot create '%s': %s\n", opt.ply_dir.c_str(), ec.message().c_str());
      return kExitFailure;
    }
  }

  Result<std::unique_ptr<net::OperatorLink>> connected = net::OperatorLink::connect(opt.connect, link_config);
  if (!connected) {
    std::fprintf(stderr, "fovea-operator: %s\n", connected.status().message().c_str());
    return connected.status().code() == ErrorCode::kInvalidArgument ? kExitUsage : kExitFailure;
  }
  net::OperatorLink& link = *connected.value();
  if (!link.notice().empty()) std::fprintf(stderr, "fovea-operator: *** %s ***\n", link.notice().c_str());
  // Latency compares the robot's capture stamp with this host's arrival time. On
  // one host the clocks are one; across hosts the robot's clock is estimated from
  // its status stamps: robot = local + offset, offset = stamp + RTT/2 - arrival.
  const std::string robot_address = link.robot().toString();
  const bool shared_clock = opt.clock == "shared" ||
                            (opt.clock == "auto" && (robot_address.rfind("127.", 0) == 0 || robot_address.rfind("[::1]", 0) == 0));
  std::optional<int64_t> clock_offset_ns;  // robot minus local
  if (shared_clock) clock_offset_ns = 0;
  std::printf("connected to %s: MTU %u, budget %.2f MB/s; latency on %s\n", robot_address.c_str(), link.mtuBytes(),
              static_cast<double>(link.budgetBytesPerS()) / 1e6,
              shared_clock ? "one clock" : "the robot's clock estimated from its status and round trip");
  std::fflush(stdout);

  // Room for the largest frame: the assembler refuses what does not fit, and counts it.
  Result<net::FrameAssembler> assembler_created = net::FrameAssembler::create(static_cast<std::size_t>(opt.max_points));
  if (!assembler_created) {
    std::fprintf(stderr, "fovea-operator: %s\n", assembler_created.status().message().c_str());
    return kExitFailure;
  }
  net::FrameAssembler& assembler = assembler_created.value();

  std::signal(SIGINT, onStopSignal);
  std::signal(SIGTERM, onStopSignal);
  tools::OperatorStats stats;
  const int64_t start_ns = monotonicNs();
  const int64_t end_ns = opt.duration_s > 0 ? start_ns + static_cast<int64_t>(opt.duration_s * 1e9) : INT64_MAX;
  const auto gaze_period_ns = static_cast<int64_t>(1e9 / opt.gaze_hz);
  int64_t next_gaze_ns = start_ns;
  int64_t next_live_ns = start_ns + 1'000'000'000;
  int64_t live_start_ns = start_ns;
  uint64_t lost_reported = 0, last_frame_id = 0, ply_written = 0, ply_failed = 0, gaze_sent = 0;
  tools::GazePoint last_gaze;
  bool robot_said_bye = false;

  auto handleReady = [&]() {
    for (std::size_t i = 0; i < assembler.readyCount(); ++i) {
      const net::AssembledFrame& f = assembler.ready(i);
      tools::FrameObservation obs;
      obs.frame_id = f.frame_id;
      // Capture to the arrival of the frame's last chunk (decoding it takes
      // microseconds); unknown (NaN, left out of the quantiles) until the
      // robot's clock is estimated.
      obs.latency_ms = clock_offset_ns ? static_cast<double>(f.last_chunk_received_ns + *clock_offset_ns -
                                                             static_cast<int64_t>(f.capture_time_ns)) * 1e-6
                                       : std::numeric_limits<double>::quiet_NaN();
      for (std::size_t r = 0; r < obs.points_per_region.size(); ++r) {
        obs.points_per_region[r] = f.points[r];
        obs.chunks_received += f.chunks_received[r];
        obs.chunks_expected += f.chunks_expected[r];
      }
      stats.frame(obs);
      last_frame_id = f.frame_id;
      if (!opt.ply_dir.empty() && f.cloud != nullptr) {
        pipeline::PlyWriteOptions ply;
        ply.double_coords = true;
        const std::string path = opt.ply_dir + "/frame_" + std::to_string(f.frame_id) + ".ply";
        if (pipeline::writePly(path, f.cloud->points, f.cloud->region.data(), ply).isOk()) {
          ++ply_written;
        } else {
          ++ply_failed;
        }
      }
    }
  };

  while (g_stop == 0 && !robot_said_bye && link.sessionActive()) {
    int64_t now = monotonicNs();
    if (now >= end_ns) break;
    if (now >= next_gaze_ns) {
      const tools::GazePoint g = script->at(now - start_ns);
      net::GazeSample sample;
      sample.gaze_origin_m = {g.origin_m.x(), g.origin_m.y(), g.origin_m.z()};
      sample.gaze_direction = {g.direction.x(), g.direction.y(), g.direction.z()};
      sample.hmd_position_m = sample.gaze_origin_m;
      sample.feedback.last_frame_id = last_frame_id;
      if (link.sendGaze(sample)) {
        ++gaze_sent;
        last_gaze = g;
      }
      next_gaze_ns += gaze_period_ns;
      if (next_gaze_ns < now) next_gaze_ns = now + gaze_period_ns;  // fell behind: no burst to catch up
    }
    if (now >= next_live_ns) {
      if (const uint64_t lost = link.counters().datagrams_lost; lost > lost_reported) {
        stats.lost(lost - lost_reported);
        lost_reported = lost;
      }
      const std::string line = stats.liveLine(static_cast<double>(now - live_start_ns) * 1e-9);
      if (!opt.quiet) {
        std::printf("%s\n", line.c_str());
        std::fflush(stdout);
      }
      live_start_ns = now;
      next_live_ns += 1'000'000'000;
    }
    const int64_t wake_ns = std::min({next_gaze_ns, next_live_ns, end_ns});
    const int timeout_ms = static_cast<int>(std::clamp<int64_t>((wake_ns - now + 999'999) / 1'000'000, 0, 1000));
    const std::optional<net::Received> received = link.receive(timeout_ms);
    if (!received) continue;
    stats.datagram(received->payload.size() + net::kDatagramOverhead);
    switch (received->type) {
      // The assembler's ready frames are those of its last call: look at them
      // right after a chunk or summary only (after any other datagram they
      // would be counted again).
      case net::MessageType::kChunk:
        (void)assembler.addChunk(received->payload, received->received_ns);  // failures are counted by the assembler
        handleReady();
        break;
      case net::MessageType::kFrameSummary:
        (void)assembler.addSummary(received->payload);
        handleReady();
        break;
      case net::MessageType::kBye:
        robot_said_bye = true;
        break;
      case net::MessageType::kStatus:
        // The link has decoded it (and echoes its stamp); the round trip the robot
        // measured from earlier echoes dates the stamp.
        if (!shared_clock) {
          if (const auto& status = link.lastStatus(); status && status->rtt_ns >= 0) {
            clock_offset_ns = tools::estimateClockOffsetNs(status->robot_stamp_ns, status->rtt_ns, received->received_ns);
          }
        }
        break;
      default:
        break;
    }
  }
  assembler.flush();
  handleReady();
  if (const uint64_t lost = link.counters().datagrams_lost; lost > lost_reported) stats.lost(lost - lost_reported);
  const double seconds = static_cast<double>(monotonicNs() - start_ns) * 1e-9;
  if (!robot_said_bye) link.bye("operator done");

  const net::FrameAssembler::Counters& ac = assembler.counters();
  const net::OperatorLinkCounters& lc = link.counters();
  std::printf("\nsummary: %llu frames in %.1f s, %llu datagrams (%llu lost, %llu dropped as invalid), %llu gaze samples sent\n",
              static_cast<unsigned long long>(stats.frames()), seconds,
              static_cast<unsigned long long>(stats.datagrams()), static_cast<unsigned long long>(lc.datagrams_lost),
              static_cast<unsigned long long>(lc.dropped.total()), static_cast<unsigned long long>(gaze_sent));
  std::printf("  chunks: %llu decoded, %llu bad, %llu late, %llu duplicate%s\n",
              static_cast<unsigned long long>(ac.chunks), static_cast<unsigned long long>(ac.bad_chunks),
              static_cast<unsigned long long>(ac.late_chunks), static_cast<unsigned long long>(ac.duplicate_chunks),
              robot_said_bye ? "; the robot ended the session" : "");
  if (!opt.ply_dir.empty()) {
    std::printf("  wrote %llu frames to %s%s\n", static_cast<unsigned long long>(ply_written), opt.ply_dir.c_str(),
                ply_failed ? " (some failed)" : "");
  }
  if (!opt.summary_path.empty()) {
    const std::string extra =
        "\"robot\": \"" + link.robot().toString() + "\", \"gaze_samples_sent\": " + std::to_string(gaze_sent) +
        ", \"last_gaze\": {\"origin_m\": " + vec3Json(last_gaze.origin_m) + ", \"direction\": " +
        vec3Json(last_gaze.direction) + "}, \"chunks_bad\": " + std::to_string(ac.bad_chunks) +
        ", \"datagrams_invalid\": " + std::to_string(lc.dropped.total());
    std::ofstream file(opt.summary_path);
    file << stats.summaryJson(seconds, extra);
    if (!file) {
      std::fprintf(stderr, "fovea-operator: --summary: cannot write '%s'\n", opt.summary_path.c_str());
      return kExitFailure;
    }
  }
  return stats.frames() > 0 ? kExitOk : kExitFailure;
}

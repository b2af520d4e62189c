// fovea-operator: the operator station without the headset. Says hello to a
// fovead stream, sends gaze from a script, receives and decodes the foveated
// frames, and measures what an operator would feel: frames per second, bytes on
// the wire, end-to-end latency, losses. The decoding is fovea::net's library
// (ChunkEncoder's counterpart), which a VR front end links the same way.
#include <algorithm>
#include <cmath>
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

#include <Eigen/Geometry>

#include "core/clock.h"
#include "io/ply.h"
#include "net/codec.h"
#include "net/key.h"
#include "net/operator_link.h"
#include "net/udp_socket.h"
#include "tools/operator/gaze_script.h"
#include "tools/operator/operator_stats.h"
#include "tools/operator/view_frame.h"
#include "tools/operator/view_server.h"

namespace {

using namespace fovea;

constexpr int kExitOk = 0, kExitFailure = 1, kExitUsage = 2;

const char* kHelp =
    "usage: fovea-operator --connect HOST:PORT (--key-file FILE | --insecure) (--gaze SCRIPT | --view [ADDR:]PORT)\n"
    "                      [--view [ADDR:]PORT [--view-tabs N]] [--duration SECONDS] [--summary FILE.json] [--frame-log FILE]\n"
    "                      [--save-ply DIR]\n"
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
    "                        (world metres; csv lines t_s,ox,oy,oz,dx,dy,dz); with --view, the viewer's\n"
    "                        scripted mode and its first eye\n"
    "  --view [ADDR:]PORT    serve the viewer page (docs/viewer.md) on ADDR (default 127.0.0.1; 0.0.0.0:\n"
    "                        every interface) and stream every decoded frame to it; the page's cursor\n"
    "                        is the gaze; the operator reconnects to the robot until stopped\n"
    "  --view-tabs N         viewer tabs served at once (default 4, 1 .. 64)\n"
    "  --duration SECONDS    stop after this long (default: until SIGINT/SIGTERM or the robot's bye)\n"
    "  --summary FILE.json   write the whole run's figures as JSON at the end\n"
    "  --frame-log FILE      one CSV line per frame decoded: frame id, capture stamp (robot clock),\n"
    "                        decoded (this host's clock), latency, points, chunks (docs/eval.md)\n"
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


struct Options {
  std::string connect;
  std::optional<std::string> key_file;
  bool insecure = false;
  std::string gaze;
  double duration_s = 0.0;
  std::string summary_path;
  std::string frame_log_path;
  std::string ply_dir;
  std::string name = "fovea-operator";
  double budget_mbps = 0.0;
  long mtu = static_cast<long>(net::kDefaultMtu);
  double gaze_hz = 120.0;
  bool quiet = false;
  long max_points = 640 * 480;
  std::string clock = "auto";
  std::string view;  // --view [ADDR:]PORT; empty: no viewer
  long view_tabs = 4;
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
    } else if (flag == "--frame-log") {
      o.frame_log_path = value;
    } else if (flag == "--save-ply") {
      o.ply_dir = value;
    } else if (flag == "--name") {
      o.name = value;
    } else if (flag == "--view") {
      o.view = value;
    } else if (flag == "--view-tabs") {
      Result<double> v = number(flag, value);
      if (!v) return v.status();
      if (!(v.value() >= 1 && v.value() <= 64)) return Result<Options>(ErrorCode::kInvalidArgument, "--view-tabs: must be within 1 .. 64");
      o.view_tabs = static_cast<long>(v.value());
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
  if (o.gaze.empty() && o.view.empty()) {
    return Result<Options>(ErrorCode::kInvalidArgument, "--gaze SCRIPT is required (or --view [ADDR:]PORT, whose page gives the gaze)");
  }
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

// The gaze a session sends at each tick: the viewer's cursor (or headset) when
// a tab drives it, else the script; without either, a sample of confidence 0,
// which keeps the session while the robot falls back as without gaze.
struct GazeChoice {
  net::GazeSample sample;
  std::optional<tools::ViewerGaze> viewer;  // what is shown to the tabs as the gaze sent
};

GazeChoice chooseGaze(const std::optional<tools::GazeScript>& script, const tools::ViewServer* view, int64_t t_ns,
                      const std::optional<net::GazeSample>& last_sent) {
  GazeChoice c;
  net::GazeSample& s = c.sample;
  const bool cursor = view != nullptr && view->gazeMode() == tools::GazeMode::kCursor;
  const std::optional<tools::TabGaze> tab = cursor ? view->latestGaze() : std::nullopt;
  if (tab) {
    const tools::ViewerGaze& g = tab->gaze;
    s.gaze_origin_m = {g.origin_m[0], g.origin_m[1], g.origin_m[2]};
    s.gaze_direction = {g.direction[0], g.direction[1], g.direction[2]};
    s.hmd_orientation = {g.orientation[0], g.orientation[1], g.orientation[2], g.orientation[3]};
  } else if (script) {
    const tools::GazePoint g = script->at(t_ns);
    s.gaze_origin_m = {g.origin_m.x(), g.origin_m.y(), g.origin_m.z()};
    s.gaze_direction = {g.direction.x(), g.direction.y(), g.direction.z()};
    // A script has no head: the head is taken to face where the eye looks (the
    // robot's view cull then keeps what is around the gaze).
    const Eigen::Quaterniond head = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), g.direction);
    s.hmd_orientation = {head.w(), head.x(), head.y(), head.z()};
  } else {
    if (last_sent) s = *last_sent;
    s.confidence = 0.0f;
  }
  s.hmd_position_m = s.gaze_origin_m;
  s.sequence = 0;
  s.operator_stamp_ns = 0;
  if (s.confidence > 0.0f) {
    tools::ViewerGaze shown;
    shown.origin_m = {s.gaze_origin_m.x, s.gaze_origin_m.y, s.gaze_origin_m.z};
    shown.direction = {s.gaze_direction.x, s.gaze_direction.y, s.gaze_direction.z};
    c.viewer = shown;
  }
  return c;
}

std::optional<std::array<double, 3>> array3(const std::optional<net::Vec3>& v) {
  if (!v) return std::nullopt;
  return std::array<double, 3>{v->x, v->y, v->z};
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
  std::optional<tools::GazeScript> script;
  if (!opt.gaze.empty()) {
    Result<tools::GazeScript> parsed_script = tools::GazeScript::parse(opt.gaze);
    if (!parsed_script) {
      std::fprintf(stderr, "fovea-operator: %s\n", parsed_script.status().message().c_str());
      return parsed_script.status().code() == ErrorCode::kInvalidArgument ? kExitUsage : kExitFailure;
    }
    script = std::move(parsed_script.value());
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
  // Room for the largest frame: the assembler refuses what does not fit, and counts it.
  Result<net::FrameAssembler> assembler_created = net::FrameAssembler::create(static_cast<std::size_t>(opt.max_points));
  if (!assembler_created) {
    std::fprintf(stderr, "fovea-operator: %s\n", assembler_created.status().message().c_str());
    return kExitFailure;
  }
  net::FrameAssembler& assembler = assembler_created.value();

  std::unique_ptr<tools::ViewServer> view;
  if (!opt.view.empty()) {
    tools::ViewServerConfig vc;
    vc.listen = opt.view;
    vc.max_tabs = static_cast<std::size_t>(opt.view_tabs);
    vc.max_points = static_cast<std::size_t>(opt.max_points);
    vc.gaze_hz = opt.gaze_hz;
    vc.script = opt.gaze;
    if (script) {
      const tools::GazePoint g = script->at(0);
      const Eigen::Vector3d target = g.origin_m + 2.0 * g.direction;
      vc.initial_eye = std::array<double, 6>{g.origin_m.x(), g.origin_m.y(), g.origin_m.z(), target.x(), target.y(), target.z()};
    }
    Result<std::unique_ptr<tools::ViewServer>> started = tools::ViewServer::start(vc);
    if (!started) {
      std::fprintf(stderr, "fovea-operator: %s\n", started.status().message().c_str());
      return started.status().code() == ErrorCode::kInvalidArgument ? kExitUsage : kExitFailure;
    }
    view = std::move(started.value());
    if (view->url().rfind("http://127.", 0) != 0 || opt.view.rfind("0.0.0.0", 0) == 0) {
      std::fprintf(stderr, "fovea-operator: warning: the viewer listens on %s: whoever reaches it sees the stream and steers the gaze\n",
                   opt.view.c_str());
    }
    std::printf("viewer: open %s\n", view->url().c_str());
    std::fflush(stdout);
  }

  std::ofstream frame_log;
  if (!opt.frame_log_path.empty()) {
    frame_log.open(opt.frame_log_path);
    frame_log << "frame_id,capture_ns,decoded_ns,latency_us,points,chunks_received,chunks_expected,summary_received\n";
    if (!frame_log) {
      std::fprintf(stderr, "fovea-operator: --frame-log: cannot write '%s'\n", opt.frame_log_path.c_str());
      return kExitFailure;
    }
  }

  std::signal(SIGINT, onStopSignal);
  std::signal(SIGTERM, onStopSignal);
  tools::OperatorStats stats;
  tools::SplatSizer splat_sizer(net::CodecConfig{}.periphery_step_ratio);
  const int64_t start_ns = monotonicNs();
  const int64_t end_ns = opt.duration_s > 0 ? start_ns + static_cast<int64_t>(opt.duration_s * 1e9) : INT64_MAX;
  const auto gaze_period_ns = static_cast<int64_t>(1e9 / opt.gaze_hz);
  uint64_t ply_written = 0, ply_failed = 0, gaze_sent = 0, sessions = 0;
  std::optional<net::GazeSample> last_sent;
  std::optional<tools::ViewerGaze> last_shown;
  tools::GazePoint last_gaze;
  bool robot_said_bye = false;
  std::string robot_address = opt.connect;
  std::optional<net::StatusReport> last_status;
  net::FrameAssembler::Counters assembler_total{};
  net::OperatorLinkCounters link_total{};
  auto publishState = [&](tools::LinkState state, const std::string& detail) {
    if (view) view->publishState(tools::stateJson(state, detail, robot_address));
  };
  // Waits up to ms, or less when stopped; false when stopped or out of time.
  auto pause = [&](int ms) {
    for (int i = 0; i < ms / 50 && g_stop == 0 && monotonicNs() < end_ns; ++i) {
      const timespec t{0, 50'000'000};
      nanosleep(&t, nullptr);
    }
    return g_stop == 0 && monotonicNs() < end_ns;
  };

  // Without the viewer: one session, as before. With it: the page stays up and
  // the operator reconnects until it is stopped (a robot restarting, refusing
  // while busy, or not yet up).
  while (g_stop == 0 && monotonicNs() < end_ns) {
    publishState(tools::LinkState::kConnecting, "saying hello to " + opt.connect);
    Result<std::unique_ptr<net::OperatorLink>> connected = net::OperatorLink::connect(opt.connect, link_config);
    if (!connected) {
      const std::string& why = connected.status().message();
      if (!view) {
        std::fprintf(stderr, "fovea-operator: %s\n", why.c_str());
        return connected.status().code() == ErrorCode::kInvalidArgument ? kExitUsage : kExitFailure;
      }
      if (connected.status().code() == ErrorCode::kInvalidArgument) {
        std::fprintf(stderr, "fovea-operator: %s\n", why.c_str());
        return kExitUsage;
      }
      const bool refused = why.find(" refused (") != std::string::npos;
      std::fprintf(stderr, "fovea-operator: %s; trying again in 1 s\n", why.c_str());
      publishState(refused ? tools::LinkState::kRefused : tools::LinkState::kConnecting, why);
      if (!pause(1000)) break;
      continue;
    }
    net::OperatorLink& link = *connected.value();
    ++sessions;
    if (!link.notice().empty()) std::fprintf(stderr, "fovea-operator: *** %s ***\n", link.notice().c_str());
    // Latency compares the robot's capture stamp with this host's arrival time. On
    // one host the clocks are one; across hosts the robot's clock is estimated from
    // its status stamps: robot = local + offset, offset = stamp + RTT/2 - arrival.
    robot_address = link.robot().toString();
    const bool shared_clock = opt.clock == "shared" ||
                              (opt.clock == "auto" && (robot_address.rfind("127.", 0) == 0 || robot_address.rfind("[::1]", 0) == 0));
    std::optional<int64_t> clock_offset_ns;  // robot minus local
    if (shared_clock) clock_offset_ns = 0;
    std::printf("connected to %s: MTU %u, budget %.2f MB/s, receive buffer %d KiB; latency on %s\n",
                robot_address.c_str(), link.mtuBytes(), static_cast<double>(link.budgetBytesPerS()) / 1e6,
                link.receiveBufferBytes() / 1024,
                shared_clock ? "one clock" : "the robot's clock estimated from its status and round trip");
    std::fflush(stdout);
    publishState(tools::LinkState::kStreaming, "");

    // What a packet capture adds to each UDP payload: the IP and UDP headers.
    const std::size_t ip_udp_header_bytes = robot_address.rfind('[', 0) == 0 ? 40 + 8 : 20 + 8;
    const int64_t session_start_ns = monotonicNs();
    int64_t next_gaze_ns = session_start_ns;
    int64_t next_live_ns = session_start_ns + 1'000'000'000;
    int64_t live_start_ns = session_start_ns;
    uint64_t lost_reported = 0, last_frame_id = 0;
    robot_said_bye = false;

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
        if (frame_log) {
          uint32_t points = 0;
          for (uint32_t p : obs.points_per_region) points += p;
          frame_log << f.frame_id << ',' << f.capture_time_ns << ',' << f.last_chunk_received_ns << ','
                    << (std::isnan(obs.latency_ms) ? std::string() : std::to_string(std::llround(obs.latency_ms * 1e3)))
                    << ',' << points << ',' << obs.chunks_received << ',' << obs.chunks_expected << ','
                    << (f.summary_received ? 1 : 0) << '\n';
        }
        last_frame_id = f.frame_id;
        if (view) view->publishFrame(tools::packViewFrame(f, splat_sizer.sizes(f), view->frameBuffer()));
        if (!opt.ply_dir.empty() && f.cloud != nullptr) {
          io::PlyWriteOptions ply;
          ply.double_coords = true;
          const std::string path = opt.ply_dir + "/frame_" + std::to_string(f.frame_id) + ".ply";
          if (io::writePly(path, f.cloud->points, f.cloud->region.data(), ply).isOk()) {
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
        GazeChoice choice = chooseGaze(script, view.get(), now - start_ns, last_sent);
        choice.sample.feedback.last_frame_id = last_frame_id;
        if (link.sendGaze(choice.sample)) {
          ++gaze_sent;
          last_sent = choice.sample;
          last_shown = choice.viewer;
          if (choice.viewer) {
            const net::GazeSample& g = choice.sample;
            last_gaze.origin_m = {g.gaze_origin_m.x, g.gaze_origin_m.y, g.gaze_origin_m.z};
            last_gaze.direction = {g.gaze_direction.x, g.gaze_direction.y, g.gaze_direction.z};
          }
        }
        next_gaze_ns += gaze_period_ns;
        if (next_gaze_ns < now) next_gaze_ns = now + gaze_period_ns;  // fell behind: no burst to catch up
      }
      if (now >= next_live_ns) {
        if (const uint64_t lost = link.counters().datagrams_lost; lost > lost_reported) {
          stats.lost(lost - lost_reported);
          lost_reported = lost;
        }
        const tools::LiveFigures live = stats.takeWindow(static_cast<double>(now - live_start_ns) * 1e-9);
        if (!opt.quiet) {
          std::printf("%s\n", tools::liveLine(live).c_str());
          std::fflush(stdout);
        }
        if (view) {
          tools::ViewerFigures figures;
          figures.fps = live.fps;
          figures.wire_mb_per_s = live.wire_mb_per_s;
          figures.latency_p50_ms = live.latency_p50_ms;
          figures.latency_p99_ms = live.latency_p99_ms;
          figures.datagrams_lost = live.lost;
          std::size_t regions = live.points_per_region.size();
          while (regions > 0 && live.points_per_region[regions - 1] == 0) --regions;
          figures.points_per_region.assign(live.points_per_region.begin(), live.points_per_region.begin() + regions);
          figures.gaze_mode = view->gazeMode();
          figures.gaze_sent = gaze_sent;
          figures.gaze_last = last_shown;
          if (const auto& status = link.lastStatus()) {
            if (status->gaze_age_ns >= 0) figures.robot_gaze_age_ms = static_cast<double>(status->gaze_age_ns) * 1e-6;
            if (status->rtt_ns >= 0) figures.robot_rtt_ms = static_cast<double>(status->rtt_ns) * 1e-6;
            figures.robot_gaze_origin_m = array3(status->gaze_origin_m);
            figures.robot_gaze_direction = array3(status->gaze_direction);
          }
          view->publishFigures(std::move(figures));
        }
        live_start_ns = now;
        next_live_ns += 1'000'000'000;
      }
      const int64_t wake_ns = std::min({next_gaze_ns, next_live_ns, end_ns});
      const int timeout_ms = static_cast<int>(std::clamp<int64_t>((wake_ns - now + 999'999) / 1'000'000, 0, 1000));
      const std::optional<net::Received> received = link.receive(timeout_ms);
      if (!received) continue;
      stats.datagram(received->payload.size() + net::kDatagramOverhead, ip_udp_header_bytes);
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
    last_status = link.lastStatus();
    const net::OperatorLinkCounters& lc = link.counters();
    link_total.datagrams_lost += lc.datagrams_lost;
    link_total.dropped.add(lc.dropped);
    if (!robot_said_bye && link.sessionActive()) link.bye("operator done");
    if (!view || g_stop != 0 || monotonicNs() >= end_ns) break;
    const std::string gone = robot_said_bye ? "the robot ended the session" : "the session ended (the robot went silent)";
    std::fprintf(stderr, "fovea-operator: %s; reconnecting\n", gone.c_str());
    publishState(tools::LinkState::kRobotGone, gone);
    if (!pause(1000)) break;
  }
  const double seconds = static_cast<double>(monotonicNs() - start_ns) * 1e-9;
  assembler_total = assembler.counters();

  const net::FrameAssembler::Counters& ac = assembler_total;
  std::printf("\nsummary: %llu frames in %.1f s, %llu datagrams (%llu lost, %llu dropped as invalid), %llu gaze samples sent\n",
              static_cast<unsigned long long>(stats.frames()), seconds,
              static_cast<unsigned long long>(stats.datagrams()), static_cast<unsigned long long>(link_total.datagrams_lost),
              static_cast<unsigned long long>(link_total.dropped.total()), static_cast<unsigned long long>(gaze_sent));
  std::printf("  chunks: %llu decoded, %llu bad, %llu late, %llu duplicate%s\n",
              static_cast<unsigned long long>(ac.chunks), static_cast<unsigned long long>(ac.bad_chunks),
              static_cast<unsigned long long>(ac.late_chunks), static_cast<unsigned long long>(ac.duplicate_chunks),
              robot_said_bye ? "; the robot ended the session" : "");
  if (!opt.ply_dir.empty()) {
    std::printf("  wrote %llu frames to %s%s\n", static_cast<unsigned long long>(ply_written), opt.ply_dir.c_str(),
                ply_failed ? " (some failed)" : "");
  }
  std::string view_json;
  if (view) {
    const tools::ViewServerCounters vc = view->counters();
    std::printf("  viewer: %llu tabs served (%llu refused), %llu frames published, %llu sent to tabs, %llu dropped for slow tabs, "
                "%llu malformed messages, %llu gaze samples from tabs\n",
                static_cast<unsigned long long>(vc.tabs_served), static_cast<unsigned long long>(vc.tabs_refused),
                static_cast<unsigned long long>(vc.frames_published), static_cast<unsigned long long>(vc.frames_sent),
                static_cast<unsigned long long>(vc.frames_dropped), static_cast<unsigned long long>(vc.malformed),
                static_cast<unsigned long long>(vc.gaze_received));
    view_json = ", \"sessions\": " + std::to_string(sessions) + ", \"viewer\": {\"tabs_served\": " +
                std::to_string(vc.tabs_served) + ", \"tabs_refused\": " + std::to_string(vc.tabs_refused) +
                ", \"frames_published\": " + std::to_string(vc.frames_published) + ", \"frames_sent\": " +
                std::to_string(vc.frames_sent) + ", \"frames_dropped\": " + std::to_string(vc.frames_dropped) +
                ", \"malformed\": " + std::to_string(vc.malformed) + ", \"gaze_received\": " + std::to_string(vc.gaze_received) +
                "}";
  }
  if (!opt.summary_path.empty()) {
    std::string robot_gaze;
    if (last_status && last_status->gaze_origin_m && last_status->gaze_direction) {
      const net::Vec3& o = *last_status->gaze_origin_m;
      const net::Vec3& d = *last_status->gaze_direction;
      robot_gaze = ", \"robot_gaze\": {\"origin_m\": " + vec3Json({o.x, o.y, o.z}) + ", \"direction\": " + vec3Json({d.x, d.y, d.z}) + "}";
    }
    const std::string extra =
        "\"robot\": \"" + robot_address + "\", \"gaze_samples_sent\": " + std::to_string(gaze_sent) +
        ", \"last_gaze\": {\"origin_m\": " + vec3Json(last_gaze.origin_m) + ", \"direction\": " +
        vec3Json(last_gaze.direction) + "}" + robot_gaze + ", \"chunks_bad\": " + std::to_string(ac.bad_chunks) +
        ", \"datagrams_invalid\": " + std::to_string(link_total.dropped.total()) + view_json;
    std::ofstream file(opt.summary_path);
    file << stats.summaryJson(seconds, extra);
    if (!file) {
      std::fprintf(stderr, "fovea-operator: --summary: cannot write '%s'\n", opt.summary_path.c_str());
      return kExitFailure;
    }
  }
  return stats.frames() > 0 ? kExitOk : kExitFailure;
}

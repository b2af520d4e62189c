// fovea-operator: the operator station without the headset. Says hello to a
// fovead stream, sends gaze from a script, receives and decodes the foveated
// frames, and measures what an operator would feel: frames per second, bytes on
// the wire, end-to-end latency, losses. The decoding is fovea::net's library
// (ChunkEncoder's counterpart), which a VR front end links the same way.
#include <algorithm>
#include <array>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <deque>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "core/clock.h"
#include "io/mcap/mapped_file.h"
#include "io/mcap/reader.h"
#include "io/mcap/recorder.h"
#include "io/ply.h"
#include "net/codec.h"
#include "net/key.h"
#include "net/operator_link.h"
#include "net/stream_channels.h"
#include "net/udp_socket.h"
#include "io/foxglove/foxglove.h"
#include "io/foxglove/recording.h"
#include "tools/operator/foxglove_server.h"
#include "tools/operator/gaze_script.h"
#include "tools/operator/held_cloud.h"
#include "tools/operator/map_holder.h"
#include "tools/operator/operator_stats.h"
#include "tools/operator/view_frame.h"
#include "tools/operator/view_server.h"

namespace {

using namespace fovea;

constexpr int kExitOk = 0, kExitFailure = 1, kExitUsage = 2;

const char* kHelp =
    "usage: fovea-operator --connect HOST:PORT (--key-file FILE | --insecure) (--gaze SCRIPT | --view [ADDR:]PORT)\n"
    "                      [--view [ADDR:]PORT [--view-tabs N]] [--foxglove [ADDR:]PORT [--foxglove-clients N]]\n"
    "                      [--duration SECONDS] [--summary FILE.json] [--frame-log FILE]\n"
    "                      [--save-ply DIR] [--save-held FRAME_ID:FILE.ply]\n"
    "                      [--name NAME] [--budget MBPS] [--mtu BYTES] [--gaze-hz HZ] [--max-points N]\n"
    "                      [--map-points N] [--map-bricks N]\n"
    "                      [--clock auto|shared|estimated] [--record FILE.mcap] [--quiet]\n"
    "       fovea-operator --replay FILE.mcap [--speed X] [--view [ADDR:]PORT] [--foxglove [ADDR:]PORT] [options above]\n"
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
    "  --foxglove [ADDR:]PORT  serve the Foxglove WebSocket protocol (foxglove.websocket.v1) on ADDR (default\n"
    "                        127.0.0.1) for the Foxglove app or Lichtblick (docs/foxglove.md): /fovea/cloud\n"
    "                        (foxglove.PointCloud), /fovea/head (foxglove.FrameTransform), /fovea/gaze_ray\n"
    "                        (foxglove.SceneUpdate), /fovea/log (foxglove.Log); each client is sent the\n"
    "                        newest message of a channel; the operator reconnects to the robot until stopped\n"
    "  --foxglove-clients N  Foxglove clients served at once (default 8, 1 .. 64)\n"
    "  --duration SECONDS    stop after this long (default: until SIGINT/SIGTERM or the robot's bye)\n"
    "  --summary FILE.json   write the whole run's figures as JSON at the end\n"
    "  --frame-log FILE      one CSV line per frame decoded: frame id, capture stamp (robot clock),\n"
    "                        decoded (this host's clock), latency, points, chunks (docs/eval.md); then\n"
    "                        what the operator holds of the robot's map: bricks, points, and the brick\n"
    "                        parts taken (not duplicates) and versions completed since the previous line;\n"
    "                        last, when the fovea's chunks were decoded and its latency (empty when a\n"
    "                        fovea chunk was lost; from the arrival order, exact on loopback)\n"
    "  --save-ply DIR        write every decoded frame as DIR/frame_ID.ply (world coordinates, region)\n"
    "  --save-held ID:FILE   once, at the first frame with id >= ID that arrived whole: write what the\n"
    "                        operator draws, that frame's points and every map brick held, to FILE (PLY,\n"
    "                        world coordinates, colour, region: the frame's, or 8 + the brick's level)\n"
    "                        and FILE + \".txt\" (the frame id, counts, steps;\n"
    "                        tools/operator/held_cloud.h); nothing when no such frame arrives whole\n"
    "  --name NAME           the name the robot shows (default fovea-operator)\n"
    "  --budget MBPS         the bandwidth to ask for, MB/s (default: what the robot allows)\n"
    "  --mtu BYTES           the largest UDP payload to ask for (default 1200)\n"
    "  --gaze-hz HZ          gaze samples per second (default 120, up to 200)\n"
    "  --max-points N        the largest frame to decode, in points (default 307200 = 640x480)\n"
    "  --map-points N        the robot's map bricks to keep, in points (default 1048576 = 1 Mi, 16 bytes\n"
    "                        each; 256 .. 67108864); with --view each viewer buffer holds them too\n"
    "  --map-bricks N        the map bricks to keep (default 4096, 1 .. 1048576); the brick least\n"
    "                        recently drawn or received goes first, and the robot is told\n"
    "  --clock MODE          how capture stamps (robot clock) compare with arrival (this host's):\n"
    "                        shared: one CLOCK_MONOTONIC (same host); estimated: the robot's clock\n"
    "                        estimated from its status stamps and the round trip it measures\n"
    "                        (RTT/2 each way); auto (default): shared on a loopback address\n"
    "  --record FILE.mcap    record the session as received (the chunks, frame summaries and map bricks\n"
    "                        the operator decrypted) into an MCAP file (docs/recording.md)\n"
    "  --replay FILE.mcap    instead of a robot: play a recording (this program's --record, or fovead\n"
    "                        serve --record's: what the robot sent) into the viewer and the figures as\n"
    "                        if live; says where the file stopped being readable, if it did\n"
    "  --speed X             --replay's pace: 1 (default) as recorded, 2 twice as fast, 0 as fast as it\n"
    "                        reads\n"
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
  std::optional<uint32_t> held_frame;  // --save-held ID:FILE
  std::string held_path;
  std::string name = "fovea-operator";
  double budget_mbps = 0.0;
  long mtu = static_cast<long>(net::kDefaultMtu);
  double gaze_hz = 120.0;
  bool quiet = false;
  long max_points = 640 * 480;
  long map_points = 1L << 20;
  long map_bricks = 4096;
  std::string clock = "auto";
  std::string view;  // --view [ADDR:]PORT; empty: no viewer
  std::string record_path;  // --record FILE.mcap
  std::string replay_path;  // --replay FILE.mcap: no robot
  double speed = 1.0;       // --replay's pace (0: as fast as it reads)
  long view_tabs = 4;
  std::string foxglove;  // --foxglove [ADDR:]PORT; empty: no Foxglove server
  long foxglove_clients = 8;
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
    } else if (flag == "--save-held") {
      const std::string spec = value;
      const std::size_t colon = spec.find(':');
      char* end = nullptr;
      const std::string id = colon == std::string::npos ? spec : spec.substr(0, colon);
      const unsigned long long frame = std::strtoull(id.c_str(), &end, 10);
      if (colon == std::string::npos || id.empty() || *end != '\0' || id[0] == '-' || frame > 0xffffffffull ||
          colon + 1 >= spec.size()) {
        return Result<Options>(ErrorCode::kInvalidArgument, "--save-held: '" + spec + "' is not FRAME_ID:FILE.ply (a frame id within 0 .. 4294967295)");
      }
      o.held_frame = static_cast<uint32_t>(frame);
      o.held_path = spec.substr(colon + 1);
      const std::filesystem::path parent = std::filesystem::path(o.held_path).parent_path();
      std::error_code ec;
      if (!parent.empty() && !std::filesystem::is_directory(parent, ec)) {
        return Result<Options>(ErrorCode::kInvalidArgument, "--save-held: no directory '" + parent.string() + "'");
      }
    } else if (flag == "--record") {
      o.record_path = value;
    } else if (flag == "--replay") {
      o.replay_path = value;
    } else if (flag == "--speed") {
      Result<double> v = number(flag, value);
      if (!v) return v.status();
      if (!(v.value() >= 0 && v.value() <= 1000)) return Result<Options>(ErrorCode::kInvalidArgument, "--speed: must be within 0 .. 1000");
      o.speed = v.value();
    } else if (flag == "--name") {
      o.name = value;
    } else if (flag == "--view") {
      o.view = value;
    } else if (flag == "--foxglove") {
      o.foxglove = value;
    } else if (flag == "--foxglove-clients") {
      Result<double> v = number(flag, value);
      if (!v) return v.status();
      if (!(v.value() >= 1 && v.value() <= 64 && v.value() == std::floor(v.value()))) {
        return Result<Options>(ErrorCode::kInvalidArgument, "--foxglove-clients: must be a whole number within 1 .. 64");
      }
      o.foxglove_clients = static_cast<long>(v.value());
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
    } else if (flag == "--map-points") {
      Result<double> v = number(flag, value);
      if (!v) return v.status();
      // At least one block of the cache's pool (256 points); at most 1 GiB of points.
      if (!(v.value() >= 256 && v.value() <= 67108864 && v.value() == std::floor(v.value()))) {
        return Result<Options>(ErrorCode::kInvalidArgument, "--map-points: must be a whole number within 256 .. 67108864");
      }
      o.map_points = static_cast<long>(v.value());
    } else if (flag == "--map-bricks") {
      Result<double> v = number(flag, value);
      if (!v) return v.status();
      if (!(v.value() >= 1 && v.value() <= 1048576 && v.value() == std::floor(v.value()))) {
        return Result<Options>(ErrorCode::kInvalidArgument, "--map-bricks: must be a whole number within 1 .. 1048576");
      }
      o.map_bricks = static_cast<long>(v.value());
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
  if (!o.replay_path.empty()) {
    // A replay talks to no robot: no key, no gaze to send.
    if (!o.connect.empty()) return Result<Options>(ErrorCode::kInvalidArgument, "--replay: not together with --connect");
    if (!o.record_path.empty()) return Result<Options>(ErrorCode::kInvalidArgument, "--record: not together with --replay");
    return o;
  }
  if (o.connect.empty()) return Result<Options>(ErrorCode::kInvalidArgument, "--connect HOST:PORT is required (or --replay FILE.mcap)");
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

// A step that ends the program returns its exit code; nullopt: carry on.
using Exit = std::optional<int>;

int failure(const char* what, const Status& s) {
  std::fprintf(stderr, "fovea-operator: %s%s\n", what, s.message().c_str());
  return kExitFailure;
}

// Bad arguments are the user's (kExitUsage); anything else is the machine's.
int startFailure(const Status& s) {
  std::fprintf(stderr, "fovea-operator: %s\n", s.message().c_str());
  return s.code() == ErrorCode::kInvalidArgument ? kExitUsage : kExitFailure;
}

bool wantsHelp(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) return true;
  }
  return false;
}

// What the operator sets up before its first hello. In this order, so that
// they are torn down in the reverse one.
struct Station {
  std::optional<tools::GazeScript> script;
  net::OperatorLinkConfig link_config;
  std::optional<net::FrameAssembler> assembler;
  std::optional<tools::MapHolder> map;
  std::unique_ptr<tools::ViewServer> view;
  std::unique_ptr<tools::FoxgloveServer> foxglove;
  std::ofstream frame_log;
  // --record: the file, its producers (all the receive loop's) and channels. The
  // Foxglove channels' transcoders outlive the recorder's writer thread (declared first).
  std::unique_ptr<foxglove::RecordingChannels> record_foxglove;
  std::unique_ptr<mcap::Recorder> recorder;
  mcap::RecorderProducer* record_producer = nullptr;
  mcap::RecorderProducer* record_clouds = nullptr;
  net::StreamChannels record_channels;
};

// The Foxglove channels (--foxglove).
constexpr uint32_t kFoxCloud = 1, kFoxHead = 2, kFoxGaze = 3, kFoxLog = 4;
constexpr std::string_view kFoxWorld = foxglove::kWorldFrame;

Exit loadGazeScript(const Options& opt, Station& station) {
  if (opt.gaze.empty()) return std::nullopt;
  Result<tools::GazeScript> parsed = tools::GazeScript::parse(opt.gaze);
  if (!parsed) return startFailure(parsed.status());
  station.script = std::move(parsed.value());
  return std::nullopt;
}

Exit configureLink(const Options& opt, net::OperatorLinkConfig& config) {
  if (opt.key_file) {
    Result<net::LoadedKey> key = net::loadKeyFile(*opt.key_file);
    if (!key) return failure("--key-file: ", key.status());
    if (!key->warning.empty()) std::fprintf(stderr, "fovea-operator: warning: %s\n", key->warning.c_str());
    config.key = key->key;
  }
  config.insecure = opt.insecure;
  config.name = opt.name;
  config.budget_bytes_per_s = static_cast<uint64_t>(opt.budget_mbps * 1e6);
  config.mtu_bytes = static_cast<uint32_t>(opt.mtu);
  return std::nullopt;
}

Exit createPlyDir(const Options& opt) {
  if (opt.ply_dir.empty()) return std::nullopt;
  std::error_code ec;
  std::filesystem::create_directories(opt.ply_dir, ec);
  if (ec) {
    std::fprintf(stderr, "fovea-operator: --save-ply: cannot create '%s': %s\n", opt.ply_dir.c_str(), ec.message().c_str());
    return kExitFailure;
  }
  return std::nullopt;
}

Exit startViewer(const Options& opt, Station& station) {
  if (opt.view.empty()) return std::nullopt;
  tools::ViewServerConfig vc;
  vc.listen = opt.view;
  vc.max_tabs = static_cast<std::size_t>(opt.view_tabs);
  // A frame's points and the whole map beside them (view_frame.h).
  vc.max_points = static_cast<std::size_t>(opt.max_points + opt.map_points);
  vc.gaze_hz = opt.gaze_hz;
  vc.script = opt.gaze;
  if (station.script) {
    const tools::GazePoint g = station.script->at(0);
    const Eigen::Vector3d target = g.origin_m + 2.0 * g.direction;
    vc.initial_eye = std::array<double, 6>{g.origin_m.x(), g.origin_m.y(), g.origin_m.z(), target.x(), target.y(), target.z()};
  }
  Result<std::unique_ptr<tools::ViewServer>> started = tools::ViewServer::start(vc);
  if (!started) return startFailure(started.status());
  station.view = std::move(started.value());
  if (station.view->url().rfind("http://127.", 0) != 0 || opt.view.rfind("0.0.0.0", 0) == 0) {
    std::fprintf(stderr, "fovea-operator: warning: the viewer listens on %s: whoever reaches it sees the stream and steers the gaze\n",
                 opt.view.c_str());
  }
  std::printf("viewer: open %s\n", station.view->url().c_str());
  std::fflush(stdout);
  return std::nullopt;
}

Exit startFoxglove(const Options& opt, Station& station) {
  if (opt.foxglove.empty()) return std::nullopt;
  tools::FoxgloveServerConfig fc;
  fc.listen = opt.foxglove;
  fc.max_clients = static_cast<std::size_t>(opt.foxglove_clients);
  fc.name = opt.name == "fovea-operator" ? opt.name : "fovea-operator " + opt.name;
  // A cloud's message: 16 bytes a point and its header (frame id, pose, fields).
  const std::size_t cloud_bytes = static_cast<std::size_t>(opt.max_points) * foxglove::kPointStride + 1024;
  fc.channels = {{kFoxCloud, std::string(foxglove::kCloudTopic), foxglove::pointCloudSchema(), cloud_bytes},
                 {kFoxHead, std::string(foxglove::kHeadTopic), foxglove::frameTransformSchema(), 1024},
                 {kFoxGaze, std::string(foxglove::kGazeRayTopic), foxglove::sceneUpdateSchema(), 1024},
                 {kFoxLog, std::string(foxglove::kLogTopic), foxglove::logSchema(), 4096}};
  Result<std::unique_ptr<tools::FoxgloveServer>> started = tools::FoxgloveServer::start(fc);
  if (!started) return startFailure(started.status());
  station.foxglove = std::move(started.value());
  if (station.foxglove->url().rfind("ws://127.", 0) != 0 || opt.foxglove.rfind("0.0.0.0", 0) == 0) {
    std::fprintf(stderr, "fovea-operator: warning: the Foxglove server listens on %s: whoever reaches it sees the stream\n",
                 opt.foxglove.c_str());
  }
  std::printf("foxglove: open %s\n", station.foxglove->url().c_str());
  std::fflush(stdout);
  return std::nullopt;
}

Exit openFrameLog(const Options& opt, std::ofstream& frame_log) {
  if (opt.frame_log_path.empty()) return std::nullopt;
  frame_log.open(opt.frame_log_path);
  frame_log << "frame_id,capture_ns,decoded_ns,latency_us,points,chunks_received,chunks_expected,summary_received,"
               "map_bricks,map_points,brick_parts,brick_versions,fovea_decoded_ns,fovea_latency_us\n";
  if (!frame_log) {
    std::fprintf(stderr, "fovea-operator: --frame-log: cannot write '%s'\n", opt.frame_log_path.c_str());
    return kExitFailure;
  }
  return std::nullopt;
}

// --record: the file and its channels (net/stream_channels.h), as fovead serve --record makes them.
Exit openRecording(const Options& opt, Station& station) {
  if (opt.record_path.empty()) return std::nullopt;
  mcap::RecorderConfig config;
  config.slots = 4096;
  config.slot_bytes = net::kMaxMtu;
  config.writer.chunk_bytes = 4 << 20;
  Result<std::unique_ptr<mcap::Recorder>> recorder = mcap::Recorder::open(opt.record_path, config, [](std::string_view line) {
    std::fprintf(stderr, "fovea-operator: --record: %.*s\n", static_cast<int>(line.size()), line.data());
  });
  if (!recorder) return failure("--record: ", recorder.status());
  Result<net::StreamChannels> channels = net::addStreamChannels(*recorder.value());
  if (!channels) return failure("--record: ", channels.status());
  // Foxglove's messages of what the operator sees: the clouds decoded, its head, its gaze, its live lines.
  foxglove::RecordingOptions fx;
  fx.max_cloud_points = static_cast<std::size_t>(opt.max_points);
  fx.pose_topic = foxglove::kHeadTopic;
  fx.pose_child = "head";
  fx.log_name = "fovea-operator";
  Result<std::unique_ptr<foxglove::RecordingChannels>> fox = foxglove::RecordingChannels::add(*recorder.value(), fx);
  if (!fox) return failure("--record: ", fox.status());
  station.record_foxglove = std::move(fox.value());
  station.record_producer = recorder.value()->addProducer();
  station.record_clouds = recorder.value()->addProducer(4, station.record_foxglove->cloudRecordBytes());
  if (Status s = recorder.value()->start(); !s) return failure("--record: ", s);
  station.record_channels = channels.value();
  station.recorder = std::move(recorder.value());
  return std::nullopt;
}

// Everything the station sets up, in the order it always has (the first failure is the one reported).
Exit setUp(const Options& opt, Station& station) {
  if (Exit e = loadGazeScript(opt, station)) return e;
  if (Exit e = configureLink(opt, station.link_config)) return e;
  if (Exit e = createPlyDir(opt)) return e;
  // Room for the largest frame: the assembler refuses what does not fit, and counts it.
  Result<net::FrameAssembler> assembler = net::FrameAssembler::create(static_cast<std::size_t>(opt.max_points));
  if (!assembler) return failure("", assembler.status());
  station.assembler.emplace(std::move(assembler.value()));
  net::BrickCacheConfig map_config;
  map_config.max_points = static_cast<std::size_t>(opt.map_points);
  map_config.max_bricks = static_cast<std::size_t>(opt.map_bricks);
  Result<tools::MapHolder> map = tools::MapHolder::create(map_config);
  if (!map) return startFailure(map.status());
  station.map.emplace(std::move(map.value()));
  if (Exit e = startViewer(opt, station)) return e;
  if (Exit e = startFoxglove(opt, station)) return e;
  if (Exit e = openRecording(opt, station)) return e;
  return openFrameLog(opt, station.frame_log);
}

// One session with the robot: its link and its clocks.
struct Session {
  explicit Session(net::OperatorLink* l) : link(l) {}

  net::OperatorLink* link;  // null in a replay
  bool shared_clock = false;
  std::optional<int64_t> clock_offset_ns;  // robot minus local
  // What a packet capture adds to each UDP payload: the IP and UDP headers.
  std::size_t ip_udp_header_bytes = 0;
  int64_t next_gaze_ns = 0;
  int64_t next_live_ns = 0;
  int64_t live_start_ns = 0;
  uint64_t lost_reported = 0;
  uint64_t last_frame_id = 0;
  std::size_t max_payload = 0;  // of a datagram in this session: its MTU less kDatagramOverhead
};

// The run over all sessions: the figures and what the steps share.
class OperatorRun {
 public:
  OperatorRun(const Options& opt, Station& station)
      : opt_(opt),
        station_(station),
        assembler_(*station.assembler),
        map_(*station.map),
        view_(station.view.get()),
        fox_(station.foxglove.get()),
        wall_offset_ns_(wallClockOffsetNs()),
        splat_sizer_(net::CodecConfig{}.periphery_step_ratio),
        start_ns_(monotonicNs()),
        end_ns_(opt.duration_s > 0 ? start_ns_ + static_cast<int64_t>(opt.duration_s * 1e9) : INT64_MAX),
        gaze_period_ns_(static_cast<int64_t>(1e9 / opt.gaze_hz)),
        robot_address_(opt.connect) {
    if (fox_) fox_cloud_.reserve(static_cast<std::size_t>(opt.max_points));
  }

  // Without the viewer: one session, as before. With it: the page stays up and
  // the operator reconnects until it is stopped (a robot restarting, refusing
  // while busy, or not yet up).
  Exit runSessions();
  // --replay: the recording's chunks, frame summaries and map bricks, paced by
  // their log times (--speed), through what a session's datagrams go through.
  Exit runReplay();
  // Prints the summary and writes --summary; the exit code.
  int finish();

 private:
  Exit connectFailed(const Status& status);
  void runSession(net::OperatorLink& link);
  Session beginSession(net::OperatorLink& link);
  void sendGaze(Session& s, int64_t now);
  void reportLive(Session& s, int64_t now);
  void publishFigures(const Session& s, const tools::LiveFigures& live);
  void handleDatagram(Session& s, const net::Received& received);
  void handleReady(Session& s);
  void sendBrickAcks(Session& s, int64_t now);
  void publishView(const net::AssembledFrame& f);
  // --foxglove: the frame's cloud, the gaze sent (ray and head), a log line.
  void publishFoxgloveCloud(const net::AssembledFrame& f, const Session& s);
  void publishFoxgloveGaze(const net::GazeSample& g, int64_t now);
  void foxLog(foxglove::LogLevel level, const std::string& line);
  uint64_t wallNs(int64_t monotonic_ns) const { return static_cast<uint64_t>(monotonic_ns + wall_offset_ns_); }
  static int64_t wallClockOffsetNs() { return wallClockNs() - monotonicNs(); }
  // The robot keeps being tried while a viewer or a Foxglove client may watch.
  bool persistent() const { return view_ != nullptr || fox_ != nullptr; }
  void logFrame(const net::AssembledFrame& f, const tools::FrameObservation& obs, int64_t fovea_decoded_ns,
                const Session& s);
  // When the frame's fovea (region 0) was decoded: the arrival of its last fovea
  // chunk, or -1 (no fovea chunk, or some of them lost). Takes the frame's
  // entries off chunk_arrivals_.
  int64_t takeFoveaArrival(const net::AssembledFrame& f);
  void saveFramePly(const net::AssembledFrame& f);
  void saveHeld(const net::AssembledFrame& f);
  void endSession(Session& s);
  std::string viewerSummary() const;
  Exit writeSummaryJson(double seconds, const std::string& view_json) const;

  void publishState(tools::LinkState state, const std::string& detail) {
    if (view_) view_->publishState(tools::stateJson(state, detail, robot_address_));
  }
  // Waits up to ms, or less when stopped; false when stopped or out of time.
  bool pause(int ms) const {
    for (int i = 0; i < ms / 50 && g_stop == 0 && monotonicNs() < end_ns_; ++i) {
      const timespec t{0, 50'000'000};
      nanosleep(&t, nullptr);
    }
    return g_stop == 0 && monotonicNs() < end_ns_;
  }

  const Options& opt_;
  Station& station_;
  net::FrameAssembler& assembler_;
  tools::MapHolder& map_;
  tools::MapTotals map_live_before_{};  // at the last live line
  tools::MapTotals map_logged_before_{};  // at the last --frame-log line
  uint64_t view_map_points_left_out_ = 0, view_map_frames_cut_ = 0;
  tools::ViewServer* view_;  // null without --view
  tools::FoxgloveServer* fox_;  // null without --foxglove
  const int64_t wall_offset_ns_;  // CLOCK_REALTIME - CLOCK_MONOTONIC, at start (Foxglove's times are Unix time)
  foxglove::PointCloudEncoder fox_cloud_;
  foxglove::FrameTransformEncoder fox_head_;
  foxglove::GazeRayEncoder fox_gaze_;
  foxglove::LogEncoder fox_log_;
  tools::OperatorStats stats_;
  tools::SplatSizer splat_sizer_;
  const int64_t start_ns_;
  const int64_t end_ns_;
  const int64_t gaze_period_ns_;
  uint64_t ply_written_ = 0, ply_failed_ = 0, gaze_sent_ = 0, sessions_ = 0;
  bool held_done_ = false;     // --save-held: written (or failed), not tried again
  std::string held_result_;    // what it wrote, or why not
  std::optional<net::GazeSample> last_sent_;
  std::optional<tools::ViewerGaze> last_shown_;
  tools::GazePoint last_gaze_;
  bool robot_said_bye_ = false;
  std::string robot_address_;
  std::optional<net::StatusReport> last_status_;
  net::OperatorLinkCounters link_total_{};
  // Arrival times of the chunks the assembler decoded into frames, in order. A
  // frame's decoded chunks are contiguous in it (the assembler holds one frame
  // in progress), so a completed frame's are the first ones; the robot sends
  // the fovea's chunks first, so in send order (loopback) the fovea was decoded
  // at the arrival of its chunks_received[0]-th chunk. Bounded: at most one
  // frame's chunks (65536) and one more are kept.
  std::deque<int64_t> chunk_arrivals_;
};

Exit OperatorRun::runSessions() {
  while (g_stop == 0 && monotonicNs() < end_ns_) {
    publishState(tools::LinkState::kConnecting, "saying hello to " + opt_.connect);
    Result<std::unique_ptr<net::OperatorLink>> connected = net::OperatorLink::connect(opt_.connect, station_.link_config);
    if (!connected) {
      if (Exit e = connectFailed(connected.status())) return e;
      if (!pause(1000)) break;
      continue;
    }
    runSession(*connected.value());
    if (!persistent() || g_stop != 0 || monotonicNs() >= end_ns_) break;
    const std::string gone = robot_said_bye_ ? "the robot ended the session" : "the session ended (the robot went silent)";
    std::fprintf(stderr, "fovea-operator: %s; reconnecting\n", gone.c_str());
    foxLog(foxglove::LogLevel::kWarning, gone + "; reconnecting");
    publishState(tools::LinkState::kRobotGone, gone);
    if (!pause(1000)) break;
  }
  return std::nullopt;
}

Exit OperatorRun::runReplay() {
  Result<mcap::MappedFile> file = mcap::MappedFile::open(opt_.replay_path);
  if (!file) return failure("--replay: ", file.status());
  mcap::Reader reader(file->bytes());
  // The recording's channel of each message type (0: not one of the link's).
  std::array<uint8_t, 65536> type_of{};
  robot_address_ = "replay of " + opt_.replay_path;
  std::printf("replaying %s at %s\n", opt_.replay_path.c_str(),
              opt_.speed > 0 ? (std::to_string(opt_.speed) + "x").c_str() : "full speed");
  std::fflush(stdout);
  publishState(tools::LinkState::kStreaming, "");
  ++sessions_;
  Session s(nullptr);
  // Recorded times are wall-clock log times, not the robot's monotonic clock:
  // latency is unknown (left out of the figures), not invented.
  s.shared_clock = false;
  s.ip_udp_header_bytes = 20 + 8;
  s.max_payload = net::kMaxMtu;
  const int64_t replay_start_ns = monotonicNs();
  s.next_live_ns = replay_start_ns + 1'000'000'000;
  s.live_start_ns = replay_start_ns;
  uint64_t first_log_ns = 0;
  bool first = true;
  uint64_t replayed = 0, too_big = 0;
  alignas(net::kPayloadAlignment) static uint8_t payload[net::kMaxMtu];
  for (mcap::Reader::Item item = reader.next(); item != mcap::Reader::Item::kEnd && g_stop == 0; item = reader.next()) {
    if (item == mcap::Reader::Item::kChannel) {
      if (const std::optional<net::MessageType> t = net::streamMessageType(reader.channel().topic)) {
        type_of[reader.channel().id] = static_cast<uint8_t>(*t);
      }
      continue;
    }
    if (item != mcap::Reader::Item::kMessage) continue;
    const mcap::MessageView& m = reader.message();
    const auto type = static_cast<net::MessageType>(type_of[m.channel_id]);
    if (type_of[m.channel_id] == 0 || type == net::MessageType::kGaze) continue;
    if (m.data.size() > sizeof payload) {
      ++too_big;
      continue;
    }
    if (first) {
      first_log_ns = m.log_time_ns;
      first = false;
    }
    // Paced: the message is due when as much time has passed as between it and the first.
    if (opt_.speed > 0) {
      const double since_ns = static_cast<double>(m.log_time_ns - first_log_ns) / opt_.speed;
      const int64_t due_ns = replay_start_ns + static_cast<int64_t>(std::min(since_ns, 9.0e18));
      for (int64_t now = monotonicNs(); now < due_ns && g_stop == 0; now = monotonicNs()) {
        if (now >= s.next_live_ns) reportLive(s, now);
        const int64_t wait_ns = std::min({due_ns - now, s.next_live_ns - now, int64_t{50'000'000}});
        const timespec t{0, static_cast<long>(std::max<int64_t>(wait_ns, 0))};
        nanosleep(&t, nullptr);
      }
    }
    const int64_t now = monotonicNs();
    if (now >= s.next_live_ns) reportLive(s, now);
    std::memcpy(payload, m.data.data(), m.data.size());
    net::Received received;
    received.type = type;
    received.payload = std::span<const uint8_t>(payload, m.data.size());
    received.received_ns = static_cast<int64_t>(m.log_time_ns);
    handleDatagram(s, received);
    if (map_.ackDue(now, s.max_payload)) sendBrickAcks(s, now);
    ++replayed;
  }
  endSession(s);
  if (!reader.complete()) {
    std::fprintf(stderr, "fovea-operator: --replay: %s: %s (the messages before it were played)\n",
                 opt_.replay_path.c_str(), reader.stopReason().c_str());
  }
  std::printf("replayed %llu messages of %s%s\n", static_cast<unsigned long long>(replayed), opt_.replay_path.c_str(),
              too_big > 0 ? (", " + std::to_string(too_big) + " larger than a datagram skipped").c_str() : "");
  // A viewer or Foxglove client keeps the last frame on screen until the operator stops.
  if (persistent() && g_stop == 0 && monotonicNs() < end_ns_) {
    std::printf("replay finished; the viewer stays until SIGINT or SIGTERM%s\n", opt_.duration_s > 0 ? " (or --duration)" : "");
    std::fflush(stdout);
    while (pause(1000)) {
    }
  }
  return std::nullopt;
}

// Without the viewer a failed hello ends the run; with it, only bad arguments do.
Exit OperatorRun::connectFailed(const Status& status) {
  const std::string& why = status.message();
  if (!persistent()) return startFailure(status);
  if (status.code() == ErrorCode::kInvalidArgument) {
    std::fprintf(stderr, "fovea-operator: %s\n", why.c_str());
    return kExitUsage;
  }
  const bool refused = why.find(" refused (") != std::string::npos;
  std::fprintf(stderr, "fovea-operator: %s; trying again in 1 s\n", why.c_str());
  foxLog(foxglove::LogLevel::kWarning, why + "; trying again in 1 s");
  publishState(refused ? tools::LinkState::kRefused : tools::LinkState::kConnecting, why);
  return std::nullopt;
}

void OperatorRun::runSession(net::OperatorLink& link) {
  ++sessions_;
  Session s = beginSession(link);
  while (g_stop == 0 && !robot_said_bye_ && link.sessionActive()) {
    const int64_t now = monotonicNs();
    if (now >= end_ns_) break;
    if (now >= s.next_gaze_ns) sendGaze(s, now);
    if (now >= s.next_live_ns) reportLive(s, now);
    if (map_.ackDue(now, s.max_payload)) sendBrickAcks(s, now);
    const int64_t wake_ns = std::min({s.next_gaze_ns, s.next_live_ns, map_.nextAckNs(), end_ns_});
    const int timeout_ms = static_cast<int>(std::clamp<int64_t>((wake_ns - now + 999'999) / 1'000'000, 0, 1000));
    const std::optional<net::Received> received = link.receive(timeout_ms);
    if (received) handleDatagram(s, *received);
  }
  endSession(s);
}

Session OperatorRun::beginSession(net::OperatorLink& link) {
  Session s(&link);
  // --record: the gaze samples as sent, on /fovea/gaze (the link's payload, before sealing).
  if (station_.recorder) {
    link.setSendTap(
        [](void* context, net::MessageType type, std::span<const uint8_t> payload, int64_t) {
          const Station& station = *static_cast<const Station*>(context);
          if (const uint16_t channel = station.record_channels.channelOf(type); channel != 0) {
            (void)station.record_producer->record(channel, static_cast<uint64_t>(wallClockNs()), payload);
          }
        },
        &station_);
  }
  if (!link.notice().empty()) std::fprintf(stderr, "fovea-operator: *** %s ***\n", link.notice().c_str());
  // Latency compares the robot's capture stamp with this host's arrival time. On
  // one host the clocks are one; across hosts the robot's clock is estimated from
  // its status stamps: robot = local + offset, offset = stamp + RTT/2 - arrival.
  robot_address_ = link.robot().toString();
  s.shared_clock = opt_.clock == "shared" ||
                   (opt_.clock == "auto" && (robot_address_.rfind("127.", 0) == 0 || robot_address_.rfind("[::1]", 0) == 0));
  if (s.shared_clock) s.clock_offset_ns = 0;
  std::printf("connected to %s: MTU %u, budget %.2f MB/s, receive buffer %d KiB; latency on %s\n",
              robot_address_.c_str(), link.mtuBytes(), static_cast<double>(link.budgetBytesPerS()) / 1e6,
              link.receiveBufferBytes() / 1024,
              s.shared_clock ? "one clock" : "the robot's clock estimated from its status and round trip");
  std::fflush(stdout);
  foxLog(foxglove::LogLevel::kInfo, "connected to " + robot_address_);
  publishState(tools::LinkState::kStreaming, "");
  s.ip_udp_header_bytes = robot_address_.rfind('[', 0) == 0 ? 40 + 8 : 20 + 8;
  s.max_payload = link.mtuBytes() - net::kDatagramOverhead;
  if (sessions_ > 1) map_.reset();  // the robot delivers its map afresh to a new session
  chunk_arrivals_.clear();
  const int64_t session_start_ns = monotonicNs();
  s.next_gaze_ns = session_start_ns;
  s.next_live_ns = session_start_ns + 1'000'000'000;
  s.live_start_ns = session_start_ns;
  robot_said_bye_ = false;
  return s;
}

void OperatorRun::sendGaze(Session& s, int64_t now) {
  GazeChoice choice = chooseGaze(station_.script, view_, now - start_ns_, last_sent_);
  choice.sample.feedback.last_frame_id = s.last_frame_id;
  if (s.link->sendGaze(choice.sample)) {
    ++gaze_sent_;
    last_sent_ = choice.sample;
    last_shown_ = choice.viewer;
    if (choice.viewer) {
      const net::GazeSample& g = choice.sample;
      last_gaze_.origin_m = {g.gaze_origin_m.x, g.gaze_origin_m.y, g.gaze_origin_m.z};
      last_gaze_.direction = {g.gaze_direction.x, g.gaze_direction.y, g.gaze_direction.z};
      if (fox_) publishFoxgloveGaze(g, now);
      if (station_.record_foxglove) {
        const auto t = static_cast<uint64_t>(wallClockNs());
        const net::Quat& q = g.hmd_orientation;
        (void)station_.record_foxglove->recordRay(*station_.record_producer, t,
                                                  {g.gaze_origin_m.x, g.gaze_origin_m.y, g.gaze_origin_m.z},
                                                  {g.gaze_direction.x, g.gaze_direction.y, g.gaze_direction.z});
        (void)station_.record_foxglove->recordPose(*station_.record_producer, t,
                                                   {g.hmd_position_m.x, g.hmd_position_m.y, g.hmd_position_m.z},
                                                   {q.w, q.x, q.y, q.z});
      }
    }
  }
  s.next_gaze_ns += gaze_period_ns_;
  if (s.next_gaze_ns < now) s.next_gaze_ns = now + gaze_period_ns_;  // fell behind: no burst to catch up
}

// Once a second: the live line, and the viewer's figures.
void OperatorRun::reportLive(Session& s, int64_t now) {
  if (const uint64_t lost = s.link ? s.link->counters().datagrams_lost : 0; lost > s.lost_reported) {
    stats_.lost(lost - s.lost_reported);
    s.lost_reported = lost;
  }
  const tools::LiveFigures live = stats_.takeWindow(static_cast<double>(now - s.live_start_ns) * 1e-9);
  const tools::MapTotals map = map_.totals();
  if (!opt_.quiet || fox_ || station_.record_foxglove) {
    // The map's figures once the robot streams bricks (a robot that does not keeps the line as it was).
    const std::string map_text = map.payloads > 0 ? " | " + tools::mapLiveText(map, map_live_before_) : std::string();
    const std::string line = tools::liveLine(live) + map_text;
    if (!opt_.quiet) {
      std::printf("%s\n", line.c_str());
      std::fflush(stdout);
    }
    foxLog(foxglove::LogLevel::kInfo, line);
    if (station_.record_foxglove) {
      (void)station_.record_foxglove->recordLog(*station_.record_producer, static_cast<uint64_t>(wallClockNs()), line);
    }
  }
  map_live_before_ = map;
  if (view_) publishFigures(s, live);
  s.live_start_ns = now;
  s.next_live_ns += 1'000'000'000;
}

void OperatorRun::publishFigures(const Session& s, const tools::LiveFigures& live) {
  tools::ViewerFigures figures;
  figures.fps = live.fps;
  figures.wire_mb_per_s = live.wire_mb_per_s;
  figures.latency_p50_ms = live.latency_p50_ms;
  figures.latency_p99_ms = live.latency_p99_ms;
  figures.datagrams_lost = live.lost;
  std::size_t regions = live.points_per_region.size();
  while (regions > 0 && live.points_per_region[regions - 1] == 0) --regions;
  figures.points_per_region.assign(live.points_per_region.begin(), live.points_per_region.begin() + regions);
  figures.gaze_mode = view_->gazeMode();
  figures.gaze_sent = gaze_sent_;
  figures.gaze_last = last_shown_;
  if (const auto& status = s.link ? s.link->lastStatus() : std::nullopt) {
    if (status->gaze_age_ns >= 0) figures.robot_gaze_age_ms = static_cast<double>(status->gaze_age_ns) * 1e-6;
    if (status->rtt_ns >= 0) figures.robot_rtt_ms = static_cast<double>(status->rtt_ns) * 1e-6;
    figures.robot_gaze_origin_m = array3(status->gaze_origin_m);
    figures.robot_gaze_direction = array3(status->gaze_direction);
  }
  view_->publishFigures(std::move(figures));
}

void OperatorRun::handleDatagram(Session& s, const net::Received& received) {
  if (station_.record_producer) {
    if (const uint16_t channel = station_.record_channels.channelOf(received.type); channel != 0) {
      (void)station_.record_producer->record(channel, wallClockNs(), received.payload);  // a full ring drops and counts
    }
  }
  stats_.datagram(received.payload.size() + net::kDatagramOverhead, s.ip_udp_header_bytes);
  switch (received.type) {
    // The assembler's ready frames are those of its last call: look at them
    // right after a chunk or summary only (after any other datagram they
    // would be counted again).
    case net::MessageType::kChunk: {
      const uint64_t decoded_before = assembler_.counters().chunks;
      (void)assembler_.addChunk(received.payload, received.received_ns);  // failures are counted by the assembler
      // A chunk of a newer frame completes the one in progress first: that one's
      // arrivals are all before this chunk's, which handleReady leaves in place.
      if (assembler_.counters().chunks > decoded_before) chunk_arrivals_.push_back(received.received_ns);
      handleReady(s);
      if (chunk_arrivals_.size() > 65537) chunk_arrivals_.clear();  // (cannot happen: a frame has < 65536 chunks)
      break;
    }
    case net::MessageType::kFrameSummary:
      (void)assembler_.addSummary(received.payload);
      handleReady(s);
      break;
    case net::MessageType::kBrickChunk:
      (void)map_.add(received.payload, received.received_ns);  // outcomes are counted by the map
      // More parts than one acknowledgement takes: send now rather than let the list grow.
      if (map_.ackDue(received.received_ns, s.max_payload)) sendBrickAcks(s, received.received_ns);
      break;
    case net::MessageType::kBye:
      robot_said_bye_ = true;
      break;
    case net::MessageType::kStatus:
      // The link has decoded it (and echoes its stamp); the round trip the robot
      // measured from earlier echoes dates the stamp.
      if (!s.shared_clock && s.link) {
        if (const auto& status = s.link->lastStatus(); status && status->rtt_ns >= 0) {
          s.clock_offset_ns = tools::estimateClockOffsetNs(status->robot_stamp_ns, status->rtt_ns, received.received_ns);
        }
      }
      break;
    default:
      break;
  }
}

void OperatorRun::handleReady(Session& s) {
  for (std::size_t i = 0; i < assembler_.readyCount(); ++i) {
    const net::AssembledFrame& f = assembler_.ready(i);
    tools::FrameObservation obs;
    obs.frame_id = f.frame_id;
    // Capture to the arrival of the frame's last chunk (decoding it takes
    // microseconds); unknown (NaN, left out of the quantiles) until the
    // robot's clock is estimated.
    obs.latency_ms = s.clock_offset_ns ? static_cast<double>(f.last_chunk_received_ns + *s.clock_offset_ns -
                                                             static_cast<int64_t>(f.capture_time_ns)) * 1e-6
                                       : std::numeric_limits<double>::quiet_NaN();
    for (std::size_t r = 0; r < obs.points_per_region.size(); ++r) {
      obs.points_per_region[r] = f.points[r];
      obs.chunks_received += f.chunks_received[r];
      obs.chunks_expected += f.chunks_expected[r];
    }
    const int64_t fovea_ns = takeFoveaArrival(f);
    obs.fovea_latency_ms = fovea_ns >= 0 && s.clock_offset_ns
                               ? static_cast<double>(fovea_ns + *s.clock_offset_ns - static_cast<int64_t>(f.capture_time_ns)) * 1e-6
                               : std::numeric_limits<double>::quiet_NaN();
    stats_.frame(obs);
    if (station_.frame_log) logFrame(f, obs, fovea_ns, s);
    s.last_frame_id = f.frame_id;
    if (view_) publishView(f);
    if (fox_ && f.cloud != nullptr) publishFoxgloveCloud(f, s);
    if (station_.record_clouds != nullptr && f.cloud != nullptr) {
      (void)station_.record_foxglove->recordCloud(*station_.record_clouds, static_cast<uint64_t>(wallClockNs()),
                                                  f.cloud->points);
    }
    if (!opt_.ply_dir.empty() && f.cloud != nullptr) saveFramePly(f);
    if (opt_.held_frame && !held_done_ && f.frame_id >= *opt_.held_frame && tools::frameComplete(f)) saveHeld(f);
  }
}

void OperatorRun::sendBrickAcks(Session& s, int64_t now) {
  // A replay has nobody to tell: its acknowledgements are taken and dropped.
  map_.sendAcks(s.max_payload, now, [&s](const net::BrickAckMsg& ack) { return s.link ? s.link->sendBrickAck(ack) : true; });
}

// The frame with the map's bricks behind its live points (the buffer holds both: startViewer).
void OperatorRun::publishView(const net::AssembledFrame& f) {
  const tools::ViewMap map{&map_.cache(), net::CodecConfig{}.periphery_step_ratio, monotonicNs()};
  const tools::ViewPack pack = tools::packViewFrame(f, splat_sizer_.sizes(f), map, view_->frameBuffer());
  if (pack.map_points_left_out > 0) {
    ++view_map_frames_cut_;
    view_map_points_left_out_ += pack.map_points_left_out;
  }
  view_->publishFrame(pack.bytes);
}

// The decoded points in the robot's world frame, stamped with their capture
// (this host's clock when the robot's is known, else the arrival).
void OperatorRun::publishFoxgloveCloud(const net::AssembledFrame& f, const Session& s) {
  if (!fox_->subscribed(kFoxCloud)) return;
  const int64_t local_ns = s.clock_offset_ns ? static_cast<int64_t>(f.capture_time_ns) - *s.clock_offset_ns
                                             : f.last_chunk_received_ns;
  const std::span<const uint8_t> bytes = fox_cloud_.encode(f.cloud->points, kFoxWorld, static_cast<int64_t>(wallNs(local_ns)));
  fox_->publish(kFoxCloud, bytes, wallNs(f.last_chunk_received_ns));
}

void OperatorRun::publishFoxgloveGaze(const net::GazeSample& g, int64_t now) {
  const auto stamp = static_cast<int64_t>(wallNs(now));
  if (fox_->subscribed(kFoxGaze)) {
    fox_->publish(kFoxGaze,
                  fox_gaze_.encode(kFoxWorld, {g.gaze_origin_m.x, g.gaze_origin_m.y, g.gaze_origin_m.z},
                                   {g.gaze_direction.x, g.gaze_direction.y, g.gaze_direction.z}, 2.0, stamp),
                  wallNs(now));
  }
  if (fox_->subscribed(kFoxHead)) {
    const net::Quat& q = g.hmd_orientation;
    fox_->publish(kFoxHead,
                  fox_head_.encode(kFoxWorld, "head", {g.hmd_position_m.x, g.hmd_position_m.y, g.hmd_position_m.z},
                                   {q.w, q.x, q.y, q.z}, stamp),
                  wallNs(now));
  }
}

void OperatorRun::foxLog(foxglove::LogLevel level, const std::string& line) {
  if (fox_ == nullptr) return;
  const int64_t now = monotonicNs();
  fox_->publish(kFoxLog, fox_log_.encode(level, line, "fovea-operator", static_cast<int64_t>(wallNs(now))), wallNs(now));
}

int64_t OperatorRun::takeFoveaArrival(const net::AssembledFrame& f) {
  std::size_t received = 0;
  for (uint16_t c : f.chunks_received) received += c;
  received = std::min(received, chunk_arrivals_.size());
  const uint16_t fovea = f.chunks_received[0];
  // The fovea is whole when the summary says so (without one: when its chunks
  // are all that arrived of region 0 and the frame had any other chunk).
  const bool whole = f.summary_received ? fovea == f.chunks_expected[0] : received > fovea;
  const int64_t at = fovea > 0 && fovea <= received && whole ? chunk_arrivals_[fovea - 1] : -1;
  chunk_arrivals_.erase(chunk_arrivals_.begin(), chunk_arrivals_.begin() + static_cast<std::ptrdiff_t>(received));
  return at;
}

void OperatorRun::logFrame(const net::AssembledFrame& f, const tools::FrameObservation& obs, int64_t fovea_decoded_ns,
                           const Session& s) {
  uint32_t points = 0;
  for (uint32_t p : obs.points_per_region) points += p;
  station_.frame_log << f.frame_id << ',' << f.capture_time_ns << ',' << f.last_chunk_received_ns << ','
                     << (std::isnan(obs.latency_ms) ? std::string() : std::to_string(std::llround(obs.latency_ms * 1e3)))
                     << ',' << points << ',' << obs.chunks_received << ',' << obs.chunks_expected << ','
                     << (f.summary_received ? 1 : 0);
  const tools::MapTotals map = map_.totals();
  station_.frame_log << ',' << map.bricks_held << ',' << map.points_held << ',' << map.parts - map_logged_before_.parts
                     << ',' << map.versions - map_logged_before_.versions << ',';
  if (fovea_decoded_ns >= 0) {
    station_.frame_log << fovea_decoded_ns << ',';
    if (s.clock_offset_ns) station_.frame_log << std::llround(obs.fovea_latency_ms * 1e3);
  } else {
    station_.frame_log << ',';
  }
  station_.frame_log << '\n';
  map_logged_before_ = map;
}

void OperatorRun::saveFramePly(const net::AssembledFrame& f) {
  io::PlyWriteOptions ply;
  ply.double_coords = true;
  const std::string path = opt_.ply_dir + "/frame_" + std::to_string(f.frame_id) + ".ply";
  if (io::writePly(path, f.cloud->points, f.cloud->region.data(), ply).isOk()) {
    ++ply_written_;
  } else {
    ++ply_failed_;
  }
}

// --save-held: once a run. Allocates (the cloud of the held bricks and the frame's
// points) and writes the file on the receive loop: a one-off, not the per-frame path.
void OperatorRun::saveHeld(const net::AssembledFrame& f) {
  held_done_ = true;
  const tools::HeldCloud held = tools::heldCloud(f, map_.cache());
  if (Status st = tools::saveHeldCloud(opt_.held_path, held); !st) {
    held_result_ = "failed: " + st.message();
    return;
  }
  held_result_ = "frame " + std::to_string(f.frame_id) + " (" + std::to_string(held.info.live_points) + " live points, " +
                 std::to_string(held.info.map_points) + " map points in " + std::to_string(held.info.map_bricks) +
                 " bricks) to " + opt_.held_path;
}

void OperatorRun::endSession(Session& s) {
  assembler_.flush();
  handleReady(s);
  if (!s.link) return;  // a replay
  net::OperatorLink& link = *s.link;
  if (const uint64_t lost = link.counters().datagrams_lost; lost > s.lost_reported) stats_.lost(lost - s.lost_reported);
  last_status_ = link.lastStatus();
  const net::OperatorLinkCounters& lc = link.counters();
  link_total_.datagrams_lost += lc.datagrams_lost;
  link_total_.dropped.add(lc.dropped);
  if (!robot_said_bye_ && link.sessionActive()) link.bye("operator done");
}

int OperatorRun::finish() {
  const double seconds = static_cast<double>(monotonicNs() - start_ns_) * 1e-9;
  const net::FrameAssembler::Counters& ac = assembler_.counters();
  std::printf("\nsummary: %llu frames in %.1f s, %llu datagrams (%llu lost, %llu dropped as invalid), %llu gaze samples sent\n",
              static_cast<unsigned long long>(stats_.frames()), seconds,
              static_cast<unsigned long long>(stats_.datagrams()), static_cast<unsigned long long>(link_total_.datagrams_lost),
              static_cast<unsigned long long>(link_total_.dropped.total()), static_cast<unsigned long long>(gaze_sent_));
  std::printf("  chunks: %llu decoded, %llu bad, %llu late, %llu duplicate%s\n",
              static_cast<unsigned long long>(ac.chunks), static_cast<unsigned long long>(ac.bad_chunks),
              static_cast<unsigned long long>(ac.late_chunks), static_cast<unsigned long long>(ac.duplicate_chunks),
              robot_said_bye_ ? "; the robot ended the session" : "");
  const tools::MapTotals map = map_.totals();
  std::printf("  map: %zu bricks and %zu points held; %llu brick parts taken (%llu duplicate, %llu stale, %llu bad, %llu no room), "
              "%llu versions completed, %llu bricks evicted, %llu acknowledgements sent (%llu failed)\n",
              map.bricks_held, map.points_held, static_cast<unsigned long long>(map.parts),
              static_cast<unsigned long long>(map.duplicate_parts), static_cast<unsigned long long>(map.stale_parts),
              static_cast<unsigned long long>(map.bad_parts), static_cast<unsigned long long>(map.no_room_parts),
              static_cast<unsigned long long>(map.versions), static_cast<unsigned long long>(map.evicted),
              static_cast<unsigned long long>(map.acks_sent), static_cast<unsigned long long>(map.ack_send_failures));
  if (!opt_.ply_dir.empty()) {
    std::printf("  wrote %llu frames to %s%s\n", static_cast<unsigned long long>(ply_written_), opt_.ply_dir.c_str(),
                ply_failed_ ? " (some failed)" : "");
  }
  if (opt_.held_frame) {
    if (held_result_.empty()) {
      held_result_ = "no frame with id >= " + std::to_string(*opt_.held_frame) + " arrived whole: nothing written";
    }
    std::printf("  --save-held: %s\n", held_result_.c_str());
  }
  if (fox_) {
    const tools::FoxgloveServerCounters fc = fox_->counters();
    std::printf("  foxglove: %llu clients served (%llu refused), %llu messages published (%llu too large), %llu sent, "
                "%llu dropped for slow clients, %llu bad requests\n",
                static_cast<unsigned long long>(fc.clients_served), static_cast<unsigned long long>(fc.clients_refused),
                static_cast<unsigned long long>(fc.published), static_cast<unsigned long long>(fc.too_large),
                static_cast<unsigned long long>(fc.sent), static_cast<unsigned long long>(fc.dropped),
                static_cast<unsigned long long>(fc.bad_requests));
  }
  const std::string view_json = viewerSummary();
  if (Exit e = writeSummaryJson(seconds, view_json)) return *e;
  return stats_.frames() > 0 ? kExitOk : kExitFailure;
}

// Prints the viewer's line of the summary; its part of --summary's JSON ("" without --view).
std::string OperatorRun::viewerSummary() const {
  if (!view_) return {};
  const tools::ViewServerCounters vc = view_->counters();
  std::printf("  viewer: %llu tabs served (%llu refused), %llu frames published, %llu sent to tabs, %llu dropped for slow tabs, "
              "%llu malformed messages, %llu gaze samples from tabs, %llu map points left out of %llu frames\n",
              static_cast<unsigned long long>(vc.tabs_served), static_cast<unsigned long long>(vc.tabs_refused),
              static_cast<unsigned long long>(vc.frames_published), static_cast<unsigned long long>(vc.frames_sent),
              static_cast<unsigned long long>(vc.frames_dropped), static_cast<unsigned long long>(vc.malformed),
              static_cast<unsigned long long>(vc.gaze_received), static_cast<unsigned long long>(view_map_points_left_out_),
              static_cast<unsigned long long>(view_map_frames_cut_));
  return ", \"sessions\": " + std::to_string(sessions_) + ", \"viewer\": {\"tabs_served\": " +
         std::to_string(vc.tabs_served) + ", \"tabs_refused\": " + std::to_string(vc.tabs_refused) +
         ", \"frames_published\": " + std::to_string(vc.frames_published) + ", \"frames_sent\": " +
         std::to_string(vc.frames_sent) + ", \"frames_dropped\": " + std::to_string(vc.frames_dropped) +
         ", \"malformed\": " + std::to_string(vc.malformed) + ", \"gaze_received\": " + std::to_string(vc.gaze_received) +
         ", \"map_points_left_out\": " + std::to_string(view_map_points_left_out_) +
         ", \"map_frames_cut\": " + std::to_string(view_map_frames_cut_) + "}";
}

Exit OperatorRun::writeSummaryJson(double seconds, const std::string& view_json) const {
  if (opt_.summary_path.empty()) return std::nullopt;
  std::string robot_gaze;
  if (last_status_ && last_status_->gaze_origin_m && last_status_->gaze_direction) {
    const net::Vec3& o = *last_status_->gaze_origin_m;
    const net::Vec3& d = *last_status_->gaze_direction;
    robot_gaze = ", \"robot_gaze\": {\"origin_m\": " + vec3Json({o.x, o.y, o.z}) + ", \"direction\": " + vec3Json({d.x, d.y, d.z}) + "}";
  }
  const std::string extra =
      "\"robot\": \"" + robot_address_ + "\", \"gaze_samples_sent\": " + std::to_string(gaze_sent_) +
      ", \"last_gaze\": {\"origin_m\": " + vec3Json(last_gaze_.origin_m) + ", \"direction\": " +
      vec3Json(last_gaze_.direction) + "}" + robot_gaze + ", \"chunks_bad\": " + std::to_string(assembler_.counters().bad_chunks) +
      ", \"datagrams_invalid\": " + std::to_string(link_total_.dropped.total()) +
      tools::mapSummaryJson(map_.totals()) + view_json;
  std::ofstream file(opt_.summary_path);
  file << stats_.summaryJson(seconds, extra);
  if (!file) {
    std::fprintf(stderr, "fovea-operator: --summary: cannot write '%s'\n", opt_.summary_path.c_str());
    return kExitFailure;
  }
  return std::nullopt;
}

}  // namespace

int main(int argc, char** argv) {
  if (wantsHelp(argc, argv)) {
    std::fputs(kHelp, stdout);
    return kExitOk;
  }
  Result<Options> parsed = parseOptions(argc, argv);
  if (!parsed) {
    std::fprintf(stderr, "fovea-operator: %s\n", parsed.status().message().c_str());
    return kExitUsage;
  }
  const Options& opt = parsed.value();
  Station station;
  if (Exit e = setUp(opt, station)) return *e;
  std::signal(SIGINT, onStopSignal);
  std::signal(SIGTERM, onStopSignal);
  OperatorRun run(opt, station);
  if (Exit e = opt.replay_path.empty() ? run.runSessions() : run.runReplay()) return *e;
  const int code = run.finish();
  if (station.recorder) {
    const Status closed = station.recorder->close();
    const mcap::RecorderCounters c = station.recorder->counters();
    std::printf("  recording %s: %llu messages, %.2f MB; dropped: ring full %llu, too big %llu, disk %llu%s%s\n",
                station.recorder->path().c_str(), static_cast<unsigned long long>(c.messages_written),
                static_cast<double>(c.bytes_written) / 1e6, static_cast<unsigned long long>(c.dropped_ring_full),
                static_cast<unsigned long long>(c.dropped_too_big), static_cast<unsigned long long>(c.dropped_disk),
                closed ? "" : "; closing failed: ", closed ? "" : closed.message().c_str());
  }
  return code;
}

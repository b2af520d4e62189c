// fovea-operator's command line: --help's text and the parser, one step for each
// kind of option (text, --save-held, --clock, numbers) and one for which go together.
#include "tools/operator/operator_options.h"

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <system_error>
#include <utility>

namespace fovea::tools {

const char* const kOperatorHelp =
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

namespace {

Result<double> number(const std::string& flag, const char* text) {
  char* end = nullptr;
  const double v = std::strtod(text, &end);
  if (end == text || *end != '\0' || !std::isfinite(v)) {
    return Result<double>(ErrorCode::kInvalidArgument, flag + ": '" + text + "' is not a number");
  }
  return v;
}

Status badOption(std::string message) { return Status(ErrorCode::kInvalidArgument, std::move(message)); }

// The options whose value is taken as it is; false: not one of them.
bool takeTextOption(const std::string& flag, const char* value, OperatorOptions& o) {
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
  } else if (flag == "--record") {
    o.record_path = value;
  } else if (flag == "--replay") {
    o.replay_path = value;
  } else if (flag == "--name") {
    o.name = value;
  } else if (flag == "--view") {
    o.view = value;
  } else if (flag == "--foxglove") {
    o.foxglove = value;
  } else {
    return false;
  }
  return true;
}

// --save-held FRAME_ID:FILE.ply, whose directory must exist.
Status parseSaveHeld(const std::string& spec, OperatorOptions& o) {
  const std::size_t colon = spec.find(':');
  char* end = nullptr;
  const std::string id = colon == std::string::npos ? spec : spec.substr(0, colon);
  const unsigned long long frame = std::strtoull(id.c_str(), &end, 10);
  if (colon == std::string::npos || id.empty() || *end != '\0' || id[0] == '-' || frame > 0xffffffffull ||
      colon + 1 >= spec.size()) {
    return badOption("--save-held: '" + spec + "' is not FRAME_ID:FILE.ply (a frame id within 0 .. 4294967295)");
  }
  o.held_frame = static_cast<uint32_t>(frame);
  o.held_path = spec.substr(colon + 1);
  const std::filesystem::path parent = std::filesystem::path(o.held_path).parent_path();
  std::error_code ec;
  if (!parent.empty() && !std::filesystem::is_directory(parent, ec)) {
    return badOption("--save-held: no directory '" + parent.string() + "'");
  }
  return Status::ok();
}

bool isNumberOption(const std::string& flag) {
  for (const char* f : {"--speed", "--foxglove-clients", "--view-tabs", "--max-points", "--map-points", "--map-bricks",
                        "--duration", "--budget", "--mtu", "--gaze-hz"}) {
    if (flag == f) return true;
  }
  return false;
}

// An option whose value is a number (isNumberOption), within its range.
Status takeNumberOption(const std::string& flag, double v, OperatorOptions& o) {
  const bool whole = v == std::floor(v);
  if (flag == "--speed") {
    if (!(v >= 0 && v <= 1000)) return badOption("--speed: must be within 0 .. 1000");
    o.speed = v;
  } else if (flag == "--foxglove-clients") {
    if (!(v >= 1 && v <= 64 && whole)) return badOption("--foxglove-clients: must be a whole number within 1 .. 64");
    o.foxglove_clients = static_cast<long>(v);
  } else if (flag == "--view-tabs") {
    if (!(v >= 1 && v <= 64)) return badOption("--view-tabs: must be within 1 .. 64");
    o.view_tabs = static_cast<long>(v);
  } else if (flag == "--max-points") {
    if (!(v >= 1 && v <= 1e8)) return badOption("--max-points: must be within 1 .. 1e8");
    o.max_points = static_cast<long>(v);
  } else if (flag == "--map-points") {
    // At least one block of the cache's pool (256 points); at most 1 GiB of points.
    if (!(v >= 256 && v <= 67108864 && whole)) return badOption("--map-points: must be a whole number within 256 .. 67108864");
    o.map_points = static_cast<long>(v);
  } else if (flag == "--map-bricks") {
    if (!(v >= 1 && v <= 1048576 && whole)) return badOption("--map-bricks: must be a whole number within 1 .. 1048576");
    o.map_bricks = static_cast<long>(v);
  } else if (flag == "--duration") {
    if (!(v > 0 && v <= 3.2e7)) return badOption("--duration: must be within 0 .. 3.2e7 s (a year)");
    o.duration_s = v;
  } else if (flag == "--budget") {
    if (!(v >= 0.01 && v <= 10000.0)) return badOption("--budget: must be within 0.01 .. 10000 MB/s");
    o.budget_mbps = v;
  } else if (flag == "--mtu") {
    if (v < static_cast<double>(net::kMinMtu) || v > static_cast<double>(net::kMaxMtu)) {
      return badOption("--mtu: must be within " + std::to_string(net::kMinMtu) + " .. " + std::to_string(net::kMaxMtu));
    }
    o.mtu = static_cast<long>(v);
  } else {  // --gaze-hz
    if (!(v >= 1 && v <= 200)) return badOption("--gaze-hz: must be within 1 .. 200");
    o.gaze_hz = v;
  }
  return Status::ok();
}

// One option that takes a value.
Status takeOption(const std::string& flag, const char* value, OperatorOptions& o) {
  if (takeTextOption(flag, value, o)) return Status::ok();
  if (flag == "--save-held") return parseSaveHeld(value, o);
  if (flag == "--clock") {
    o.clock = value;
    if (o.clock != "auto" && o.clock != "shared" && o.clock != "estimated") {
      return badOption("--clock: '" + o.clock + "' is not auto, shared or estimated");
    }
    return Status::ok();
  }
  if (isNumberOption(flag)) {
    Result<double> v = number(flag, value);
    if (!v) return v.status();
    return takeNumberOption(flag, v.value(), o);
  }
  return badOption("unknown argument '" + flag + "' (see --help)");
}

// Which options go together, once all are read.
Status checkCombination(const OperatorOptions& o) {
  if (!o.replay_path.empty()) {
    // A replay talks to no robot: no key, no gaze to send.
    if (!o.connect.empty()) return badOption("--replay: not together with --connect");
    if (!o.record_path.empty()) return badOption("--record: not together with --replay");
    return Status::ok();
  }
  if (o.connect.empty()) return badOption("--connect HOST:PORT is required (or --replay FILE.mcap)");
  if (o.gaze.empty() && o.view.empty()) {
    return badOption("--gaze SCRIPT is required (or --view [ADDR:]PORT, whose page gives the gaze)");
  }
  if (o.key_file && o.insecure) return badOption("--insecure: not together with --key-file");
  if (!o.key_file && !o.insecure) {
    return badOption("--key-file FILE is required (or --insecure for a robot started with --insecure)");
  }
  return Status::ok();
}

}  // namespace

bool wantsHelp(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) return true;
  }
  return false;
}

Result<OperatorOptions> parseOptions(int argc, char** argv) {
  OperatorOptions o;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--insecure") { o.insecure = true; continue; }
    if (flag == "--quiet") { o.quiet = true; continue; }
    if (i + 1 >= argc) return Result<OperatorOptions>(ErrorCode::kInvalidArgument, flag + ": unknown, or needs a value (see --help)");
    if (Status s = takeOption(flag, argv[++i], o); !s) return s;
  }
  if (Status s = checkCombination(o); !s) return s;
  return o;
}

}  // namespace fovea::tools

// The station's set-up before the first hello, one step for each part (gaze
// script, link, --save-ply's directory, viewer, Foxglove, recording, frame log),
// and the recording's close after the run.
#include "tools/operator/operator_station.h"

#include <array>
#include <cstdio>
#include <filesystem>
#include <string>
#include <system_error>
#include <utility>

#include <Eigen/Core>

#include "net/key.h"
#include "net/wire.h"

namespace fovea::tools {

namespace {

Exit loadGazeScript(const OperatorOptions& opt, Station& station) {
  if (opt.gaze.empty()) return std::nullopt;
  Result<tools::GazeScript> parsed = tools::GazeScript::parse(opt.gaze);
  if (!parsed) return startFailure(parsed.status());
  station.script = std::move(parsed.value());
  return std::nullopt;
}

Exit configureLink(const OperatorOptions& opt, net::OperatorLinkConfig& config) {
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

Exit createPlyDir(const OperatorOptions& opt) {
  if (opt.ply_dir.empty()) return std::nullopt;
  std::error_code ec;
  std::filesystem::create_directories(opt.ply_dir, ec);
  if (ec) {
    std::fprintf(stderr, "fovea-operator: --save-ply: cannot create '%s': %s\n", opt.ply_dir.c_str(), ec.message().c_str());
    return kExitFailure;
  }
  return std::nullopt;
}

Exit startViewer(const OperatorOptions& opt, Station& station) {
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

Exit startFoxglove(const OperatorOptions& opt, Station& station) {
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

Exit openFrameLog(const OperatorOptions& opt, std::ofstream& frame_log) {
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
Exit openRecording(const OperatorOptions& opt, Station& station) {
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

}  // namespace

// Everything the station sets up, in the order it always has (the first failure is the one reported).
Exit setUp(const OperatorOptions& opt, Station& station) {
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

void closeRecording(Station& station) {
  if (!station.recorder) return;
  const Status closed = station.recorder->close();
  const mcap::RecorderCounters c = station.recorder->counters();
  std::printf("  recording %s: %llu messages, %.2f MB; dropped: ring full %llu, too big %llu, disk %llu%s%s\n",
              station.recorder->path().c_str(), static_cast<unsigned long long>(c.messages_written),
              static_cast<double>(c.bytes_written) / 1e6, static_cast<unsigned long long>(c.dropped_ring_full),
              static_cast<unsigned long long>(c.dropped_too_big), static_cast<unsigned long long>(c.dropped_disk),
              closed ? "" : "; closing failed: ", closed ? "" : closed.message().c_str());
}

}  // namespace fovea::tools

// OperatorRun's live sessions with the robot: connecting and reconnecting, the
// receive loop, the gaze it sends, the live line, and each datagram received (a
// replay's go through the same steps).
#include <algorithm>
#include <array>
#include <cstdio>
#include <limits>
#include <memory>
#include <optional>
#include <string>

#include <Eigen/Geometry>

#include "tools/operator/held_cloud.h"
#include "tools/operator/operator_run.h"

namespace fovea::tools {

namespace {

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

}  // namespace fovea::tools

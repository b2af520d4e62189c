// OperatorRun's --replay: a recording's chunks, frame summaries and map bricks,
// paced by their log times (--speed), through what a session's datagrams go
// through, as if live.
#include <algorithm>
#include <array>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <span>
#include <string>

#include "io/mcap/mapped_file.h"
#include "net/stream_channels.h"
#include "net/wire.h"
#include "tools/operator/operator_run.h"

namespace fovea::tools {

Exit OperatorRun::runReplay() {
  Result<mcap::MappedFile> file = mcap::MappedFile::open(opt_.replay_path);
  if (!file) return failure("--replay: ", file.status());
  mcap::Reader reader(file->bytes());
  Session s = beginReplay();
  const int64_t replay_start_ns = monotonicNs();
  s.next_live_ns = replay_start_ns + 1'000'000'000;
  s.live_start_ns = replay_start_ns;
  const ReplayCounts counts = replayMessages(reader, s, replay_start_ns);
  endSession(s);
  reportReplayEnd(reader, counts);
  holdAfterReplay();
  return std::nullopt;
}

// Says what it plays and sets up the session a replay is: no link, no clock.
Session OperatorRun::beginReplay() {
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
  return s;
}

// Plays every message of the link's types but gaze (the operator's own), until
// the file ends or the run is stopped.
OperatorRun::ReplayCounts OperatorRun::replayMessages(mcap::Reader& reader, Session& s, int64_t replay_start_ns) {
  // The recording's channel of each message type (0: not one of the link's).
  std::array<uint8_t, 65536> type_of{};
  uint64_t first_log_ns = 0;
  bool first = true;
  ReplayCounts counts;
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
    if (m.data.size() > net::kMaxMtu) {  // larger than replayMessage's datagram
      ++counts.too_big;
      continue;
    }
    if (first) {
      first_log_ns = m.log_time_ns;
      first = false;
    }
    // Paced: the message is due when as much time has passed as between it and the first.
    if (opt_.speed > 0) {
      const double since_ns = static_cast<double>(m.log_time_ns - first_log_ns) / opt_.speed;
      waitForReplayDue(s, replay_start_ns + static_cast<int64_t>(std::min(since_ns, 9.0e18)));
    }
    replayMessage(s, type, m);
    ++counts.replayed;
  }
  return counts;
}

// Sleeps until due_ns (or the run is stopped), keeping the live line going.
void OperatorRun::waitForReplayDue(Session& s, int64_t due_ns) {
  for (int64_t now = monotonicNs(); now < due_ns && g_stop == 0; now = monotonicNs()) {
    if (now >= s.next_live_ns) reportLive(s, now);
    const int64_t wait_ns = std::min({due_ns - now, s.next_live_ns - now, int64_t{50'000'000}});
    const timespec t{0, static_cast<long>(std::max<int64_t>(wait_ns, 0))};
    nanosleep(&t, nullptr);
  }
}

// The message as the datagram it was received as, stamped with its log time.
void OperatorRun::replayMessage(Session& s, net::MessageType type, const mcap::MessageView& m) {
  alignas(net::kPayloadAlignment) static uint8_t payload[net::kMaxMtu];
  const int64_t now = monotonicNs();
  if (now >= s.next_live_ns) reportLive(s, now);
  std::memcpy(payload, m.data.data(), m.data.size());
  net::Received received;
  received.type = type;
  received.payload = std::span<const uint8_t>(payload, m.data.size());
  received.received_ns = static_cast<int64_t>(m.log_time_ns);
  handleDatagram(s, received);
  if (map_.ackDue(now, s.max_payload)) sendBrickAcks(s, now);
}

// Where the file stopped being readable, if it did, and what was played.
void OperatorRun::reportReplayEnd(const mcap::Reader& reader, const ReplayCounts& counts) const {
  if (!reader.complete()) {
    std::fprintf(stderr, "fovea-operator: --replay: %s: %s (the messages before it were played)\n",
                 opt_.replay_path.c_str(), reader.stopReason().c_str());
  }
  std::printf("replayed %llu messages of %s%s\n", static_cast<unsigned long long>(counts.replayed),
              opt_.replay_path.c_str(),
              counts.too_big > 0 ? (", " + std::to_string(counts.too_big) + " larger than a datagram skipped").c_str() : "");
}

// A viewer or Foxglove client keeps the last frame on screen until the operator stops.
void OperatorRun::holdAfterReplay() const {
  if (persistent() && g_stop == 0 && monotonicNs() < end_ns_) {
    std::printf("replay finished; the viewer stays until SIGINT or SIGTERM%s\n", opt_.duration_s > 0 ? " (or --duration)" : "");
    std::fflush(stdout);
    while (pause(1000)) {
    }
  }
}

}  // namespace fovea::tools

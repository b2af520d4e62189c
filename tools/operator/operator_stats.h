// What fovea-operator measures: frames per second, megabytes per second on the
// wire, end-to-end latency from capture to decoded (p50, p99), datagrams lost
// and points per region, once a second (live) and for the whole run (summary).
#pragma once

#include <array>
#include <limits>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "pipeline/acuity.h"

namespace fovea::tools {

// The robot's clock minus this host's, from a robot timestamp received at
// received_ns (this host's clock) and the round trip the robot measured:
// the stamp was taken half a round trip before it arrived (symmetric paths).
inline int64_t estimateClockOffsetNs(int64_t robot_stamp_ns, int64_t rtt_ns, int64_t received_ns) {
  return robot_stamp_ns + rtt_ns / 2 - received_ns;
}

// Nearest-rank quantile of samples (q in [0, 1]); NaN when there are none.
double quantile(std::vector<double> samples, double q);

struct FrameObservation {
  uint32_t frame_id = 0;
  double latency_ms = 0.0;  // capture (robot) to decoded (operator); NaN: unknown (left out)
  double fovea_latency_ms = std::numeric_limits<double>::quiet_NaN();  // capture to the fovea decoded; NaN: unknown
  std::array<uint32_t, pipeline::kMaxRegions> points_per_region{};
  uint32_t chunks_received = 0;
  uint32_t chunks_expected = 0;  // from the frame summary (0 when it was lost)
};

// One window's figures (NaN latency: none measured).
struct LiveFigures {
  double fps = 0.0;
  double wire_mb_per_s = 0.0;
  double latency_p50_ms = 0.0;
  double latency_p99_ms = 0.0;
  uint64_t lost = 0;
  uint64_t points_per_frame = 0;
  std::array<uint64_t, pipeline::kMaxRegions> points_per_region{};  // per frame
};
// The live line fovea-operator prints.
std::string liveLine(const LiveFigures& f);

class OperatorStats {
 public:
  // wire_bytes: the UDP payload; ip_udp_header_bytes: the IP and UDP headers a
  // packet capture would also count (28 for IPv4, 48 for IPv6).
  void datagram(std::size_t wire_bytes, std::size_t ip_udp_header_bytes = 0) {
    window_.datagrams += 1;
    window_.wire_bytes += wire_bytes;
    total_.datagrams += 1;
    total_.wire_bytes += wire_bytes;
    total_.ip_bytes += wire_bytes + ip_udp_header_bytes;
  }
  void lost(uint64_t datagrams) {
    window_.lost += datagrams;
    total_.lost += datagrams;
  }
  void frame(const FrameObservation& f);

  // The last window of `seconds`; then a new window starts.
  LiveFigures takeWindow(double seconds);
  // The whole run as a JSON object; `extra` (already JSON members, may be empty)
  // is added at the top level.
  std::string summaryJson(double seconds, const std::string& extra) const;

  uint64_t frames() const { return total_.frames; }
  uint64_t datagrams() const { return total_.datagrams; }

 private:
  struct Tally {
    uint64_t frames = 0;
    uint64_t datagrams = 0;
    uint64_t wire_bytes = 0;
    uint64_t ip_bytes = 0;  // wire_bytes with the IP and UDP headers
    uint64_t lost = 0;
    uint64_t chunks_received = 0;
    uint64_t chunks_expected = 0;
    std::array<uint64_t, pipeline::kMaxRegions> points{};
    std::vector<double> latency_ms;
    std::vector<double> fovea_latency_ms;
  };
  static void add(Tally& t, const FrameObservation& f);
  Tally window_;
  Tally total_;
};

}  // namespace fovea::tools

// OperatorRun's --foxglove messages: each frame's cloud, the gaze sent (its ray
// and the head) and the log lines, on the channels the station opened.
#include <string>

#include "tools/operator/operator_run.h"

namespace fovea::tools {

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

}  // namespace fovea::tools

// OperatorRun's end of run: the summary's lines (frames, chunks, map, files,
// Foxglove, viewer) and --summary's JSON.
#include <cstdio>
#include <fstream>
#include <string>

#include <Eigen/Core>

#include "tools/operator/operator_run.h"

namespace fovea::tools {

namespace {

std::string vec3Json(const Eigen::Vector3d& v) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "[%.9g, %.9g, %.9g]", v.x(), v.y(), v.z());
  return buf;
}

}  // namespace

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

}  // namespace fovea::tools

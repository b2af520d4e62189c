// What OperatorRun sends each decoded frame to besides the figures: the viewer
// (with the map behind it), --frame-log's line, --save-ply's file and --save-held.
#include <cmath>
#include <string>

#include "io/ply.h"
#include "tools/operator/held_cloud.h"
#include "tools/operator/operator_run.h"

namespace fovea::tools {

// The frame with the map's bricks behind its live points (the buffer holds both: startViewer in
// operator_station.cpp).
void OperatorRun::publishView(const net::AssembledFrame& f) {
  const tools::ViewMap map{&map_.cache(), net::CodecConfig{}.periphery_step_ratio, monotonicNs()};
  const tools::ViewPack pack = tools::packViewFrame(f, splat_sizer_.sizes(f), map, view_->frameBuffer());
  if (pack.map_points_left_out > 0) {
    ++view_map_frames_cut_;
    view_map_points_left_out_ += pack.map_points_left_out;
  }
  view_->publishFrame(pack.bytes);
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

}  // namespace fovea::tools

// The service's status line: every status_interval_ms the supervisor formats
// the window since the previous one (rates, drops, latency quantiles, gaze,
// pose, map, memory, lines, USB) without allocating, and writes it to the log,
// the recording and systemd's STATUS.
#include "firmware/service.h"

#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <cstring>

#include "core/clock.h"

namespace fovea::firmware {

namespace {

// ", unfused N (why)" after the `used` characters of `out`, when they fit.
void appendUnfused(char* out, std::size_t size, int& used, uint64_t frames, const char* why) {
  if (used <= 0 || static_cast<std::size_t>(used) >= size) return;
  const int more =
      std::snprintf(out + used, size - static_cast<std::size_t>(used), ", unfused %" PRIu64 " (%s)", frames, why);
  if (more > 0) used += more;
}

// USB hot-plug counts since start: "arrived 1 left 0", or "off" when not watched.
void formatUsbCounts(const hal::usb::UsbMonitorCounters& counts, char* out, std::size_t size) {
  if (counts.available) {
    std::snprintf(out, size, "arrived %" PRIu64 " left %" PRIu64, counts.arrivals, counts.removals);
  } else {
    std::snprintf(out, size, "off");
  }
}

// The age of the operator's newest gaze (received at gaze_ns; 0: none yet).
void formatGazeAge(int64_t gaze_ns, int64_t now_ns, char* out, std::size_t size) {
  if (gaze_ns == 0) {
    std::snprintf(out, size, "none");
  } else {
    std::snprintf(out, size, "%" PRId64 " ms", (now_ns - gaze_ns) / 1'000'000);
  }
}

}  // namespace

void Service::writeStatusLine(int64_t now_ns) {
  char line[kLogLineBytes];
  std::memcpy(line, "STATUS=", 7);
  const std::size_t n = formatStatusLine(line + 7, sizeof line - 7);
  log().log(LogLevel::kInfo, "%s", line + 7);
  if (recorder_) recorder_->onStatusLine(std::string_view(line + 7, n));
  status_lines_written_.fetch_add(1, std::memory_order_relaxed);
  if (config_.runtime.systemd_notify) notifier_.notify(std::string_view(line, 7 + n));
  const int64_t interval_ns = config_.runtime.status_interval_ms * 1'000'000;
  next_status_ns_ += interval_ns * ((now_ns - next_status_ns_) / interval_ns + 1);
}

std::size_t Service::formatStatusLine(char* out, std::size_t size) {
  const int64_t now = monotonicNs();
  const double dt_s = std::max(1e-9, static_cast<double>(now - window_.at_ns) * 1e-9);
  const fovea::RingCounters capture_ring = frames_->ring().counters();
  const fovea::RingCounters foveation_ring = foveated_->ring().counters();
  Window w;
  w.at_ns = now;
  w.captured = capture_ring.published;
  w.foveated = frames_foveated_.load(std::memory_order_relaxed);
  w.sent = frames_sent_.load(std::memory_order_relaxed);
  w.wire_bytes = wire_bytes_.load(std::memory_order_relaxed);
  w.capture_drops = capture_ring.dropped;
  w.foveation_drops = foveation_ring.dropped;
  LatencyTexts latency;
  formatWindowLatencies(latency);
  const int64_t gaze_ns = gaze_received_ns_.load(std::memory_order_relaxed);
  char usb[48];
  formatUsbCounts(usb_monitor_->counters(), usb, sizeof usb);
  char gaze_age[32];
  formatGazeAge(gaze_ns, now, gaze_age, sizeof gaze_age);
  char pose[192] = "";
  formatPoseFields(pose, sizeof pose);
  char map[320] = "";
  formatMapFields(latency[3], map, sizeof map);
  // Frames since start dropped for more voxels or points than configured, and
  // those foveated coarser to fit them (each only once there is one).
  char over[80] = "";
  int over_used = 0;
  if (const uint64_t n_over = frames_over_capacity_.load(std::memory_order_relaxed); n_over > 0) {
    over_used = std::snprintf(over, sizeof over, " over capacity %" PRIu64, n_over);
  }
  if (const uint64_t n_coarse = frames_coarsened_.load(std::memory_order_relaxed); n_coarse > 0) {
    std::snprintf(over + over_used, sizeof over - static_cast<std::size_t>(over_used), " coarsened %" PRIu64, n_coarse);
  }
  const int n = std::snprintf(
      out, size,
      "status: fps in %.1f foveated %.1f out %.1f | drops capture %" PRIu64 " foveation %" PRIu64
      "%s | ms p50/p99 capture %s foveate %s send %s | wire %.2f MB/s | gaze age %s%s%s%s | memory %.1f MiB"
      " | lines heartbeat %s streaming %d fault %d | usb %s",
      static_cast<double>(w.captured - window_.captured) / dt_s, static_cast<double>(w.foveated - window_.foveated) / dt_s,
      static_cast<double>(w.sent - window_.sent) / dt_s, w.capture_drops - window_.capture_drops,
      w.foveation_drops - window_.foveation_drops, over, latency[0], latency[1], latency[2],
      static_cast<double>(w.wire_bytes - window_.wire_bytes) / dt_s / 1e6, gaze_age,
      status_lines_->state().privacy_active ? " | privacy pause" : "", pose, map,
      static_cast<double>(memory_.totalBytes()) / kMiB,
      // The heartbeat's level changes every half period: report whether it toggles.
      heartbeat_toggles_.load(std::memory_order_relaxed) != window_heartbeat_toggles_ ? "toggling" : "held",
      status_lines_->state().streaming ? 1 : 0, status_lines_->state().fault ? 1 : 0, usb);
  window_heartbeat_toggles_ = heartbeat_toggles_.load(std::memory_order_relaxed);
  window_ = w;
  return n < 0 ? 0 : std::min(static_cast<std::size_t>(n), size - 1);
}

// Each histogram's counts since the previous status line (its snapshot less
// the previous one, which it then replaces), as "p50/p99" in ms.
void Service::formatWindowLatencies(LatencyTexts& text) {
  const LatencyHistogram* histograms[4] = {&capture_latency_, &foveate_latency_, &send_latency_, &fuse_latency_};
  for (int i = 0; i < 4; ++i) {
    histograms[i]->snapshot(histogram_scratch_.get());
    uint64_t* previous = histogram_previous_[i].get();
    for (std::size_t b = 0; b < LatencyHistogram::kBuckets; ++b) {
      const uint64_t now_count = histogram_scratch_[b];
      histogram_scratch_[b] = now_count - previous[b];
      previous[b] = now_count;
    }
    const double p50 = histogramQuantileMs(histogram_scratch_.get(), LatencyHistogram::kBuckets, 0.5);
    const double p99 = histogramQuantileMs(histogram_scratch_.get(), LatencyHistogram::kBuckets, 0.99);
    if (p50 < 0) {
      std::snprintf(text[i], sizeof text[i], "-");
    } else {
      std::snprintf(text[i], sizeof text[i], "%.1f/%.1f", p50, p99);
    }
  }
}

// The pose source's part (a socket source) and the tracker's (when tracking);
// empty with neither.
void Service::formatPoseFields(char* out, std::size_t size) const {
  int used = 0;
  if (pose_source_->config().kind == hal::PoseSourceConfig::Kind::kSocket) {
    const hal::PoseCounters pc = pose_source_->counters();
    used = std::snprintf(out, size, " | pose %s, %" PRIu64 " stale frames", pose_stale_.load() ? "STALE" : "fresh",
                         pc.frames_stale);
  }
  if (tracking_ && used >= 0 && static_cast<std::size_t>(used) < size) {
    // "pose LOST" while lost: what an operator greps for.
    std::snprintf(out + used, size - static_cast<std::size_t>(used),
                  " | pose %s, track %.1f ms, model %.1f ms, moving %.1f %%, lost %" PRIu64
                  " frames, relocalised %" PRIu64 ", prior off by %.1f cm",
                  tracking_lost_.load(std::memory_order_relaxed) ? "LOST" : "tracked",
                  static_cast<double>(track_ns_.load(std::memory_order_relaxed)) * 1e-6,
                  static_cast<double>(model_ns_.load(std::memory_order_relaxed)) * 1e-6,
                  moving_share_.load(std::memory_order_relaxed) * 100.0,
                  frames_track_lost_.load(std::memory_order_relaxed), frames_relocalised_.load(std::memory_order_relaxed),
                  prior_disagreement_m_.load(std::memory_order_relaxed) * 100.0);
  }
}

// The map: its size, this window's fusion time, and since start the surfels
// evicted, the new surfels dropped (pool or brick table full) and the frames
// refused (no pose; anything else); with a time budget, the frames it left
// unfused; with a fusion thread, those it was busy for; with bricks, their
// versions and the frames planned while the last batch was still out.
// Empty without a map.
void Service::formatMapFields(const char* fuse_latency, char* out, std::size_t size) const {
  if (stage_->map() == nullptr) return;
  int used = std::snprintf(
      out, size,
      " | map %" PRIu64 " surfels, fuse %s ms, evicted %" PRIu64 ", dropped %" PRIu64 ", refused %" PRIu64
      " no pose %" PRIu64 " other",
      map_surfels_.load(std::memory_order_relaxed), fuse_latency, map_evicted_.load(std::memory_order_relaxed),
      map_dropped_.load(std::memory_order_relaxed),
      map_refused_no_pose_.load(std::memory_order_relaxed), map_refused_other_.load(std::memory_order_relaxed));
  if (stage_->fusionThread()) appendUnfused(out, size, used, map_fusion_busy_.load(std::memory_order_relaxed), "busy");
  if (stage_->hasFusionBudget()) {
    appendUnfused(out, size, used, map_fusion_skipped_.load(std::memory_order_relaxed), "budget");
  }
  if (map_bricks_ && used > 0 && static_cast<std::size_t>(used) < size) {
    std::snprintf(out + used, size - static_cast<std::size_t>(used),
                  ", brick versions %" PRIu64 " sent %" PRIu64 " acknowledged %" PRIu64 " lost %" PRIu64
                  " unstaged %" PRIu64 " deferred",
                  brick_versions_.load(std::memory_order_relaxed), brick_versions_done_.load(std::memory_order_relaxed),
                  brick_versions_lost_.load(std::memory_order_relaxed), bricks_unstaged_.load(std::memory_order_relaxed),
                  brick_plans_deferred_.load(std::memory_order_relaxed));
  }
}

}  // namespace fovea::firmware

#include "tools/operator/operator_stats.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "pipeline/quantile.h"

namespace fovea::tools {

double quantile(std::vector<double> samples, double q) {
  return samples.empty() ? std::numeric_limits<double>::quiet_NaN() : pipeline::nearestRankQuantile(samples, q);
}

void OperatorStats::add(Tally& t, const FrameObservation& f) {
  t.frames += 1;
  t.chunks_received += f.chunks_received;
  t.chunks_expected += f.chunks_expected;
  for (std::size_t r = 0; r < f.points_per_region.size(); ++r) t.points[r] += f.points_per_region[r];
  if (!std::isnan(f.latency_ms)) t.latency_ms.push_back(f.latency_ms);  // NaN: not known
  if (!std::isnan(f.fovea_latency_ms)) t.fovea_latency_ms.push_back(f.fovea_latency_ms);
}

void OperatorStats::frame(const FrameObservation& f) {
  add(window_, f);
  add(total_, f);
}

namespace {

std::string jsonNumber(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

}  // namespace

LiveFigures OperatorStats::takeWindow(double seconds) {
  const double s = seconds > 0 ? seconds : 1.0;
  LiveFigures f;
  f.fps = static_cast<double>(window_.frames) / s;
  f.wire_mb_per_s = static_cast<double>(window_.wire_bytes) / s / 1e6;
  f.latency_p50_ms = quantile(window_.latency_ms, 0.5);
  f.latency_p99_ms = quantile(window_.latency_ms, 0.99);
  f.lost = window_.lost;
  for (std::size_t r = 0; r < window_.points.size(); ++r) {
    f.points_per_region[r] = window_.frames ? window_.points[r] / window_.frames : 0;
    f.points_per_frame += window_.points[r];
  }
  f.points_per_frame = window_.frames ? f.points_per_frame / window_.frames : 0;
  window_ = Tally{};
  return f;
}

std::string liveLine(const LiveFigures& f) {
  char line[512];
  int n = std::snprintf(line, sizeof line,
                        "fps %5.1f | %6.2f MB/s | latency ms p50 %6.1f p99 %6.1f | lost %llu | points/frame %llu:", f.fps,
                        f.wire_mb_per_s, f.latency_p50_ms, f.latency_p99_ms, static_cast<unsigned long long>(f.lost),
                        static_cast<unsigned long long>(f.points_per_frame));
  std::string out(line, static_cast<std::size_t>(std::max(n, 0)));
  for (std::size_t r = 0; r < f.points_per_region.size(); ++r) {
    if (f.points_per_region[r] == 0) continue;
    std::snprintf(line, sizeof line, " r%zu=%llu", r, static_cast<unsigned long long>(f.points_per_region[r]));
    out += line;
  }
  return out;
}

std::string OperatorStats::summaryJson(double seconds, const std::string& extra) const {
  const double s = seconds > 0 ? seconds : 1.0;
  std::string j = "{\n";
  if (!extra.empty()) j += "  " + extra + ",\n";
  j += "  \"duration_s\": " + jsonNumber(seconds) + ",\n";
  j += "  \"frames\": " + std::to_string(total_.frames) + ",\n";
  j += "  \"fps\": " + jsonNumber(static_cast<double>(total_.frames) / s) + ",\n";
  j += "  \"datagrams\": " + std::to_string(total_.datagrams) + ",\n";
  j += "  \"datagrams_lost\": " + std::to_string(total_.lost) + ",\n";
  j += "  \"wire_bytes\": " + std::to_string(total_.wire_bytes) + ",\n";
  j += "  \"wire_mb_per_s\": " + jsonNumber(static_cast<double>(total_.wire_bytes) / s / 1e6) + ",\n";
  j += "  \"ip_udp_bytes\": " + std::to_string(total_.ip_bytes) + ",\n";
  j += "  \"ip_udp_mb_per_s\": " + jsonNumber(static_cast<double>(total_.ip_bytes) / s / 1e6) + ",\n";
  j += "  \"chunks_received\": " + std::to_string(total_.chunks_received) + ",\n";
  j += "  \"chunks_expected\": " + std::to_string(total_.chunks_expected) + ",\n";
  j += "  \"latency_ms\": {\"p50\": " + jsonNumber(quantile(total_.latency_ms, 0.5)) +
       ", \"p99\": " + jsonNumber(quantile(total_.latency_ms, 0.99)) +
       ", \"max\": " + jsonNumber(quantile(total_.latency_ms, 1.0)) + "},\n";
  // Capture to the fovea's chunks decoded (fovea-operator --frame-log: fovea_latency_us).
  j += "  \"fovea_latency_ms\": {\"p50\": " + jsonNumber(quantile(total_.fovea_latency_ms, 0.5)) +
       ", \"p99\": " + jsonNumber(quantile(total_.fovea_latency_ms, 0.99)) +
       ", \"max\": " + jsonNumber(quantile(total_.fovea_latency_ms, 1.0)) + "},\n";
  j += "  \"points_per_frame_by_region\": [";
  for (std::size_t r = 0; r < total_.points.size(); ++r) {
    j += (r ? ", " : "") + jsonNumber(total_.frames ? static_cast<double>(total_.points[r]) / static_cast<double>(total_.frames) : 0.0);
  }
  j += "]\n}\n";
  return j;
}

}  // namespace fovea::tools

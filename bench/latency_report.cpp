// fovea-latency-report: a frame's trip stage by stage, p50 and p99 over every
// frame (the first second included) and over the first second alone, from one
// run of `fovead serve --timing-log TIMING.csv` and `fovea-operator --frame-log
// FRAMES.csv` on one host (toolchain/run-latency runs both and calls this).
// Frames are joined by frame id; a frame the operator did not decode has no
// end-to-end figure but keeps its robot-side stages. Nothing is timed here: the
// figures are what the two programs logged (one host's CLOCK_MONOTONIC).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "pipeline/quantile.h"
#include "tools/eval/csv_table.h"

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double number(const std::string& s) {
  if (s.empty()) return kNaN;
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  return end == s.c_str() + s.size() ? v : kNaN;
}

struct Frame {
  double captured_ns = kNaN;
  double bytes_sent = 0.0;
  std::map<std::string, double> ms;  // stage -> milliseconds
};

struct Stage {
  const char* key;
  const char* title;
};

// In the frame's order; "acquire" waits for the camera and comes before capture.
const Stage kStages[] = {
    {"acquire", "capture (camera acquire; before the stamp)"},
    {"queue", "queue to foveation"},
    {"backproject", "foveate: back-projection"},
    {"partition", "foveate: partition / levels"},
    {"sample", "foveate: sampling"},
    {"foveate", "foveate (queue + the three above)"},
    {"handoff", "queue to sending"},
    {"encode", "encode"},
    {"send", "send (pacing, to the frame summary)"},
    {"to_sent", "capture to end of sending"},
    {"decode", "network, receive and decode"},
    {"fovea", "capture to fovea decoded"},
    {"frame", "capture to frame decoded"},
};

double quantile(std::vector<double> v, double q) {
  return v.empty() ? kNaN : fovea::pipeline::nearestRankQuantile(v, q);
}

void printTable(const char* title, const std::vector<const Frame*>& frames) {
  std::printf("%s: %zu frames\n", title, frames.size());
  std::printf("  %-44s %8s %8s %8s %6s\n", "stage [ms]", "p50", "p99", "max", "n");
  for (const Stage& st : kStages) {
    std::vector<double> v;
    for (const Frame* f : frames) {
      const auto it = f->ms.find(st.key);
      if (it != f->ms.end() && std::isfinite(it->second)) v.push_back(it->second);
    }
    if (v.empty()) {
      std::printf("  %-44s %8s %8s %8s %6d\n", st.title, "-", "-", "-", 0);
      continue;
    }
    std::printf("  %-44s %8.2f %8.2f %8.2f %6zu\n", st.title, quantile(v, 0.5), quantile(v, 0.99), quantile(v, 1.0),
                v.size());
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr,
                 "usage: fovea-latency-report TIMING.csv FRAMES.csv\n"
                 "  TIMING.csv: fovead serve --timing-log; FRAMES.csv: fovea-operator --frame-log (one host)\n");
    return 2;
  }
  fovea::Result<fovea::tools::CsvTable> robot_read = fovea::tools::readCsvTable(
      argv[1], {"frame_id", "captured_ns", "acquire_us", "queue_us", "backproject_us", "partition_us", "sample_us",
                "handoff_us", "encode_us", "send_us", "captured_to_sent_us"});
  fovea::Result<fovea::tools::CsvTable> op_read = fovea::tools::readCsvTable(argv[2], {"frame_id", "latency_us"});
  for (const fovea::Status& s : {robot_read.status(), op_read.status()}) {
    if (!s.isOk()) {
      std::fprintf(stderr, "fovea-latency-report: %s\n", s.message().c_str());
      return 1;
    }
  }
  const fovea::tools::CsvTable& robot = robot_read.value();
  const fovea::tools::CsvTable& op = op_read.value();
  std::map<std::string, Frame> frames;  // by frame id
  std::vector<std::string> order;
  const auto us = [](const std::vector<std::string>& row, int c) { return number(row[static_cast<std::size_t>(c)]) * 1e-3; };
  for (const auto& row : robot.rows) {
    Frame& f = frames[row[static_cast<std::size_t>(robot.column("frame_id"))]];
    if (f.ms.empty()) order.push_back(row[static_cast<std::size_t>(robot.column("frame_id"))]);
    f.captured_ns = number(row[static_cast<std::size_t>(robot.column("captured_ns"))]);
    if (const int c = robot.column("bytes_sent"); c >= 0) f.bytes_sent = number(row[static_cast<std::size_t>(c)]);
    for (const char* k : {"acquire", "queue", "backproject", "partition", "sample", "handoff", "encode", "send"}) {
      f.ms[k] = us(row, robot.column(std::string(k) + "_us"));
    }
    f.ms["foveate"] = f.ms["queue"] + f.ms["backproject"] + f.ms["partition"] + f.ms["sample"];
    f.ms["to_sent"] = us(row, robot.column("captured_to_sent_us"));
  }
  const int fovea_col = op.column("fovea_latency_us");
  std::size_t decoded = 0;
  for (const auto& row : op.rows) {
    const auto it = frames.find(row[static_cast<std::size_t>(op.column("frame_id"))]);
    if (it == frames.end()) continue;
    Frame& f = it->second;
    ++decoded;
    f.ms["frame"] = us(row, op.column("latency_us"));
    f.ms["decode"] = f.ms["frame"] - f.ms["to_sent"];
    if (fovea_col >= 0) f.ms["fovea"] = us(row, fovea_col);
  }
  if (order.empty()) {
    std::fprintf(stderr, "fovea-latency-report: %s has no frame\n", argv[1]);
    return 1;
  }
  std::vector<const Frame*> all, first_second, after;
  const double first_ns = frames[order.front()].captured_ns;
  for (const std::string& id : order) {
    const Frame& f = frames[id];
    all.push_back(&f);
    (f.captured_ns - first_ns < 1e9 ? first_second : after).push_back(&f);
  }
  std::printf("frames sent %zu, decoded by the operator %zu (joined by frame id)\n", all.size(), decoded);
  // The uplink over any second: the bytes of the frames captured within one
  // second of each frame's capture (datagram bytes, summaries included).
  double max_window = 0.0, total = 0.0;
  for (std::size_t i = 0, j = 0; i < all.size(); ++i) {
    total += all[i]->bytes_sent;
    double window = 0.0;
    for (j = i; j < all.size() && all[j]->captured_ns - all[i]->captured_ns < 1e9; ++j) window += all[j]->bytes_sent;
    if (all.back()->captured_ns - all[i]->captured_ns >= 1e9) max_window = std::max(max_window, window);
  }
  const double span_s = (all.back()->captured_ns - all.front()->captured_ns) * 1e-9;
  std::printf("uplink: %.2f MB/s over the run, at most %.2f MB in any second of frames\n\n",
              span_s > 0 ? total / span_s * 1e-6 : kNaN, max_window * 1e-6);
  printTable("every frame sent (the first second included)", all);
  std::printf("\n");
  printTable("the first second", first_second);
  std::printf("\n");
  printTable("after the first second", after);
  return 0;
}

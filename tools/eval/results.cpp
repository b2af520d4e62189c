#include "tools/eval/results.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <sstream>

#include "pipeline/quantile.h"
#include "tools/eval/csv_table.h"
#include "tools/common/nan.h"
#include "tools/eval/statistics.h"

namespace fovea::tools::eval {

namespace {

bool parseNumber(const std::string& s, double& out) {
  if (s.empty()) return false;
  char* end = nullptr;
  out = std::strtod(s.c_str(), &end);
  return end == s.c_str() + s.size() && std::isfinite(out);
}

// Nearest rank (pipeline/quantile.h) of a copy; NaN when there are no values.
double quantile(std::vector<double> v, double q) { return v.empty() ? kNaN : pipeline::nearestRankQuantile(v, q); }

std::string number(double v, int precision = 4) {
  if (!std::isfinite(v)) return "";
  std::ostringstream o;
  o.precision(precision);
  o << std::fixed << v;
  return o.str();
}

}  // namespace

Result<RunResult> readRun(const std::string& dir, int frames) {
  using R = Result<RunResult>;
  static const std::vector<std::string> kRobot = {"frame_id", "captured_ns", "acquire_us", "queue_us", "backproject_us",
                                                  "partition_us", "sample_us", "handoff_us", "encode_us", "send_us",
                                                  "captured_to_sent_us", "points_out", "chunks_sent", "bytes_sent",
                                                  "completed"};
  static const std::vector<std::string> kOperator = {"frame_id", "latency_us"};
  Result<CsvTable> robot = readCsvTable(dir + "/timing.csv", kRobot);
  if (!robot) return robot.status();
  Result<CsvTable> op = readCsvTable(dir + "/frames.csv", kOperator);
  if (!op) return op.status();
  std::map<long long, std::size_t> by_id;
  const int id_col = robot->column("frame_id");
  for (std::size_t i = 0; i < robot->rows.size(); ++i) {
    double id;
    if (parseNumber(robot->rows[i][id_col], id)) by_id[static_cast<long long>(id)] = i;
  }
  RunResult r;
  double bytes = 0.0, points = 0.0;
  double first_captured = kNaN, last_captured = kNaN, first_id = 0.0, last_id = 0.0;
  const int op_id = op->column("frame_id"), op_latency = op->column("latency_us");
  for (const auto& row : op->rows) {
    if (r.frames >= frames) break;
    double id, latency_us;
    if (!parseNumber(row[op_id], id) || !parseNumber(row[op_latency], latency_us)) continue;  // latency unknown
    auto it = by_id.find(static_cast<long long>(id));
    if (it == by_id.end()) continue;
    const std::vector<std::string>& t = robot->rows[it->second];
    std::array<double, kStageCount - 1> us{};
    double v[6];
    bool ok = true;
    for (std::size_t s = 0; s + 1 < kStageCount && ok; ++s) {
      ok = parseNumber(t[robot->column(std::string(kStageNames[s]) + "_us")], us[s]);
    }
    const char* extra[6] = {"captured_ns", "captured_to_sent_us", "points_out", "chunks_sent", "bytes_sent", "completed"};
    for (int k = 0; k < 6 && ok; ++k) ok = parseNumber(t[robot->column(extra[k])], v[k]);
    if (!ok) return R(ErrorCode::kParseError, dir + "/timing.csv: frame " + row[op_id] + ": a field is not a number");
    for (std::size_t s = 0; s + 1 < kStageCount; ++s) r.stage_ms[s].push_back(us[s] * 1e-3);
    r.stage_ms[kStageCount - 1].push_back(std::max(0.0, (latency_us - v[1]) * 1e-3));
    r.end_to_end_ms.push_back(latency_us * 1e-3);
    points += v[2];
    // Each chunk and the frame summary is one datagram.
    bytes += v[4] + kIpUdpHeaderBytes * (v[3] + 1.0);
    if (v[5] == 0.0) ++r.incomplete;
    if (r.frames == 0) first_captured = v[0], first_id = id;
    last_captured = v[0], last_id = id;
    ++r.frames;
  }
  // The operator's datagram counts, from its summary's "datagrams": N and "datagrams_lost": N.
  {
    std::ifstream in(dir + "/summary.json");
    const std::string json((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const auto field = [&](const std::string& name) -> long {
      const std::size_t at = json.find("\"" + name + "\": ");
      return at == std::string::npos ? -1 : std::strtol(json.c_str() + at + name.size() + 4, nullptr, 10);
    };
    r.datagrams = field("datagrams");
    r.datagrams_lost = field("datagrams_lost");
    if (r.datagrams < 0 || r.datagrams_lost < 0) return R(ErrorCode::kParseError, dir + "/summary.json: no datagram counts");
  }
  if (r.frames < 2) {
    return R(ErrorCode::kNotFound, dir + ": " + std::to_string(r.frames) + " frames both logged and decoded (need 2)");
  }
  r.bytes_per_frame = bytes / r.frames;
  r.points_per_frame = points / r.frames;
  // The camera's rate over those frames: frame ids are its sequence numbers (a frame
  // the operator missed still took its interval).
  r.frames_per_s = (last_id - first_id) / ((last_captured - first_captured) * 1e-9);
  r.mb_per_s = r.bytes_per_frame * r.frames_per_s / 1e6;
  return r;
}

std::string runCsvHeader() {
  std::string h = "dataset,condition,position,frames,bytes_per_frame,frames_per_s,mb_per_s,points_per_frame,incomplete,"
                  "latency_mean_ms,latency_p99_ms,datagrams,datagrams_lost";
  for (const char* s : kStageNames) h += std::string(",") + s + "_mean_ms";
  return h + "\n";
}

std::string runCsvLine(const RunResult& r) {
  std::string l = r.dataset + "," + r.condition + "," + std::to_string(r.position) + "," + std::to_string(r.frames) + "," +
                  number(r.bytes_per_frame, 1) + "," + number(r.frames_per_s, 3) + "," + number(r.mb_per_s) + "," +
                  number(r.points_per_frame, 1) + "," + std::to_string(r.incomplete) + "," + number(mean(r.end_to_end_ms)) +
                  "," + number(quantile(r.end_to_end_ms, 0.99)) + "," + std::to_string(r.datagrams) + "," +
                  std::to_string(r.datagrams_lost);
  for (const auto& s : r.stage_ms) l += "," + number(mean(s));
  return l + "\n";
}

std::vector<ConditionSummary> summarise(const std::vector<RunResult>& runs) {
  std::vector<ConditionSummary> out;
  for (const RunResult& r : runs) {
    auto it = std::find_if(out.begin(), out.end(), [&](const ConditionSummary& c) {
      return c.dataset == r.dataset && c.condition == r.condition;
    });
    if (it == out.end()) {
      out.push_back({});
      it = out.end() - 1;
      it->dataset = r.dataset;
      it->condition = r.condition;
    }
    it->positions += 1;
    it->frames += r.frames;
    it->mb_per_s.push_back(r.mb_per_s);
    it->latency_ms.push_back(mean(r.end_to_end_ms));
    it->points_per_frame += r.points_per_frame;
    it->incomplete += r.incomplete;
    it->datagrams += r.datagrams;
    it->datagrams_lost += r.datagrams_lost;
  }
  for (ConditionSummary& c : out) {
    std::vector<double> latency;
    std::array<std::vector<double>, kStageCount> stages;
    for (const RunResult& r : runs) {
      if (r.dataset != c.dataset || r.condition != c.condition) continue;
      latency.insert(latency.end(), r.end_to_end_ms.begin(), r.end_to_end_ms.end());
      for (std::size_t s = 0; s < kStageCount; ++s) stages[s].insert(stages[s].end(), r.stage_ms[s].begin(), r.stage_ms[s].end());
    }
    c.points_per_frame /= std::max(1, c.positions);
    c.mb_per_s_mean = mean(c.mb_per_s);
    c.mb_per_s_sd = sampleStdDev(c.mb_per_s);
    c.latency_mean_ms = mean(c.latency_ms);
    c.latency_sd_ms = sampleStdDev(c.latency_ms);
    c.latency_p99_ms = quantile(latency, 0.99);
    for (std::size_t s = 0; s < kStageCount; ++s) {
      c.stage_mean_ms[s] = mean(stages[s]);
      c.stage_p99_ms[s] = quantile(stages[s], 0.99);
    }
  }
  for (ConditionSummary& c : out) {
    auto ref = std::find_if(out.begin(), out.end(), [&](const ConditionSummary& x) {
      return x.dataset == c.dataset && x.condition == "FREF";
    });
    if (ref == out.end() || c.condition == "FREF") {
      c.bandwidth_reduction = c.latency_reduction = c.bandwidth_p = c.latency_p = kNaN;
      continue;
    }
    c.bandwidth_reduction = 100.0 * (1.0 - c.mb_per_s_mean / ref->mb_per_s_mean);
    c.latency_reduction = 100.0 * (1.0 - c.latency_mean_ms / ref->latency_mean_ms);
    c.bandwidth_p = welchTTest(c.mb_per_s, ref->mb_per_s).p;
    c.latency_p = welchTTest(c.latency_ms, ref->latency_ms).p;
  }
  return out;
}

}  // namespace fovea::tools::eval

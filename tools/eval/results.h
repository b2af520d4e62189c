// fovea-eval's measurements: one run (a dataset, a condition, an HMD position)
// read back from the service's timing log and the operator's frame log, and the
// tables made from all runs (docs/eval.md says what each column means).
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <vector>

#include "core/result.h"

namespace fovea::tools::eval {

// The stages of a frame's trip, in order: fovead serve --timing-log's columns and,
// last, what the operator adds (the network, receiving and decoding: capture to
// decoded minus capture to the end of sending, both on the one host's clock).
inline constexpr std::size_t kStageCount = 9;
inline constexpr std::array<const char*, kStageCount> kStageNames = {
    "acquire", "queue", "backproject", "partition", "sample", "handoff", "encode", "send", "receive_decode"};
inline constexpr std::array<const char*, kStageCount> kStageTitles = {
    "capture (acquire)", "queue to foveation", "back-projection", "partition / levels", "sampling",
    "queue to sending", "encoding", "pacing and sending", "network, receive and decode"};

// What a packet capture adds to each UDP payload on IPv4 (loopback): IP and UDP headers.
inline constexpr double kIpUdpHeaderBytes = 28.0;

struct RunResult {
  std::string dataset, condition;
  int position = 0;
  int frames = 0;                 // frames used (the first ones decoded)
  double bytes_per_frame = 0.0;   // at the robot's socket: payloads plus IP and UDP headers
  double frames_per_s = 0.0;      // the capture rate over those frames
  double mb_per_s = 0.0;          // bytes_per_frame x frames_per_s / 1e6
  double points_per_frame = 0.0;  // sent by the robot
  int incomplete = 0;             // frames whose sending hit the deadline
  long datagrams = 0, datagrams_lost = 0;  // the operator's whole session (summary.json)
  std::vector<double> end_to_end_ms;                   // capture to decoded, per frame
  std::array<std::vector<double>, kStageCount> stage_ms;  // per frame
};

// Reads runs/<name>/timing.csv and frames.csv: the first `frames` frames the
// operator decoded that the service logged; and the datagrams received and lost
// from summary.json. Errors name the file.
Result<RunResult> readRun(const std::string& dir, int frames);

// A run's figures as one CSV line (and the header), for runs.csv.
std::string runCsvHeader();
std::string runCsvLine(const RunResult& r);

// One row of the table: a dataset and condition over its positions.
struct ConditionSummary {
  std::string dataset, condition;
  int positions = 0;
  int frames = 0;
  std::vector<double> mb_per_s;         // per position
  std::vector<double> latency_ms;       // per position (the mean of its frames)
  double mb_per_s_mean = 0.0, mb_per_s_sd = 0.0;
  double latency_mean_ms = 0.0, latency_sd_ms = 0.0;  // over positions
  double latency_p99_ms = 0.0;                        // over every frame
  std::array<double, kStageCount> stage_mean_ms{}, stage_p99_ms{};
  double points_per_frame = 0.0;
  int incomplete = 0;
  long datagrams = 0, datagrams_lost = 0;
  // Against FREF of the same dataset (NaN for FREF itself or without it).
  double bandwidth_reduction = 0.0, latency_reduction = 0.0;  // percent
  double bandwidth_p = 0.0, latency_p = 0.0;                  // Welch's t-test across positions
};
std::vector<ConditionSummary> summarise(const std::vector<RunResult>& runs);

}  // namespace fovea::tools::eval

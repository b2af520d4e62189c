// fovea-compare's rows as they run: made from the table, timed in rounds, their
// errors measured afterwards.
#include "bench/compare_rows.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>

namespace fovea::bench::compare {
namespace {

double medianMs(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

void finish(Method& method, Timing& t) {
  t.ran = true;
  t.median = medianMs(t.ms);
  t.min = *std::min_element(t.ms.begin(), t.ms.end());
  t.max = *std::max_element(t.ms.begin(), t.ms.end());
  t.out_points = method.outputSize();
  t.has_output = method.output(t.output);
}

}  // namespace

std::vector<Row> makeRows(const Input& input, const std::string& only_methods) {
  std::vector<Row> rows;
  for (const MethodEntry& entry : methodTable()) {
    // Rows not asked for are not listed either.
    if (!only_methods.empty() && only_methods.find(std::string(",") + entry.name + ",") == std::string::npos) continue;
    Row& row = rows.emplace_back();
    row.entry = &entry;
    if (entry.make != nullptr) row.method = entry.make(input);
  }
  return rows;
}

int timeRows(std::vector<Row>& rows, int runs) {
  // One warm-up run each (caches, page faults, PCL's first allocations), then the
  // timed runs in rounds, every method once per round: a load change on the
  // machine then affects all methods alike instead of whichever ran at the time.
  for (int round = -1; round < runs; ++round) {
    for (Row& row : rows) {
      if (row.method == nullptr) continue;
      const auto start = std::chrono::steady_clock::now();
      const Status s = row.method->run();
      const auto end = std::chrono::steady_clock::now();
      if (!s) {
        std::fprintf(stderr, "fovea-compare: %s failed: %s\n", row.entry->name, s.toString().c_str());
        return 1;
      }
      if (round >= 0) row.timing.ms.push_back(std::chrono::duration<double, std::milli>(end - start).count());
    }
  }
  for (Row& row : rows) {
    if (row.method != nullptr) finish(*row.method, row.timing);
  }
  return 0;
}

void measureErrors(std::vector<Row>& rows) {
  for (Row& row : rows) {
    pipeline::ErrorMetrics metrics;
    if (row.method != nullptr && row.method->error(metrics)) row.error = metrics;
  }
}

const Timing* findTiming(const std::vector<Row>& rows, std::string_view name) {
  for (const Row& r : rows) {
    if (r.entry->name == name && r.timing.ran) return &r.timing;
  }
  return nullptr;
}

const FoveaMethod* foveaRef(const std::vector<Row>& rows) {
  for (const Row& r : rows) {
    if (r.method != nullptr && std::string_view(r.entry->name) == "fovea-ref") {
      return static_cast<const FoveaMethod*>(r.method.get());
    }
  }
  return nullptr;
}

}  // namespace fovea::bench::compare

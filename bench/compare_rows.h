// fovea-compare's rows as they run: each row's method, its timings and its
// error, and the steps that fill them (make, time in rounds, measure the error).
#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <string_view>
#include <vector>

#include "bench/compare_methods.h"

namespace fovea::bench::compare {

struct Timing {
  std::vector<double> ms;
  double median = 0, min = 0, max = 0;
  std::size_t out_points = 0;
  bool ran = false;
  Output output;
  bool has_output = false;
};

struct Row {
  const MethodEntry* entry = nullptr;
  std::unique_ptr<Method> method;  // null: not built, or not for this input (the pyramid on a cloud)
  Timing timing;
  std::optional<pipeline::ErrorMetrics> error;  // measured after the timing
};

// The rows asked for (only_methods: ",a,b," or empty: every row), each with its
// method made on `input`. Rows not asked for are not listed either.
std::vector<Row> makeRows(const Input& input, const std::string& only_methods);

// One warm-up run each, then `runs` timed rounds; then each row's figures.
// Returns 0, or the exit status 1 after printing which method failed.
int timeRows(std::vector<Row>& rows, int runs);

// The error of each output, after the timing (it runs the method again).
void measureErrors(std::vector<Row>& rows);

// The timing of the row named `name`, if it ran.
const Timing* findTiming(const std::vector<Row>& rows, std::string_view name);

// The fovea-ref row's method, if it was made.
const FoveaMethod* foveaRef(const std::vector<Row>& rows);

}  // namespace fovea::bench::compare

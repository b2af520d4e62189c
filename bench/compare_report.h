// fovea-compare's report: what it prints before the runs (the input, the gaze)
// and after them (the table, the pyramid's cells, what differs from PCL and one
// machine-readable line per method).
#pragma once

#include <vector>

#include "bench/compare_input.h"
#include "bench/compare_options.h"
#include "bench/compare_rows.h"

namespace fovea::bench::compare {

// The input, the SIMD target, the gaze and what is timed.
void printPreamble(const CompareOptions& options, const Input& input);

// Everything after the runs, in order.
void printReport(const std::vector<Row>& rows, const Input& input);

}  // namespace fovea::bench::compare

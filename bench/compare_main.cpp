// fovea-compare: foveation methods side by side, in one process, on the same input.
//
//   fovea-compare [--runs N] [--preset F1|F2|F3|FREF]
//                 [--tum PATH [--frame N] | --ply FILE --gaze-origin X,Y,Z --gaze-dir X,Y,Z]
//
// Input: the mock living-room frame at 640x480 (default), a TUM RGB-D frame, or a
// PLY cloud. Each method runs once to warm up, then --runs times (default 20);
// every run is timed from the depth image to the sampled output (for a PLY input,
// from the cloud). The methods are rows of the table in compare_methods.cpp.
//
// The parts: the command line (compare_options), the input (compare_input), the
// methods (compare_methods), the rows as they run (compare_rows), the comparison
// against PCL (compare_against_pcl) and the report (compare_report).
#include <optional>
#include <vector>

#include "bench/compare_input.h"
#include "bench/compare_options.h"
#include "bench/compare_report.h"
#include "bench/compare_rows.h"

namespace fovea::bench::compare {
namespace {

int run(int argc, char** argv) {
  CompareOptions options;
  if (std::optional<int> stop = parseOptions(argc, argv, options)) return *stop;
  Input input;
  if (int status = loadInput(options, input); status != 0) return status;
  printPreamble(options, input);
  std::vector<Row> rows = makeRows(input, options.only_methods);
  if (int status = timeRows(rows, options.runs); status != 0) return status;
  measureErrors(rows);
  printReport(rows, input);
  return 0;
}

}  // namespace
}  // namespace fovea::bench::compare

int main(int argc, char** argv) { return fovea::bench::compare::run(argc, argv); }

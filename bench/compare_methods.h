// fovea-compare's methods: the Method interface every row of the table runs, the
// two methods whose statistics the report prints (FoveaMethod, PyramidMethod),
// and the table of rows (methodTable(); the others live in compare_methods.cpp).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "bench/compare_input.h"
#include "core/kernel_set.h"
#include "pipeline/error_metrics.h"
#include "pipeline/kernels/backprojector.h"
#include "pipeline/pyramid_sampler.h"

namespace fovea::bench::compare {

// A method's output in world coordinates, for the comparison against PCL.
struct Output {
  std::vector<std::array<double, 3>> world;
  std::vector<uint8_t> region;
  std::array<double, pipeline::kMaxRegions> voxel_size_m{};
  int region_count = 0;
};

class Method {
 public:
  virtual ~Method() = default;
  virtual Status run() = 0;  // the timed part
  virtual std::size_t outputSize() const = 0;
  virtual bool output(Output&) const { return false; }  // false: nothing to compare
  // After the timed runs: the error of the output against the full cloud, seen by
  // the fixed observer (pipeline/error_metrics.h, m = 0.022). false: not measured.
  virtual bool error(pipeline::ErrorMetrics&) { return false; }
};

// (ii)/(iii) fovea: back-projection from the depth image (or the given cloud)
// through the foveated output, with the scalar reference kernels or the SIMD
// kernels on `threads` threads. The outputs are identical (docs/kernels.md).
class FoveaMethod final : public Method {
 public:
  // acuity: Preset::kAcuity in place of the input's preset (a different method:
  // its output is not compared with PCL's); kEveryFeature adds the
  // distance-dependent floor (--acuity-floor, 1 mm per m^2 by default), a 5-degree
  // fovea growth and the view cull (drop, the head along the gaze), to time what they
  // cost when on; kFloor only the floor: at 1 mm/m^2, ACUITY at F1's bytes
  // (docs/acuity-levels.md).
  enum class Acuity { kNo, kDefault, kFloor, kEveryFeature, kRefined };
  FoveaMethod(const Input& input, fovea::KernelSet kernels, int threads, Acuity acuity = Acuity::kNo);
  Status run() override;
  std::size_t outputSize() const override { return out_.size(); }
  bool output(Output& o) const override;
  bool error(pipeline::ErrorMetrics& metrics) override;
  const pipeline::FoveationStats& stats() const { return stats_; }
  const uint8_t* regions() const { return foveator_.lastRegions(); }
  const pipeline::PointCloud& cloud() const { return input_.has_frame ? cloud_ : input_.cloud; }

 private:
  static pipeline::FoveationConfig configFor(const Input& input, Acuity acuity);
  static pipeline::Gaze gazeFor(const Input& input, Acuity acuity);
  const Input& input_;
  bool acuity_;
  pipeline::Gaze gaze_;
  std::size_t capacity_;
  pipeline::PointCloud cloud_;
  pipeline::FoveatedCloud out_;
  pipeline::Backprojector backprojector_;
  pipeline::Foveator foveator_;
  pipeline::FoveationStats stats_;
};

// (v) ACUITY on the image pyramid (pipeline/pyramid_sampler.h): approximate, from
// the depth image straight to the output, with ACUITY's knobs (the distance floor
// with kFloor). Frames only: a PLY cloud has no image.
class PyramidMethod final : public Method {
 public:
  PyramidMethod(const Input& input, bool floor);
  Status run() override { return sampler_.sample(input_.frame, input_.range, input_.gaze, rule_, out_, stats_); }
  std::size_t outputSize() const override { return out_.size(); }
  const pipeline::PyramidStats& stats() const { return stats_; }
  bool error(pipeline::ErrorMetrics& metrics) override;

 private:
  static pipeline::FoveationConfig configFor(const Input& input, bool floor);
  const Input& input_;
  pipeline::FoveationConfig config_;
  pipeline::PyramidRule rule_;
  pipeline::PyramidSampler sampler_;
  pipeline::FoveatedCloud out_;
  pipeline::PyramidStats stats_;
};

// The methods, one row each. A row whose make is null is listed as not built.
struct MethodEntry {
  const char* name;
  const char* what;
  std::unique_ptr<Method> (*make)(const Input&);
};

// Every row, in the table's order.
std::span<const MethodEntry> methodTable();

// Threads for the multi-threaded row: every core the process may use.
int allCores();

}  // namespace fovea::bench::compare

// fovea-compare: foveation methods side by side, in one process, on the same input.
//
//   fovea-compare [--runs N] [--preset F1|F2|F3|FREF]
//                 [--tum PATH [--frame N] | --ply FILE --gaze-origin X,Y,Z --gaze-dir X,Y,Z]
//
// Input: the mock living-room frame at 640x480 (default), a TUM RGB-D frame, or a
// PLY cloud. Each method runs once to warm up, then --runs times (default 20);
// every run is timed from the depth image to the sampled output (for a PLY input,
// from the cloud). The methods are rows of the table in makeMethods().
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <string_view>
#include <tuple>
#include <vector>

#include "bench/bench_input.h"
#include "io/ply.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "pipeline/kernels/backprojector.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/error_metrics.h"
#include "pipeline/partition.h"
#include "pipeline/pyramid_sampler.h"
#include "pipeline/voxel_sampler.h"
#ifdef FOVEA_HAVE_PCL
#include "bench/pcl_method.h"
#endif

namespace fovea::bench {
namespace {

using pipeline::PointCloud;

struct Input {
  bool has_frame = false;
  hal::RgbdFrame frame;         // has_frame: the RGB-D frame every method starts from
  PointCloud cloud;             // !has_frame: the PLY cloud every method starts from
  pipeline::Gaze gaze;          // normalised
  pipeline::DepthRange range;   // back-projection range (fovead's default 0.1..10 m)
  pipeline::FoveationConfig config;
  double acuity_floor_per_m2 = 0.001;  // the floor of acuity-floor-simd-1t and acuity-features-simd-1t
  double pyramid_margin = 0.0;         // the pyramid rows' margin (0: ACUITY's level_margin)
  std::string description;
  std::size_t input_points = 0;  // valid points after back-projection (the ns/point denominator)
};

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

// The full cloud of the input (back-projected with the reference) and the
// evaluator, for the error column: computed once, after the timed runs.
struct ErrorInput {
  PointCloud cloud;
  std::optional<pipeline::ErrorEvaluator> evaluator;
};

ErrorInput& errorInput(const Input& input) {
  static ErrorInput e;
  if (!e.evaluator) {
    if (input.has_frame) {
      e.cloud = PointCloud(input.frame.pixelCount());
      pipeline::BackprojectCounts counts;
      (void)pipeline::backprojectRef(input.frame, input.range, e.cloud, counts);
    } else {
      e.cloud = input.cloud;
    }
    e.evaluator.emplace(pipeline::ErrorEvaluator::create(e.cloud.size()).value());
  }
  return e;
}

// (iv) The memory-bandwidth floor: one pass that reads the input images (depth
// and colour; for a PLY input the cloud's x, y, z and colour arrays) and sums
// them. No method that looks at every pixel can be faster.
class FloorMethod final : public Method {
 public:
  explicit FloorMethod(const Input& input) : input_(input) {}
  Status run() override {
    uint64_t sum = 0;
    if (input_.has_frame) {
      const std::size_t n = input_.frame.pixelCount();
      const uint16_t* depth = input_.frame.depth();
      const uint8_t* rgb = input_.frame.rgb();
      for (std::size_t i = 0; i < n; ++i) sum += depth[i];
      for (std::size_t i = 0; i < 3 * n; ++i) sum += rgb[i];
    } else {
      const std::size_t n = input_.cloud.size();
      for (const float* a : {input_.cloud.x(), input_.cloud.y(), input_.cloud.z()}) {
        for (std::size_t i = 0; i < n; ++i) {
          uint32_t bits;
          std::memcpy(&bits, &a[i], sizeof bits);
          sum += bits;
        }
      }
      for (std::size_t i = 0; i < n; ++i) sum += input_.cloud.rgb()[i];
    }
    sink_ = sum;
    return Status::ok();
  }
  std::size_t outputSize() const override { return 0; }

 private:
  const Input& input_;
  volatile uint64_t sink_ = 0;
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
  FoveaMethod(const Input& input, fovea::KernelSet kernels, int threads, Acuity acuity = Acuity::kNo)
      : input_(input),
        acuity_(acuity != Acuity::kNo),
        gaze_(gazeFor(input, acuity)),
        capacity_(input.has_frame ? input.frame.pixelCount() : input.cloud.size()),
        cloud_(input.has_frame ? capacity_ : 0),
        out_(capacity_),
        backprojector_(threads, kernels),
        foveator_(pipeline::Foveator::create({capacity_, capacity_, kernels, threads}, configFor(input, acuity)).value()) {}
  Status run() override {
    const PointCloud* in = &input_.cloud;
    if (input_.has_frame) {
      pipeline::BackprojectCounts counts;
      if (Status s = backprojector_.run(input_.frame, input_.range, cloud_, counts); !s) return s;
      in = &cloud_;
    }
    return foveator_.foveate(*in, gaze_, out_, stats_);
  }
  std::size_t outputSize() const override { return out_.size(); }
  bool output(Output& o) const override {
    if (acuity_) return false;
    o.world.clear();
    o.region.clear();
    for (std::size_t i = 0; i < out_.size(); ++i) {
      const Eigen::Vector3d w = out_.points.world(i);
      o.world.push_back({w.x(), w.y(), w.z()});
      o.region.push_back(out_.region[i]);
    }
    o.region_count = stats_.region_count;
    for (int r = 0; r < stats_.region_count; ++r) o.voxel_size_m[r] = stats_.regions[r].voxel_size_m;
    return true;
  }
  bool error(pipeline::ErrorMetrics& metrics) override {
    ErrorInput& e = errorInput(input_);
    std::vector<uint32_t> representative(e.cloud.size());
    pipeline::FoveatedCloud out(e.cloud.size());
    pipeline::FoveationStats stats;
    if (!foveator_.foveate(e.cloud, gaze_, out, stats, representative.data())) return false;
    pipeline::ErrorModel model;
    model.model = &foveator_.model();
    for (int r = 0; r < stats.region_count; ++r) model.voxel_size_m[r] = stats.regions[r].voxel_size_m;
    return static_cast<bool>(e.evaluator->evaluate(e.cloud, foveator_.lastRegions(), representative.data(),
                                                   out.points, gaze_, model, metrics));
  }
  const pipeline::FoveationStats& stats() const { return stats_; }
  const uint8_t* regions() const { return foveator_.lastRegions(); }
  const PointCloud& cloud() const { return input_.has_frame ? cloud_ : input_.cloud; }

 private:
  static pipeline::FoveationConfig configFor(const Input& input, Acuity acuity) {
    pipeline::FoveationConfig config = input.config;
    if (acuity != Acuity::kNo) config.acuity.preset = pipeline::Preset::kAcuity;
    if (acuity == Acuity::kFloor || acuity == Acuity::kEveryFeature) {
      config.acuity.floor_per_m2 = input.acuity_floor_per_m2;
    }
    if (acuity == Acuity::kEveryFeature) {
      config.acuity.view_cull = pipeline::ViewCull::kDrop;
    }
    if (acuity == Acuity::kRefined) {
      // fovea-eval's ACUITY-REFINED (docs/acuity-levels.md): margin 0.3, one pass.
      config.acuity.level_margin = 0.3;
      config.acuity.refine_passes = 1;
    }
    return config;
  }
  static pipeline::Gaze gazeFor(const Input& input, Acuity acuity) {
    pipeline::Gaze gaze = input.gaze;
    if (acuity == Acuity::kEveryFeature) {
      gaze.fovea_growth_deg = 5.0;
      gaze.view_known = true;
      gaze.view_forward = gaze.direction;
    }
    return gaze;
  }
  const Input& input_;
  bool acuity_;
  pipeline::Gaze gaze_;
  std::size_t capacity_;
  PointCloud cloud_;
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
  PyramidMethod(const Input& input, bool floor)
      : input_(input),
        config_(configFor(input, floor)),
        rule_(pipeline::PyramidRule::fromAcuity(config_.acuity)),
        sampler_(pipeline::PyramidSampler::create(input.frame.width(), input.frame.height()).value()),
        out_(input.frame.pixelCount()) {}
  Status run() override { return sampler_.sample(input_.frame, input_.range, input_.gaze, rule_, out_, stats_); }
  std::size_t outputSize() const override { return out_.size(); }
  const pipeline::PyramidStats& stats() const { return stats_; }
  bool error(pipeline::ErrorMetrics& metrics) override {
    ErrorInput& e = errorInput(input_);
    std::vector<uint32_t> by_pixel(input_.frame.pixelCount());
    if (!sampler_.sample(input_.frame, input_.range, input_.gaze, rule_, out_, stats_, by_pixel.data())) return false;
    // Valid pixels in row-major order are the back-projected cloud's points.
    std::vector<uint32_t> representative;
    for (const uint32_t r : by_pixel) {
      if (r != pipeline::PyramidSampler::kNoRepresentative) representative.push_back(r);
    }
    if (representative.size() != e.cloud.size()) return false;
    const std::vector<uint8_t> region(e.cloud.size(), 0);  // no regions: the pooled figures are the measure
    auto model = pipeline::RegionModel::create(config_.acuity);
    if (!model) return false;
    pipeline::ErrorModel error_model;
    error_model.model = &model.value();
    return static_cast<bool>(e.evaluator->evaluate(e.cloud, region.data(), representative.data(), out_.points,
                                                   input_.gaze, error_model, metrics));
  }

 private:
  static pipeline::FoveationConfig configFor(const Input& input, bool floor) {
    pipeline::FoveationConfig config = input.config;
    config.acuity.preset = pipeline::Preset::kAcuity;
    if (floor) config.acuity.floor_per_m2 = input.acuity_floor_per_m2;
    if (input.pyramid_margin > 0.0) config.acuity.level_margin = input.pyramid_margin;
    return config;
  }
  const Input& input_;
  pipeline::FoveationConfig config_;
  pipeline::PyramidRule rule_;
  pipeline::PyramidSampler sampler_;
  pipeline::FoveatedCloud out_;
  pipeline::PyramidStats stats_;
};

// Threads for the multi-threaded row: every core the process may use.
int allCores() { return std::max(1, static_cast<int>(std::thread::hardware_concurrency())); }

#ifdef FOVEA_HAVE_PCL
// (i) The paper's method with PCL: back-projection (fovea's; PCL has no depth
// image converter outside its grabbers), partition (fovea's partitionRef), then
// one pcl::VoxelGrid per region with leaf = fovea's voxel size; fovea untouched.
class PclMethod final : public Method {
 public:
  explicit PclMethod(const Input& input)
      : input_(input),
        capacity_(input.has_frame ? input.frame.pixelCount() : input.cloud.size()),
        cloud_(input.has_frame ? capacity_ : 0),
        pcl_(capacity_, input.config) {}
  Status run() override {
    const PointCloud* in = &input_.cloud;
    if (input_.has_frame) {
      pipeline::BackprojectCounts counts;
      if (Status s = pipeline::backprojectRef(input_.frame, input_.range, cloud_, counts); !s) return s;
      in = &cloud_;
    }
    return pcl_.run(*in, input_.gaze);
  }
  std::size_t outputSize() const override { return pcl_.outputSize(); }
  bool output(Output& o) const override {
    pcl_.output(o.world, o.region);
    o.region_count = pcl_.regionCount();
    o.voxel_size_m = pcl_.voxelSizes();
    return true;
  }

 private:
  const Input& input_;
  std::size_t capacity_;
  PointCloud cloud_;
  PclFoveation pcl_;
};
#endif

// The methods, one row each. A row whose make is null is listed as not built.
struct MethodEntry {
  const char* name;
  const char* what;
  std::unique_ptr<Method> (*make)(const Input&);
};

const MethodEntry kMethods[] = {
#ifdef FOVEA_HAVE_PCL
    {"pcl", "paper's method: fovea partition + one pcl::VoxelGrid per region",
     [](const Input& in) -> std::unique_ptr<Method> { return std::make_unique<PclMethod>(in); }},
#else
    {"pcl", "paper's method with PCL (not built: PCL not found, FOVEA_WITH_PCL)", nullptr},
#endif
    {"fovea-ref", "fovea scalar reference kernels: backprojectRef, partitionRef, radix-sort sampler",
     [](const Input& in) -> std::unique_ptr<Method> {
       return std::make_unique<FoveaMethod>(in, fovea::KernelSet::kRef, 1);
     }},
    {"fovea-simd-1t", "fovea SIMD kernels (Highway) and hash sampler, one thread",
     [](const Input& in) -> std::unique_ptr<Method> {
       return std::make_unique<FoveaMethod>(in, fovea::KernelSet::kSimd, 1);
     }},
    {"fovea-simd-mt", "fovea SIMD kernels and hash sampler, one thread per core",
     [](const Input& in) -> std::unique_ptr<Method> {
       return std::make_unique<FoveaMethod>(in, fovea::KernelSet::kSimd, allCores());
     }},
    {"acuity-simd-1t", "ACUITY (docs/acuity-levels.md): SIMD levels and hash sampler, one thread",
     [](const Input& in) -> std::unique_ptr<Method> {
       return std::make_unique<FoveaMethod>(in, fovea::KernelSet::kSimd, 1, FoveaMethod::Acuity::kDefault);
     }},
    {"acuity-floor-simd-1t",
     "ACUITY with the distance floor (--acuity-floor; 1 mm/m^2: F1's bytes on the mock room), one thread",
     [](const Input& in) -> std::unique_ptr<Method> {
       return std::make_unique<FoveaMethod>(in, fovea::KernelSet::kSimd, 1, FoveaMethod::Acuity::kFloor);
     }},
    {"acuity-features-simd-1t",
     "ACUITY with the distance floor (--acuity-floor), a 5-degree fovea growth and the view cull (drop), one thread",
     [](const Input& in) -> std::unique_ptr<Method> {
       return std::make_unique<FoveaMethod>(in, fovea::KernelSet::kSimd, 1, FoveaMethod::Acuity::kEveryFeature);
     }},
    {"acuity-refined-simd-1t",
     "ACUITY refined (margin 0.3, one refinement pass: fovea-eval's ACUITY-REFINED), one thread",
     [](const Input& in) -> std::unique_ptr<Method> {
       return std::make_unique<FoveaMethod>(in, fovea::KernelSet::kSimd, 1, FoveaMethod::Acuity::kRefined);
     }},
    {"acuity-pyramid-1t",
     "ACUITY on the image pyramid (approximate; pipeline/pyramid_sampler.h), one thread; frames only",
     [](const Input& in) -> std::unique_ptr<Method> {
       if (!in.has_frame) return nullptr;
       return std::make_unique<PyramidMethod>(in, false);
     }},
    {"acuity-pyramid-floor-1t",
     "the same with the distance floor (--acuity-floor)",
     [](const Input& in) -> std::unique_ptr<Method> {
       if (!in.has_frame) return nullptr;
       return std::make_unique<PyramidMethod>(in, true);
     }},
    {"floor", "memory-bandwidth floor: one pass summing the depth and colour images",
     [](const Input& in) -> std::unique_ptr<Method> { return std::make_unique<FloorMethod>(in); }},
};

struct Timing {
  std::vector<double> ms;
  double median = 0, min = 0, max = 0;
  std::size_t out_points = 0;
  bool ran = false;
  Output output;
  bool has_output = false;
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

void finish(Method& method, Timing& t) {
  t.ran = true;
  t.median = median(t.ms);
  t.min = *std::min_element(t.ms.begin(), t.ms.end());
  t.max = *std::max_element(t.ms.begin(), t.ms.end());
  t.out_points = method.outputSize();
  t.has_output = method.output(t.output);
}

// --- Comparison against PCL, voxel by voxel -------------------------------

using VoxelKey = std::tuple<int, int64_t, int64_t, int64_t>;  // region, world voxel index

VoxelKey keyOf(const Output& o, std::size_t i) {
  const int r = o.region[i];
  const double inv = 1.0 / o.voxel_size_m[r];
  return {r, static_cast<int64_t>(std::floor(o.world[i][0] * inv)),
          static_cast<int64_t>(std::floor(o.world[i][1] * inv)), static_cast<int64_t>(std::floor(o.world[i][2] * inv))};
}

struct Difference {
  std::size_t fovea_here = 0, fovea_pcl = 0;  // region-0 points
  std::size_t matched = 0, only_here = 0, only_pcl = 0;
  double max_mm = 0, p99_mm = 0, median_mm = 0;  // all matched voxels (max) / unaffected ones (p99, median)
  std::size_t moved_voxels = 0;    // matched voxels that gained or lost a point to PCL's float lattice
  double moved_max_mm = 0;
  double same_members_max_mm = 0;  // the other matched voxels
  bool same_voxel_sizes = true;
};

// `moved`: voxels (by fovea's key) that gained or lost a point to PCL's float
// lattice; their centroids are reported apart.
Difference compareWithPcl(const Output& here, const Output& pcl, const std::set<VoxelKey>* moved = nullptr) {
  Difference d;
  for (int r = 1; r < here.region_count; ++r) {
    d.same_voxel_sizes = d.same_voxel_sizes && here.voxel_size_m[r] == pcl.voxel_size_m[r];
  }
  std::map<VoxelKey, std::array<double, 3>> pcl_voxels;
  for (std::size_t i = 0; i < pcl.world.size(); ++i) {
    if (pcl.region[i] == 0) {
      ++d.fovea_pcl;
      continue;
    }
    // Two PCL centroids can floor into one voxel when PCL's float lattice
    // disagrees with the double one near a face; the second counts as unmatched.
    if (!pcl_voxels.emplace(keyOf(pcl, i), pcl.world[i]).second) ++d.only_pcl;
  }
  std::vector<double> diffs_mm;
  std::size_t found = 0;
  for (std::size_t i = 0; i < here.world.size(); ++i) {
    if (here.region[i] == 0) {
      ++d.fovea_here;
      continue;
    }
    const auto it = pcl_voxels.find(keyOf(here, i));
    if (it == pcl_voxels.end()) {
      ++d.only_here;
      continue;
    }
    ++found;
    const double dx = here.world[i][0] - it->second[0];
    const double dy = here.world[i][1] - it->second[1];
    const double dz = here.world[i][2] - it->second[2];
    const double mm = 1000.0 * std::sqrt(dx * dx + dy * dy + dz * dz);
    if (moved != nullptr && moved->count(it->first) != 0) {
      ++d.moved_voxels;
      d.moved_max_mm = std::max(d.moved_max_mm, mm);
      d.max_mm = std::max(d.max_mm, mm);
      continue;
    }
    diffs_mm.push_back(mm);
  }
  d.matched = found;
  d.only_pcl += pcl_voxels.size() - found;
  if (!diffs_mm.empty()) {
    std::sort(diffs_mm.begin(), diffs_mm.end());
    d.same_members_max_mm = diffs_mm.back();
    d.max_mm = std::max(d.max_mm, diffs_mm.back());
    d.p99_mm = diffs_mm[std::min(diffs_mm.size() - 1, diffs_mm.size() * 99 / 100)];
    d.median_mm = diffs_mm[diffs_mm.size() / 2];
  }
  return d;
}

// Sampled input points whose voxel under PCL's float lattice (float world
// coordinate times float 1/leaf, floored: voxel_grid.hpp) differs from fovea's
// double lattice (floor((origin + x) * (1 / v))).
std::size_t latticeDisagreements(const PointCloud& cloud, const uint8_t* region, const Output& fovea,
                                 std::size_t& sampled, std::set<VoxelKey>& moved) {
  std::size_t differ = 0;
  sampled = 0;
  const double origin[3] = {cloud.origin_m.x(), cloud.origin_m.y(), cloud.origin_m.z()};
  const float* coord[3] = {cloud.x(), cloud.y(), cloud.z()};
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const int r = region[i];
    if (r == 0 || r >= fovea.region_count) continue;
    ++sampled;
    const double inv = 1.0 / fovea.voxel_size_m[r];
    const float inv_f = 1.0f / static_cast<float>(fovea.voxel_size_m[r]);
    int64_t k_double[3], k_float[3];
    for (int a = 0; a < 3; ++a) {
      k_double[a] = static_cast<int64_t>(pipeline::voxelIndex(origin[a], coord[a][i], inv));
      const float world_f = static_cast<float>(origin[a] + static_cast<double>(coord[a][i]));
      k_float[a] = static_cast<int64_t>(std::floor(world_f * inv_f));
    }
    if (k_double[0] != k_float[0] || k_double[1] != k_float[1] || k_double[2] != k_float[2]) {
      ++differ;
      moved.insert({r, k_double[0], k_double[1], k_double[2]});
      moved.insert({r, k_float[0], k_float[1], k_float[2]});
    }
  }
  return differ;
}

// --- Command line ----------------------------------------------------------

int usage(const char* message) {
  if (message) std::fprintf(stderr, "fovea-compare: %s\n", message);
  std::fprintf(stderr,
               "usage: fovea-compare [--runs N] [--preset F1|F2|F3|FREF] [--acuity-floor MM] [--methods A,B,...]\n"
               "                     [--tum PATH [--frame N] | --ply FILE --gaze-origin X,Y,Z --gaze-dir X,Y,Z]\n"
               "Runs the foveation methods on one input (default: the mock living-room frame, 640x480)\n"
               "and prints a table and one `method=... ms_median=...` line per method.\n"
               "  --acuity-floor MM  distance floor of the acuity-floor and acuity-features methods, mm per m^2\n"
               "                     of distance (foveation.floor_per_m2 x 1000; default 1: F1's bytes on the\n"
               "                     mock room)\n"
               "  --methods A,B,...  run only these rows (by name; the table lists them all)\n"
               "  --pyramid-margin M the pyramid rows' margin (default ACUITY's level_margin, 0.5): smaller keeps\n"
               "                     fewer points, with more above the MAR\n");
  return 2;
}

bool parseVector(const std::string& text, Eigen::Vector3d& out) {
  double v[3];
  if (std::sscanf(text.c_str(), "%lf,%lf,%lf", &v[0], &v[1], &v[2]) != 3) return false;
  out = Eigen::Vector3d(v[0], v[1], v[2]);
  return out.allFinite();
}

int run(int argc, char** argv) {
  int runs = 20;
  std::string tum_path, ply_path, preset = "F1";
  int frame_index = 0;
  double acuity_floor_mm = 1.0;
  std::string only_methods;  // ",a,b," or empty: every method
  double input_pyramid_margin = 0.0;
  std::optional<Eigen::Vector3d> gaze_origin, gaze_dir;
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    const auto value = [&]() -> const char* { return i + 1 < argc ? argv[++i] : nullptr; };
    if (arg == "--help" || arg == "-h") {
      usage(nullptr);
      return 0;
    }
    const char* v = value();
    if (v == nullptr) return usage(("missing value after " + std::string(arg)).c_str());
    if (arg == "--runs") {
      runs = std::atoi(v);
      if (runs < 1 || runs > 100000) return usage("--runs: expected a count in 1..100000");
    } else if (arg == "--pyramid-margin") {
      char* end = nullptr;
      input_pyramid_margin = std::strtod(v, &end);
      if (end == v || *end != '\0' || !(input_pyramid_margin > 0.0 && input_pyramid_margin <= 100.0)) {
        return usage("--pyramid-margin: expected a margin in (0, 100]");
      }
    } else if (arg == "--methods") {
      only_methods = std::string(",") + v + ",";
      std::size_t begin = 1;
      while (begin < only_methods.size()) {
        const std::size_t end = only_methods.find(',', begin);
        const std::string name = only_methods.substr(begin, end - begin);
        const bool known = std::any_of(std::begin(kMethods), std::end(kMethods),
                                       [&](const MethodEntry& e) { return name == e.name; });
        if (!known) return usage(("--methods: no method named '" + name + "'").c_str());
        begin = end + 1;
      }
    } else if (arg == "--tum") {
      tum_path = v;
    } else if (arg == "--frame") {
      frame_index = std::atoi(v);
      if (frame_index < 0) return usage("--frame: expected an index >= 0");
    } else if (arg == "--ply") {
      ply_path = v;
    } else if (arg == "--preset") {
      preset = v;
    } else if (arg == "--acuity-floor") {
      char* end = nullptr;
      acuity_floor_mm = std::strtod(v, &end);
      if (end == v || *end != '\0' || !(acuity_floor_mm > 0.0 && acuity_floor_mm <= 1000.0)) {
        return usage("--acuity-floor: expected mm per m^2 in (0, 1000]");
      }
    } else if (arg == "--gaze-origin" || arg == "--gaze-dir") {
      Eigen::Vector3d vec;
      if (!parseVector(v, vec)) return usage((std::string(arg) + ": expected X,Y,Z").c_str());
      (arg == "--gaze-origin" ? gaze_origin : gaze_dir) = vec;
    } else {
      return usage(("unknown option " + std::string(arg)).c_str());
    }
  }
  if (!tum_path.empty() && !ply_path.empty()) return usage("--tum and --ply exclude each other");
  if (frame_index != 0 && tum_path.empty()) return usage("--frame needs --tum");
  if (!ply_path.empty() && (!gaze_origin || !gaze_dir)) return usage("--ply needs --gaze-origin and --gaze-dir");

  Input input;
  Result<pipeline::Preset> parsed_preset = pipeline::parsePreset(preset);
  if (!parsed_preset) return usage(parsed_preset.status().message().c_str());
  input.config.acuity.preset = parsed_preset.value();
  input.acuity_floor_per_m2 = acuity_floor_mm * 1e-3;
  input.pyramid_margin = input_pyramid_margin;
  pipeline::Gaze gaze;
  if (!ply_path.empty()) {
    Result<io::PlyCloud> ply = io::readPly(ply_path);
    if (!ply) {
      std::fprintf(stderr, "fovea-compare: %s\n", ply.status().toString().c_str());
      return 1;
    }
    input.cloud = std::move(ply.value().points);
    input.description = ply_path + " (" + std::to_string(input.cloud.size()) + " points; no back-projection)";
  } else {
    Result<FrameInput> frame = tum_path.empty() ? mockLivingRoom() : tumFrame(tum_path, frame_index);
    if (!frame) {
      std::fprintf(stderr, "fovea-compare: %s\n", frame.status().toString().c_str());
      return 1;
    }
    input.has_frame = true;
    input.frame = std::move(frame.value().frame);
    input.description = frame.value().description;
    gaze = frame.value().gaze;
  }
  if (gaze_origin) gaze.origin_m = *gaze_origin;
  if (gaze_dir) gaze.direction = *gaze_dir;
  Result<pipeline::Gaze> unit = pipeline::normalizeGaze(gaze);
  if (!unit) {
    std::fprintf(stderr, "fovea-compare: %s\n", unit.status().toString().c_str());
    return 1;
  }
  input.gaze = unit.value();
  if (input.has_frame) {
    PointCloud probe(input.frame.pixelCount());
    pipeline::BackprojectCounts counts;
    if (Status s = pipeline::backprojectRef(input.frame, input.range, probe, counts); !s) {
      std::fprintf(stderr, "fovea-compare: %s\n", s.toString().c_str());
      return 1;
    }
    input.input_points = counts.valid;
  } else {
    input.input_points = input.cloud.size();
  }
  if (input.input_points == 0) {
    std::fprintf(stderr, "fovea-compare: the input has no valid points\n");
    return 1;
  }

  std::printf("fovea-compare: %s\n", input.description.c_str());
  std::printf("  SIMD target %s, %d cores for fovea-simd-mt\n", pipeline::simdTargetName(pipeline::activeSimdTarget()),
              allCores());
  std::printf("  gaze origin (%.3f, %.3f, %.3f) m, direction (%.4f, %.4f, %.4f); preset %s, fixation hit; "
              "%zu input points; %d timed rounds (each method once per round) after one warm-up; ACUITY's "
              "distance floor %g mm/m^2\n",
              input.gaze.origin_m.x(), input.gaze.origin_m.y(), input.gaze.origin_m.z(), input.gaze.direction.x(),
              input.gaze.direction.y(), input.gaze.direction.z(), preset.c_str(), input.input_points, runs,
              acuity_floor_mm);

  struct Row {
    const MethodEntry* entry;
    Timing timing;
  };
  std::vector<Row> rows;
  FoveaMethod* fovea_ref = nullptr;
  std::vector<std::unique_ptr<Method>> methods;
  std::vector<Method*> by_row;
  for (const MethodEntry& entry : kMethods) {
    // Rows not asked for are not listed either.
    if (!only_methods.empty() && only_methods.find(std::string(",") + entry.name + ",") == std::string::npos) continue;
    rows.push_back({&entry, {}});
    by_row.push_back(nullptr);
    if (entry.make == nullptr) continue;
    methods.push_back(entry.make(input));
    by_row.back() = methods.back().get();
    if (by_row.back() == nullptr) continue;
    if (std::string_view(entry.name) == "fovea-ref") fovea_ref = static_cast<FoveaMethod*>(methods.back().get());
  }
  // One warm-up run each (caches, page faults, PCL's first allocations), then the
  // timed runs in rounds, every method once per round: a load change on the
  // machine then affects all methods alike instead of whichever ran at the time.
  for (int round = -1; round < runs; ++round) {
    for (std::size_t m = 0; m < rows.size(); ++m) {
      if (by_row[m] == nullptr) continue;
      const auto start = std::chrono::steady_clock::now();
      const Status s = by_row[m]->run();
      const auto end = std::chrono::steady_clock::now();
      if (!s) {
        std::fprintf(stderr, "fovea-compare: %s failed: %s\n", rows[m].entry->name, s.toString().c_str());
        return 1;
      }
      if (round >= 0) rows[m].timing.ms.push_back(std::chrono::duration<double, std::milli>(end - start).count());
    }
  }
  for (std::size_t m = 0; m < rows.size(); ++m) {
    if (by_row[m] != nullptr) finish(*by_row[m], rows[m].timing);
  }
  // The error of each output, after the timing (it runs the method again).
  std::vector<std::optional<pipeline::ErrorMetrics>> errors(rows.size());
  for (std::size_t m = 0; m < rows.size(); ++m) {
    pipeline::ErrorMetrics metrics;
    if (by_row[m] != nullptr && by_row[m]->error(metrics)) errors[m] = metrics;
  }
  const auto find = [&](std::string_view name) -> const Timing* {
    for (const Row& r : rows) {
      if (r.entry->name == name && r.timing.ran) return &r.timing;
    }
    return nullptr;
  };
  const Timing* pcl = find("pcl");
  const Timing* floor = find("floor");

  if (fovea_ref != nullptr) {
    const pipeline::FoveationStats& s = fovea_ref->stats();
    std::printf("  d0 %.3f m (%s); voxel sizes:", s.fixation.d0_m,
                std::string(pipeline::fixationSourceName(s.fixation.source)).c_str());
    for (int r = 1; r < s.region_count; ++r) std::printf(" region %d %.2f mm", r, 1000.0 * s.regions[r].voxel_size_m);
    std::printf("\n");
  }
  std::printf("\n%-23s %9s %9s %9s %10s %9s %9s %9s %12s %9s %8s\n", "method", "median ms", "min ms", "max ms",
              "out points", "ns/point", "vs pcl", "vs floor", "max d [mm]", ">MAR %", "rms mm");
  for (std::size_t m = 0; m < rows.size(); ++m) {
    const Row& row = rows[m];
    const Timing& t = row.timing;
    if (!t.ran) {
      std::printf("%-23s %9s   -- %s\n", row.entry->name, "-", row.entry->what);
      continue;
    }
    char vs_pcl[16] = "-", vs_floor[16] = "-", diff[24] = "-";
    if (pcl) std::snprintf(vs_pcl, sizeof vs_pcl, "%.2fx", pcl->median / t.median);
    if (floor) std::snprintf(vs_floor, sizeof vs_floor, "%.3fx", floor->median / t.median);
    if (pcl && t.has_output && &t != pcl) {
      std::snprintf(diff, sizeof diff, "%.4f", compareWithPcl(t.output, pcl->output).max_mm);
    } else if (&t == pcl) {
      std::snprintf(diff, sizeof diff, "(reference)");
    }
    char above[16] = "-", rms[16] = "-";
    if (errors[m]) {
      std::snprintf(above, sizeof above, "%.3f", 100.0 * errors[m]->all.shareAboveReferenceMar());
      std::snprintf(rms, sizeof rms, "%.3f", 1000.0 * errors[m]->all.rmsM());
    }
    std::printf("%-23s %9.3f %9.3f %9.3f %10zu %9.2f %9s %9s %12s %9s %8s\n", row.entry->name, t.median, t.min, t.max,
                t.out_points, 1e6 * t.median / static_cast<double>(input.input_points), vs_pcl, vs_floor, diff,
                above, rms);
  }
  std::printf(
      "\n  ns/point: median time / %zu input points. vs pcl, vs floor: speed-up = that method's median / this "
      "method's\n  (above 1: faster). The floor only reads the input once; it produces nothing.\n"
      "  >MAR %%: input points whose move to their output point the eye resolves (pipeline/error_metrics.h, the\n"
      "  fixed observer m = 0.022); rms mm: root mean square of those moves. Measured after the timing.\n",
      input.input_points);

  // The pyramid's cells: where its points came from and how many cells it tested.
  for (std::size_t m = 0; m < rows.size(); ++m) {
    if (by_row[m] == nullptr || std::string_view(rows[m].entry->name).find("pyramid") == std::string_view::npos) {
      continue;
    }
    const pipeline::PyramidStats& ps = static_cast<const PyramidMethod*>(by_row[m])->stats();
    std::printf("  %s: %u cells tested; points by level (0 = pixels):", rows[m].entry->name, ps.cells_tested);
    for (std::size_t k = 0; k < ps.out_by_level.size(); ++k) std::printf(" %u", ps.out_by_level[k]);
    std::printf("\n");
  }

  // What differs from PCL, and why.
  for (const Row& row : rows) {
    const Timing& t = row.timing;
    if (!pcl || !t.ran || !t.has_output || &t == pcl) continue;
    std::set<VoxelKey> moved;
    std::size_t sampled = 0, differ = 0;
    const bool is_ref = fovea_ref != nullptr && &t == find("fovea-ref");
    if (is_ref) differ = latticeDisagreements(fovea_ref->cloud(), fovea_ref->regions(), t.output, sampled, moved);
    const Difference d = compareWithPcl(t.output, pcl->output, is_ref ? &moved : nullptr);
    std::printf("\n  %s vs pcl, voxels matched by (region, world voxel index floor(c / v)):\n", row.entry->name);
    std::printf("    fovea points: %zu vs %zu (%s); voxel sizes %s\n", d.fovea_here, d.fovea_pcl,
                d.fovea_here == d.fovea_pcl ? "both untouched" : "DIFFERENT",
                d.same_voxel_sizes ? "identical" : "DIFFERENT");
    std::printf("    %zu voxels matched, %zu only in %s, %zu only in pcl\n", d.matched, d.only_here, row.entry->name,
                d.only_pcl);
    std::printf("    centroid distance, matched voxels with the same points: median %.5f mm, p99 %.5f mm, max %.5f mm\n",
                d.median_mm, d.p99_mm, d.same_members_max_mm);
    if (is_ref) {
      std::printf("    centroid distance, %zu matched voxels that gained or lost a point to PCL's lattice: max %.4f mm\n",
                  d.moved_voxels, d.moved_max_mm);
      std::printf(
          "    why: PCL's lattice is world-anchored too (it floors p * inverse_leaf), but in float: the world\n"
          "    coordinate, 1/leaf and their product are rounded to float, so %zu of %zu sampled points (%.4f %%)\n"
          "    fall into a neighbouring voxel; those voxels gain or lose a point (centroids up to millimetres\n"
          "    apart, or unmatched voxels). Elsewhere PCL sums in float (pcl::CentroidPoint, Vector3f) where\n"
          "    fovea sums in double relative to the voxel's first point: float rounding (micrometres).\n",
          differ, sampled, sampled ? 100.0 * static_cast<double>(differ) / static_cast<double>(sampled) : 0.0);
    }
  }

  std::printf("\n");
  for (const Row& row : rows) {
    const Timing& t = row.timing;
    if (!t.ran) continue;
    const std::size_t m = static_cast<std::size_t>(&row - rows.data());
    std::printf("method=%s ms_median=%.4f ms_min=%.4f ms_max=%.4f out_points=%zu ns_per_point=%.3f", row.entry->name,
                t.median, t.min, t.max, t.out_points, 1e6 * t.median / static_cast<double>(input.input_points));
    if (errors[m]) {
      std::printf(" above_mar_pct=%.4f rms_mm=%.4f", 100.0 * errors[m]->all.shareAboveReferenceMar(),
                  1000.0 * errors[m]->all.rmsM());
    }
    std::printf("\n");
  }
  return 0;
}

}  // namespace
}  // namespace fovea::bench

int main(int argc, char** argv) { return fovea::bench::run(argc, argv); }

// fovea-compare's methods: each a row of the table (kMethods below), from the
// memory-bandwidth floor to fovea's kernels, ACUITY and, when built, PCL.
#include "bench/compare_methods.h"

#include <algorithm>
#include <cstring>
#include <optional>
#include <thread>

#include "pipeline/backproject.h"
#ifdef FOVEA_HAVE_PCL
#include "bench/pcl_method.h"
#endif

namespace fovea::bench::compare {
namespace {

using pipeline::PointCloud;

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

}  // namespace

FoveaMethod::FoveaMethod(const Input& input, fovea::KernelSet kernels, int threads, Acuity acuity)
    : input_(input),
      acuity_(acuity != Acuity::kNo),
      gaze_(gazeFor(input, acuity)),
      capacity_(input.has_frame ? input.frame.pixelCount() : input.cloud.size()),
      cloud_(input.has_frame ? capacity_ : 0),
      out_(capacity_),
      backprojector_(threads, kernels),
      foveator_(pipeline::Foveator::create({capacity_, capacity_, kernels, threads}, configFor(input, acuity)).value()) {}

Status FoveaMethod::run() {
  const PointCloud* in = &input_.cloud;
  if (input_.has_frame) {
    pipeline::BackprojectCounts counts;
    if (Status s = backprojector_.run(input_.frame, input_.range, cloud_, counts); !s) return s;
    in = &cloud_;
  }
  return foveator_.foveate(*in, gaze_, out_, stats_);
}

bool FoveaMethod::output(Output& o) const {
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

bool FoveaMethod::error(pipeline::ErrorMetrics& metrics) {
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

pipeline::FoveationConfig FoveaMethod::configFor(const Input& input, Acuity acuity) {
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

pipeline::Gaze FoveaMethod::gazeFor(const Input& input, Acuity acuity) {
  pipeline::Gaze gaze = input.gaze;
  if (acuity == Acuity::kEveryFeature) {
    gaze.fovea_growth_deg = 5.0;
    gaze.view_known = true;
    gaze.view_forward = gaze.direction;
  }
  return gaze;
}

PyramidMethod::PyramidMethod(const Input& input, bool floor)
    : input_(input),
      config_(configFor(input, floor)),
      rule_(pipeline::PyramidRule::fromAcuity(config_.acuity)),
      sampler_(pipeline::PyramidSampler::create(input.frame.width(), input.frame.height()).value()),
      out_(input.frame.pixelCount()) {}

bool PyramidMethod::error(pipeline::ErrorMetrics& metrics) {
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

pipeline::FoveationConfig PyramidMethod::configFor(const Input& input, bool floor) {
  pipeline::FoveationConfig config = input.config;
  config.acuity.preset = pipeline::Preset::kAcuity;
  if (floor) config.acuity.floor_per_m2 = input.acuity_floor_per_m2;
  if (input.pyramid_margin > 0.0) config.acuity.level_margin = input.pyramid_margin;
  return config;
}

std::span<const MethodEntry> methodTable() { return kMethods; }

int allCores() { return std::max(1, static_cast<int>(std::thread::hardware_concurrency())); }

}  // namespace fovea::bench::compare

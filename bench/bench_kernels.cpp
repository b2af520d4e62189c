// fovea-bench-kernels: Google Benchmark of each pipeline kernel on the mock
// living-room frame (640x480, gaze at the scene centre, preset F1, fixation hit).
// Each benchmark reports per_point: CPU time per valid input point (302k); the
// Time column is wall time. Multi-threaded variants should add ->UseRealTime().
//
// Kernels are rows of kKernels below. A SIMD variant is one more row with a
// function of the same shape (see the "SIMD kernels" comment); the fixture
// gives every row the same input.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <thread>
#include <vector>

#include "bench/bench_input.h"
#include "pipeline/backproject.h"
#include "pipeline/fixation.h"
#include "pipeline/foveator.h"
#include "pipeline/kernels/backprojector.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/kernels/hash_voxel_sampler.h"
#include "pipeline/partition.h"
#include "pipeline/voxel_sampler.h"

namespace fovea::bench {
namespace {

using pipeline::PointCloud;

// Built once; every benchmark reads it (and writes only its own scratch).
struct Fixture {
  FrameInput input;
  pipeline::Gaze gaze;  // normalised
  pipeline::DepthRange range;
  pipeline::FoveationConfig config;
  PointCloud cloud;                       // back-projected input
  std::vector<uint8_t> region;            // partition of cloud
  int region_count = 0;
  pipeline::ConeBounds bounds;
  std::array<double, pipeline::kMaxRegions> voxel_size_m{};
  std::size_t points = 0;

  static Fixture& get() {
    static Fixture* fixture = build();
    return *fixture;
  }

 private:
  static Fixture* build() {
    auto* f = new Fixture;
    Result<FrameInput> input = mockLivingRoom();
    if (!input) {
      std::fprintf(stderr, "fovea-bench-kernels: %s\n", input.status().toString().c_str());
      std::exit(1);
    }
    f->input = std::move(input).value();
    f->gaze = pipeline::normalizeGaze(f->input.gaze).value();
    const std::size_t pixels = f->input.frame.pixelCount();
    f->cloud = PointCloud(pixels);
    pipeline::BackprojectCounts bc;
    if (Status s = pipeline::backprojectRef(f->input.frame, f->range, f->cloud, bc); !s) {
      std::fprintf(stderr, "fovea-bench-kernels: %s\n", s.toString().c_str());
      std::exit(1);
    }
    f->points = f->cloud.size();
    pipeline::Foveator foveator =
        pipeline::Foveator::create({pixels, pixels, pipeline::KernelSet::kRef, 1}, f->config).value();
    pipeline::FoveatedCloud out(pixels);
    pipeline::FoveationStats stats;
    if (Status s = foveator.foveate(f->cloud, f->gaze, out, stats); !s) {
      std::fprintf(stderr, "fovea-bench-kernels: %s\n", s.toString().c_str());
      std::exit(1);
    }
    f->region.assign(foveator.lastRegions(), foveator.lastRegions() + f->cloud.size());
    f->region_count = stats.region_count;
    f->bounds = pipeline::ConeBounds::fromModel(foveator.model());
    for (int r = 0; r < stats.region_count; ++r) f->voxel_size_m[r] = stats.regions[r].voxel_size_m;
    return f;
  }
};

void setPointCounter(benchmark::State& state, std::size_t points) {
  // points per second, inverted: seconds per point, printed with an SI prefix ("4.3ns").
  state.counters["per_point"] = benchmark::Counter(
      static_cast<double>(points), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["points"] = static_cast<double>(points);
}

// --- The scalar reference -------------------------------------------------

// One benchmark per kernel, templated on the variant (the table at the end
// names them), so the reference and the SIMD kernel run the same loop.

template <auto Backproject>
void bmBackproject(benchmark::State& state) {
  Fixture& f = Fixture::get();
  PointCloud out(f.input.frame.pixelCount());
  pipeline::BackprojectCounts counts;
  for (auto _ : state) {
    Status s = Backproject(f.input.frame, f.range, out, counts);
    benchmark::DoNotOptimize(s);
    benchmark::DoNotOptimize(out.x());
    benchmark::ClobberMemory();
  }
  setPointCounter(state, f.points);
}

template <auto Partition>
void bmPartition(benchmark::State& state) {
  Fixture& f = Fixture::get();
  std::vector<uint8_t> region(f.cloud.size());
  pipeline::PartitionCounts counts;
  for (auto _ : state) {
    Partition(f.cloud, f.gaze, f.bounds, region.data(), counts);
    benchmark::DoNotOptimize(region.data());
    benchmark::ClobberMemory();
  }
  setPointCounter(state, f.points);
}

template <typename Sampler>
void bmVoxelSample(benchmark::State& state) {
  Fixture& f = Fixture::get();
  Sampler sampler(f.cloud.size(), f.cloud.size());
  pipeline::FoveatedCloud out(f.cloud.size());
  pipeline::SampleCounts counts;
  for (auto _ : state) {
    Status s = sampler.sample(f.cloud, f.region.data(), f.region_count, f.voxel_size_m, out, counts);
    benchmark::DoNotOptimize(s);
    benchmark::ClobberMemory();
  }
  setPointCounter(state, f.points);
}

// --- The scalar reference -------------------------------------------------

void bmFoveatorRef(benchmark::State& state) {
  Fixture& f = Fixture::get();
  pipeline::Foveator foveator =
      pipeline::Foveator::create({f.cloud.size(), f.cloud.size(), pipeline::KernelSet::kRef, 1}, f.config).value();
  pipeline::FoveatedCloud out(f.cloud.size());
  pipeline::FoveationStats stats;
  for (auto _ : state) {
    Status s = foveator.foveate(f.cloud, f.gaze, out, stats);
    benchmark::DoNotOptimize(s);
    benchmark::ClobberMemory();
  }
  setPointCounter(state, f.points);
}

// The whole frame: back-projection from the depth image, then foveate.
void bmPipelineRef(benchmark::State& state) {
  Fixture& f = Fixture::get();
  const std::size_t pixels = f.input.frame.pixelCount();
  pipeline::Foveator foveator =
      pipeline::Foveator::create({pixels, pixels, pipeline::KernelSet::kRef, 1}, f.config).value();
  PointCloud cloud(pixels);
  pipeline::FoveatedCloud out(pixels);
  pipeline::BackprojectCounts bc;
  pipeline::FoveationStats stats;
  for (auto _ : state) {
    Status s = pipeline::backprojectRef(f.input.frame, f.range, cloud, bc);
    if (s) s = foveator.foveate(cloud, f.gaze, out, stats);
    benchmark::DoNotOptimize(s);
    benchmark::ClobberMemory();
  }
  setPointCounter(state, f.points);
}

// --- The SIMD kernels (Highway, the target dispatch picks) --------------------

// The whole frame with the SIMD kernel set on `threads` threads.
void pipelineSimd(benchmark::State& state, int threads) {
  Fixture& f = Fixture::get();
  const std::size_t pixels = f.input.frame.pixelCount();
  pipeline::Foveator foveator =
      pipeline::Foveator::create({pixels, pixels, pipeline::KernelSet::kSimd, threads}, f.config).value();
  pipeline::Backprojector backprojector(threads, pipeline::KernelSet::kSimd);
  PointCloud cloud(pixels);
  pipeline::FoveatedCloud out(pixels);
  pipeline::BackprojectCounts bc;
  pipeline::FoveationStats stats;
  for (auto _ : state) {
    Status s = backprojector.run(f.input.frame, f.range, cloud, bc);
    if (s) s = foveator.foveate(cloud, f.gaze, out, stats);
    benchmark::DoNotOptimize(s);
    benchmark::ClobberMemory();
  }
  setPointCounter(state, f.points);
}
void bmPipelineSimd1(benchmark::State& state) { pipelineSimd(state, 1); }
void bmPipelineSimdAll(benchmark::State& state) {
  pipelineSimd(state, std::max(1, static_cast<int>(std::thread::hardware_concurrency())));
}

struct KernelBench {
  const char* name;  // "<kernel>/<variant>"
  void (*run)(benchmark::State&);
};

const KernelBench kKernels[] = {
    {"backproject/ref", &bmBackproject<pipeline::backprojectRef>},
    {"partition/ref", &bmPartition<pipeline::partitionRef>},
    {"voxel_sample/ref", &bmVoxelSample<pipeline::VoxelSampler>},
    {"foveate/ref", &bmFoveatorRef},    // partition + fixation + voxel sampling
    {"pipeline/ref", &bmPipelineRef},   // back-projection + foveate
    {"backproject/simd", &bmBackproject<pipeline::backprojectSimd>},
    {"partition/simd", &bmPartition<pipeline::partitionSimd>},
    {"voxel_sample/hash", &bmVoxelSample<pipeline::HashVoxelSampler>},
    {"pipeline/simd-1t", &bmPipelineSimd1},
    {"pipeline/simd-all-cores", &bmPipelineSimdAll},
};

}  // namespace
}  // namespace fovea::bench

int main(int argc, char** argv) {
  for (const fovea::bench::KernelBench& k : fovea::bench::kKernels) {
    benchmark::RegisterBenchmark(k.name, k.run)->Unit(benchmark::kMicrosecond);
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  std::fprintf(stderr, "input: %s; SIMD target %s\n", fovea::bench::Fixture::get().input.description.c_str(),
               fovea::pipeline::simdTargetName(fovea::pipeline::activeSimdTarget()));
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}

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
#include <type_traits>
#include <vector>

#include <Eigen/Geometry>

#include "bench/bench_input.h"
#include "hal/camera/mock/mock_camera.h"
#include "hal/camera/registration/registration.h"
#include "pipeline/acuity_levels.h"
#include "pipeline/backproject.h"
#include "pipeline/fixation.h"
#include "pipeline/foveator.h"
#include "pipeline/kernels/backprojector.h"
#include "pipeline/kernels/foveation_simd.h"
#include "pipeline/kernels/hash_voxel_sampler.h"
#include "pipeline/map/map_kernels.h"
#include "pipeline/map/surfel_map.h"
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
  // The same cloud under Preset::kAcuity (docs/acuity-levels.md): its levels and voxels,
  // with the defaults and with the 1 mm/m^2 distance floor (F1's bytes on this frame).
  struct Acuity {
    pipeline::FoveationConfig config;
    std::vector<uint8_t> level;
    int level_count = 0;
    pipeline::LevelBounds bounds;
    std::array<double, pipeline::kMaxRegions> voxel_m{};
  };
  Acuity acuity, acuity_floor;
  const Acuity& acuityVariant(bool floor) const { return floor ? acuity_floor : acuity; }

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
        pipeline::Foveator::create({pixels, pixels, fovea::KernelSet::kRef, 1}, f->config).value();
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

    for (Acuity* a : {&f->acuity, &f->acuity_floor}) {
      a->config.acuity.preset = pipeline::Preset::kAcuity;
      if (a == &f->acuity_floor) a->config.acuity.floor_per_m2 = 0.001;
      pipeline::Foveator levels =
          pipeline::Foveator::create({pixels, pixels, fovea::KernelSet::kRef, 1}, a->config).value();
      if (Status s = levels.foveate(f->cloud, f->gaze, out, stats); !s) {
        std::fprintf(stderr, "fovea-bench-kernels: %s\n", s.toString().c_str());
        std::exit(1);
      }
      a->level.assign(levels.lastRegions(), levels.lastRegions() + f->cloud.size());
      a->level_count = stats.region_count;
      a->bounds = pipeline::LevelBounds::fromModel(levels.model());
      for (int r = 0; r < stats.region_count; ++r) a->voxel_m[r] = stats.regions[r].voxel_size_m;
    }
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

// ACUITY's level assignment (in place of the partition), without or with the floor.
template <auto AssignLevels, bool kFloor = false>
void bmLevels(benchmark::State& state) {
  Fixture& f = Fixture::get();
  const Fixture::Acuity& a = f.acuityVariant(kFloor);
  std::vector<uint8_t> level(f.cloud.size());
  pipeline::PartitionCounts counts;
  for (auto _ : state) {
    AssignLevels(f.cloud, f.gaze, a.bounds, level.data(), counts);
    benchmark::DoNotOptimize(level.data());
    benchmark::ClobberMemory();
  }
  setPointCounter(state, f.points);
}

// Voxel sampling of the fixture's F1 regions, or (kAcuityLevels) of its ACUITY levels,
// without or with the floor.
template <typename Sampler, bool kAcuityLevels = false, bool kFloor = false>
void bmVoxelSample(benchmark::State& state) {
  Fixture& f = Fixture::get();
  const Fixture::Acuity& a = f.acuityVariant(kFloor);
  Sampler sampler(f.cloud.size(), f.cloud.size());
  pipeline::FoveatedCloud out(f.cloud.size());
  pipeline::SampleCounts counts;
  const uint8_t* region = kAcuityLevels ? a.level.data() : f.region.data();
  const int count = kAcuityLevels ? a.level_count : f.region_count;
  const auto& voxel_m = kAcuityLevels ? a.voxel_m : f.voxel_size_m;
  for (auto _ : state) {
    Status s = sampler.sample(f.cloud, region, count, voxel_m, out, counts);
    benchmark::DoNotOptimize(s);
    benchmark::ClobberMemory();
  }
  setPointCounter(state, f.points);
  state.counters["out"] = static_cast<double>(out.size());
  if constexpr (std::is_same_v<Sampler, pipeline::HashVoxelSampler>) {
    state.counters["lookups"] = static_cast<double>(sampler.lastTableLookups());  // recent-voxel cache misses
  }
}

// Colour registration of the fixture's depth (640x480) into a 1280x720 colour
// image, D435-like: 15 mm baseline, a degree of rotation, a mild plumb-bob
// distortion (so the polynomial is timed). per_point is per depth pixel here.
template <auto Register>
void bmRegister(benchmark::State& state) {
  Fixture& f = Fixture::get();
  const hal::RgbdFrame& frame = f.input.frame;
  hal::RegistrationParams p;
  p.depth.intrinsics = frame.intrinsics;
  p.depth_scale_m = frame.depth_scale_m;
  p.colour.intrinsics = {1280, 720, 910.0, 910.0, 641.3, 359.2};
  p.colour.distortion.model = hal::Distortion::Model::kPlumbBob;
  p.colour.distortion.coeffs = {0.08, -0.15, 4e-4, -2e-4, 0.05};
  p.T_colour_depth.R_world_cam =
      Eigen::AngleAxisd(0.017, Eigen::Vector3d(0.2, 1.0, 0.1).normalized()).toRotationMatrix();
  p.T_colour_depth.t_world_cam = Eigen::Vector3d(0.015, 0.0002, -0.0004);
  Result<hal::DepthToColourRegistration> reg = hal::DepthToColourRegistration::create(p);
  if (!reg) {
    state.SkipWithError(reg.status().toString().c_str());
    return;
  }
  std::vector<uint8_t> colour(1280 * 720 * 3);
  for (std::size_t i = 0; i < colour.size(); ++i) colour[i] = static_cast<uint8_t>(i * 2654435761u >> 24);
  std::vector<uint8_t> out(frame.pixelCount() * 3);
  hal::RegistrationCounts counts;
  for (auto _ : state) {
    counts = ((*reg).*Register)(frame.depth(), colour.data(), out.data());
    benchmark::DoNotOptimize(counts);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  setPointCounter(state, frame.pixelCount());
  state.counters["coloured"] = static_cast<double>(counts.coloured);
}

// --- The scalar reference -------------------------------------------------

void bmFoveatorRef(benchmark::State& state) {
  Fixture& f = Fixture::get();
  pipeline::Foveator foveator =
      pipeline::Foveator::create({f.cloud.size(), f.cloud.size(), fovea::KernelSet::kRef, 1}, f.config).value();
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
      pipeline::Foveator::create({pixels, pixels, fovea::KernelSet::kRef, 1}, f.config).value();
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

// The whole frame with the SIMD kernel set on `threads` threads (F1, or ACUITY's
// configuration).
void pipelineSimd(benchmark::State& state, int threads, const pipeline::FoveationConfig* acuity = nullptr) {
  Fixture& f = Fixture::get();
  const std::size_t pixels = f.input.frame.pixelCount();
  pipeline::Foveator foveator = pipeline::Foveator::create({pixels, pixels, fovea::KernelSet::kSimd, threads},
                                                           acuity ? *acuity : f.config)
                                    .value();
  pipeline::Backprojector backprojector(threads, fovea::KernelSet::kSimd);
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
void bmPipelineAcuitySimd1(benchmark::State& state) { pipelineSimd(state, 1, &Fixture::get().acuity.config); }
void bmPipelineAcuityFloorSimd1(benchmark::State& state) {
  pipelineSimd(state, 1, &Fixture::get().acuity_floor.config);
}
void bmPipelineSimdAll(benchmark::State& state) {
  pipelineSimd(state, std::max(1, static_cast<int>(std::thread::hardware_concurrency())));
}

// --- The surfel map (pipeline/map/) -------------------------------------------

// The per-pixel kernel of fuse()'s step 2 (pipeline/map/map_kernels.h): vertices,
// normals, radii and weights of the frame. per_point: per pixel of the frame.
template <fovea::KernelSet kKernels>
void bmMapVertices(benchmark::State& state) {
  Fixture& f = Fixture::get();
  const hal::RgbdFrame& frame = f.input.frame;
  const std::size_t pixels = frame.pixelCount();
  std::vector<float> maps[6];
  for (auto& m : maps) m.resize(pixels);
  const pipeline::map::PixelMaps out{maps[0].data(), maps[1].data(), maps[2].data(),
                                     maps[3].data(), maps[4].data(), maps[5].data()};
  pipeline::map::VertexTables tables(frame.width(), frame.height());
  const pipeline::RawDepthRange raw = pipeline::rawDepthRange(pipeline::map::SurfelMapConfig{}.depth, frame.depth_scale_m);
  uint32_t valid = 0;
  for (auto _ : state) {
    // As fuse() does it: the parameters (and the weight's exp() per column and row) every frame.
    const pipeline::map::VertexParams params = pipeline::map::prepareVertices(frame, raw, tables);
    valid = pipeline::map::computeVertices(params, out, kKernels);
    benchmark::DoNotOptimize(valid);
    benchmark::ClobberMemory();
  }
  setPointCounter(state, pixels);
  state.counters["valid"] = static_cast<double>(valid);
}

// Fusing the frame into a map that already holds it, as a static camera does
// frame after frame: every pixel with a normal associates and merges (one
// thread; the kernel set is step 2's). per_point: per pixel of the frame.
template <fovea::KernelSet kKernels>
void bmMapFuse(benchmark::State& state) {
  Fixture& f = Fixture::get();
  hal::RgbdFrame frame = f.input.frame;
  pipeline::map::SurfelMapConfig config;
  config.max_width = frame.width();
  config.max_height = frame.height();
  config.kernels = kKernels;
  pipeline::map::SurfelMap map = pipeline::map::SurfelMap::create(config).value();
  pipeline::map::FuseStats stats;
  for (int i = 0; i < 5; ++i) {  // the surfels become stable
    ++frame.stamp_ns;
    (void)map.fuse(frame, stats);
  }
  double vertices_ns = 0, index_map_ns = 0, associate_ns = 0, add_ns = 0;
  for (auto _ : state) {
    ++frame.stamp_ns;
    benchmark::DoNotOptimize(map.fuse(frame, stats));
    benchmark::ClobberMemory();
    vertices_ns += static_cast<double>(stats.vertices_ns);
    index_map_ns += static_cast<double>(stats.index_map_ns);
    associate_ns += static_cast<double>(stats.associate_ns);
    add_ns += static_cast<double>(stats.add_ns);
  }
  setPointCounter(state, frame.pixelCount());
  state.counters["surfels"] = static_cast<double>(map.size());
  state.counters["merged"] = static_cast<double>(stats.merged);
  state.counters["added"] = static_cast<double>(stats.added);
  state.counters["carved"] = static_cast<double>(stats.carved);
  state.counters["valid"] = static_cast<double>(stats.pixels_valid);
  // Each step's mean time a frame, in microseconds (FuseStats' *_ns).
  const double frames = static_cast<double>(std::max<benchmark::IterationCount>(state.iterations(), 1));
  state.counters["vertices_us"] = vertices_ns / frames * 1e-3;
  state.counters["index_map_us"] = index_map_ns / frames * 1e-3;
  state.counters["associate_us"] = associate_ns / frames * 1e-3;
  state.counters["add_us"] = add_ns / frames * 1e-3;
}

// The mock camera's frame on the orbit at 640x480 (realtime off: as fast as it
// renders), the static room rendered row by row into the frame or through its
// whole noiseless image (MockCameraOptions::stream_rows; the same frames).
template <bool kStreamRows>
void bmMockOrbitFrame(benchmark::State& state) {
  hal::mock::MockCameraOptions options = hal::mock::parseMockCameraOptions("living-room,path=orbit").value();
  options.stream_rows = kStreamRows;
  hal::mock::MockCamera camera(options);
  if (!camera.open() || !camera.start()) {
    state.SkipWithError("mock camera did not open");
    return;
  }
  hal::RgbdFrame frame(options.width, options.height);
  for (auto _ : state) {
    if (!camera.acquire(frame, std::chrono::seconds(1))) {
      state.SkipWithError("mock camera acquire failed");
      return;
    }
    benchmark::DoNotOptimize(frame.depth());
  }
  setPointCounter(state, frame.pixelCount());
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
    {"registration/ref", &bmRegister<&hal::DepthToColourRegistration::registerRef>},
    {"backproject/simd", &bmBackproject<pipeline::backprojectSimd>},
    {"partition/simd", &bmPartition<pipeline::partitionSimd>},
    {"voxel_sample/hash", &bmVoxelSample<pipeline::HashVoxelSampler>},
    {"registration/simd", &bmRegister<&hal::DepthToColourRegistration::registerSimd>},
    {"pipeline/simd-1t", &bmPipelineSimd1},
    {"pipeline/simd-all-cores", &bmPipelineSimdAll},
    // ACUITY (docs/acuity-levels.md): its levels, and the hash sampler on them
    {"levels/ref", &bmLevels<pipeline::assignLevelsRef>},
    {"levels/simd", &bmLevels<pipeline::assignLevelsSimd>},
    {"voxel_sample/hash-acuity", &bmVoxelSample<pipeline::HashVoxelSampler, true>},
    {"pipeline/acuity-simd-1t", &bmPipelineAcuitySimd1},
    // ... with the 1 mm/m^2 distance floor: F1's bytes on this frame
    {"levels/simd-floor", &bmLevels<pipeline::assignLevelsSimd, true>},
    {"voxel_sample/hash-acuity-floor", &bmVoxelSample<pipeline::HashVoxelSampler, true, true>},
    {"pipeline/acuity-floor-simd-1t", &bmPipelineAcuityFloorSimd1},
    // The surfel map's fusion of one 640x480 frame (docs/map.md)
    {"map/vertices-ref", &bmMapVertices<fovea::KernelSet::kRef>},
    {"map/vertices-simd", &bmMapVertices<fovea::KernelSet::kSimd>},
    {"map/fuse-ref", &bmMapFuse<fovea::KernelSet::kRef>},
    {"map/fuse-simd", &bmMapFuse<fovea::KernelSet::kSimd>},
    // The mock camera's frame (hal/camera/mock), as the service's capture stage makes it
    {"mock/orbit-rows", &bmMockOrbitFrame<true>},
    {"mock/orbit-image", &bmMockOrbitFrame<false>},
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

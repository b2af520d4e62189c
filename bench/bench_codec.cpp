// fovea-bench-codec: bytes per point and encode/decode time per point of fovea's
// chunk codec against Google Draco and PCL's octree codec, on one foveated frame
// (the mock living room at 640x480, preset F1, gaze to the scene centre).
// See bench/README.md ("fovea-bench-codec"). Not a test: nothing is asserted.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "bench/bench_input.h"
#include "bench/codec_baselines.h"
#include "bench/foveated_frame.h"
#include "net/codec.h"
#include "pipeline/foveator.h"

namespace fovea::bench {
namespace {

struct Row {
  std::string name;
  CodecRun run;
  std::size_t datagrams = 0;  // fovea: chunks (0: one stream)
  std::string note;
  std::function<CodecRun(std::size_t& datagrams)> runner;  // one warm-up and one timed run
  std::vector<double> encode_ms, decode_ms;
};

// A row before its runs. Filled member by member: GCC 12 at -O3 (the Release
// build) warns -Wmaybe-uninitialized about the aggregate temporary's std::string
// when a Row is brace-initialised in place, a false positive.
void addRow(std::vector<Row>& rows, std::string name, std::string note,
            std::function<CodecRun(std::size_t& datagrams)> runner) {
  Row& row = rows.emplace_back();
  row.name = std::move(name);
  row.note = std::move(note);
  row.runner = std::move(runner);
}

// fovea's codec: encode the frame, then decode every chunk into one cloud.
CodecRun runFovea(const pipeline::FoveatedCloud& cloud, std::span<const double> voxel, const net::CodecConfig& config,
                  int runs, std::size_t& chunks) {
  using Clock = ThreadCpuClock;
  CodecRun run;
  Result<net::ChunkEncoder> created = net::ChunkEncoder::create(config, cloud.size());
  if (!created) {
    run.error = created.status().toString();
    return run;
  }
  net::ChunkEncoder& enc = created.value();
  pipeline::FoveatedCloud out(cloud.size());
  std::vector<double> enc_ms, dec_ms;
  for (int r = 0; r <= runs; ++r) {
    const auto t0 = Clock::now();
    const Status st = enc.encode(cloud, voxel, static_cast<uint32_t>(r), 0);
    const auto t1 = Clock::now();
    if (!st) {
      run.error = st.toString();
      return run;
    }
    out.clear();
    const auto t2 = Clock::now();
    for (std::size_t i = 0; i < enc.chunkCount(); ++i) {
      Result<net::DecodedChunk> d = net::decodeChunk(enc.chunk(i), out);
      if (!d) {
        run.error = d.status().toString();
        return run;
      }
    }
    const auto t3 = Clock::now();
    if (r > 0) {
      enc_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
      dec_ms.push_back(std::chrono::duration<double, std::milli>(t3 - t2).count());
    }
  }
  run.bytes = 0;
  for (std::size_t i = 0; i < enc.chunkCount(); ++i) run.bytes += enc.chunk(i).size();
  chunks = enc.chunkCount();
  run.points_out = out.size();
  run.encode_ms = median(enc_ms);
  run.decode_ms = median(dec_ms);
  double max_step = 0.0;
  for (std::size_t r = 0; r < voxel.size(); ++r) max_step = std::max(max_step, enc.regionStep(static_cast<int>(r)));
  run.max_error_m = max_step / 2;
  return run;
}

int usage() {
  std::fprintf(stderr,
               "usage: fovea-bench-codec [--runs N (>= 1, default 25)] [--preset F1|F2|F3|FREF] [--only NAME-PREFIX]\n"
               "bytes per point and encode/decode ns per point of fovea's chunk codec, Draco and PCL's octree codec\n");
  return 2;
}

struct CodecOptions {
  int runs = 25;
  std::string only;  // run only the codecs whose name starts with this
  pipeline::FoveationConfig config;
};

// Returns the exit status of a usage error, else nothing.
std::optional<int> parseOptions(int argc, char** argv, CodecOptions& options) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--runs" && i + 1 < argc) {
      options.runs = std::atoi(argv[++i]);
      if (options.runs < 1) return usage();
    } else if (arg == "--only" && i + 1 < argc) {
      options.only = argv[++i];
    } else if (arg == "--preset" && i + 1 < argc) {
      Result<pipeline::Preset> p = pipeline::parsePreset(argv[++i]);
      if (!p) return usage();
      options.config.acuity.preset = p.value();
    } else {
      return usage();
    }
  }
  return std::nullopt;
}

// The input line: the frame, the preset, each region's points and voxel.
void printInput(const FrameInput& input, const FoveatedFrame& frame, const std::vector<double>& voxel,
                const CodecOptions& options) {
  const pipeline::FoveationStats& stats = frame.stats;
  std::printf("input: %s, preset %s: %zu foveated points (", input.description.c_str(),
              std::string(pipeline::presetName(options.config.acuity.preset)).c_str(), frame.cloud.size());
  for (int r = 0; r < stats.region_count; ++r) {
    std::printf("%sregion %d: %u pts, voxel %.1f mm", r ? "; " : "", r, stats.regions[static_cast<std::size_t>(r)].points_out,
                voxel[static_cast<std::size_t>(r)] * 1e3);
  }
  std::printf("), %d rounds (each codec once per round, after its own warm-up run), medians of thread CPU time\n\n",
              options.runs);
}

// fovea's codec in its configurations: as it ships, then on Draco 11-bit's grid.
void addFoveaRows(std::vector<Row>& rows, const pipeline::FoveatedCloud& fov, const std::vector<double>& voxel,
                  double draco11, const std::string& only) {
  auto fovea = [&](const std::string& name, const net::CodecConfig& c, std::span<const double> v, const std::string& note) {
    if (name.rfind(only, 0) != 0) return;
    const std::vector<double> sizes(v.begin(), v.end());
    addRow(rows, name, note, [&fov, c, sizes](std::size_t& d) { return runFovea(fov, sizes, c, 1, d); });
  };
  net::CodecConfig def;
  fovea("fovea default", def, voxel, "fovea 1 mm, periphery voxel/8, Exp-Golomb, MTU 1200");
  net::CodecConfig half = def;
  half.halve_peripheral_chroma = true;
  fovea("fovea half chroma", half, voxel, "as default, chroma per pair outside the fovea");
  net::CodecConfig zstd = def;
  zstd.entropy_coding = true;
  fovea("fovea + zstd", zstd, voxel, "as default, zstd level 1 per chunk where it pays");
  net::CodecConfig jumbo = def;
  jumbo.max_payload = net::kMaxMtu - net::kDatagramOverhead;
  fovea("fovea jumbo", jumbo, voxel, "as default, MTU 8952");
  // Draco's precision: every region on Draco's 11-bit grid (ratio 1, voxel := step).
  net::CodecConfig matched = def;
  matched.fovea_step_m = draco11;
  matched.periphery_step_ratio = 1.0;
  const std::vector<double> grid(voxel.size(), draco11);
  fovea("fovea @ draco-11 grid", matched, grid, "every region at Draco 11-bit's step, MTU 1200");
  net::CodecConfig matched_jumbo = matched;
  matched_jumbo.max_payload = net::kMaxMtu - net::kDatagramOverhead;
  fovea("fovea @ draco-11, jumbo", matched_jumbo, grid, "as above, MTU 8952");
  net::CodecConfig matched_half = matched;
  matched_half.halve_peripheral_chroma = true;
  fovea("fovea @ draco-11, half chroma", matched_half, grid, "as above, chroma per pair outside the fovea");
}

// The baselines that were built: Draco and PCL's octree codec.
void addBaselineRows(std::vector<Row>& rows, const pipeline::FoveatedCloud& fov, double draco11, const std::string& only) {
  const bool draco = haveDraco() && std::string("draco").rfind(only, 0) == 0;
  if (draco) {
    addRow(rows, "draco 11-bit", "kd-tree, speed 10, 8-bit colour",
           [&fov](std::size_t&) { return runDraco(fov, 11, 1); });
    // Draco at fovea's foveal precision: the fewest bits whose step is <= 1 mm.
    const net::CodecConfig def;
    int bits = 11;
    while (bits < 30 && dracoStep(fov, bits) > def.fovea_step_m) ++bits;
    addRow(rows, "draco " + std::to_string(bits) + "-bit", "as above, step <= fovea's 1 mm everywhere",
           [&fov, bits](std::size_t&) { return runDraco(fov, bits, 1); });
  } else if (!haveDraco()) {
    std::printf("draco: not built (libdraco-dev not found)\n");
  }
  if (havePclOctree() && std::string("pcl").rfind(only, 0) == 0) {
    // Detail truncated to point_resolution: error < point_resolution, so half Draco's step.
    addRow(rows, "pcl octree @ draco-11", "point res = Draco step / 2, octree 16 x Draco step",
           [&fov, draco11](std::size_t&) { return runPclOctree(fov, draco11 / 2, 32 * draco11 / 2, 1); });
    addRow(rows, "pcl octree 1 mm", "point res 1 mm, octree 32 mm",
           [&fov](std::size_t&) { return runPclOctree(fov, 0.001, 0.032, 1); });
  } else if (!havePclOctree()) {
    std::printf("pcl octree codec: not built (PCL not found)\n");
  }
}

void runRounds(std::vector<Row>& rows, int runs) {
  // Rounds: each codec once per round, so a change in machine load hits every codec alike.
  for (int round = 0; round < runs; ++round) {
    for (Row& row : rows) {
      if (!row.run.error.empty()) continue;
      row.run = row.runner(row.datagrams);
      row.encode_ms.push_back(row.run.encode_ms);
      row.decode_ms.push_back(row.run.decode_ms);
    }
  }
  for (Row& row : rows) {
    row.run.encode_ms = median(row.encode_ms);
    row.run.decode_ms = median(row.decode_ms);
  }
}

// The table, against Draco 11-bit where it ran, and its legend; n: the foveated points.
void printTable(const std::vector<Row>& rows, double n) {
  const CodecRun* draco_ref = nullptr;
  for (const Row& r : rows) {
    if (r.name == "draco 11-bit" && r.run.error.empty()) draco_ref = &r.run;
  }
  std::printf("%-30s %9s %7s %7s %9s %9s %8s %8s %9s %9s %9s\n", "codec", "bytes", "B/pt", "wire B/pt", "enc ms",
              "dec ms", "enc ns/pt", "dec ns/pt", "max err mm", "B vs draco", "enc x draco");
  for (const Row& r : rows) {
    if (!r.run.error.empty()) {
      std::printf("%-30s %s\n", r.name.c_str(), r.run.error.c_str());
      continue;
    }
    const double bpp = static_cast<double>(r.run.bytes) / n;
    const double wire = static_cast<double>(r.run.bytes + r.datagrams * net::kDatagramOverhead) / n;
    std::printf("%-30s %9zu %7.3f %9.3f %9.3f %9.3f %8.1f %8.1f %9.3f", r.name.c_str(), r.run.bytes, bpp,
                r.datagrams ? wire : bpp, r.run.encode_ms, r.run.decode_ms, r.run.encode_ms * 1e6 / n,
                r.run.decode_ms * 1e6 / n, r.run.max_error_m * 1e3);
    if (draco_ref) {
      std::printf(" %9.2f %9.1f", static_cast<double>(r.run.bytes) / static_cast<double>(draco_ref->bytes),
                  draco_ref->encode_ms / r.run.encode_ms);
    }
    std::printf("\n");
  }
  std::printf("\nB/pt: payload bytes per point; wire B/pt adds %zu bytes of datagram framing per chunk.\n"
              "max err: the configuration's bound on the per-axis position error (largest region step / 2 for fovea).\n"
              "B vs draco: bytes relative to Draco 11-bit (below 1 is smaller); enc x draco: Draco 11-bit's encode time\n"
              "divided by this codec's (above 1 is faster).\n\n",
              net::kDatagramOverhead);
}

// One `codec="..." bytes=...` line per codec that ran.
void printMachineLines(const std::vector<Row>& rows, std::size_t points) {
  for (const Row& r : rows) {
    if (!r.run.error.empty()) continue;
    std::printf("codec=\"%s\" bytes=%zu points=%zu points_out=%zu datagrams=%zu enc_ms=%.4f dec_ms=%.4f max_err_m=%.6f  # %s\n",
                r.name.c_str(), r.run.bytes, points, r.run.points_out, r.datagrams, r.run.encode_ms, r.run.decode_ms,
                r.run.max_error_m, r.note.c_str());
  }
}

int run(int argc, char** argv) {
  CodecOptions options;
  if (std::optional<int> stop = parseOptions(argc, argv, options)) return *stop;
  Result<FrameInput> input = mockLivingRoom(640, 480);
  if (!input) {
    std::fprintf(stderr, "fovea-bench-codec: %s\n", input.status().toString().c_str());
    return 1;
  }
  Result<FoveatedFrame> frame = foveateFrame(input.value(), options.config);
  if (!frame) {
    std::fprintf(stderr, "fovea-bench-codec: %s\n", frame.status().toString().c_str());
    return 1;
  }
  const pipeline::FoveatedCloud& fov = frame->cloud;
  std::vector<double> voxel;
  for (int r = 0; r < frame->stats.region_count; ++r) {
    voxel.push_back(frame->stats.regions[static_cast<std::size_t>(r)].voxel_size_m);
  }
  printInput(input.value(), frame.value(), voxel, options);

  const double draco11 = dracoStep(fov, 11);
  std::vector<Row> rows;
  addFoveaRows(rows, fov, voxel, draco11, options.only);
  addBaselineRows(rows, fov, draco11, options.only);
  runRounds(rows, options.runs);
  printTable(rows, static_cast<double>(fov.size()));
  printMachineLines(rows, fov.size());
  return 0;
}

}  // namespace
}  // namespace fovea::bench

int main(int argc, char** argv) { return fovea::bench::run(argc, argv); }

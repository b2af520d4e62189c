// fovea-bench-recorder: what recording costs (docs/recording.md). Medians of
// 21 repetitions of:
//   record()   a stage's call: copy a message into a slot of the Recorder's ring
//              and publish it (4000 calls into a ring of 4096, nothing taking)
//   writer     the writer thread's work per MB of messages (Writer::write and
//              the chunks' compression and write() to a file in $TMPDIR),
//              zstd level 1 and uncompressed, on bytes as incompressible as
//              fovea's entropy-coded chunks (random) and on a JSON-like text
//   fovea-bench-recorder [MESSAGE_BYTES=1200]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <random>
#include <string>
#include <vector>

#include <unistd.h>

#include "io/mcap/recorder.h"
#include "io/mcap/writer.h"

namespace {

using Clock = std::chrono::steady_clock;

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

std::string tempPath() {
  const char* dir = std::getenv("TMPDIR");
  return std::string(dir && *dir ? dir : "/tmp") + "/fovea-bench-recorder-" + std::to_string(::getpid()) + ".mcap";
}

}  // namespace

int main(int argc, char** argv) {
  using namespace fovea::mcap;
  const std::size_t bytes = argc > 1 ? static_cast<std::size_t>(std::atol(argv[1])) : 1200;
  const int reps = 21;
  const int calls = 4000;
  std::vector<uint8_t> random(bytes);
  std::mt19937 rng(28);
  for (auto& b : random) b = static_cast<uint8_t>(rng());
  // Distinct incompressible messages (zstd would find a repeated one).
  std::vector<uint8_t> noise(16u << 20);
  for (auto& b : noise) b = static_cast<uint8_t>(rng());
  const std::string path = tempPath();

  std::vector<double> record_ns;
  for (int r = 0; r < reps; ++r) {
    RecorderConfig config;
    config.slots = 4096;
    config.slot_bytes = bytes;
    auto recorder = Recorder::open(path, config, nullptr);
    if (!recorder) {
      std::fprintf(stderr, "%s\n", recorder.status().toString().c_str());
      return 1;
    }
    auto channel = (*recorder)->addChannel("/bench", "raw", 0);
    RecorderProducer* producer = (*recorder)->addProducer();
    // Warm: every slot touched once (a service's ring is, after its first
    // seconds). The timed calls then find the ring full and drop its oldest, as
    // a ring whose writer fell behind does: the slower path.
    for (int i = 0; i < calls + 100; ++i) (void)producer->record(*channel, 0, random);
    const auto t0 = Clock::now();
    int recorded = 0;
    for (int i = 0; i < calls; ++i) recorded += producer->record(*channel, static_cast<uint64_t>(i), random) ? 1 : 0;
    const auto t1 = Clock::now();
    if (recorded != calls) std::fprintf(stderr, "only %d of %d recorded\n", recorded, calls);
    record_ns.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count() / calls);
  }
  std::printf("record() of %zu bytes: %.0f ns a call (median of %d x %d calls)\n", bytes, median(record_ns), reps, calls);

  std::string text;
  while (text.size() < bytes) text += "{\"frame_id\":12345,\"translation_m\":[0.125,1.5,-2.25],\"pose_fresh\":true}";
  text.resize(bytes);
  const std::vector<uint8_t> json(text.begin(), text.end());
  for (const auto& [data, what] : {std::pair<const std::vector<uint8_t>*, const char*>{&random, "random bytes (distinct)"},
                                 std::pair<const std::vector<uint8_t>*, const char*>{&json, "JSON text"}}) {
    for (Compression compression : {Compression::kZstd, Compression::kNone}) {
      std::vector<double> mb_per_s;
      double ratio = 0;
      for (int r = 0; r < reps; ++r) {
        WriterOptions options;
        options.compression = compression;
        auto writer = Writer::open(path, options);
        if (!writer) return 1;
        auto channel = (*writer)->addChannel("/bench", "raw", 0);
        const int messages = static_cast<int>((8u << 20) / bytes);  // 8 MB
        const auto t0 = Clock::now();
        for (int i = 0; i < messages; ++i) {
          std::span<const uint8_t> message(*data);
          if (data == &random) message = std::span<const uint8_t>(noise).subspan((static_cast<std::size_t>(i) * bytes) % (noise.size() - bytes), bytes);
          (void)(*writer)->write(*channel, static_cast<uint64_t>(i), 0, message);
        }
        if (!(*writer)->close()) return 1;
        const auto t1 = Clock::now();
        const double mb = static_cast<double>(messages) * static_cast<double>(bytes) / 1e6;
        mb_per_s.push_back(mb / std::chrono::duration<double>(t1 - t0).count());
        ratio = static_cast<double>((*writer)->statistics().file_bytes) / (mb * 1e6);
      }
      std::printf("writer, %s, %s: %.0f MB/s of messages, file %.3f x the messages' bytes\n", what,
                  compression == Compression::kZstd ? "zstd 1" : "uncompressed", median(mb_per_s), ratio);
    }
  }
  std::remove(path.c_str());
  return 0;
}

// fovea-bench-foxglove: a foveated frame's foxglove.PointCloud encoded as
// Protobuf (io/foxglove, what fovea-operator --foxglove and the recordings
// send) against JSON as Foxglove's "json" message encoding with the jsonschema
// schema would need it (the `data` field base64): bytes per message and encode
// time (median of thread CPU time over many runs, the encodings interleaved in
// each round). See docs/foxglove.md. Not a test: nothing is asserted.
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/bench_input.h"
#include "bench/codec_baselines.h"
#include "bench/foveated_frame.h"
#include "io/foxglove/foxglove.h"
#include "pipeline/foveator.h"

namespace fovea::bench {
namespace {

constexpr char kBase64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

void appendBase64(std::string& out, const uint8_t* p, std::size_t n) {
  std::size_t i = 0;
  for (; i + 3 <= n; i += 3) {
    const uint32_t v = (uint32_t{p[i]} << 16) | (uint32_t{p[i + 1]} << 8) | p[i + 2];
    const char q[4] = {kBase64[v >> 18], kBase64[(v >> 12) & 63], kBase64[(v >> 6) & 63], kBase64[v & 63]};
    out.append(q, 4);
  }
  if (const std::size_t rest = n - i; rest > 0) {
    const uint32_t v = (uint32_t{p[i]} << 16) | (rest == 2 ? uint32_t{p[i + 1]} << 8 : 0u);
    const char q[4] = {kBase64[v >> 18], kBase64[(v >> 12) & 63], rest == 2 ? kBase64[(v >> 6) & 63] : '=', '='};
    out.append(q, 4);
  }
}

// The point bytes, as the Protobuf encoder lays them out (x, y, z float32, rgba 0xAARRGGBB).
void packPoints(const pipeline::PointCloud& c, std::vector<uint8_t>& data) {
  data.resize(c.size() * foxglove::kPointStride);
  for (std::size_t i = 0; i < c.size(); ++i) {
    uint8_t* q = data.data() + i * foxglove::kPointStride;
    std::memcpy(q, &c.x()[i], 4);
    std::memcpy(q + 4, &c.y()[i], 4);
    std::memcpy(q + 8, &c.z()[i], 4);
    const uint32_t rgb = c.rgb()[i];
    q[12] = pipeline::rgbBlue(rgb);
    q[13] = pipeline::rgbGreen(rgb);
    q[14] = pipeline::rgbRed(rgb);
    q[15] = 0xff;
  }
}

// JSON written by hand into a reused string: the fastest a JSON encoder can be here.
std::size_t encodeJsonDirect(const pipeline::PointCloud& c, int64_t stamp_ns, std::vector<uint8_t>& data, std::string& out) {
  packPoints(c, data);
  out.clear();
  char head[512];
  const int n = std::snprintf(head, sizeof head,
                              "{\"timestamp\":{\"sec\":%" PRId64 ",\"nsec\":%" PRId64 "},\"frame_id\":\"world\","
                              "\"pose\":{\"position\":{\"x\":%.17g,\"y\":%.17g,\"z\":%.17g},"
                              "\"orientation\":{\"x\":0,\"y\":0,\"z\":0,\"w\":1}},\"point_stride\":16,"
                              "\"fields\":[{\"name\":\"x\",\"offset\":0,\"type\":7},{\"name\":\"y\",\"offset\":4,\"type\":7},"
                              "{\"name\":\"z\",\"offset\":8,\"type\":7},{\"name\":\"rgba\",\"offset\":12,\"type\":5}],\"data\":\"",
                              stamp_ns / 1'000'000'000, stamp_ns % 1'000'000'000, c.origin_m.x(), c.origin_m.y(),
                              c.origin_m.z());
  out.append(head, static_cast<std::size_t>(n));
  appendBase64(out, data.data(), data.size());
  out.append("\"}");
  return out.size();
}

// The same JSON through nlohmann-json (the JSON library fovea already links): a fresh document each time.
std::size_t encodeJsonLibrary(const pipeline::PointCloud& c, int64_t stamp_ns, std::vector<uint8_t>& data, std::string& out) {
  packPoints(c, data);
  std::string b64;
  b64.reserve((data.size() + 2) / 3 * 4);
  appendBase64(b64, data.data(), data.size());
  nlohmann::json j = {
      {"timestamp", {{"sec", stamp_ns / 1'000'000'000}, {"nsec", stamp_ns % 1'000'000'000}}},
      {"frame_id", "world"},
      {"pose", {{"position", {{"x", c.origin_m.x()}, {"y", c.origin_m.y()}, {"z", c.origin_m.z()}}},
                {"orientation", {{"x", 0}, {"y", 0}, {"z", 0}, {"w", 1}}}}},
      {"point_stride", 16},
      {"fields", nlohmann::json::array({{{"name", "x"}, {"offset", 0}, {"type", 7}},
                                        {{"name", "y"}, {"offset", 4}, {"type", 7}},
                                        {{"name", "z"}, {"offset", 8}, {"type", 7}},
                                        {{"name", "rgba"}, {"offset", 12}, {"type", 5}}})},
      {"data", std::move(b64)}};
  out = j.dump();
  return out.size();
}

int usage() {
  std::fprintf(stderr, "usage: fovea-bench-foxglove [--runs N] [--tum DIR --frame I]\n");
  return 2;
}

struct FoxgloveOptions {
  int runs = 200;
  std::string tum;
  int tum_frame = 10;
};

// Returns the exit status of a usage error, else nothing.
std::optional<int> parseOptions(int argc, char** argv, FoxgloveOptions& options) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) return usage();
    if (a == "--runs") {
      options.runs = std::atoi(argv[++i]);
      if (options.runs < 1) return usage();
    } else if (a == "--tum") {
      options.tum = argv[++i];
    } else if (a == "--frame") {
      options.tum_frame = std::atoi(argv[++i]);
    } else {
      return usage();
    }
  }
  return std::nullopt;
}

// Each encoding's bytes and median encode time, over `runs` rounds.
struct Encodings {
  std::size_t proto_bytes = 0, direct_bytes = 0, library_bytes = 0;
  double proto_ms = 0, direct_ms = 0, library_ms = 0;
};

Encodings timeEncodings(const pipeline::PointCloud& pts, int runs) {
  foxglove::PointCloudEncoder proto;
  std::vector<uint8_t> data;
  std::string json_direct, json_library;
  const int64_t stamp = 1'764'000'000'123'456'789;
  Encodings e;
  e.proto_bytes = proto.encode(pts, "world", stamp).size();
  e.direct_bytes = encodeJsonDirect(pts, stamp, data, json_direct);
  e.library_bytes = encodeJsonLibrary(pts, stamp, data, json_library);
  std::vector<double> t_proto, t_direct, t_library;
  using Clock = ThreadCpuClock;
  auto ms = [](Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); };
  for (int r = 0; r < runs; ++r) {
    const auto t0 = Clock::now();
    e.proto_bytes = proto.encode(pts, "world", stamp + r).size();
    const auto t1 = Clock::now();
    e.direct_bytes = encodeJsonDirect(pts, stamp + r, data, json_direct);
    const auto t2 = Clock::now();
    e.library_bytes = encodeJsonLibrary(pts, stamp + r, data, json_library);
    const auto t3 = Clock::now();
    t_proto.push_back(ms(t0, t1));
    t_direct.push_back(ms(t1, t2));
    t_library.push_back(ms(t2, t3));
  }
  e.proto_ms = median(t_proto);
  e.direct_ms = median(t_direct);
  e.library_ms = median(t_library);
  return e;
}

void printTable(const Encodings& e, std::size_t points) {
  const double n = static_cast<double>(points);
  const double mp = e.proto_ms;
  std::printf("%-40s %12s %10s %12s %10s %8s\n", "encoding", "bytes", "B/point", "encode ms", "ns/point", "x proto");
  auto row = [&](const char* name, std::size_t bytes, double m) {
    std::printf("%-40s %12zu %10.2f %12.3f %10.1f %8.2f\n", name, bytes, static_cast<double>(bytes) / n, m, m * 1e6 / n,
                m / mp);
  };
  row("protobuf (io/foxglove, libprotobuf)", e.proto_bytes, mp);
  row("json, written by hand, data base64", e.direct_bytes, e.direct_ms);
  row("json, nlohmann-json, data base64", e.library_bytes, e.library_ms);
}

int run(int argc, char** argv) {
  FoxgloveOptions options;
  if (std::optional<int> stop = parseOptions(argc, argv, options)) return *stop;
  Result<FrameInput> input = options.tum.empty() ? mockLivingRoom(640, 480) : tumFrame(options.tum, options.tum_frame);
  if (!input) {
    std::fprintf(stderr, "fovea-bench-foxglove: %s\n", input.status().toString().c_str());
    return 1;
  }
  const pipeline::FoveationConfig config;
  Result<FoveatedFrame> frame = foveateFrame(input.value(), config);
  if (!frame) {
    std::fprintf(stderr, "fovea-bench-foxglove: %s\n", frame.status().toString().c_str());
    return 1;
  }
  const pipeline::PointCloud& pts = frame->cloud.points;
  std::printf("input: %s, preset %s: %zu foveated points; %d rounds (each encoding once per round, after a warm-up), "
              "medians of thread CPU time\n\n",
              input->description.c_str(), std::string(pipeline::presetName(config.acuity.preset)).c_str(), pts.size(),
              options.runs);
  printTable(timeEncodings(pts, options.runs), pts.size());
  return 0;
}

}  // namespace
}  // namespace fovea::bench

int main(int argc, char** argv) { return fovea::bench::run(argc, argv); }

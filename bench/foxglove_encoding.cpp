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
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/bench_input.h"
#include "bench/codec_baselines.h"
#include "io/foxglove/foxglove.h"
#include "pipeline/backproject.h"
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

}  // namespace
}  // namespace fovea::bench

int main(int argc, char** argv) {
  using namespace fovea;
  using namespace fovea::bench;
  int runs = 200;
  std::string tum;
  int tum_frame = 10;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) return usage();
    if (a == "--runs") {
      runs = std::atoi(argv[++i]);
      if (runs < 1) return usage();
    } else if (a == "--tum") {
      tum = argv[++i];
    } else if (a == "--frame") {
      tum_frame = std::atoi(argv[++i]);
    } else {
      return usage();
    }
  }
  Result<FrameInput> input = tum.empty() ? mockLivingRoom(640, 480) : tumFrame(tum, tum_frame);
  if (!input) {
    std::fprintf(stderr, "fovea-bench-foxglove: %s\n", input.status().toString().c_str());
    return 1;
  }
  const hal::RgbdFrame& frame = input->frame;
  const std::size_t pixels = static_cast<std::size_t>(frame.width()) * frame.height();
  pipeline::PointCloud cloud(pixels);
  pipeline::BackprojectCounts counts;
  pipeline::FoveationConfig config;
  Result<pipeline::Foveator> foveator = pipeline::Foveator::create({pixels, pixels}, config);
  pipeline::FoveatedCloud fov(pixels);
  pipeline::FoveationStats stats;
  if (Status s = pipeline::backprojectRef(frame, pipeline::DepthRange{}, cloud, counts); !s) {
    std::fprintf(stderr, "fovea-bench-foxglove: %s\n", s.toString().c_str());
    return 1;
  }
  if (!foveator) {
    std::fprintf(stderr, "fovea-bench-foxglove: %s\n", foveator.status().toString().c_str());
    return 1;
  }
  if (Status s = foveator->foveate(cloud, input->gaze, fov, stats); !s) {
    std::fprintf(stderr, "fovea-bench-foxglove: %s\n", s.toString().c_str());
    return 1;
  }
  const pipeline::PointCloud& pts = fov.points;
  std::printf("input: %s, preset %s: %zu foveated points; %d rounds (each encoding once per round, after a warm-up), "
              "medians of thread CPU time\n\n",
              input->description.c_str(), std::string(pipeline::presetName(config.acuity.preset)).c_str(), pts.size(), runs);

  foxglove::PointCloudEncoder proto;
  std::vector<uint8_t> data;
  std::string json_direct, json_library;
  const int64_t stamp = 1'764'000'000'123'456'789;
  std::size_t proto_bytes = proto.encode(pts, "world", stamp).size();
  std::size_t direct_bytes = encodeJsonDirect(pts, stamp, data, json_direct);
  std::size_t library_bytes = encodeJsonLibrary(pts, stamp, data, json_library);
  std::vector<double> t_proto, t_direct, t_library;
  using Clock = ThreadCpuClock;
  auto ms = [](Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); };
  for (int r = 0; r < runs; ++r) {
    const auto t0 = Clock::now();
    proto_bytes = proto.encode(pts, "world", stamp + r).size();
    const auto t1 = Clock::now();
    direct_bytes = encodeJsonDirect(pts, stamp + r, data, json_direct);
    const auto t2 = Clock::now();
    library_bytes = encodeJsonLibrary(pts, stamp + r, data, json_library);
    const auto t3 = Clock::now();
    t_proto.push_back(ms(t0, t1));
    t_direct.push_back(ms(t1, t2));
    t_library.push_back(ms(t2, t3));
  }
  const double n = static_cast<double>(pts.size());
  const double mp = median(t_proto), md = median(t_direct), ml = median(t_library);
  std::printf("%-40s %12s %10s %12s %10s %8s\n", "encoding", "bytes", "B/point", "encode ms", "ns/point", "x proto");
  auto row = [&](const char* name, std::size_t bytes, double m) {
    std::printf("%-40s %12zu %10.2f %12.3f %10.1f %8.2f\n", name, bytes, static_cast<double>(bytes) / n, m, m * 1e6 / n,
                m / mp);
  };
  row("protobuf (io/foxglove, libprotobuf)", proto_bytes, mp);
  row("json, written by hand, data base64", direct_bytes, md);
  row("json, nlohmann-json, data base64", library_bytes, ml);
  return 0;
}

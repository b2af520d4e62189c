// The chunk codec (net/codec.h): round trips within half a quantization step,
// datagram sizes, loss of any chunk, range limits and hostile payloads.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <random>
#include <span>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#define ZSTD_STATIC_LINKING_ONLY  // the context size estimates
#include <zstd.h>

#include "net/chunk_header.h"
#include "net/codec.h"
#include "tests/support/clouds.h"
#include "tests/unit/net/mock_frame.h"

namespace fovea::net {
namespace {

using Key = std::tuple<int, int64_t, int64_t, int64_t>;  // region, lattice x y z

const test::MockFoveatedFrame& livingRoom() {
  static const test::MockFoveatedFrame frame = test::mockFoveatedFrame();
  return frame;
}

ChunkEncoder makeEncoder(const CodecConfig& config, std::size_t max_points) {
  Result<ChunkEncoder> enc = ChunkEncoder::create(config, max_points);
  EXPECT_TRUE(enc.isOk()) << enc.status().toString();
  return std::move(enc).value();
}

// Decodes every chunk of the encoder into one cloud.
pipeline::FoveatedCloud decodeAll(const ChunkEncoder& enc, std::size_t capacity) {
  pipeline::FoveatedCloud out(capacity);
  for (std::size_t i = 0; i < enc.chunkCount(); ++i) {
    Result<DecodedChunk> d = decodeChunk(enc.chunk(i), out);
    EXPECT_TRUE(d.isOk()) << "chunk " << i << ": " << d.status().toString();
  }
  return out;
}

// Checks the decoded cloud against the source: the same multiset of lattice
// points per region, every source point within half a step of its lattice point
// (per axis), every decoded point on it; colours exact, or with halved chroma
// exact in the fovea and close elsewhere (mean channel error returned).
double expectRoundTrip(const pipeline::FoveatedCloud& src, const pipeline::FoveatedCloud& dec, const ChunkEncoder& enc,
                       bool exact_colour) {
  double error_sum = 0.0;
  std::size_t error_count = 0;
  EXPECT_EQ(src.size(), dec.size());
  if (src.size() != dec.size()) return 1e9;
  std::map<Key, std::vector<uint32_t>> source;  // lattice point -> colours
  for (std::size_t i = 0; i < src.size(); ++i) {
    const int r = src.region[i];
    const double step = enc.regionStep(r);
    const Eigen::Vector3d w = src.points.world(i);
    Key key{r, std::llround(w.x() / step), std::llround(w.y() / step), std::llround(w.z() / step)};
    // Float input far from the origin: allow the float's own rounding.
    const double slack = 1e-9 + 1e-7 * w.norm();
    EXPECT_LE(std::fabs(w.x() - std::get<1>(key) * step), step / 2 + slack);
    EXPECT_LE(std::fabs(w.y() - std::get<2>(key) * step), step / 2 + slack);
    EXPECT_LE(std::fabs(w.z() - std::get<3>(key) * step), step / 2 + slack);
    source[key].push_back(src.points.rgb()[i]);
  }
  for (std::size_t i = 0; i < dec.size(); ++i) {
    const int r = dec.region[i];
    const double step = enc.regionStep(r);
    const Eigen::Vector3d w = dec.points.world(i);
    Key key{r, std::llround(w.x() / step), std::llround(w.y() / step), std::llround(w.z() / step)};
    const double slack = 1e-9 + 2e-7 * (w - dec.points.origin_m).norm() + 1e-12 * w.norm();
    const double off = (w - Eigen::Vector3d(std::get<1>(key), std::get<2>(key), std::get<3>(key)) * step).cwiseAbs().maxCoeff();
    EXPECT_LE(off, slack) << "decoded point " << i << " is off its lattice point";
    auto it = source.find(key);
    EXPECT_NE(it, source.end()) << "decoded point " << i << " matches no source point";
    if (it == source.end()) return 1e9;
    std::vector<uint32_t>& colours = it->second;
    EXPECT_FALSE(colours.empty()) << "decoded point " << i << ": more decoded points than source points there";
    if (colours.empty()) return 1e9;
    const uint32_t got = dec.points.rgb()[i];
    if (exact_colour || r == 0) {
      auto c = std::find(colours.begin(), colours.end(), got);
      EXPECT_NE(c, colours.end()) << "decoded point " << i << " (region " << r << "): colour differs";
      if (c == colours.end()) return 1e9;
      colours.erase(c);
    } else {
      auto channelError = [got](uint32_t c) {
        return std::abs(pipeline::rgbRed(c) - pipeline::rgbRed(got)) + std::abs(pipeline::rgbGreen(c) - pipeline::rgbGreen(got)) +
               std::abs(pipeline::rgbBlue(c) - pipeline::rgbBlue(got));
      };
      auto c = std::min_element(colours.begin(), colours.end(),
                                [&](uint32_t a, uint32_t b) { return channelError(a) < channelError(b); });
      error_sum += channelError(*c) / 3.0;
      ++error_count;
      colours.erase(c);
    }
  }
  return error_count ? error_sum / static_cast<double>(error_count) : 0.0;
}

TEST(CodecConfig, DefaultsAreValidAndErrorsNameTheField) {
  EXPECT_TRUE(validate(CodecConfig{}).isOk());
  CodecConfig c;
  c.max_payload = 100;
  EXPECT_NE(validate(c).message().find("codec.max_payload"), std::string::npos);
  c = {};
  c.fovea_step_m = std::nan("");
  EXPECT_NE(validate(c).message().find("codec.fovea_step_m"), std::string::npos);
  c = {};
  c.periphery_step_ratio = 0.0;
  EXPECT_NE(validate(c).message().find("codec.periphery_step_ratio"), std::string::npos);
  c = {};
  c.zstd_level = 30;
  EXPECT_NE(validate(c).message().find("codec.zstd_level"), std::string::npos);
  EXPECT_FALSE(ChunkEncoder::create(CodecConfig{}, 0).isOk());
}

struct Variant {
  bool entropy;
  bool half_chroma;
};
class CodecRoundTrip : public ::testing::TestWithParam<Variant> {};

TEST_P(CodecRoundTrip, MockLivingRoomWithinHalfAStep) {
  const test::MockFoveatedFrame& f = livingRoom();
  ASSERT_GT(f.cloud.size(), 10000u);
  CodecConfig config;
  config.entropy_coding = GetParam().entropy;
  config.halve_peripheral_chroma = GetParam().half_chroma;
  ChunkEncoder enc = makeEncoder(config, f.cloud.size());
  ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, 7, f.capture_ns).isOk());
  EXPECT_DOUBLE_EQ(enc.regionStep(0), 0.001);
  for (std::size_t r = 1; r < f.voxel_size_m.size(); ++r) {
    EXPECT_DOUBLE_EQ(enc.regionStep(static_cast<int>(r)), f.voxel_size_m[r] * 0.125);
  }
  const pipeline::FoveatedCloud dec = decodeAll(enc, f.cloud.size());
  const double colour_error = expectRoundTrip(f.cloud, dec, enc, !GetParam().half_chroma);
  // Halved chroma: a small mean error per channel outside the fovea (exact inside).
  EXPECT_LT(colour_error, GetParam().half_chroma ? 6.0 : 1e-12);
  // Chunks: fovea first then outward, indices in order, the count everywhere.
  uint8_t last_region = 0;
  for (std::size_t i = 0; i < enc.chunkCount(); ++i) {
    pipeline::FoveatedCloud one(f.cloud.size());
    Result<DecodedChunk> d = decodeChunk(enc.chunk(i), one);
    ASSERT_TRUE(d.isOk());
    EXPECT_EQ(d->frame_id, 7u);
    EXPECT_EQ(d->chunk_index, i);
    EXPECT_EQ(d->chunk_count, enc.chunkCount());
    EXPECT_EQ(d->capture_time_ns, f.capture_ns);
    EXPECT_EQ(d->region, enc.chunkRegion(i));
    EXPECT_EQ(d->points, enc.chunkPoints(i));
    EXPECT_GE(d->region, last_region);
    last_region = d->region;
  }
}

INSTANTIATE_TEST_SUITE_P(Variants, CodecRoundTrip,
                         ::testing::Values(Variant{false, false}, Variant{true, false}, Variant{false, true},
                                           Variant{true, true}),
                         [](const ::testing::TestParamInfo<Variant>& info) {
                           return std::string(info.param.entropy ? "Zstd" : "Raw") +
                                  (info.param.half_chroma ? "HalfChroma" : "FullChroma");
                         });

TEST(CodecColour, HalvedChromaOfAUniformColourIsWithinOneLevel) {
  pipeline::FoveatedCloud cloud(1000);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  const uint32_t colours[] = {pipeline::packRgb(200, 100, 50), pipeline::packRgb(0, 255, 0),
                              pipeline::packRgb(255, 255, 255), pipeline::packRgb(0, 0, 0), pipeline::packRgb(13, 7, 250)};
  for (uint32_t colour : colours) {
    cloud.clear();
    for (int i = 0; i < 500; ++i) {
      ASSERT_TRUE(cloud.points.push(u(rng), u(rng), u(rng), colour));
      cloud.region[static_cast<std::size_t>(i)] = 1;
    }
    CodecConfig config;
    config.halve_peripheral_chroma = true;
    ChunkEncoder enc = makeEncoder(config, 1000);
    const double voxel[] = {0.0, 0.02};
    ASSERT_TRUE(enc.encode(cloud, voxel, 1, 0).isOk());
    const pipeline::FoveatedCloud dec = decodeAll(enc, 1000);
    ASSERT_EQ(dec.size(), 500u);
    for (std::size_t i = 0; i < dec.size(); ++i) {
      const uint32_t c = dec.points.rgb()[i];
      EXPECT_LE(std::abs(pipeline::rgbRed(c) - pipeline::rgbRed(colour)), 1) << std::hex << colour;
      EXPECT_LE(std::abs(pipeline::rgbGreen(c) - pipeline::rgbGreen(colour)), 1) << std::hex << colour;
      EXPECT_LE(std::abs(pipeline::rgbBlue(c) - pipeline::rgbBlue(colour)), 1) << std::hex << colour;
    }
  }
}

class CodecMtu : public ::testing::TestWithParam<std::size_t> {};

TEST_P(CodecMtu, EveryChunkFitsItsDatagramAndDecodesAlone) {
  const test::MockFoveatedFrame& f = livingRoom();
  for (bool entropy : {false, true}) {
    CodecConfig config;
    config.max_payload = GetParam() - kDatagramOverhead;
    config.entropy_coding = entropy;
    config.halve_peripheral_chroma = entropy;
    ChunkEncoder enc = makeEncoder(config, f.cloud.size());
    ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, 1, 0).isOk());
    std::size_t points = 0;
    // One cloud, emptied before each chunk: a fresh frame-sized cloud per chunk
    // cost a minute under ASan at the smallest MTU (thousands of chunks).
    pipeline::FoveatedCloud one(f.cloud.size());
    for (std::size_t i = 0; i < enc.chunkCount(); ++i) {
      ASSERT_LE(enc.chunk(i).size(), config.max_payload) << "chunk " << i;
      one.clear();
      Result<DecodedChunk> d = decodeChunk(enc.chunk(i), one);
      ASSERT_TRUE(d.isOk()) << d.status().toString();
      points += d->points;
    }
    EXPECT_EQ(points, f.cloud.size());
    if (GetParam() == kMaxMtu) {
      EXPECT_LT(enc.chunkCount(), 40u);  // jumbo datagrams: few chunks
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Mtus, CodecMtu, ::testing::Values(kMinMtu, kDefaultMtu, kMaxMtu));

// The decoder fills a cloud made without weights (the operator's own choice)
// with the same points.
TEST(CodecFrames, ACloudWithoutWeightsDecodesTheSamePoints) {
  pipeline::FoveatedCloud cloud(3000);
  cloud.points = test::randomCloud(3000, Eigen::Vector3d(1.0, 2.0, 0.5), 2.0f, 5);
  for (std::size_t i = 0; i < 3000; ++i) cloud.region[i] = static_cast<uint8_t>(i % 3);
  ChunkEncoder enc = makeEncoder(CodecConfig{}, 3000);
  const double voxel[] = {0.0, 0.01, 0.05};
  ASSERT_TRUE(enc.encode(cloud, voxel, 1, 0).isOk());
  const pipeline::FoveatedCloud with = decodeAll(enc, 3000);
  pipeline::FoveatedCloud without(3000, pipeline::FoveatedCloud::Weights::kNone);
  for (std::size_t i = 0; i < enc.chunkCount(); ++i) ASSERT_TRUE(decodeChunk(enc.chunk(i), without).isOk());
  ASSERT_EQ(without.size(), with.size());
  for (std::size_t o = 0; o < with.size(); ++o) {
    ASSERT_EQ(without.points.x()[o], with.points.x()[o]) << o;
    ASSERT_EQ(without.points.rgb()[o], with.points.rgb()[o]) << o;
    ASSERT_EQ(without.region[o], with.region[o]) << o;
  }
  EXPECT_FALSE(without.hasWeights());
}

TEST(CodecLoss, DroppedChunksCostOnlyTheirOwnPoints) {
  const test::MockFoveatedFrame& f = livingRoom();
  ChunkEncoder enc = makeEncoder(CodecConfig{}, f.cloud.size());
  ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, 1, 0).isOk());
  std::mt19937 rng(11);
  for (int trial = 0; trial < 5; ++trial) {
    pipeline::FoveatedCloud out(f.cloud.size());
    std::size_t expected = 0, dropped = 0;
    for (std::size_t i = 0; i < enc.chunkCount(); ++i) {
      if (rng() % 10 == 0) {
        ++dropped;
        continue;
      }
      ASSERT_TRUE(decodeChunk(enc.chunk(i), out).isOk());
      expected += enc.chunkPoints(i);
    }
    EXPECT_GT(dropped, 0u);
    EXPECT_EQ(out.size(), expected);
  }
}

TEST(CodecFrames, EmptyFrameHasNoChunksAndASummary) {
  ChunkEncoder enc = makeEncoder(CodecConfig{}, 100);
  pipeline::FoveatedCloud empty(100);
  const double voxel[] = {0.0};
  ASSERT_TRUE(enc.encode(empty, voxel, 5, 0).isOk());
  EXPECT_EQ(enc.chunkCount(), 0u);
  const uint16_t sent[] = {0, 0, 0, 0};
  Result<FrameSummaryInfo> s = decodeSummary(enc.encodeSummary(5, sent, sent));
  ASSERT_TRUE(s.isOk()) << s.status().toString();
  EXPECT_EQ(s->frame_id, 5u);
  EXPECT_EQ(s->chunk_count, 0u);
  EXPECT_EQ(s->region_count, 4);
}

TEST(CodecFrames, SummaryRoundTrip) {
  const test::MockFoveatedFrame& f = livingRoom();
  ChunkEncoder enc = makeEncoder(CodecConfig{}, f.cloud.size());
  ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, 9, 0).isOk());
  std::array<uint16_t, 4> sent{}, cut{};
  for (std::size_t i = 0; i < enc.chunkCount(); ++i) ++sent[enc.chunkRegion(i)];
  cut[3] = sent[3];
  sent[3] = 0;
  Result<FrameSummaryInfo> s = decodeSummary(enc.encodeSummary(9, sent, cut));
  ASSERT_TRUE(s.isOk());
  EXPECT_EQ(s->chunk_count, enc.chunkCount());
  for (std::size_t r = 0; r < 4; ++r) {
    EXPECT_EQ(s->chunks_sent[r], sent[r]);
    EXPECT_EQ(s->chunks_cut[r], cut[r]);
  }
}

TEST(CodecFrames, FrameLargerThanAnyBudget) {
  // 300 000 random points in a 4 m cube, all in the fovea (1 mm steps), 256-byte datagrams.
  const std::size_t n = 300000;
  pipeline::FoveatedCloud cloud(n);
  cloud.points = test::randomCloud(n, Eigen::Vector3d(1, 2, 3), 2.0f, 42);
  std::fill(cloud.region.begin(), cloud.region.end(), uint8_t{0});
  CodecConfig config;
  config.max_payload = kMinMtu - kDatagramOverhead;
  ChunkEncoder enc = makeEncoder(config, n);
  const double voxel[] = {0.0};
  ASSERT_TRUE(enc.encode(cloud, voxel, 1, 0).isOk());
  EXPECT_GT(enc.chunkCount(), 1000u);
  for (std::size_t i = 0; i < enc.chunkCount(); ++i) ASSERT_LE(enc.chunk(i).size(), config.max_payload);
  expectRoundTrip(cloud, decodeAll(enc, n), enc, true);
  // More points than the encoder was made for: a clear error.
  ChunkEncoder small = makeEncoder(config, 1000);
  Status st = small.encode(cloud, voxel, 1, 0);
  EXPECT_EQ(st.code(), ErrorCode::kCapacityExceeded);
  EXPECT_EQ(small.chunkCount(), 0u);
}

// Two encoders that share their per-point arrays (the streamer's frame and
// brick encoders) and encode in turn give, chunk for chunk, the bytes each
// gives with arrays of its own; a shared set smaller than an encoder is refused.
std::vector<std::vector<uint8_t>> chunksOf(const ChunkEncoder& enc) {
  std::vector<std::vector<uint8_t>> out;
  for (std::size_t i = 0; i < enc.chunkCount(); ++i) out.emplace_back(enc.chunk(i).begin(), enc.chunk(i).end());
  return out;
}

TEST(CodecScratch, EncodersSharingTheirPointArraysGiveTheBytesOfEncodersAlone) {
  const std::size_t frame_points = 20000, brick_points = 4000;
  CodecConfig config;
  config.entropy_coding = true;
  const double voxel[] = {0.0, 0.002, 0.004};
  const BrickTag tag{-3, 7, 0, 5, 2};
  std::shared_ptr<ChunkEncoder::PointScratch> shared = ChunkEncoder::makePointScratch(frame_points);
  Result<ChunkEncoder> frame_shared = ChunkEncoder::create(config, frame_points, shared);
  Result<ChunkEncoder> brick_shared = ChunkEncoder::create(config, brick_points, shared);
  ASSERT_TRUE(frame_shared.isOk() && brick_shared.isOk());
  shared.reset();  // the encoders keep it
  ChunkEncoder frame_alone = makeEncoder(config, frame_points), brick_alone = makeEncoder(config, brick_points);
  for (uint64_t seed = 1; seed <= 3; ++seed) {
    SCOPED_TRACE(testing::Message() << "seed " << seed);
    pipeline::FoveatedCloud frame(frame_points), brick(brick_points);
    frame.points = test::randomCloud(frame_points - 1000 * seed, Eigen::Vector3d(1, 2, 3), 2.0f, seed);
    for (std::size_t i = 0; i < frame.size(); ++i) frame.region[i] = static_cast<uint8_t>((i * 7 + seed) % 3);
    brick.points = test::randomCloud(brick_points - 500 * seed, Eigen::Vector3d(-1.25, 3.75, 0.25), 0.25f, 100 + seed);
    std::fill(brick.region.begin(), brick.region.begin() + static_cast<std::ptrdiff_t>(brick.size()), uint8_t{2});
    // In turn, as the send stage does: the frame, then a brick, then the frame again.
    ASSERT_TRUE(frame_shared->encode(frame, voxel, 10, 20).isOk());
    const auto first = chunksOf(*frame_shared);
    ASSERT_TRUE(brick_shared->encode(brick, voxel, 10, 20, &tag).isOk());
    ASSERT_TRUE(brick_alone.encode(brick, voxel, 10, 20, &tag).isOk());
    EXPECT_EQ(chunksOf(*brick_shared), chunksOf(brick_alone));
    EXPECT_EQ(chunksOf(*frame_shared), first) << "the frame's chunks stay as they were while a brick is encoded";
    ASSERT_TRUE(frame_alone.encode(frame, voxel, 10, 20).isOk());
    EXPECT_EQ(first, chunksOf(frame_alone));
    ASSERT_GT(first.size(), 3u);
  }
  Result<ChunkEncoder> too_big = ChunkEncoder::create(config, frame_points + 1, ChunkEncoder::makePointScratch(frame_points));
  EXPECT_EQ(too_big.status().code(), ErrorCode::kInvalidArgument);
  EXPECT_NE(too_big.status().message().find("shared point scratch"), std::string::npos) << too_big.status().message();
}

// An encoder capped at fewer chunks than its points may need (the streamer's
// brick encoder, at the sender's parts a version): the arena holds that many;
// a cloud within the cap gives the bytes of an encoder without it, one beyond
// it is a capacity error that leaves no chunk, and a cap above what the points
// can need changes nothing.
TEST(CodecCapacity, ACappedEncoderHoldsItsCapAndRefusesACloudBeyondIt) {
  const std::size_t n = 6000;
  CodecConfig config;
  const double voxel[] = {0.0};
  ChunkEncoder whole = makeEncoder(config, n);
  EXPECT_EQ(whole.maxChunkCount(), maxChunks(config, n));
  pipeline::FoveatedCloud cloud(n);
  cloud.points = test::randomCloud(n, Eigen::Vector3d(1, 2, 3), 2.0f, 17);
  std::fill(cloud.region.begin(), cloud.region.end(), uint8_t{0});
  ASSERT_TRUE(whole.encode(cloud, voxel, 3, 4).isOk());
  const std::size_t needed = whole.chunkCount();
  ASSERT_GT(needed, 10u);
  ASSERT_LT(needed, maxChunks(config, n));

  Result<ChunkEncoder> at_need = ChunkEncoder::create(config, n, nullptr, needed);
  ASSERT_TRUE(at_need.isOk()) << at_need.status().toString();
  EXPECT_EQ(at_need->maxChunkCount(), needed);
  ASSERT_TRUE(at_need->encode(cloud, voxel, 3, 4).isOk());
  EXPECT_EQ(chunksOf(*at_need), chunksOf(whole));

  Result<ChunkEncoder> below = ChunkEncoder::create(config, n, nullptr, needed - 1);
  ASSERT_TRUE(below.isOk());
  const Status st = below->encode(cloud, voxel, 3, 4);
  EXPECT_EQ(st.code(), ErrorCode::kCapacityExceeded);
  EXPECT_NE(st.message().find(std::to_string(needed - 1) + " chunks"), std::string::npos) << st.message();
  EXPECT_EQ(below->chunkCount(), 0u);
  // A smaller cloud still fits it, and the encoder works after the error.
  ASSERT_TRUE(cloud.points.resize(n / 4));
  ASSERT_TRUE(below->encode(cloud, voxel, 3, 4).isOk());
  ASSERT_TRUE(whole.encode(cloud, voxel, 3, 4).isOk());
  EXPECT_EQ(chunksOf(*below), chunksOf(whole));

  Result<ChunkEncoder> above = ChunkEncoder::create(config, n, nullptr, 10 * maxChunks(config, n));
  ASSERT_TRUE(above.isOk());
  EXPECT_EQ(above->maxChunkCount(), maxChunks(config, n));
}

// zstd's context is sized for a chunk, not for a source of any size
// (zstdWorkspaceBytes): at every level the configuration allows and at the
// smallest, the default and the largest MTU, the library's own estimate for
// every source size up to the largest chunk is within it; and encoders with
// entropy coding compress chunks at every level (a context too small would
// fail each compression, which the encoder takes as "does not pay" and sends
// the chunk as it is: no chunk would carry the zstd flag).
TEST(CodecEntropy, TheChunkSizedZstdContextCompressesAtEveryLevel) {
  for (int level = -7; level <= 9; ++level) {
    SCOPED_TRACE(testing::Message() << "level " << level);
    for (std::size_t payload : {codec_detail::kMinPayload, kDefaultMtu - kDatagramOverhead, codec_detail::kMaxPayload}) {
      const std::size_t bound = payload + 64;  // the encoder's raw chunk buffer
      const std::size_t bytes = zstdWorkspaceBytes(level, bound);
      EXPECT_LT(bytes, ZSTD_estimateCCtxSize(level));
      for (std::size_t n = 1; n <= bound; ++n) {
        ASSERT_LE(ZSTD_estimateCCtxSize_usingCParams(ZSTD_getCParams(level, n, 0)), bytes) << n << " bytes";
      }
    }
  }
  // A regular grid in one colour: its chunks' data repeats, and zstd pays.
  const std::size_t n = 8000;
  pipeline::FoveatedCloud cloud(n);
  for (std::size_t i = 0; i < n; ++i) {
    ASSERT_TRUE(cloud.points.push(0.004f * static_cast<float>(i % 20), 0.004f * static_cast<float>((i / 20) % 20),
                                  1.0f + 0.004f * static_cast<float>(i / 400), 0x406080));
    cloud.region[i] = 0;
  }
  const double voxel[] = {0.0};
  for (int level = -7; level <= 9; ++level) {
    SCOPED_TRACE(testing::Message() << "level " << level);
    CodecConfig config;
    config.entropy_coding = true;
    config.zstd_level = level;
    ChunkEncoder enc = makeEncoder(config, n);
    ASSERT_TRUE(enc.encode(cloud, voxel, 1, 0).isOk());
    std::size_t compressed = 0;
    for (std::size_t i = 0; i < enc.chunkCount(); ++i) {
      compressed += (enc.chunk(i)[18] & codec_detail::kHeaderFlagZstd) != 0;  // the region and flags byte
    }
    EXPECT_EQ(compressed, enc.chunkCount());
    expectRoundTrip(cloud, decodeAll(enc, n), enc, true);
  }
}

TEST(CodecRange, PointsFarFromTheWorldOrigin) {
  for (const Eigen::Vector3d& origin : {Eigen::Vector3d(1e4, -2e4, 5e3), Eigen::Vector3d(-3e6, 4e6, 1e5)}) {
    pipeline::FoveatedCloud cloud(5000);
    cloud.points = test::randomCloud(5000, origin, 3.0f, 7);
    for (std::size_t i = 0; i < 5000; ++i) cloud.region[i] = static_cast<uint8_t>(i % 3);
    ChunkEncoder enc = makeEncoder(CodecConfig{}, 5000);
    const double voxel[] = {0.0, 0.01, 0.05};
    ASSERT_TRUE(enc.encode(cloud, voxel, 1, 0).isOk());
    const pipeline::FoveatedCloud dec = decodeAll(enc, 5000);
    EXPECT_LT((dec.points.origin_m - origin).norm(), 10.0);  // floats stay small
    expectRoundTrip(cloud, dec, enc, true);
  }
}

TEST(CodecRange, RegionWiderThanTheLatticeIsAnErrorNotAWrap) {
  pipeline::FoveatedCloud cloud(10);
  ASSERT_TRUE(cloud.points.push(0.f, 0.f, 0.f, 0));
  ASSERT_TRUE(cloud.points.push(2100.f, 0.f, 0.f, 0));  // 2.1e6 steps of 1 mm > 2^21 - 1
  cloud.region[0] = cloud.region[1] = 0;
  ChunkEncoder enc = makeEncoder(CodecConfig{}, 10);
  const double voxel[] = {0.0};
  Status st = enc.encode(cloud, voxel, 1, 0);
  EXPECT_EQ(st.code(), ErrorCode::kRangeExceeded);
  EXPECT_NE(st.message().find("region 0 spans"), std::string::npos) << st.message();
  EXPECT_EQ(enc.chunkCount(), 0u);
  // 2000 m fits (2e6 steps), and round-trips.
  cloud.points.x()[1] = 2000.f;
  ASSERT_TRUE(enc.encode(cloud, voxel, 1, 0).isOk());
  expectRoundTrip(cloud, decodeAll(enc, 10), enc, true);
}

// The bounds come from each region's extremes; a point out of range is named
// as the first in the cloud, whichever region it is in.
TEST(CodecRange, TheFirstPointOutOfRangeIsNamed) {
  pipeline::FoveatedCloud cloud(10);
  for (int i = 0; i < 10; ++i) {
    ASSERT_TRUE(cloud.points.push(0.1f * static_cast<float>(i), 0.f, 1.f, 0));
    cloud.region[static_cast<std::size_t>(i)] = static_cast<uint8_t>(i % 2);
  }
  ChunkEncoder enc = makeEncoder(CodecConfig{}, 10);
  const double voxel[] = {0.0, 0.02};
  cloud.points.z()[6] = std::nanf("");
  cloud.points.y()[4] = std::numeric_limits<float>::infinity();
  Status st = enc.encode(cloud, voxel, 1, 0);
  EXPECT_EQ(st.code(), ErrorCode::kInvalidInput);
  EXPECT_NE(st.message().find("point 4 is not finite"), std::string::npos) << st.message();
  cloud.points.y()[4] = 1e15f;  // 1e18 steps of 1 mm
  st = enc.encode(cloud, voxel, 1, 0);
  EXPECT_EQ(st.code(), ErrorCode::kRangeExceeded);
  EXPECT_NE(st.message().find("point 4 is beyond"), std::string::npos) << st.message();
  cloud.points.y()[4] = 0.f;
  st = enc.encode(cloud, voxel, 1, 0);
  EXPECT_NE(st.message().find("point 6 is not finite"), std::string::npos) << st.message();
  cloud.points.z()[6] = 1.f;
  ASSERT_TRUE(enc.encode(cloud, voxel, 1, 0).isOk());
  expectRoundTrip(cloud, decodeAll(enc, 10), enc, true);
}

TEST(CodecRange, ExtremeAndNonFiniteCoordinates) {
  pipeline::FoveatedCloud cloud(10);
  ASSERT_TRUE(cloud.points.push(0.f, 0.f, 0.f, 0));
  cloud.region[0] = 0;
  ChunkEncoder enc = makeEncoder(CodecConfig{}, 10);
  const double voxel[] = {0.0};
  cloud.points.origin_m = Eigen::Vector3d(1e300, 0, 0);
  EXPECT_EQ(enc.encode(cloud, voxel, 1, 0).code(), ErrorCode::kRangeExceeded);
  cloud.points.origin_m = Eigen::Vector3d(0, -1e13, 0);  // 1e16 steps > 2^50
  EXPECT_EQ(enc.encode(cloud, voxel, 1, 0).code(), ErrorCode::kRangeExceeded);
  cloud.points.origin_m = Eigen::Vector3d::Zero();
  cloud.points.x()[0] = std::nanf("");
  EXPECT_EQ(enc.encode(cloud, voxel, 1, 0).code(), ErrorCode::kInvalidInput);
  cloud.points.x()[0] = 0.f;
  cloud.region[0] = 2;  // no voxel size for region 2
  EXPECT_EQ(enc.encode(cloud, voxel, 1, 0).code(), ErrorCode::kInvalidInput);
  const double bad_voxel[] = {0.0, 0.0, -1.0};
  EXPECT_EQ(enc.encode(cloud, bad_voxel, 1, 0).code(), ErrorCode::kInvalidInput);
  // The encoder still works after errors.
  cloud.region[0] = 0;
  ASSERT_TRUE(enc.encode(cloud, voxel, 1, 0).isOk());
  EXPECT_EQ(enc.chunkCount(), 1u);
}

// A small frame, whose chunks' bytes are pinned below (CodecWire): a change of the
// wire format must show here, and bump the protocol version (net/wire.h).
pipeline::FoveatedCloud smallFrame() {
  pipeline::FoveatedCloud cloud(16);
  for (int i = 0; i < 16; ++i) {
    EXPECT_TRUE(cloud.points.push(0.013f * static_cast<float>(i), -0.007f * static_cast<float>(i % 5),
                                  1.5f + 0.002f * static_cast<float>(i % 3),
                                  pipeline::packRgb(static_cast<uint8_t>(16 * i), 80, static_cast<uint8_t>(255 - 9 * i))));
    cloud.region[static_cast<std::size_t>(i)] = static_cast<uint8_t>(i % 2);
  }
  return cloud;
}

std::string hex(std::span<const uint8_t> bytes) {
  static const char* digits = "0123456789abcdef";
  std::string s;
  for (uint8_t b : bytes) s += {digits[b >> 4], digits[b & 15]};
  return s;
}

TEST(CodecWire, FrameChunkBytesAreUnchanged) {
  // Protocol version 2: the binary header (frame 42, capture 987654321 ns, chunk i of 2,
  // 8 points, region, step as a double, the origin's three zigzag varints), then the
  // data exactly as in version 1's FlatBuffers chunks (whose bytes were here before).
  const char* const golden[] = {
      // region 0 (fovea, 1 mm steps)
      "2a000000b168de3a0000000000000200080000fca9f1d24d62503f0037b8170f0307040de6856b92e11b9df1c73df85a16528b509308c93b32b89337887d26b290dad88d3dee41d9b2905a",
      // region 1 (voxel 2 cm, steps of 2.5 mm)
      "2a000000b168de3a00000000010002000800017b14ae47e17a643f0a15b0090c030704ca8690e53362a6c71ff7cb6e9be54c1a7fdc7965cb426a7505b290da01b2c71dc4b3210ba905",
  };
  ChunkEncoder enc = makeEncoder(CodecConfig{}, 16);
  const double voxel[] = {0.0, 0.02};
  ASSERT_TRUE(enc.encode(smallFrame(), voxel, 42, 987654321).isOk());
  ASSERT_EQ(enc.chunkCount(), std::size(golden));
  for (std::size_t i = 0; i < enc.chunkCount(); ++i) EXPECT_EQ(hex(enc.chunk(i)), golden[i]) << "chunk " << i;
}

// A map brick's surfels streamed as point chunks: the tag in every part.
TEST(CodecBrick, EveryPartCarriesTheTagFitsAndRoundTrips) {
  const std::size_t n = 4000;
  pipeline::FoveatedCloud cloud(n);
  cloud.points = test::randomCloud(n, Eigen::Vector3d(-1.25, 3.75, 0.25), 0.25f, 9);  // one 0.5 m brick
  std::fill(cloud.region.begin(), cloud.region.end(), uint8_t{2});
  const double voxel[] = {0.0, 0.002, 0.004};
  const BrickTag tag{-3, 7, 0, 0xfffffffeu, 3};
  for (std::size_t max_payload : {kMinMtu - kDatagramOverhead, kDefaultMtu - kDatagramOverhead}) {
    for (bool entropy : {false, true}) {
      CodecConfig config;
      config.max_payload = max_payload;
      config.entropy_coding = entropy;
      config.halve_peripheral_chroma = entropy;
      ChunkEncoder enc = makeEncoder(config, n);
      ASSERT_TRUE(enc.encode(cloud, voxel, 77, 555, &tag).isOk());
      ASSERT_GT(enc.chunkCount(), 3u);
      pipeline::FoveatedCloud one(n);
      for (std::size_t i = 0; i < enc.chunkCount(); ++i) {
        ASSERT_LE(enc.chunk(i).size(), max_payload) << "part " << i;
        one.clear();
        Result<DecodedChunk> d = decodeChunk(enc.chunk(i), one);
        ASSERT_TRUE(d.isOk()) << d.status().toString();
        EXPECT_TRUE(d->has_brick);
        EXPECT_EQ(d->brick.x, -3);
        EXPECT_EQ(d->brick.y, 7);
        EXPECT_EQ(d->brick.z, 0);
        EXPECT_EQ(d->brick.version, 0xfffffffeu);
        EXPECT_EQ(d->brick.level, 3);
        EXPECT_EQ(d->chunk_index, i);  // part i of chunkCount()
        EXPECT_EQ(d->chunk_count, enc.chunkCount());
        EXPECT_EQ(d->frame_id, 77u);
        EXPECT_EQ(d->capture_time_ns, 555u);
        EXPECT_EQ(d->points, enc.chunkPoints(i));
      }
      const double colour_error = expectRoundTrip(cloud, decodeAll(enc, n), enc, !entropy);
      EXPECT_LT(colour_error, entropy ? 40.0 : 1e-12);  // random colours: halved chroma is coarse
      // The same points as a frame: no tag, and no fewer points per chunk.
      const std::size_t brick_chunks = enc.chunkCount();
      ASSERT_TRUE(enc.encode(cloud, voxel, 77, 555).isOk());
      EXPECT_LE(enc.chunkCount(), brick_chunks);
      for (std::size_t i = 0; i < enc.chunkCount(); ++i) {
        one.clear();
        Result<DecodedChunk> d = decodeChunk(enc.chunk(i), one);
        ASSERT_TRUE(d.isOk());
        EXPECT_FALSE(d->has_brick);
      }
    }
  }
}

// The tag is 17 bytes after the origin (docs/protocol-chunks.md "Chunk header"):
// x, y, z, version (little-endian 32-bit), level.
std::vector<uint8_t> tagBytes(const BrickTag& tag) {
  std::vector<uint8_t> out;
  for (uint32_t v : {static_cast<uint32_t>(tag.x), static_cast<uint32_t>(tag.y), static_cast<uint32_t>(tag.z), tag.version}) {
    for (int i = 0; i < 4; ++i) out.push_back(static_cast<uint8_t>(v >> (8 * i)));
  }
  out.push_back(tag.level);
  return out;
}

TEST(CodecBrick, TagAddsSeventeenBytesAndLeavesTheDataAsIs) {
  ChunkEncoder enc = makeEncoder(CodecConfig{}, 16);
  const double voxel[] = {0.0, 0.02};
  ASSERT_TRUE(enc.encode(smallFrame(), voxel, 42, 987654321).isOk());
  std::vector<std::vector<uint8_t>> frame;
  for (std::size_t i = 0; i < enc.chunkCount(); ++i) frame.emplace_back(enc.chunk(i).begin(), enc.chunk(i).end());
  const BrickTag tag{1, 2, 3, 4, 5};
  ASSERT_TRUE(enc.encode(smallFrame(), voxel, 42, 987654321, &tag).isOk());
  ASSERT_EQ(enc.chunkCount(), frame.size());
  const std::vector<uint8_t> tb = tagBytes(tag);
  for (std::size_t i = 0; i < frame.size(); ++i) {
    const std::span<const uint8_t> b = enc.chunk(i);
    ASSERT_EQ(b.size(), frame[i].size() + 17) << i;
    // The same header but for the brick flag (bit 5 of byte 18), then the tag, then the same data.
    const std::size_t header = std::search(b.begin(), b.end(), tb.begin(), tb.end()) - b.begin();
    ASSERT_LT(header, b.size()) << i;
    EXPECT_EQ(b[18], frame[i][18] | 0x20) << i;
    EXPECT_TRUE(std::equal(b.begin(), b.begin() + 18, frame[i].begin())) << i;
    EXPECT_TRUE(std::equal(b.begin() + 19, b.begin() + static_cast<std::ptrdiff_t>(header), frame[i].begin() + 19)) << i;
    EXPECT_TRUE(std::equal(b.begin() + static_cast<std::ptrdiff_t>(header + 17), b.end(),
                           frame[i].begin() + static_cast<std::ptrdiff_t>(header), frame[i].end()))
        << i;
  }
}

// A brick chunk of the small frame with tag {4, 5, 6, 1, level}: the encoder's, its level byte patched.
std::vector<uint8_t> chunkWithBrickLevel(ChunkEncoder& enc, uint8_t level) {
  const double voxel[] = {0.0, 0.02};
  const BrickTag tag{4, 5, 6, 1, 0};
  EXPECT_TRUE(enc.encode(smallFrame(), voxel, 1, 0, &tag).isOk());
  std::vector<uint8_t> c(enc.chunk(0).begin(), enc.chunk(0).end());
  const std::vector<uint8_t> tb = tagBytes(tag);
  const auto at = std::search(c.begin(), c.end(), tb.begin(), tb.end());
  EXPECT_NE(at, c.end());
  if (at != c.end()) at[16] = level;
  return c;  // starts 8-aligned (the vector's allocation)
}

TEST(CodecBrick, LevelOutOfRangeIsRefused) {
  ChunkEncoder enc = makeEncoder(CodecConfig{}, 16);
  const double voxel[] = {0.0, 0.02};
  pipeline::FoveatedCloud out(16);
  const std::vector<uint8_t> last = chunkWithBrickLevel(enc, pipeline::kMaxRegions - 1);
  Result<DecodedChunk> d = decodeChunk(last, out);
  ASSERT_TRUE(d.isOk()) << d.status().toString();
  EXPECT_EQ(d->brick.level, pipeline::kMaxRegions - 1);
  EXPECT_EQ(d->brick.z, 6);
  for (int level : {pipeline::kMaxRegions, 255}) {
    out.clear();
    d = decodeChunk(chunkWithBrickLevel(enc, static_cast<uint8_t>(level)), out);
    EXPECT_EQ(d.status().code(), ErrorCode::kParseError) << level;
    EXPECT_EQ(out.size(), 0u);
  }
  // The encoder never makes one.
  const BrickTag bad{0, 0, 0, 0, pipeline::kMaxRegions};
  EXPECT_EQ(enc.encode(smallFrame(), voxel, 1, 0, &bad).code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(enc.chunkCount(), 0u);
}

// Every payload starts at kPayloadAlignment (net/wire.h): the summary is FlatBuffers,
// read in place, and every decoder holds to the same rule. Each payload the encoder
// hands out starts aligned, and one off the boundary is an error, never read.
TEST(CodecDecode, PayloadUnalignedIsAnErrorNotARead) {
  const test::MockFoveatedFrame& f = livingRoom();
  ChunkEncoder enc = makeEncoder(CodecConfig{}, f.cloud.size());
  ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, 3, 0).isOk());
  ASSERT_GT(enc.chunkCount(), 2u);
  for (std::size_t i = 0; i < enc.chunkCount(); ++i) EXPECT_TRUE(isPayloadAligned(enc.chunk(i).data())) << i;
  std::array<uint16_t, 4> sent{1, 1, 1, 1};
  const std::span<const uint8_t> summary = enc.encodeSummary(3, sent, sent);
  EXPECT_TRUE(isPayloadAligned(summary.data()));

  const std::span<const uint8_t> chunk = enc.chunk(0);
  std::vector<uint8_t> shifted(chunk.size() + kPayloadAlignment);
  std::copy(chunk.begin(), chunk.end(), shifted.begin() + 1);
  pipeline::FoveatedCloud out(f.cloud.size());
  Result<DecodedChunk> d = decodeChunk({shifted.data() + 1, chunk.size()}, out);
  EXPECT_EQ(d.status().code(), ErrorCode::kParseError);
  EXPECT_EQ(out.size(), 0u);
  std::copy(summary.begin(), summary.end(), shifted.begin() + 1);
  EXPECT_EQ(decodeSummary({shifted.data() + 1, summary.size()}).status().code(), ErrorCode::kParseError);
  std::copy(chunk.begin(), chunk.end(), shifted.begin());
  EXPECT_TRUE(decodeChunk({shifted.data(), chunk.size()}, out).isOk());
}

// The header's own rules (docs/protocol-chunks.md "Decoding rules" 1 and 2), each
// broken in an otherwise valid chunk: an error that says so, nothing appended.
TEST(CodecDecode, MalformedHeadersAreErrorsNamingTheRule) {
  ChunkEncoder enc = makeEncoder(CodecConfig{}, 16);
  const double voxel[] = {0.0, 0.02};
  ASSERT_TRUE(enc.encode(smallFrame(), voxel, 42, 987654321).isOk());
  const std::vector<uint8_t> good(enc.chunk(1).begin(), enc.chunk(1).end());
  pipeline::FoveatedCloud out(16);
  ASSERT_TRUE(decodeChunk(good, out).isOk());
  auto expectError = [&](std::vector<uint8_t> bad, const std::string& what) {
    out.clear();
    Result<DecodedChunk> d = decodeChunk(bad, out);
    EXPECT_EQ(d.status().code(), ErrorCode::kParseError) << what;
    EXPECT_NE(d.status().message().find(what), std::string::npos) << d.status().toString();
    EXPECT_EQ(out.size(), 0u);
  };
  std::vector<uint8_t> c = good;
  c[18] |= 0x40;  // bits 6-7 of the region byte
  expectError(c, "unknown flags");
  c = good;
  c[14] = c[15] = 0;  // chunk_count 0
  expectError(c, "chunk index out of range");
  c = good;
  for (std::size_t i = 27; i < 27 + 8; ++i) c[i] = 0x80;  // a varint of more than 8 bytes
  expectError(c, "origin varint");
  c = good;
  for (std::size_t i = 27; i < 27 + 7; ++i) c[i] = 0xff;  // 8 bytes, but 2^56 - 1 >= 2^51
  c[34] = 0x7f;
  expectError(c, "origin beyond 2^50 steps");
  c = good;
  const double nan = std::nan("");
  std::memcpy(c.data() + 19, &nan, 8);  // little-endian host (as the encoder's putLe)
  expectError(c, "step is not finite");
  expectError({good.begin(), good.begin() + 29}, "shorter than its header");
  c = good;
  c[18] |= 0x20;  // a brick flag without a tag: the tag is truncated or the data too short
  c.resize(27 + 3 + 10);
  expectError(c, "brick tag truncated");
}

TEST(CodecDecode, FullOutputCloudIsAnErrorAndAppendsNothing) {
  const test::MockFoveatedFrame& f = livingRoom();
  ChunkEncoder enc = makeEncoder(CodecConfig{}, f.cloud.size());
  ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, 1, 0).isOk());
  pipeline::FoveatedCloud out(10);
  Result<DecodedChunk> d = decodeChunk(enc.chunk(0), out);
  EXPECT_EQ(d.status().code(), ErrorCode::kCapacityExceeded);
  EXPECT_EQ(out.size(), 0u);
}

// Decoding must return (ok or an error), never crash; what it appends is finite.
void expectSafeDecode(std::span<const uint8_t> bytes, pipeline::FoveatedCloud& out) {
  out.clear();
  Result<DecodedChunk> d = decodeChunk(bytes, out);
  if (d.isOk()) {
    for (std::size_t i = 0; i < out.size(); ++i) {
      ASSERT_TRUE(std::isfinite(out.points.x()[i]) && std::isfinite(out.points.y()[i]) &&
                  std::isfinite(out.points.z()[i]));
    }
  } else {
    EXPECT_FALSE(d.status().message().empty());
  }
  (void)decodeSummary(bytes);
}

TEST(CodecRobustness, RandomBytesTruncationsAndBitFlips) {
  const test::MockFoveatedFrame& f = livingRoom();
  CodecConfig config;
  config.halve_peripheral_chroma = true;
  ChunkEncoder enc = makeEncoder(config, f.cloud.size());
  ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, 1, 0).isOk());
  pipeline::FoveatedCloud out(f.cloud.size());
  std::mt19937 rng(5);
  std::vector<uint8_t> bytes;
  // Random payloads of every size up to a jumbo datagram.
  for (int t = 0; t < 3000; ++t) {
    bytes.resize(rng() % (kMaxMtu + 16));
    for (uint8_t& b : bytes) b = static_cast<uint8_t>(rng());
    expectSafeDecode(bytes, out);
  }
  // Every truncation and every single-bit flip of some chunks, and multi-byte garbage.
  // (Raw chunks only: with entropy_coding on, zstd is kept only where it makes a chunk
  // smaller, which on the mock room it never does, net/codec.h.)
  std::size_t flips_ok = 0, flips = 0;
  for (std::size_t i = 0; i < enc.chunkCount(); i += std::max<std::size_t>(1, enc.chunkCount() / 6)) {
    const std::span<const uint8_t> chunk = enc.chunk(i);
    for (std::size_t len = 0; len < chunk.size(); ++len) {
      bytes.assign(chunk.begin(), chunk.begin() + static_cast<std::ptrdiff_t>(len));
      out.clear();
      // Only the alignment padding at the end may go (the data vector ends within 8 bytes).
      Result<DecodedChunk> d = decodeChunk(bytes, out);
      if (d.isOk()) {
        EXPECT_GE(len + 8, chunk.size()) << "truncated to " << len;
        EXPECT_EQ(d->points, enc.chunkPoints(i));
      }
    }
    for (std::size_t bit = 0; bit < chunk.size() * 8; ++bit) {
      bytes.assign(chunk.begin(), chunk.end());
      bytes[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
      expectSafeDecode(bytes, out);
      ++flips;
      flips_ok += out.size() > 0;
    }
    for (int t = 0; t < 500; ++t) {
      bytes.assign(chunk.begin(), chunk.end());
      for (int k = 0; k < 4; ++k) bytes[rng() % bytes.size()] = static_cast<uint8_t>(rng());
      expectSafeDecode(bytes, out);
    }
  }
  EXPECT_GT(flips, 0u);
  EXPECT_LT(flips_ok, flips);  // some flips are caught...
  // A summary's truncations too.
  const uint16_t sent[] = {1, 2, 3, 4};
  const std::span<const uint8_t> summary = enc.encodeSummary(1, sent, sent);
  const std::vector<uint8_t> copy(summary.begin(), summary.end());
  for (std::size_t len = 0; len < copy.size(); ++len) {
    EXPECT_FALSE(decodeSummary(std::span<const uint8_t>(copy.data(), len)).isOk());
  }
}

TEST(FrameAssembler, CollectsFramesAndCountsWhatWasLost) {
  const test::MockFoveatedFrame& f = livingRoom();
  ChunkEncoder enc = makeEncoder(CodecConfig{}, f.cloud.size());
  FrameAssembler asmb = FrameAssembler::create(f.cloud.size()).value();
  std::array<uint32_t, 4> points_by_region{};
  std::array<uint16_t, 4> sent{}, received{};

  // Frame 10: every fifth chunk lost; then its summary.
  ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, 10, 555).isOk());
  for (std::size_t i = 0; i < enc.chunkCount(); ++i) {
    const uint8_t r = enc.chunkRegion(i);
    ++sent[r];
    if (i % 5 == 4) continue;
    ++received[r];
    points_by_region[r] += enc.chunkPoints(i);
    ASSERT_TRUE(asmb.addChunk(enc.chunk(i)).isOk());
    ASSERT_TRUE(asmb.addChunk(enc.chunk(i)).isOk());  // a duplicate
    EXPECT_EQ(asmb.readyCount(), 0u);
  }
  const std::array<uint16_t, 4> cut{};
  ASSERT_TRUE(asmb.addSummary(enc.encodeSummary(10, sent, cut)).isOk());
  ASSERT_EQ(asmb.readyCount(), 1u);
  const AssembledFrame& a = asmb.ready(0);
  EXPECT_EQ(a.frame_id, 10u);
  EXPECT_TRUE(a.summary_received);
  EXPECT_EQ(a.capture_time_ns, 555u);
  EXPECT_EQ(a.chunk_count, enc.chunkCount());
  std::size_t total = 0;
  for (std::size_t r = 0; r < 4; ++r) {
    EXPECT_EQ(a.points[r], points_by_region[r]);
    EXPECT_EQ(a.chunks_received[r], received[r]);
    EXPECT_EQ(a.chunks_expected[r], sent[r]);
    // The step a viewer sizes splats from: the fovea's absolute step, the
    // periphery's a fraction of its voxel.
    const CodecConfig defaults;
    const double voxel = f.voxel_size_m[r];
    EXPECT_DOUBLE_EQ(a.step_m[r], r == 0 || voxel == 0.0 ? defaults.fovea_step_m : voxel * defaults.periphery_step_ratio) << r;
    total += a.points[r];
  }
  EXPECT_EQ(a.cloud->size(), total);
  EXPECT_EQ(asmb.counters().duplicate_chunks, enc.chunkCount() - enc.chunkCount() / 5);

  // A late chunk of frame 10 is dropped and counted.
  ASSERT_TRUE(asmb.addChunk(enc.chunk(4)).isOk());
  EXPECT_EQ(asmb.readyCount(), 0u);
  EXPECT_EQ(asmb.counters().late_chunks, 1u);

  // Frame 11 without its summary completes when frame 12 starts.
  ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, 11, 0).isOk());
  ASSERT_TRUE(asmb.addChunk(enc.chunk(0)).isOk());
  ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, 12, 0).isOk());
  ASSERT_TRUE(asmb.addChunk(enc.chunk(1)).isOk());
  ASSERT_EQ(asmb.readyCount(), 1u);
  EXPECT_EQ(asmb.ready(0).frame_id, 11u);
  EXPECT_FALSE(asmb.ready(0).summary_received);
  EXPECT_EQ(asmb.ready(0).cloud->size(), enc.chunkPoints(0));
  // A summary of frame 13 (every chunk lost) completes 12 and reports 13 empty.
  sent = {1, 1, 1, 1};
  ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, 13, 0).isOk());
  ASSERT_TRUE(asmb.addSummary(enc.encodeSummary(13, sent, cut)).isOk());
  ASSERT_EQ(asmb.readyCount(), 2u);
  EXPECT_EQ(asmb.ready(0).frame_id, 12u);
  EXPECT_EQ(asmb.ready(1).frame_id, 13u);
  EXPECT_EQ(asmb.ready(1).cloud->size(), 0u);
  EXPECT_EQ(asmb.ready(1).chunks_expected[0], 1u);
  EXPECT_NE(asmb.ready(0).cloud, asmb.ready(1).cloud);
  // Garbage is counted, not fatal.
  const uint8_t junk[] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
  EXPECT_FALSE(asmb.addChunk(junk).isOk());
  EXPECT_FALSE(asmb.addSummary(junk).isOk());
  EXPECT_EQ(asmb.counters().bad_chunks, 1u);
  EXPECT_EQ(asmb.counters().bad_summaries, 1u);
}

TEST(FrameAssembler, BrickChunksAreNoPartOfAFrame) {
  ChunkEncoder enc = makeEncoder(CodecConfig{}, 16);
  FrameAssembler asmb = FrameAssembler::create(64).value();
  const double voxel[] = {0.0, 0.02};
  ASSERT_TRUE(enc.encode(smallFrame(), voxel, 5, 0).isOk());
  ASSERT_TRUE(asmb.addChunk(enc.chunk(0)).isOk());
  // Brick chunks of the same and of a newer frame id: refused, the frame goes on.
  const BrickTag tag{1, 1, 1, 9, 0};
  for (uint32_t id : {5u, 6u}) {
    ASSERT_TRUE(enc.encode(smallFrame(), voxel, id, 0, &tag).isOk());
    for (std::size_t i = 0; i < enc.chunkCount(); ++i) {
      EXPECT_EQ(asmb.addChunk(enc.chunk(i)).code(), ErrorCode::kParseError);
      EXPECT_EQ(asmb.readyCount(), 0u);
    }
  }
  EXPECT_EQ(asmb.counters().bad_chunks, 4u);
  EXPECT_EQ(asmb.counters().chunks, 1u);
  ASSERT_TRUE(enc.encode(smallFrame(), voxel, 5, 0).isOk());
  ASSERT_TRUE(asmb.addChunk(enc.chunk(1)).isOk());
  asmb.flush();
  ASSERT_EQ(asmb.readyCount(), 1u);
  EXPECT_EQ(asmb.ready(0).frame_id, 5u);
  EXPECT_EQ(asmb.ready(0).cloud->size(), 16u);
}

TEST(FrameAssembler, FrameIdsMayWrap) {
  const test::MockFoveatedFrame& f = livingRoom();
  ChunkEncoder enc = makeEncoder(CodecConfig{}, f.cloud.size());
  FrameAssembler asmb = FrameAssembler::create(f.cloud.size()).value();
  ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, 0xffffffffu, 0).isOk());
  ASSERT_TRUE(asmb.addChunk(enc.chunk(0)).isOk());
  ASSERT_TRUE(enc.encode(f.cloud, f.voxel_size_m, 0, 0).isOk());
  ASSERT_TRUE(asmb.addChunk(enc.chunk(0)).isOk());
  ASSERT_EQ(asmb.readyCount(), 1u);
  EXPECT_EQ(asmb.ready(0).frame_id, 0xffffffffu);
  asmb.flush();
  ASSERT_EQ(asmb.readyCount(), 1u);
  EXPECT_EQ(asmb.ready(0).frame_id, 0u);
}

}  // namespace
}  // namespace fovea::net

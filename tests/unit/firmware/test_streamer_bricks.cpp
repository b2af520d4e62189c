// The streamer's side of the map's bricks (issue 26), over loopback to a real
// OperatorLink and BrickCache: a frame's bricks arrive whole beside the live
// frame and are acknowledged; an operator that never acknowledges gets the
// same parts again until it does; an
// eviction, a new session and a frame with no session tell the planner what the
// operator lacks; acknowledgements of what was never sent are counted and change
// nothing. The batch the service's two stages share (SharedBrickBatch) is free
// once sendFrame has staged it, and never read and written at once.
#include "firmware/streamer.h"

#include <atomic>
#include <chrono>
#include <cstring>
#include <memory>
#include <random>
#include <set>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "core/clock.h"
#include "core/ring.h"
#include "firmware/shared_brick_batch.h"
#include "net/brick_cache.h"
#include "net/operator_link.h"
#include "tests/support/test_time.h"

namespace fovea::firmware {
namespace {

using namespace std::chrono_literals;

constexpr std::size_t kMaxBricks = 64;
constexpr std::size_t kLivePoints = 1000;  // the streamer's max_points

// A point of a brick at level 0, as the brick sampler writes it.
bool pushBrickPoint(pipeline::map::BrickBatch& batch, float x, float y, float z, uint32_t rgb) {
  if (!batch.points.points.push(x, y, z, rgb)) return false;
  batch.points.region[batch.points.size() - 1] = 0;
  batch.points.weight[batch.points.size() - 1] = 1;
  return true;
}

// Three bricks of a few hundred points each, at level 0, slots 3, 7 and 11.
pipeline::map::BrickBatch makeBatch(uint32_t version, std::size_t points_per_brick = 300) {
  pipeline::map::BrickBatch batch(4096, 16);
  batch.clear(Eigen::Vector3d(1.0, 2.0, 0.5));
  const uint16_t slots[3] = {3, 7, 11};
  for (int b = 0; b < 3; ++b) {
    auto& e = batch.add();
    e.brick = slots[b];
    e.key = {b, -1, 2};
    e.version = version;
    e.level = 0;
    e.fovea = b == 0;
    e.first = static_cast<uint32_t>(batch.points.size());
    for (std::size_t i = 0; i < points_per_brick; ++i) {
      const float x = 0.5f * static_cast<float>(b) + 0.01f * static_cast<float>(i % 40);
      const float y = 0.01f * static_cast<float>(i / 40);
      EXPECT_TRUE(pushBrickPoint(batch, x, y, 0.25f, pipeline::packRgb(10, 20, static_cast<uint8_t>(b))));
    }
    e.count = static_cast<uint32_t>(points_per_brick);
  }
  return batch;
}

// An operator connected to `streamer` over loopback (mtu_bytes 0: its default);
// the streamer's link is polled meanwhile, as its send stage would.
std::unique_ptr<net::OperatorLink> connectOperator(Streamer& streamer, uint32_t mtu_bytes) {
  std::atomic<bool> stop{false};
  std::thread robot([&] {
    while (!stop.load()) streamer.idleUntil(monotonicNs() + 2'000'000);
  });
  net::OperatorLinkConfig op_config;
  op_config.insecure = true;
  if (mtu_bytes > 0) op_config.mtu_bytes = mtu_bytes;
  op_config.connect_timeout_ms = static_cast<int>(test::scaled(std::chrono::milliseconds(3000)).count());
  Result<std::unique_ptr<net::OperatorLink>> link =
      net::OperatorLink::connect(streamer.localEndpoint().toString(), op_config);
  stop.store(true);
  robot.join();
  EXPECT_TRUE(link) << link.status().message();
  return link ? std::move(link.value()) : nullptr;
}

struct Rig {
  std::unique_ptr<Streamer> streamer;
  BrickFeedback feedback{kMaxBricks};
  std::unique_ptr<net::OperatorLink> op;
  pipeline::FoveatedCloud live{kLivePoints};
  pipeline::FoveationStats stats;

  // mtu_bytes: the operator's (0: its default); max_frame_bricks and
  // max_parts (a brick version's): the streamer's.
  explicit Rig(int64_t resend_after_ns = 100'000'000, uint32_t mtu_bytes = 0, std::size_t max_frame_bricks = 16,
               std::size_t max_parts = 256) {
    StreamConfig config;
    config.link.listen = "127.0.0.1:0";
    config.link.insecure = true;
    // The operator here sends nothing, so the robot ends the session after its
    // silence timeout: scaled with the build (under TSan on CI's loaded machine
    // one of these tests took 4.5 s, and its acknowledgement found the session
    // ended by the default 3 s).
    config.link.session_timeout_ns = std::chrono::nanoseconds(test::scaled(std::chrono::seconds(3))).count();
    config.map_bricks = true;
    config.brick_sender.max_bricks = kMaxBricks;
    config.brick_sender.resend_after_ns = resend_after_ns;
    config.brick_sender.max_parts = max_parts;
    config.max_brick_points = 1024;
    config.max_frame_brick_points = 4096;
    config.max_frame_bricks = max_frame_bricks;
    Result<std::unique_ptr<Streamer>> created = Streamer::create(config, kLivePoints);
    EXPECT_TRUE(created) << created.status().message();
    streamer = std::move(created.value());
    streamer->attachBrickFeedback(&feedback);
    op = connectOperator(*streamer, mtu_bytes);
    // A live frame of a few points in the fovea.
    for (int i = 0; i < 10; ++i) EXPECT_TRUE(live.points.push(0.1f * static_cast<float>(i), 0.0f, 1.0f, 0x808080));
    std::fill_n(live.region.begin(), 10, uint8_t{0});
    std::fill_n(live.weight.begin(), 10, 1u);
    stats.region_count = 1;
  }

  // The deadline is what the sends may take, a bound (a frame of this size
  // goes out in well under a millisecond): scaled, so that a sanitizer build on
  // a loaded machine does not cut the frame these tests look at whole.
  Result<FrameSendReport> send(const pipeline::map::BrickBatch* batch, uint32_t frame_id) {
    const int64_t now = monotonicNs();
    const auto deadline = static_cast<int64_t>(test::waitLimitSeconds(0.030) * 1e9);
    return streamer->sendFrame(live, stats, frame_id, now, now + deadline, 33'000'000, batch);
  }

  // Polls until the operator's acknowledgements have completed `versions`
  // brick versions (scaled wait); false if they never do.
  bool versionsDone(uint64_t versions) {
    return test::waitUntil(
        [&] {
          streamer->poll();
          return streamer->brickCounters()->versions_done == versions;
        },
        3000ms);
  }

  // What the planner would hear now.
  std::set<std::size_t> forgotten(bool* all = nullptr) {
    std::set<std::size_t> out;
    bool everything = false;
    feedback.drain([&](std::size_t b) { out.insert(b); }, [&] { everything = true; });
    if (all) *all = everything;
    return out;
  }
  // ... and of the bricks found too large for a version.
  std::set<std::size_t> tooLarge() {
    std::set<std::size_t> out;
    feedback.drainTooLarge([&](std::size_t b) { out.insert(b); });
    return out;
  }
};

// The operator: receives for `ms`, brick parts into the cache, and
// acknowledges what it took when `acknowledge`.
struct Operator {
  net::BrickCache cache = net::BrickCache::create(net::BrickCacheConfig{}).value();
  pipeline::FoveatedCloud scratch{1 << 14};
  std::size_t frame_chunks = 0, brick_parts = 0;

  void receive(net::OperatorLink& link, int ms, bool acknowledge) {
    alignas(16) static uint8_t aligned[net::kMaxMtu];
    const int64_t end = monotonicNs() + test::scaled(std::chrono::milliseconds(ms)).count() * 1'000'000;
    while (monotonicNs() < end) {
      std::optional<net::Received> r = link.receive(5);
      if (r && (r->type == net::MessageType::kBrickChunk || r->type == net::MessageType::kChunk)) {
        std::memcpy(aligned, r->payload.data(), r->payload.size());
        scratch.clear();
        Result<net::DecodedChunk> d = net::decodeChunk(std::span<const uint8_t>(aligned, r->payload.size()), scratch);
        ASSERT_TRUE(d) << d.status().message();
        EXPECT_EQ(d->has_brick, r->type == net::MessageType::kBrickChunk);
        if (d->has_brick) {
          ++brick_parts;
          cache.add(d.value(), scratch, 0, monotonicNs());
        } else {
          ++frame_chunks;
        }
      }
      if (acknowledge && !cache.received().empty()) {
        net::BrickAckMsg ack;
        for (const net::BrickPartId& id : cache.received()) {
          if (ack.part_count == net::BrickAckMsg::kMaxParts) break;
          ack.parts[ack.part_count++] = id;
        }
        ASSERT_TRUE(link.sendBrickAck(ack));
        cache.clearReceived();
      }
    }
  }
};

TEST(BrickFeedback, TellsEachForgottenBrickOnceAndANewSessionFirst) {
  BrickFeedback feedback(130);
  std::vector<std::size_t> got;
  int all = 0;
  auto drain = [&] {
    got.clear();
    all = 0;
    feedback.drain([&](std::size_t b) { got.push_back(b); }, [&] { ++all; });
  };
  drain();
  EXPECT_TRUE(got.empty());
  EXPECT_EQ(all, 0);
  feedback.forget(0);
  feedback.forget(129);
  feedback.forget(64);
  feedback.forget(64);
  feedback.forget(100000);  // beyond the map: ignored
  feedback.forgetAll();
  drain();
  EXPECT_EQ(got, (std::vector<std::size_t>{0, 64, 129}));
  EXPECT_EQ(all, 1);
  drain();
  EXPECT_TRUE(got.empty());
  EXPECT_EQ(all, 0);
  // From another thread, while the planner drains.
  std::thread sender([&] {
    for (std::size_t b = 0; b < 130; ++b) feedback.forget(b);
  });
  std::set<std::size_t> seen;
  for (int i = 0; i < 1000 && seen.size() < 130; ++i) {
    feedback.drain([&](std::size_t b) { seen.insert(b); }, [] {});
  }
  sender.join();
  feedback.drain([&](std::size_t b) { seen.insert(b); }, [] {});
  EXPECT_EQ(seen.size(), 130u);
}

TEST(StreamerBricks, ABatchArrivesWholeBesideTheLiveFrameAndIsAcknowledged) {
  Rig rig;
  Operator op;
  pipeline::map::BrickBatch batch = makeBatch(1);
  Result<FrameSendReport> sent = rig.send(&batch, 1);
  ASSERT_TRUE(sent) << sent.status().message();
  EXPECT_TRUE(sent->had_session);
  EXPECT_EQ(sent->bricks, 3u);
  EXPECT_EQ(sent->brick_parts_sent, sent->brick_parts);
  EXPECT_GE(sent->brick_parts, 3u);
  EXPECT_TRUE(sent->completed);
  op.receive(*rig.op, 300, true);
  EXPECT_GE(op.frame_chunks, 1u);
  EXPECT_EQ(op.cache.bricksHeld(), 3u);
  EXPECT_EQ(op.cache.pointsHeld(), 900u);
  const int held = op.cache.find(net::BrickKey{1, -1, 2});
  ASSERT_GE(held, 0);
  EXPECT_EQ(op.cache.version(static_cast<std::size_t>(held)), 1u);
  // Every point where the robot had it (world = batch origin + point), to the codec's step.
  std::size_t near = 0;
  op.cache.forEachPoint(static_cast<std::size_t>(held), [&](const Eigen::Vector3d& p, uint32_t rgb) {
    const Eigen::Vector3d rel = p - Eigen::Vector3d(1.0, 2.0, 0.5);
    near += std::abs(rel.z() - 0.25) < 0.002 && rel.x() > 0.49 && rel.x() < 0.9 && pipeline::rgbBlue(rgb) == 1 ? 1 : 0;
  });
  EXPECT_EQ(near, 300u);
  // The acknowledgements reach the robot with its next poll: every version done.
  ASSERT_TRUE(rig.versionsDone(3));
  EXPECT_EQ(rig.streamer->brickCounters()->acks_unknown, 0u);
  bool all = false;
  EXPECT_TRUE(rig.forgotten(&all).empty());
  EXPECT_TRUE(all);  // the session began: the operator held nothing
  // Nothing is resent once acknowledged.
  Result<FrameSendReport> next = rig.send(nullptr, 2);
  ASSERT_TRUE(next);
  EXPECT_EQ(next->brick_resends, 0u);
}

// The frame's tables of datagrams hold what the codec can make of a frame and
// its bricks (net::maxChunks: every chunk but a region's last nearly full of
// the costliest points), not one entry per point: at the service's sizes (a
// 640x480 frame, a frame's share of 12.5 MB/s in bricks) a few thousand
// entries at the largest MTU where one per point was 158 000; a session at
// the smallest MTU gets tables for it.
TEST(StreamerBricks, TheDatagramTablesFollowTheCodecAtTheSessionsMtu) {
  StreamConfig config;
  config.link.listen = "127.0.0.1:0";
  config.link.insecure = true;
  config.map_bricks = true;
  config.brick_sender.max_bricks = kMaxBricks;
  config.max_brick_points = 1u << 16;
  config.max_frame_brick_points = 92'593;
  config.max_frame_bricks = 1024;
  constexpr std::size_t kPixels = 640 * 480;
  Result<std::unique_ptr<Streamer>> created = Streamer::create(config, kPixels);
  ASSERT_TRUE(created) << created.status().message();
  net::CodecConfig at_max = config.codec, at_min = config.codec;
  at_max.max_payload = config.link.max_mtu_bytes - net::kDatagramOverhead;
  at_min.max_payload = net::kMinMtu - net::kDatagramOverhead;
  auto expected = [&](const net::CodecConfig& codec) {
    return std::min<std::size_t>(net::maxChunks(codec, kPixels), 0xffff) + net::maxChunks(codec, 92'593) +
           1024 * (pipeline::kMaxRegions + 2) + config.max_resend_parts;
  };
  const std::size_t largest_mtu = (*created)->datagramCapacity();
  EXPECT_EQ(largest_mtu, expected(at_max));
  EXPECT_LT(largest_mtu, 20'000u);
  // A session at the smallest MTU: the tables for it, as its encoders.
  std::unique_ptr<Streamer> streamer = std::move(created.value());
  std::unique_ptr<net::OperatorLink> op = connectOperator(*streamer, static_cast<uint32_t>(net::kMinMtu));
  ASSERT_NE(op, nullptr);
  pipeline::FoveatedCloud live(16);
  ASSERT_TRUE(live.points.push(0.0f, 0.0f, 1.0f, 0x808080));
  live.region[0] = 0;
  live.weight[0] = 1;
  pipeline::FoveationStats stats;
  stats.region_count = 1;
  const int64_t now = monotonicNs();
  ASSERT_TRUE(streamer->sendFrame(live, stats, 1, now, now + 30'000'000, 33'000'000, nullptr));
  EXPECT_EQ(streamer->datagramCapacity(), expected(at_min));
  EXPECT_GT(streamer->datagramCapacity(), largest_mtu);
}

// The frame's tables of datagrams follow the session's MTU (sized from the
// codec, not one per point): at the smallest MTU a live frame at the
// streamer's max_points and a batch of as many bricks and points as a frame may
// hold, all of them scattered over their space in random colours, are staged
// whole, nothing of them told to the planner as not sent.
TEST(StreamerBricks, AtTheSmallestMtuAFullFrameAndAFullBatchAreStaged) {
  constexpr std::size_t kBricks = 16, kPointsPerBrick = 256;
  Rig rig(100'000'000, static_cast<uint32_t>(net::kMinMtu), kBricks);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  auto colour = [&] { return pipeline::packRgb(rng() & 0xff, rng() & 0xff, rng() & 0xff); };
  rig.live.clear();
  for (std::size_t i = 0; i < kLivePoints; ++i) {
    ASSERT_TRUE(rig.live.points.push(4.0f * unit(rng) - 2.0f, 3.0f * unit(rng) - 1.5f, 0.5f + 4.0f * unit(rng), colour()));
  }
  std::fill_n(rig.live.region.begin(), kLivePoints, uint8_t{0});
  std::fill_n(rig.live.weight.begin(), kLivePoints, 1u);
  pipeline::map::BrickBatch batch(kBricks * kPointsPerBrick, kBricks);
  batch.clear(Eigen::Vector3d(-1.0, 0.5, 2.0));
  for (std::size_t b = 0; b < kBricks; ++b) {
    auto& e = batch.add();
    e.brick = static_cast<uint16_t>(b);
    e.key = {static_cast<int32_t>(b), 0, 0};
    e.version = 1;
    e.level = 0;
    e.fovea = b < 2;
    e.first = static_cast<uint32_t>(batch.points.size());
    for (std::size_t i = 0; i < kPointsPerBrick; ++i) {
      ASSERT_TRUE(pushBrickPoint(batch, 0.5f * static_cast<float>(b) + 0.5f * unit(rng), 0.5f * unit(rng),
                                 0.5f * unit(rng), colour()));
    }
    e.count = static_cast<uint32_t>(kPointsPerBrick);
  }
  Result<FrameSendReport> sent = rig.send(&batch, 1);
  ASSERT_TRUE(sent) << sent.status().message();
  EXPECT_TRUE(sent->had_session);
  EXPECT_EQ(sent->bricks, kBricks);
  EXPECT_EQ(sent->bricks_unstaged, 0u);
  EXPECT_GT(sent->chunks, 20u);  // at this MTU the live frame takes many datagrams (a handful at the default)
  EXPECT_EQ(sent->chunks_cut, 0u);  // the budget's burst holds them all
  // Every brick staged, none told to the planner as not sent (parts the
  // deadline leaves behind are the sender's to resend: not counted here, so
  // that a slow build cannot fail what only the tables decide).
  EXPECT_GT(sent->brick_parts, kBricks);
  EXPECT_TRUE(rig.forgotten().empty());
}

TEST(StreamerBricks, ABrickWhoseSurfelsAllWentIsSentAsAnEmptyVersion) {
  Rig rig;
  Operator op;
  pipeline::map::BrickBatch batch = makeBatch(1);
  ASSERT_TRUE(rig.send(&batch, 1));
  op.receive(*rig.op, 200, true);
  ASSERT_EQ(op.cache.pointsHeld(), 900u);
  // Version 2: brick 7 ({1,-1,2}) has no point left.
  pipeline::map::BrickBatch emptied(64, 4);
  emptied.clear(Eigen::Vector3d(1.0, 2.0, 0.5));
  auto& e = emptied.add();
  e.brick = 7;
  e.key = {1, -1, 2};
  e.version = 2;
  e.count = 0;
  Result<FrameSendReport> sent = rig.send(&emptied, 2);
  ASSERT_TRUE(sent);
  EXPECT_EQ(sent->bricks, 1u);
  EXPECT_EQ(sent->brick_parts, 1u);
  op.receive(*rig.op, 200, true);
  const int slot = op.cache.find(net::BrickKey{1, -1, 2});
  ASSERT_GE(slot, 0);
  EXPECT_EQ(op.cache.version(static_cast<std::size_t>(slot)), 2u);
  EXPECT_EQ(op.cache.pointCount(static_cast<std::size_t>(slot)), 0u);
  EXPECT_EQ(op.cache.pointsHeld(), 600u);
}

// The map gives an emptied brick's slot to a new place (SurfelMap::pinBrick):
// the slot then answers for its new key only, however often that happens
// (here three times as many places as the streamer's index has keys for), and
// an acknowledgement for an old place reaches no version in flight.
TEST(StreamerBricks, ASlotGivenToANewPlaceAnswersForItsNewKeyOnly) {
  Rig rig;
  Operator op;
  const uint32_t places = 3 * kMaxBricks;
  for (uint32_t v = 1; v <= places; ++v) {
    pipeline::map::BrickBatch batch(64, 4);
    batch.clear(Eigen::Vector3d(1.0, 2.0, 0.5));
    auto& e = batch.add();
    e.brick = 3;
    e.key = {static_cast<int32_t>(v), 100, 100};
    e.version = v;
    e.first = 0;
    for (int i = 0; i < 5; ++i) {
      ASSERT_TRUE(pushBrickPoint(batch, 0.01f * static_cast<float>(i), 0.0f, 0.25f, 0x102030));
    }
    e.count = 5;
    ASSERT_TRUE(rig.send(&batch, v));
  }
  op.receive(*rig.op, 300, true);
  ASSERT_GE(op.cache.find(net::BrickKey{static_cast<int32_t>(places), 100, 100}), 0);
  ASSERT_TRUE(rig.versionsDone(1));
  // Each older place's acknowledgement named a key the slot no longer has: not
  // taken for slot 3's version in flight.
  EXPECT_EQ(rig.streamer->brickCounters()->acks_unknown, 0u);
  EXPECT_EQ(rig.streamer->brickCounters()->versions_replaced, places - 1);
}

TEST(StreamerBricks, UnacknowledgedPartsGoAgainUntilAcknowledged) {
  Rig rig(20'000'000);  // resend after 20 ms
  Operator op;
  pipeline::map::BrickBatch batch = makeBatch(5);
  ASSERT_TRUE(rig.send(&batch, 1));
  op.receive(*rig.op, 100, false);
  EXPECT_EQ(op.cache.bricksHeld(), 3u);
  const std::size_t first_parts = op.brick_parts;
  // Later frames carry the resends: duplicates at the operator, nothing new drawn.
  uint32_t resent = 0;
  for (uint32_t f = 2; f < 6; ++f) {
    std::this_thread::sleep_for(25ms);
    Result<FrameSendReport> r = rig.send(nullptr, f);
    ASSERT_TRUE(r);
    resent += r->brick_resends;
  }
  EXPECT_GE(resent, first_parts);
  op.receive(*rig.op, 100, false);
  EXPECT_GT(op.cache.counters().duplicate_parts, 0u);
  EXPECT_EQ(op.cache.counters().versions, 3u);
  // Acknowledging now ends the resends.
  op.receive(*rig.op, 10, false);
  {
    net::BrickAckMsg ack;
    for (const net::BrickPartId& id : op.cache.received()) {
      if (ack.part_count < net::BrickAckMsg::kMaxParts) ack.parts[ack.part_count++] = id;
    }
    ASSERT_TRUE(rig.op->sendBrickAck(ack));
  }
  ASSERT_TRUE(rig.versionsDone(3));
}

// A brick version needs more parts than the sender keeps (the brick encoder
// holds no more chunks than that): that brick is told to the planner as not
// sent and as too large (to be planned coarser), and the batch's other bricks go.
TEST(StreamerBricks, ABrickOfMorePartsThanTheSenderKeepsIsToldToThePlanner) {
  Rig rig(100'000'000, 0, 16, /*max_parts=*/2);
  pipeline::map::BrickBatch batch = makeBatch(1, 100);
  // A fourth brick, slot 20: 1000 points scattered over half a metre at 1 mm
  // steps in random colours, at least 3 bytes a point: more than 2 parts.
  std::mt19937 rng(8);
  std::uniform_real_distribution<float> unit(0.0f, 0.5f);
  auto& big = batch.add();
  big.brick = 20;
  big.key = {5, 5, 5};
  big.version = 1;
  big.first = static_cast<uint32_t>(batch.points.size());
  for (int i = 0; i < 1000; ++i) {
    ASSERT_TRUE(pushBrickPoint(batch, unit(rng), unit(rng), unit(rng),
                               pipeline::packRgb(rng() & 0xff, rng() & 0xff, rng() & 0xff)));
  }
  big.count = 1000;
  Result<FrameSendReport> sent = rig.send(&batch, 1);
  ASSERT_TRUE(sent) << sent.status().message();
  EXPECT_EQ(sent->bricks, 3u);
  EXPECT_EQ(sent->bricks_unstaged, 1u);
  EXPECT_EQ(rig.streamer->bricksUnstaged(), 1u);
  EXPECT_EQ(rig.forgotten(), std::set<std::size_t>({20}));
  EXPECT_EQ(rig.tooLarge(), std::set<std::size_t>({20}));
  EXPECT_EQ(rig.streamer->bricksTooLarge(), 1u);
  EXPECT_EQ(rig.streamer->brickCounters()->versions, 3u);  // the fourth never began
  EXPECT_TRUE(rig.tooLarge().empty());  // told once
}

TEST(StreamerBricks, EvictionsAndFramesThatCannotGoAreToldToThePlanner) {
  Rig rig;
  Operator op;
  pipeline::map::BrickBatch batch = makeBatch(1);
  ASSERT_TRUE(rig.send(&batch, 1));
  op.receive(*rig.op, 200, true);
  ASSERT_EQ(op.cache.bricksHeld(), 3u);
  (void)rig.forgotten();
  // The operator evicts brick {1,-1,2} (slot 7), and acknowledges parts of a
  // brick never sent and of a version never sent.
  net::BrickAckMsg ack;
  ack.evicted[ack.evicted_count++] = net::BrickKey{1, -1, 2};
  ack.parts[ack.part_count++] = net::BrickPartId{net::BrickKey{40, 40, 40}, 1, 0};
  ack.parts[ack.part_count++] = net::BrickPartId{net::BrickKey{0, -1, 2}, 99, 0};
  ASSERT_TRUE(rig.op->sendBrickAck(ack));
  std::set<std::size_t> forgotten;
  ASSERT_TRUE(test::waitUntil(
      [&] {
        rig.streamer->poll();
        for (std::size_t b : rig.forgotten()) forgotten.insert(b);
        return !forgotten.empty();
      },
      3000ms));
  EXPECT_EQ(forgotten, std::set<std::size_t>({7}));
  EXPECT_GE(rig.streamer->brickCounters()->acks_unknown, 1u);  // the version never sent
  // A frame's bricks that cannot go (privacy, or no session) are due again.
  rig.streamer->discardBricks(batch);
  EXPECT_EQ(rig.forgotten(), std::set<std::size_t>({3, 7, 11}));
  // Without map_bricks a batch is refused, not sent.
  StreamConfig plain;
  plain.link.listen = "127.0.0.1:0";
  plain.link.insecure = true;
  std::unique_ptr<Streamer> frames_only = Streamer::create(plain, 100).value();
  EXPECT_FALSE(frames_only->sendFrame(rig.live, rig.stats, 1, 0, monotonicNs() + 1'000'000, 33'000'000, &batch));
}

// sendFrame is done with the batch once its bricks are staged: the hook runs
// once for a frame with bricks, before its datagrams go, and a batch emptied
// and refilled with other points from the hook (the next frame's plan) changes
// nothing the operator gets. A frame without bricks runs no hook; a frame
// refused or without a session runs it too (the batch is free then as well).
TEST(StreamerBricks, TheBatchIsFreeOnceStagedAndRefillingItChangesNothingSent) {
  Rig rig;
  Operator op;
  struct Hooked {
    pipeline::map::BrickBatch* batch = nullptr;
    int calls = 0;
  } hooked;
  pipeline::map::BrickBatch batch = makeBatch(1);
  hooked.batch = &batch;
  rig.streamer->setBricksDoneHook(
      [](void* context) {
        auto* h = static_cast<Hooked*>(context);
        ++h->calls;
        // The next plan: other points where these were, and no entries.
        h->batch->clear(Eigen::Vector3d(-5.0, -5.0, -5.0));
        for (int i = 0; i < 900; ++i) (void)pushBrickPoint(*h->batch, 9.0f, 9.0f, 9.0f, 0xffffff);
      },
      &hooked);
  Result<FrameSendReport> sent = rig.send(&batch, 1);
  ASSERT_TRUE(sent) << sent.status().message();
  EXPECT_EQ(hooked.calls, 1);
  EXPECT_EQ(sent->bricks, 3u);
  op.receive(*rig.op, 300, true);
  ASSERT_EQ(op.cache.bricksHeld(), 3u);
  EXPECT_EQ(op.cache.pointsHeld(), 900u);
  std::size_t near = 0;
  for (std::size_t b = 0; b < 3; ++b) {
    const int held = op.cache.find(net::BrickKey{static_cast<int>(b), -1, 2});
    ASSERT_GE(held, 0);
    op.cache.forEachPoint(static_cast<std::size_t>(held), [&](const Eigen::Vector3d& p, uint32_t) {
      near += std::abs(p.z() - 0.75) < 0.002 ? 1 : 0;  // z: the batch's origin 0.5 + 0.25
    });
  }
  EXPECT_EQ(near, 900u);
  ASSERT_TRUE(rig.send(nullptr, 2));
  EXPECT_EQ(hooked.calls, 1);
  // Refused (a batch without map_bricks) and without a session: the hook runs.
  StreamConfig plain;
  plain.link.listen = "127.0.0.1:0";
  plain.link.insecure = true;
  std::unique_ptr<Streamer> frames_only = Streamer::create(plain, 100).value();
  frames_only->setBricksDoneHook([](void* context) { ++static_cast<Hooked*>(context)->calls; }, &hooked);
  pipeline::map::BrickBatch other = makeBatch(2);
  EXPECT_FALSE(frames_only->sendFrame(rig.live, rig.stats, 1, 0, monotonicNs() + 1'000'000, 33'000'000, &other));
  EXPECT_EQ(hooked.calls, 2);
  BrickFeedback unconnected_feedback{kMaxBricks};  // a streamer no operator connected to
  StreamConfig alone;
  alone.link.listen = "127.0.0.1:0";
  alone.link.insecure = true;
  alone.map_bricks = true;
  alone.brick_sender.max_bricks = kMaxBricks;
  alone.max_brick_points = 1024;
  alone.max_frame_brick_points = 4096;
  alone.max_frame_bricks = 16;
  std::unique_ptr<Streamer> unconnected = Streamer::create(alone, kLivePoints).value();
  unconnected->attachBrickFeedback(&unconnected_feedback);
  unconnected->setBricksDoneHook([](void* context) { ++static_cast<Hooked*>(context)->calls; }, &hooked);
  Result<FrameSendReport> unsent =
      unconnected->sendFrame(rig.live, rig.stats, 1, 0, monotonicNs() + 1'000'000, 33'000'000, &other);
  ASSERT_TRUE(unsent);
  EXPECT_FALSE(unsent->had_session);
  EXPECT_EQ(hooked.calls, 3);
}

// Lent to a slot, only that slot gives it back; taken back, it is free.
TEST(SharedBrickBatch, OnlyTheSlotItIsLentToGivesItBack) {
  SharedBrickBatch shared(pipeline::map::BrickBatch(16, 2));
  EXPECT_TRUE(shared.available());
  EXPECT_FALSE(shared.giveBack(0));  // nobody holds it
  shared.lend(2);
  EXPECT_FALSE(shared.available());
  EXPECT_TRUE(shared.ownedBy(2));
  EXPECT_FALSE(shared.ownedBy(1));
  EXPECT_FALSE(shared.giveBack(1));
  EXPECT_TRUE(shared.ownedBy(2));
  EXPECT_TRUE(shared.giveBack(2));
  EXPECT_TRUE(shared.available());
  EXPECT_FALSE(shared.giveBack(2));  // once
  shared.lend(0);
  shared.takeBack();
  EXPECT_TRUE(shared.available());
}

// The service's protocol for its one batch, run by two threads over a real
// ring as its foveation and send stages do (the send side slow at times, so
// that the ring drops frames): the planner fills the batch only while it is
// free and lends it to the frame; it takes it back from a frame the ring
// dropped; the sender reads it only from a frame that owns it, then gives it
// back. Every batch the sender reads is whole and the frame's own (each point
// carries its frame's number), every lent batch is read or taken back, and
// both the deferral and the take-back happen. Under TSan, a batch written
// while read is a reported race.
TEST(SharedBrickBatch, TwoStagesNeverShareItAndADroppedFrameGivesItBack) {
  struct Frame {
    uint32_t id = 0;
  };
  SlotPoolRing<Frame> ring(1, 1, Frame{});
  SharedBrickBatch shared(pipeline::map::BrickBatch(256, 4));
  constexpr uint32_t kFrames = 3000;
  constexpr int kPoints = 200;
  std::atomic<bool> planner_done{false};
  uint64_t lent = 0, taken_back = 0, deferred = 0;
  std::atomic<uint64_t> read{0}, torn{0};
  std::thread sender([&] {
    uint32_t n = 0;
    for (;;) {
      const bool done = planner_done.load(std::memory_order_acquire);
      SlotIndex slot;
      if (!ring.ring().tryTake(slot)) {
        if (done) break;
        std::this_thread::yield();
        continue;
      }
      const uint32_t id = ring.slot(slot).id;
      if (shared.ownedBy(slot)) {
        const pipeline::map::BrickBatch& b = shared.batch();
        bool whole = b.entries().size() == 1 && b.entries()[0].version == id && b.points.size() == kPoints;
        for (std::size_t i = 0; whole && i < b.points.size(); ++i) whole = b.points.points.x()[i] == static_cast<float>(id);
        if (!whole) torn.fetch_add(1);
        read.fetch_add(1);
        EXPECT_TRUE(shared.giveBack(slot));
      }
      if (++n % 3 == 0) std::this_thread::sleep_for(std::chrono::microseconds(300));  // a slow send
      EXPECT_TRUE(ring.ring().release(slot));
    }
  });
  for (uint32_t id = 1; id <= kFrames; ++id) {
    SlotIndex out;
    while (!ring.ring().tryAcquire(out)) std::this_thread::yield();  // the instant after a release
    if (shared.ownedBy(out)) {  // dropped before the sender took it
      shared.takeBack();
      ++taken_back;
    }
    if (shared.available()) {
      pipeline::map::BrickBatch& b = shared.batch();
      b.clear(Eigen::Vector3d::Zero());
      auto& e = b.add();
      e.version = id;
      for (int i = 0; i < kPoints; ++i) ASSERT_TRUE(b.points.points.push(static_cast<float>(id), 0.0f, 1.0f, 0));
      shared.lend(out);
      ++lent;
    } else {
      ++deferred;
    }
    ring.slot(out).id = id;
    ring.ring().publish(out);
    if (id % 7 == 0) std::this_thread::sleep_for(std::chrono::microseconds(50));
  }
  planner_done.store(true, std::memory_order_release);
  sender.join();
  // A frame dropped last may still own it: nobody takes a slot back after the end.
  const uint64_t still_out = shared.available() ? 0 : 1;
  EXPECT_EQ(torn.load(), 0u);
  EXPECT_EQ(read.load() + taken_back + still_out, lent);
  EXPECT_GT(taken_back, 0u);
  EXPECT_GT(deferred, 0u);
  EXPECT_GT(read.load(), 0u);
}

}  // namespace
}  // namespace fovea::firmware

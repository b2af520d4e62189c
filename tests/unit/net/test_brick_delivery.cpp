// Delivering map bricks over a lossy link (net/brick_sender.h on the robot,
// net/brick_cache.h on the operator, the codec's brick chunks between them):
// with 10 % of the parts and of the acknowledgements lost, duplicates and
// reordering, every brick's last version is drawn within a bounded number of
// resend rounds after the loss stops, and the sender's memory stays fixed;
// parts overwritten in the store before their acknowledgement make the version
// lost, and the caller is told.
#include <algorithm>
#include <deque>
#include <map>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "net/brick_cache.h"
#include "net/brick_sender.h"
#include "net/codec.h"
#include "net/wire.h"

namespace fovea::net {
namespace {

constexpr int64_t kMs = 1'000'000;

// The points of version `version` of brick `b`: a small slab whose size and
// height depend on both, so that versions differ.
void brickPoints(int b, uint32_t version, pipeline::FoveatedCloud& out) {
  out.clear();
  out.points.origin_m = Eigen::Vector3d(b * 0.5, 0.0, 1.0);
  const int n = 300 + static_cast<int>((b * 37 + version * 11) % 500);
  for (int i = 0; i < n; ++i) {
    ASSERT_TRUE(out.points.push(0.001f * static_cast<float>(i % 40), 0.001f * static_cast<float>(i / 40),
                                0.0001f * static_cast<float>(version), 0x808080u));
  }
  std::fill_n(out.region.begin(), out.size(), uint8_t{0});
  std::fill_n(out.weight.begin(), out.size(), 1u);
}

struct Datagram {
  std::vector<uint8_t> payload;  // a chunk: 8-byte aligned when copied into an aligned buffer
};

// The robot's BrickSender and the operator's BrickCache over a simulated link
// that loses, duplicates and reorders datagrams (and loses acknowledgements)
// while `lossy`, on a simulated clock (`now`).
class LossyBrickLink {
 public:
  static constexpr int kBricks = 12;

  LossyBrickLink()
      : sender_(BrickSender::create(senderConfig()).value()),
        cache_(BrickCache::create(cacheConfig()).value()),
        encoder_(ChunkEncoder::create(CodecConfig{}, 4096).value()) {}

  // The robot sends a new version of brick `b`, every part through the link.
  void sendVersion(int b) {
    ++version_[b];
    brickPoints(b, version_[b], points_);
    const double fovea[1] = {0.0};
    const BrickTag tag{b, 0, 2, version_[b], 0};
    ASSERT_TRUE(encoder_.encode(points_, fovea, 0, 0, &tag));
    int lost = -2;
    ASSERT_TRUE(sender_.begin(static_cast<uint16_t>(b), version_[b], static_cast<uint16_t>(encoder_.chunkCount()), now_, &lost));
    EXPECT_EQ(lost, -1);
    for (std::size_t i = 0; i < encoder_.chunkCount(); ++i) {
      ASSERT_TRUE(sender_.addPart(static_cast<uint16_t>(i), encoder_.chunk(i)));
      send(encoder_.chunk(i));
    }
  }

  // One round of 10 ms: the operator takes what arrived and acknowledges it,
  // the robot takes the acknowledgements and resends what is overdue.
  void exchangeRound() {
    operatorReceives();
    robotReceives();
    resendRound();
  }
  // The last acknowledgements, with no resends after them.
  void deliverAcknowledgements() {
    operatorReceives();
    robotReceives();
  }

  void advance() { now_ += 10 * kMs; }
  void stopLoss() { lossy_ = false; }
  std::mt19937::result_type nextRandom() { return rng_(); }

  // Whether the operator draws every sent brick's last version.
  bool converged() const {
    for (int b = 0; b < kBricks; ++b) {
      if (version_[b] == 0) continue;
      const int slot = cache_.find({b, 0, 2});
      if (slot < 0 || !cache_.held(static_cast<std::size_t>(slot)) ||
          cache_.version(static_cast<std::size_t>(slot)) != version_[b]) {
        return false;
      }
    }
    return true;
  }

  // Each drawn brick holds exactly its last version's points.
  void expectEachBrickHoldsItsLastVersion() {
    for (int b = 0; b < kBricks; ++b) {
      if (version_[b] == 0) continue;
      brickPoints(b, version_[b], points_);
      EXPECT_EQ(cache_.pointCount(static_cast<std::size_t>(cache_.find({b, 0, 2}))), points_.size()) << "brick " << b;
    }
  }

  const BrickSender& sender() const { return sender_; }
  const BrickCache& cache() const { return cache_; }
  std::size_t lostVersions() const { return lost_versions_; }

 private:
  static BrickSenderConfig senderConfig() {
    BrickSenderConfig config;
    config.store_bytes = 1 << 20;
    config.max_bricks = kBricks;
    config.resend_after_ns = 30 * kMs;
    return config;
  }
  static BrickCacheConfig cacheConfig() {
    BrickCacheConfig config;
    config.max_bricks = 64;
    config.max_points = 1 << 16;
    return config;
  }

  void send(std::span<const uint8_t> payload) {
    if (lossy_ && rng_() % 10 == 0) return;  // lost
    to_operator_.push_back({{payload.begin(), payload.end()}});
    if (lossy_ && rng_() % 10 == 0) to_operator_.push_back({{payload.begin(), payload.end()}});  // duplicated
    if (lossy_ && to_operator_.size() > 1 && rng_() % 4 == 0) {
      std::swap(to_operator_.back(), to_operator_[rng_() % to_operator_.size()]);  // reordered
    }
  }

  void operatorReceives() {
    while (!to_operator_.empty()) {
      const Datagram d = std::move(to_operator_.front());
      to_operator_.pop_front();
      std::copy(d.payload.begin(), d.payload.end(), aligned_);
      decoded_.clear();
      Result<DecodedChunk> chunk = decodeChunk(std::span<const uint8_t>(aligned_, d.payload.size()), decoded_);
      ASSERT_TRUE(chunk) << chunk.status().toString();
      cache_.add(chunk.value(), decoded_, 0, now_);
    }
    for (const BrickPartId& id : cache_.received()) {
      if (lossy_ && rng_() % 10 == 0) continue;  // the acknowledgement is lost
      to_robot_.push_back(id);
    }
    cache_.clearReceived();
  }

  void robotReceives() {
    while (!to_robot_.empty()) {
      const BrickPartId id = to_robot_.front();
      to_robot_.pop_front();
      sender_.acknowledge(static_cast<uint16_t>(id.key.x), id.version, id.part);
    }
  }

  void resendRound() {
    sender_.collectResends(now_, 10'000, [&](uint16_t, uint16_t, std::span<const uint8_t> payload) { send(payload); },
                           [&](uint16_t) { ++lost_versions_; });
  }

  BrickSender sender_;
  BrickCache cache_;
  ChunkEncoder encoder_;
  pipeline::FoveatedCloud points_{4096}, decoded_{4096};
  std::mt19937 rng_{1026};
  std::deque<Datagram> to_operator_;
  std::deque<BrickPartId> to_robot_;
  std::vector<uint32_t> version_ = std::vector<uint32_t>(kBricks, 0);
  alignas(8) uint8_t aligned_[kMaxMtu];
  bool lossy_ = true;
  int64_t now_ = 0;
  std::size_t lost_versions_ = 0;
};

TEST(BrickDelivery, TenPercentLossDuplicatesAndReorderingConvergeToTheLastVersions) {
  LossyBrickLink link;
  // 50 rounds of 10 ms: every brick gets a few versions, all with loss.
  for (int round = 0; round < 50; ++round, link.advance()) {
    if (round % 5 == 0) {
      for (int b = 0; b < LossyBrickLink::kBricks; ++b) {
        if (link.nextRandom() % 2 == 0) link.sendVersion(b);
      }
    }
    link.exchangeRound();
  }
  // The loss stops: within 20 rounds (200 ms, resend_after 30 ms) the operator draws every brick's last version.
  link.stopLoss();
  int rounds = 0;
  for (; rounds < 20 && !link.converged(); ++rounds, link.advance()) link.exchangeRound();
  EXPECT_TRUE(link.converged()) << "after " << rounds << " rounds without loss";
  EXPECT_EQ(link.lostVersions(), 0u) << "the store holds every part in flight";
  EXPECT_GT(link.sender().counters().resends, 0u);
  EXPECT_GT(link.cache().counters().duplicate_parts, 0u);
  // Every version done once its acknowledgements arrive.
  link.deliverAcknowledgements();
  EXPECT_EQ(link.sender().inFlight(), 0u);
  link.expectEachBrickHoldsItsLastVersion();
}

TEST(BrickDelivery, PartsOverwrittenBeforeTheirAcknowledgementLoseTheVersion) {
  BrickSenderConfig config;
  config.store_bytes = 65536;
  config.max_bricks = 4;
  config.resend_after_ns = 10 * kMs;
  BrickSender sender = BrickSender::create(config).value();
  std::vector<uint8_t> part(4000, 7);
  ASSERT_TRUE(sender.begin(0, 1, 2, 0, nullptr));
  ASSERT_TRUE(sender.addPart(0, part));
  ASSERT_TRUE(sender.addPart(1, part));
  EXPECT_EQ(sender.acknowledge(0, 1, 0), BrickSender::Ack::kPart);
  // Brick 1's versions fill the store past brick 0's unacknowledged part.
  for (uint32_t v = 1; v <= 20; ++v) {
    ASSERT_TRUE(sender.begin(1, v, 1, 0, nullptr));
    ASSERT_TRUE(sender.addPart(0, part));
  }
  std::vector<int> lost;
  std::size_t resent = 0;
  sender.collectResends(20 * kMs, 100, [&](uint16_t, uint16_t, std::span<const uint8_t>) { ++resent; },
                        [&](uint16_t brick) { lost.push_back(brick); });
  EXPECT_EQ(lost, std::vector<int>{0});
  EXPECT_EQ(resent, 1u) << "brick 1's last version is still whole and resent";
  EXPECT_FALSE(sender.inFlight(0));
  // Acknowledgements of what is not in flight are counted, not trusted.
  EXPECT_EQ(sender.acknowledge(0, 1, 1), BrickSender::Ack::kUnknown);
  EXPECT_EQ(sender.acknowledge(1, 19, 0), BrickSender::Ack::kUnknown);  // replaced by 20
  EXPECT_EQ(sender.acknowledge(3, 1, 0), BrickSender::Ack::kUnknown);   // never sent
  EXPECT_EQ(sender.acknowledge(1, 20, 5), BrickSender::Ack::kUnknown);  // no such part
  EXPECT_EQ(sender.acknowledge(1, 20, 0), BrickSender::Ack::kDone);
  EXPECT_EQ(sender.acknowledge(1, 20, 0), BrickSender::Ack::kUnknown);  // again
  EXPECT_EQ(sender.counters().acks_unknown, 5u);
  EXPECT_EQ(sender.inFlight(), 0u);
}

// A part's place in the store is walked from its version's start and the
// parts' lengths: a version whose parts straddle 4 GiB of the store's writes
// (hours of bricks at a robot's rates; the places were once kept in 32 bits)
// is still whole and resent as the same bytes, and one overwritten there is
// still lost. 65 535 parts of 64 KiB get there.
TEST(BrickDelivery, PartsPastFourGibibytesOfWritesAreFoundAsBefore) {
  BrickSenderConfig config;
  config.store_bytes = std::size_t{1} << 20;  // 16 parts of 65 535 bytes a turn, then a skip of 16
  config.max_bricks = 4;
  config.resend_after_ns = 10 * kMs;
  BrickSender sender = BrickSender::create(config).value();
  std::vector<uint8_t> part(65535, 0);
  for (uint32_t v = 1; v <= 65535; ++v) {  // brick 0: each version acknowledged at once
    ASSERT_TRUE(sender.begin(0, v, 1, 0, nullptr));
    ASSERT_TRUE(sender.addPart(0, part));
    ASSERT_EQ(sender.acknowledge(0, v, 0), BrickSender::Ack::kDone);
  }
  // 2^32 - 65 551 bytes written: brick 1's three parts lie either side of 2^32.
  ASSERT_TRUE(sender.begin(1, 1, 3, 0, nullptr));
  for (uint16_t p = 0; p < 3; ++p) {
    std::fill(part.begin(), part.end(), static_cast<uint8_t>(p + 1));
    ASSERT_TRUE(sender.addPart(p, part));
  }
  std::vector<uint16_t> resent;
  std::vector<int> lost;
  sender.collectResends(
      20 * kMs, 100,
      [&](uint16_t brick, uint16_t p, std::span<const uint8_t> bytes) {
        EXPECT_EQ(brick, 1);
        EXPECT_EQ(bytes.size(), 65535u);
        EXPECT_TRUE(std::all_of(bytes.begin(), bytes.end(), [&](uint8_t b) { return b == p + 1; })) << "part " << p;
        resent.push_back(p);
      },
      [&](uint16_t brick) { lost.push_back(brick); });
  EXPECT_EQ(resent, (std::vector<uint16_t>{0, 1, 2}));
  EXPECT_TRUE(lost.empty());
  // Overwritten past 2^32: lost, as at the start.
  for (uint32_t v = 65536; v < 65536 + 17; ++v) {
    ASSERT_TRUE(sender.begin(0, v, 1, 0, nullptr));
    ASSERT_TRUE(sender.addPart(0, part));
    ASSERT_EQ(sender.acknowledge(0, v, 0), BrickSender::Ack::kDone);
  }
  sender.collectResends(40 * kMs, 100, [&](uint16_t, uint16_t, std::span<const uint8_t>) {},
                        [&](uint16_t brick) { lost.push_back(brick); });
  EXPECT_EQ(lost, std::vector<int>{1});
}

TEST(BrickDelivery, AFullTableCrowdsOutTheOldestVersionAndSaysWhich) {
  BrickSenderConfig config;
  config.max_in_flight = 2;
  config.max_bricks = 8;
  BrickSender sender = BrickSender::create(config).value();
  int lost = -2;
  ASSERT_TRUE(sender.begin(5, 1, 1, 0, &lost));
  EXPECT_EQ(lost, -1);
  ASSERT_TRUE(sender.begin(6, 1, 1, 0, &lost));
  ASSERT_TRUE(sender.begin(7, 1, 1, 0, &lost));
  EXPECT_EQ(lost, 5);
  EXPECT_FALSE(sender.inFlight(5));
  EXPECT_EQ(sender.inFlight(), 2u);
  // Bad calls: a brick beyond the table, too many parts, a part of nothing begun.
  EXPECT_FALSE(sender.begin(8, 1, 1, 0, &lost));
  EXPECT_FALSE(sender.begin(1, 1, 0, 0, &lost));
  EXPECT_FALSE(sender.begin(1, 1, 300, 0, &lost));
  EXPECT_FALSE(sender.addPart(1, std::vector<uint8_t>(10)));
  EXPECT_FALSE(sender.addPart(0, std::vector<uint8_t>{})) << "an empty part";
  // Parts come in order: one ahead of the next, or one stored already, is refused.
  ASSERT_TRUE(sender.begin(6, 2, 3, 0, &lost));
  EXPECT_FALSE(sender.addPart(1, std::vector<uint8_t>(10))) << "part 0 is next";
  EXPECT_TRUE(sender.addPart(0, std::vector<uint8_t>(10)));
  EXPECT_FALSE(sender.addPart(0, std::vector<uint8_t>(10))) << "part 0 again";
  EXPECT_TRUE(sender.addPart(1, std::vector<uint8_t>(10)));
  BrickSenderConfig bad;
  bad.store_bytes = 100;
  EXPECT_FALSE(BrickSender::create(bad));
}

}  // namespace
}  // namespace fovea::net

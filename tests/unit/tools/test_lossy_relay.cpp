// fovea-lossy-relay: the seeded decisions (repeatable, the asked shares, the
// edges 0 and 1, invalid shares refused) and the relay on the loopback (what
// arrives is exactly what the policy decided, in both directions, the held
// datagram after the next one).
#include "tools/lossy_relay/lossy_relay.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstring>
#include <optional>
#include <vector>

namespace fovea::tools {
namespace {

std::vector<RelayAction> draws(const LossShares& shares, uint64_t seed, int n) {
  LossyPolicy policy = LossyPolicy::create(shares, seed).value();
  std::vector<RelayAction> out;
  for (int i = 0; i < n; ++i) out.push_back(policy.next());
  return out;
}

int count(const std::vector<RelayAction>& v, RelayAction a) {
  int n = 0;
  for (RelayAction x : v) n += x == a;
  return n;
}

TEST(LossyPolicy, SameSeedSameDecisionsOtherSeedOthers) {
  const LossShares shares{0.2, 0.05};
  EXPECT_EQ(draws(shares, 7, 5000), draws(shares, 7, 5000));
  EXPECT_NE(draws(shares, 7, 5000), draws(shares, 8, 5000));
  EXPECT_NE(draws(shares, 0, 5000), draws(shares, 1, 5000));  // seed 0 is a seed like any other
}

TEST(LossyPolicy, DropsAndReordersTheAskedShares) {
  // 200 000 draws: the binomial standard deviation of 2 % is 63 datagrams, so
  // +-600 is far outside chance for a correct generator and far inside a wrong share.
  const std::vector<RelayAction> v = draws({0.02, 0.01}, 42, 200'000);
  EXPECT_NEAR(count(v, RelayAction::kDrop), 4000, 600);
  EXPECT_NEAR(count(v, RelayAction::kHold), 2000, 450);
  EXPECT_EQ(count(v, RelayAction::kDrop) + count(v, RelayAction::kHold) + count(v, RelayAction::kForward), 200'000);
  // Drops do not come in one run: both halves carry about half of them.
  const std::vector<RelayAction> first(v.begin(), v.begin() + 100'000);
  EXPECT_NEAR(count(first, RelayAction::kDrop), 2000, 450);
}

TEST(LossyPolicy, DuplicatesTheAskedShareAndRecoversWhenTold) {
  Result<LossyPolicy> p = LossyPolicy::create({0.1, 0.01, 0.02}, 7);
  ASSERT_TRUE(p);
  std::vector<RelayAction> v;
  for (int i = 0; i < 200'000; ++i) v.push_back(p->next());
  EXPECT_NEAR(count(v, RelayAction::kDrop), 20000, 1200);
  EXPECT_NEAR(count(v, RelayAction::kHold), 2000, 450);
  EXPECT_NEAR(count(v, RelayAction::kDuplicate), 4000, 600);
  // The link recovers: every datagram is forwarded from then on.
  ASSERT_TRUE(p->setShares({}));
  for (int i = 0; i < 10'000; ++i) ASSERT_EQ(p->next(), RelayAction::kForward);
  EXPECT_FALSE(p->setShares({0.6, 0.0, 0.5}));  // more than everything
  EXPECT_FALSE(LossyPolicy::create({0.0, 0.0, -0.1}, 1));
}

TEST(LossyPolicy, EdgesZeroAndOne) {
  EXPECT_EQ(count(draws({0.0, 0.0}, 3, 100'000), RelayAction::kForward), 100'000);
  EXPECT_EQ(count(draws({1.0, 0.0}, 3, 100'000), RelayAction::kDrop), 100'000);
  EXPECT_EQ(count(draws({0.0, 1.0}, 3, 100'000), RelayAction::kHold), 100'000);
}

TEST(LossyPolicy, RefusesSharesOutsideZeroToOne) {
  for (LossShares bad : {LossShares{-0.1, 0}, LossShares{1.1, 0}, LossShares{0, -1}, LossShares{0.7, 0.4},
                         LossShares{std::nan(""), 0}}) {
    Result<LossyPolicy> p = LossyPolicy::create(bad, 1);
    ASSERT_FALSE(p) << bad.drop << " " << bad.reorder;
    EXPECT_EQ(p.status().code(), ErrorCode::kInvalidArgument);
  }
}

// A client and a server socket on the loopback with the relay between them.
class RelayOnLoopback : public ::testing::Test {
 protected:
  void start(const LossShares& up, const LossShares& down, uint64_t seed) {
    server_ = net::UdpSocket::bind(net::Endpoint::parse("127.0.0.1:0").value()).value();
    LossyRelayConfig config;
    config.listen = net::Endpoint::parse("127.0.0.1:0").value();
    config.server = server_.localEndpoint();
    config.up = up;
    config.down = down;
    config.seed = seed;
    // Held datagrams leave only after the next one (or at flush), never on a
    // timer: what arrives then follows from the decisions alone.
    config.hold_timeout_ns = int64_t{3600} * 1'000'000'000;
    relay_.emplace(LossyRelay::create(config).value());
    client_ = net::UdpSocket::forPeer(relay_->localEndpoint()).value();
  }
  static std::array<uint8_t, 8> payload(uint32_t i) {
    std::array<uint8_t, 8> p{};
    std::memcpy(p.data(), &i, sizeof i);
    return p;
  }
  // Receives at `at` until `got` holds n datagrams (or nothing came for 2 s).
  static void receiveUntil(net::UdpSocket& at, net::Endpoint& from, std::vector<uint32_t>& got, std::size_t n) {
    std::array<uint8_t, 64> buf{};
    while (got.size() < n && at.waitReadable(2000)) {
      const long len = at.receive(buf, from);
      if (len < 0) continue;
      EXPECT_EQ(len, 8);
      uint32_t i = 0;
      std::memcpy(&i, buf.data(), sizeof i);
      got.push_back(i);
    }
  }
  net::UdpSocket server_;
  net::UdpSocket client_;
  std::optional<LossyRelay> relay_;
};

TEST_F(RelayOnLoopback, DeliversExactlyWhatThePolicyDecidedBothWays) {
  const LossShares up{0.1, 0.02}, down{0.3, 0.05};
  const uint64_t seed = 11;
  start(up, down, seed);
  // The relay's directions draw from seed*2 and seed*2+1 (lossy_relay.cpp).
  LossyPolicy expect_up = LossyPolicy::create(up, seed * 2).value();
  LossyPolicy expect_down = LossyPolicy::create(down, seed * 2 + 1).value();

  constexpr uint32_t kDatagrams = 400;
  std::vector<uint32_t> want_up, got_up, want_down, got_down;
  // The datagram each direction holds back, -1 for none (std::optional trips
  // GCC 12's -Wmaybe-uninitialized here).
  int64_t held_up = -1, held_down = -1;
  net::Endpoint client_addr, from;
  const auto expected = [](LossyPolicy& p, uint32_t i, int64_t& held, std::vector<uint32_t>& want) {
    const RelayAction a = p.next();
    if (a == RelayAction::kDrop) return;
    if (a == RelayAction::kHold && held < 0) {
      held = i;
      return;
    }
    want.push_back(i);
    if (held >= 0) want.push_back(static_cast<uint32_t>(held)), held = -1;
  };
  for (uint32_t i = 0; i < kDatagrams; ++i) {
    ASSERT_TRUE(client_.sendTo(payload(i), relay_->localEndpoint()));
    relay_->pump(100);
    expected(expect_up, i, held_up, want_up);
    receiveUntil(server_, client_addr, got_up, want_up.size());
  }
  // The server answers to the relay's address it heard from.
  ASSERT_TRUE(client_addr.valid());
  for (uint32_t i = 0; i < kDatagrams; ++i) {
    ASSERT_TRUE(server_.sendTo(payload(i), client_addr));
    relay_->pump(100);
    expected(expect_down, i, held_down, want_down);
    receiveUntil(client_, from, got_down, want_down.size());
  }
  relay_->flush();
  if (held_up >= 0) want_up.push_back(static_cast<uint32_t>(held_up));
  if (held_down >= 0) want_down.push_back(static_cast<uint32_t>(held_down));
  receiveUntil(server_, client_addr, got_up, want_up.size());
  receiveUntil(client_, from, got_down, want_down.size());
  // Nothing more than decided arrives.
  EXPECT_FALSE(server_.waitReadable(50));
  EXPECT_FALSE(client_.waitReadable(50));

  EXPECT_EQ(got_up, want_up);
  EXPECT_EQ(got_down, want_down);
  EXPECT_EQ(relay_->up().received, kDatagrams);
  EXPECT_EQ(relay_->down().received, kDatagrams);
  EXPECT_EQ(relay_->up().forwarded + relay_->up().dropped, kDatagrams);
  EXPECT_EQ(relay_->down().forwarded + relay_->down().dropped, kDatagrams);
  EXPECT_EQ(relay_->up().forwarded, got_up.size());
  EXPECT_GT(relay_->down().dropped, relay_->up().dropped);  // 30 % against 10 %
  EXPECT_GT(relay_->up().reordered, 0u);
  EXPECT_GT(relay_->down().reordered, 0u);
}

}  // namespace
}  // namespace fovea::tools

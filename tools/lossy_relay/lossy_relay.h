// fovea-lossy-relay's parts: a seeded decision per datagram (forward, drop, or
// hold back one datagram so that it arrives after the next: a reordering) and
// a relay between one client and one server over UDP that applies it in each
// direction. The soak test (toolchain/soak) puts it between fovea-operator and
// fovead serve on the loopback, which loses nothing by itself.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/result.h"
#include "net/udp_socket.h"

namespace fovea::tools {

// Shares of datagrams, each in [0, 1], drop + reorder + duplicate <= 1.
struct LossShares {
  double drop = 0.0;
  double reorder = 0.0;
  double duplicate = 0.0;  // forwarded twice
};

enum class RelayAction : uint8_t { kForward, kDrop, kHold, kDuplicate };

// One direction's decisions: a fixed sequence for a seed (splitmix64), so a
// soak run can be repeated datagram for datagram.
class LossyPolicy {
 public:
  static Result<LossyPolicy> create(const LossShares& shares, uint64_t seed);
  RelayAction next();
  // New shares from the next datagram on (the sequence goes on).
  Status setShares(const LossShares& shares);

 private:
  LossyPolicy(const LossShares& shares, uint64_t seed) : shares_(shares), state_(seed) {}
  LossShares shares_;
  uint64_t state_;
};

struct RelayDirectionCounters {
  uint64_t received = 0;
  uint64_t forwarded = 0;  // includes the reordered ones
  uint64_t dropped = 0;
  uint64_t reordered = 0;  // held back and sent after a later datagram
  uint64_t duplicated = 0;  // forwarded twice (counted once in forwarded)
  uint64_t send_failures = 0;
};

struct LossyRelayConfig {
  net::Endpoint listen;  // where the client (the operator) sends
  net::Endpoint server;  // where the relay forwards (the service)
  LossShares up;         // client -> server
  LossShares down;       // server -> client
  uint64_t seed = 1;
  int64_t hold_timeout_ns = 20'000'000;  // a held datagram goes out after this at the latest
};

class LossyRelay {
 public:
  static Result<LossyRelay> create(const LossyRelayConfig& config);

  // Waits up to timeout_ms for datagrams and relays every one waiting.
  void pump(int timeout_ms);
  // Sends what is held back (at the end of a run).
  void flush();
  // New shares in each direction from the next datagram on (a link that
  // recovers, for a test of what follows the loss).
  Status setShares(const LossShares& up, const LossShares& down);

  net::Endpoint localEndpoint() const { return client_side_.localEndpoint(); }
  const RelayDirectionCounters& up() const { return up_.counters; }
  const RelayDirectionCounters& down() const { return down_.counters; }

 private:
  struct Direction {
    LossyPolicy policy;
    RelayDirectionCounters counters;
    std::vector<uint8_t> held;
    bool holding = false;
    int64_t held_since_ns = 0;
  };
  LossyRelay(LossyRelayConfig config, net::UdpSocket client_side, net::UdpSocket server_side, LossyPolicy up,
             LossyPolicy down);
  void relay(Direction& d, std::span<const uint8_t> datagram, net::UdpSocket& out, const net::Endpoint& to);
  void releaseHeld(Direction& d, net::UdpSocket& out, const net::Endpoint& to);

  LossyRelayConfig config_;
  net::UdpSocket client_side_;  // bound to config_.listen
  net::UdpSocket server_side_;  // talks to config_.server
  net::Endpoint client_;        // the last client heard from
  Direction up_;
  Direction down_;
  std::vector<uint8_t> buffer_;
};

}  // namespace fovea::tools

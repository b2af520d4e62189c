#include "tools/lossy_relay/lossy_relay.h"

#include <poll.h>
#include <sys/socket.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "core/clock.h"

namespace fovea::tools {
namespace {

// splitmix64: small, fast and well mixed; any seed (0 too) gives a full sequence.
uint64_t splitmix64(uint64_t& state) {
  uint64_t z = (state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// Each socket's receive buffer: a frame's burst of about a hundred datagrams must
// wait in the kernel while the relay is off the CPU, or the kernel drops them
// where the relay cannot count them. SO_RCVBUFFORCE passes net.core.rmem_max as
// root; otherwise the kernel caps SO_RCVBUF at that limit (about 208 KiB).
void enlargeReceiveBuffer(int fd) {
  const int bytes = 8 << 20;
  if (::setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &bytes, sizeof bytes) != 0) {
    (void)::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &bytes, sizeof bytes);
  }
}

bool isShare(double v) { return std::isfinite(v) && v >= 0.0 && v <= 1.0; }

// The largest datagram UDP carries; the relay never truncates.
constexpr std::size_t kMaxDatagramBytes = 65'536;

}  // namespace

namespace {
Status checkShares(const LossShares& shares) {
  if (!isShare(shares.drop) || !isShare(shares.reorder) || !isShare(shares.duplicate) ||
      shares.drop + shares.reorder + shares.duplicate > 1.0) {
    return {ErrorCode::kInvalidArgument, "loss, reorder and duplicate shares must be within 0..1 and add up to at most 1 (got " +
                                             std::to_string(shares.drop) + ", " + std::to_string(shares.reorder) +
                                             " and " + std::to_string(shares.duplicate) + ")"};
  }
  return Status::ok();
}
}  // namespace

Result<LossyPolicy> LossyPolicy::create(const LossShares& shares, uint64_t seed) {
  if (Status s = checkShares(shares); !s) return Result<LossyPolicy>(s.code(), s.message());
  return LossyPolicy(shares, seed);
}

Status LossyPolicy::setShares(const LossShares& shares) {
  if (Status s = checkShares(shares); !s) return s;
  shares_ = shares;
  return Status::ok();
}

Status LossyRelay::setShares(const LossShares& up, const LossShares& down) {
  if (Status s = checkShares(up); !s) return s;
  if (Status s = checkShares(down); !s) return s;
  (void)up_.policy.setShares(up);
  (void)down_.policy.setShares(down);
  return Status::ok();
}

RelayAction LossyPolicy::next() {
  // The top 53 bits as a uniform double in [0, 1).
  const double u = static_cast<double>(splitmix64(state_) >> 11) * 0x1.0p-53;
  if (u < shares_.drop) return RelayAction::kDrop;
  if (u < shares_.drop + shares_.reorder) return RelayAction::kHold;
  if (u < shares_.drop + shares_.reorder + shares_.duplicate) return RelayAction::kDuplicate;
  return RelayAction::kForward;
}

Result<LossyRelay> LossyRelay::create(const LossyRelayConfig& config) {
  if (!config.listen.valid() || !config.server.valid()) {
    return Result<LossyRelay>(ErrorCode::kInvalidArgument, "the relay needs a listen address and a server address");
  }
  // Each direction its own sequence: the seed's decisions upstream do not depend
  // on how many datagrams went downstream.
  Result<LossyPolicy> up = LossyPolicy::create(config.up, config.seed * 2 + 0);
  if (!up) return up.status();
  Result<LossyPolicy> down = LossyPolicy::create(config.down, config.seed * 2 + 1);
  if (!down) return down.status();
  Result<net::UdpSocket> client_side = net::UdpSocket::bind(config.listen);
  if (!client_side) return client_side.status();
  Result<net::UdpSocket> server_side = net::UdpSocket::forPeer(config.server);
  if (!server_side) return server_side.status();
  enlargeReceiveBuffer(client_side->fd());
  enlargeReceiveBuffer(server_side->fd());
  return LossyRelay(config, std::move(client_side.value()), std::move(server_side.value()), up.value(), down.value());
}

LossyRelay::LossyRelay(LossyRelayConfig config, net::UdpSocket client_side, net::UdpSocket server_side, LossyPolicy up,
                       LossyPolicy down)
    : config_(std::move(config)),
      client_side_(std::move(client_side)),
      server_side_(std::move(server_side)),
      up_{up, {}, {}, false, 0},
      down_{down, {}, {}, false, 0},
      buffer_(kMaxDatagramBytes) {
  up_.held.reserve(kMaxDatagramBytes);
  down_.held.reserve(kMaxDatagramBytes);
}

void LossyRelay::releaseHeld(Direction& d, net::UdpSocket& out, const net::Endpoint& to) {
  if (!d.holding) return;
  d.holding = false;
  if (out.sendTo(d.held, to)) {
    d.counters.forwarded += 1;
  } else {
    d.counters.send_failures += 1;
  }
}

void LossyRelay::relay(Direction& d, std::span<const uint8_t> datagram, net::UdpSocket& out, const net::Endpoint& to) {
  d.counters.received += 1;
  const RelayAction action = d.policy.next();
  switch (action) {
    case RelayAction::kDrop:
      d.counters.dropped += 1;
      return;
    case RelayAction::kHold:
      if (!d.holding) {
        d.held.assign(datagram.begin(), datagram.end());
        d.holding = true;
        d.held_since_ns = monotonicNs();
        d.counters.reordered += 1;
        return;
      }
      [[fallthrough]];  // one slot: a second hold while one waits is forwarded
    case RelayAction::kDuplicate:
    case RelayAction::kForward:
      if (out.sendTo(datagram, to)) {
        d.counters.forwarded += 1;
      } else {
        d.counters.send_failures += 1;
      }
      if (action == RelayAction::kDuplicate && out.sendTo(datagram, to)) d.counters.duplicated += 1;
      releaseHeld(d, out, to);  // the held one arrives after this one
      return;
  }
}

void LossyRelay::pump(int timeout_ms) {
  pollfd fds[2] = {{client_side_.fd(), POLLIN, 0}, {server_side_.fd(), POLLIN, 0}};
  if (up_.holding || down_.holding) {
    timeout_ms = std::min(timeout_ms, static_cast<int>(config_.hold_timeout_ns / 1'000'000) + 1);
  }
  ::poll(fds, 2, timeout_ms);
  net::Endpoint from;
  long n = 0;
  while ((n = client_side_.receive(buffer_, from)) >= 0) {
    client_ = from;
    relay(up_, std::span<const uint8_t>(buffer_.data(), std::min(buffer_.size(), static_cast<std::size_t>(n))), server_side_, config_.server);
  }
  while ((n = server_side_.receive(buffer_, from)) >= 0) {
    if (!(from == config_.server) || !client_.valid()) continue;  // not the server's, or nobody to send to yet
    relay(down_, std::span<const uint8_t>(buffer_.data(), std::min(buffer_.size(), static_cast<std::size_t>(n))), client_side_, client_);
  }
  const int64_t now = monotonicNs();
  if (up_.holding && now - up_.held_since_ns >= config_.hold_timeout_ns) releaseHeld(up_, server_side_, config_.server);
  if (down_.holding && now - down_.held_since_ns >= config_.hold_timeout_ns) releaseHeld(down_, client_side_, client_);
}

void LossyRelay::flush() {
  releaseHeld(up_, server_side_, config_.server);
  if (client_.valid()) releaseHeld(down_, client_side_, client_);
}

}  // namespace fovea::tools

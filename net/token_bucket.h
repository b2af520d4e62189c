// A token bucket that paces datagrams to a bandwidth budget. Time is an
// argument (CLOCK_MONOTONIC ns from the caller), so tests need no clock.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>

namespace fovea::net {

class TokenBucket {
 public:
  TokenBucket() = default;
  // rate_bytes_per_s > 0; burst_bytes: the most that can go out back to back
  // (at least one datagram). The bucket starts full.
  TokenBucket(double rate_bytes_per_s, double burst_bytes, int64_t now_ns) { reset(rate_bytes_per_s, burst_bytes, now_ns); }

  void reset(double rate_bytes_per_s, double burst_bytes, int64_t now_ns) {
    rate_bytes_per_s_ = rate_bytes_per_s;
    burst_bytes_ = burst_bytes;
    tokens_ = burst_bytes;
    last_ns_ = now_ns;
  }

  // Adds what the rate earned since the last call, up to the burst. Time that
  // runs backwards (a caller bug, or two clocks) adds nothing.
  void refill(int64_t now_ns) {
    if (now_ns > last_ns_) {
      tokens_ = std::min(burst_bytes_, tokens_ + rate_bytes_per_s_ * 1e-9 * static_cast<double>(now_ns - last_ns_));
      last_ns_ = now_ns;
    }
  }

  double available(int64_t now_ns) {
    refill(now_ns);
    return tokens_;
  }

  // Takes `bytes` tokens if they are there.
  [[nodiscard]] bool tryConsume(std::size_t bytes, int64_t now_ns) {
    refill(now_ns);
    if (tokens_ < static_cast<double>(bytes)) return false;
    tokens_ -= static_cast<double>(bytes);
    return true;
  }

  // Takes `bytes` whether or not they are there (a small message that must go,
  // such as a frame summary); the debt delays what follows.
  void charge(std::size_t bytes, int64_t now_ns) {
    refill(now_ns);
    tokens_ -= static_cast<double>(bytes);
  }

  // How long until `bytes` tokens are there (0: now). A request above the burst
  // can never be met; it is answered with the time to fill the bucket.
  int64_t waitNs(std::size_t bytes, int64_t now_ns) {
    refill(now_ns);
    const double need = std::min(static_cast<double>(bytes), burst_bytes_) - tokens_;
    if (need <= 0.0) return 0;
    return static_cast<int64_t>(std::ceil(need / rate_bytes_per_s_ * 1e9));
  }

  double rateBytesPerS() const { return rate_bytes_per_s_; }
  double burstBytes() const { return burst_bytes_; }

 private:
  double rate_bytes_per_s_ = 1.0;
  double burst_bytes_ = 0.0;
  double tokens_ = 0.0;
  int64_t last_ns_ = 0;
};

}  // namespace fovea::net

#include "net/uplink_scheduler.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "net/wire.h"

namespace fovea::net {

namespace {

Status checkBudget(double budget_bytes_per_s, double burst_bytes) {
  if (!(budget_bytes_per_s > 0.0) || !std::isfinite(budget_bytes_per_s)) {
    return {ErrorCode::kInvalidArgument, "uplink budget: must be a positive number of bytes per second"};
  }
  if (!(burst_bytes >= kMinMtu) || !std::isfinite(burst_bytes)) {
    return {ErrorCode::kInvalidArgument,
            "uplink burst: must be at least " + std::to_string(kMinMtu) + " bytes (one datagram)"};
  }
  return Status::ok();
}

}  // namespace

Result<UplinkScheduler> UplinkScheduler::create(std::size_t max_chunks, double budget_bytes_per_s,
                                                double burst_bytes, int64_t now_ns) {
  if (max_chunks == 0) return Result<UplinkScheduler>(ErrorCode::kInvalidArgument, "uplink: max_chunks must be >= 1");
  if (Status s = checkBudget(budget_bytes_per_s, burst_bytes); !s) return s;
  UplinkScheduler scheduler;
  scheduler.max_chunks_ = max_chunks;
  scheduler.bytes_.assign(max_chunks, 0);
  scheduler.bucket_.reset(budget_bytes_per_s, burst_bytes, now_ns);
  return scheduler;
}

void UplinkScheduler::setMaxChunks(std::size_t max_chunks) {
  // The frame under way (of the session before) is dropped, as beginFrame drops it.
  if (next_ < planned_) {
    counters_.chunks_superseded += planned_ - next_;
    ++counters_.frames_superseded;
  }
  next_ = planned_ = 0;
  max_chunks_ = std::max<std::size_t>(max_chunks, 1);
  std::vector<uint32_t>().swap(bytes_);  // the old table goes first
  bytes_.assign(max_chunks_, 0);
}

Status UplinkScheduler::setBudget(double budget_bytes_per_s, double burst_bytes, int64_t now_ns) {
  if (Status s = checkBudget(budget_bytes_per_s, burst_bytes); !s) return s;
  bucket_.reset(budget_bytes_per_s, burst_bytes, now_ns);
  return Status::ok();
}

Status UplinkScheduler::beginFrame(std::span<const uint32_t> datagram_bytes, std::span<const uint8_t> region,
                                   int64_t now_ns, int64_t frame_interval_ns) {
  if (datagram_bytes.size() != region.size()) {
    return {ErrorCode::kInvalidInput, "uplink: chunk sizes and regions differ in length"};
  }
  if (datagram_bytes.size() > max_chunks_) {
    return {ErrorCode::kCapacityExceeded, "uplink: frame has " + std::to_string(datagram_bytes.size()) +
                                              " chunks, capacity is " + std::to_string(max_chunks_)};
  }
  for (std::size_t i = 0; i < region.size(); ++i) {
    if (region[i] >= pipeline::kMaxRegions || (i > 0 && region[i] < region[i - 1])) {
      return {ErrorCode::kInvalidInput, "uplink: chunk regions must be in send order (fovea first, outward)"};
    }
  }

  // What the previous frame did not get out is dropped, not sent late.
  if (next_ < planned_) {
    counters_.chunks_superseded += planned_ - next_;
    ++counters_.frames_superseded;
  }
  ++counters_.frames;

  // The bytes this frame may use: the tokens now plus what the interval earns.
  const double allowance =
      bucket_.available(now_ns) + bucket_.rateBytesPerS() * 1e-9 * static_cast<double>(std::max<int64_t>(frame_interval_ns, 0));
  double total = 0.0;
  for (uint32_t b : datagram_bytes) total += b;
  std::size_t keep = datagram_bytes.size();
  // Cut from the tail (outermost region first); the fovea (region 0) stays.
  while (keep > 0 && total > allowance && region[keep - 1] != 0) {
    --keep;
    total -= datagram_bytes[keep];
  }

  planned_per_region_.fill(0);
  cut_per_region_.fill(0);
  for (std::size_t i = 0; i < datagram_bytes.size(); ++i) {
    bytes_[i] = datagram_bytes[i];
    if (i < keep) {
      ++planned_per_region_[region[i]];
    } else {
      ++cut_per_region_[region[i]];
      ++counters_.chunks_cut_per_region[region[i]];
    }
  }
  if (keep < datagram_bytes.size()) {
    ++counters_.frames_cut;
    counters_.chunks_cut += datagram_bytes.size() - keep;
  }
  planned_ = keep;
  next_ = 0;
  return Status::ok();
}

UplinkScheduler::Step UplinkScheduler::next(int64_t now_ns) {
  Step step;
  if (next_ >= planned_) return step;  // kDone
  const uint32_t bytes = bytes_[next_];
  if (!bucket_.tryConsume(bytes, now_ns)) {
    step.kind = Step::Kind::kWait;
    // At least 1 us, so a caller that sleeps for wait_ns always makes progress.
    step.wait_ns = std::max<int64_t>(bucket_.waitNs(bytes, now_ns), 1000);
    // A datagram larger than the burst could never pass: let it through on a
    // full bucket instead of stalling the frame forever.
    if (bytes > bucket_.burstBytes() && bucket_.available(now_ns) >= bucket_.burstBytes()) {
      bucket_.charge(bytes, now_ns);
    } else {
      return step;
    }
  }
  step.kind = Step::Kind::kSend;
  step.chunk = next_++;
  ++counters_.chunks_sent;
  counters_.bytes_sent += bytes;
  return step;
}

void UplinkScheduler::chargeExtra(std::size_t datagram_bytes, int64_t now_ns) {
  bucket_.charge(datagram_bytes, now_ns);
  counters_.bytes_sent += datagram_bytes;
}

}  // namespace fovea::net

#include "net/brick_sender.h"

#include <algorithm>
#include <cstring>
#include <limits>

namespace fovea::net {


Status BrickSenderConfig::validate() const {
  auto bad = [](const char* what) { return Status(ErrorCode::kInvalidArgument, std::string("brick_sender.") + what); };
  if (store_bytes < 65536 || store_bytes > (std::size_t{1} << 30)) return bad("store_bytes: must be in [64 KiB, 1 GiB]");
  if (max_in_flight == 0 || max_in_flight > 65536) return bad("max_in_flight: must be in [1, 65536]");
  if (max_parts == 0 || max_parts > 65535) return bad("max_parts: must be in [1, 65535]");
  if (max_bricks == 0 || max_bricks > 65536) return bad("max_bricks: must be in [1, 65536]");
  if (resend_after_ns <= 0) return bad("resend_after_ns: must be > 0");
  return Status::ok();
}

Result<BrickSender> BrickSender::create(const BrickSenderConfig& config) {
  if (Status s = config.validate(); !s) return Result<BrickSender>(s.code(), s.message());
  return BrickSender(config);
}

BrickSender::BrickSender(const BrickSenderConfig& config) : config_(config) {
  part_bytes_ = (config.max_parts + 7) / 8;
  ring_.resize(config.store_bytes);
  records_.resize(config.max_in_flight);
  record_of_.assign(config.max_bricks, -1);
  ack_bits_.assign(config.max_in_flight * part_bytes_, 0);
  part_length_.assign(config.max_in_flight * config.max_parts, 0);
}

std::size_t BrickSender::memoryBytes() const {
  return ring_.capacity() + records_.capacity() * sizeof(Record) + record_of_.capacity() * sizeof(int32_t) +
         ack_bits_.capacity() + part_length_.capacity() * sizeof(uint16_t);
}

void BrickSender::release(std::size_t r) {
  Record& rec = records_[r];
  if (!rec.used) return;
  record_of_[rec.brick] = -1;
  rec.used = false;
  --in_flight_;
  if (current_ == r) current_ = SIZE_MAX;
}

// A part never wraps around the ring's end: it skips to its start.
uint64_t BrickSender::placed(uint64_t written, uint16_t length) const {
  const std::size_t at = static_cast<std::size_t>(written % ring_.size());
  return at + length > ring_.size() ? written + (ring_.size() - at) : written;
}

bool BrickSender::begin(uint16_t brick, uint32_t version, uint16_t parts, int64_t now_ns, int* lost) {
  if (lost) *lost = -1;
  if (brick >= record_of_.size() || parts == 0 || parts > config_.max_parts) return false;
  if (record_of_[brick] >= 0) {
    release(static_cast<std::size_t>(record_of_[brick]));
    ++counters_.versions_replaced;
  }
  std::size_t r = records_.size();
  for (std::size_t i = 0; i < records_.size(); ++i) {
    if (!records_[i].used) {
      r = i;
      break;
    }
  }
  if (r == records_.size()) {
    // Full: the oldest version in flight goes.
    r = 0;
    for (std::size_t i = 1; i < records_.size(); ++i) {
      if (records_[i].begun < records_[r].begun) r = i;
    }
    if (lost) *lost = records_[r].brick;
    ++counters_.versions_lost;
    release(r);
  }
  Record& rec = records_[r];
  rec = Record{true, brick, version, parts, 0, 0, now_ns, ++begun_, written_};
  record_of_[brick] = static_cast<int32_t>(r);
  std::memset(bits(r), 0, part_bytes_);
  std::fill_n(lengths(r), parts, uint16_t{0});
  ++in_flight_;
  ++counters_.versions;
  current_ = r;
  return true;
}

bool BrickSender::addPart(uint16_t part, std::span<const uint8_t> payload, std::span<const uint8_t>* stored) {
  if (current_ == SIZE_MAX || part != records_[current_].stored || part >= records_[current_].parts ||
      payload.empty() || payload.size() > ring_.size() / 10 || payload.size() > std::numeric_limits<uint16_t>::max()) {
    return false;
  }
  const auto length = static_cast<uint16_t>(payload.size());
  written_ = placed(written_, length);
  const std::size_t start = static_cast<std::size_t>(written_ % ring_.size());
  std::memcpy(ring_.data() + start, payload.data(), payload.size());
  lengths(current_)[part] = length;
  ++records_[current_].stored;
  written_ += length;
  ++counters_.parts;
  if (stored) *stored = std::span<const uint8_t>(ring_.data() + start, payload.size());
  return true;
}

BrickSender::Ack BrickSender::acknowledge(uint16_t brick, uint32_t version, uint16_t part) {
  if (brick >= record_of_.size() || record_of_[brick] < 0) {
    ++counters_.acks_unknown;
    return Ack::kUnknown;
  }
  const auto r = static_cast<std::size_t>(record_of_[brick]);
  Record& rec = records_[r];
  if (rec.version != version || part >= rec.parts || acked(r, part)) {
    ++counters_.acks_unknown;
    return Ack::kUnknown;
  }
  uint8_t* b = bits(r);
  b[part / 8] = static_cast<uint8_t>(b[part / 8] | (1u << (part % 8)));
  ++counters_.acks;
  if (++rec.acked < rec.parts) return Ack::kPart;
  ++counters_.versions_done;
  release(r);
  return Ack::kDone;
}

void BrickSender::drop(uint16_t brick) {
  if (brick < record_of_.size() && record_of_[brick] >= 0) release(static_cast<std::size_t>(record_of_[brick]));
}

void BrickSender::reset() {
  for (std::size_t r = 0; r < records_.size(); ++r) release(r);
}

}  // namespace fovea::net

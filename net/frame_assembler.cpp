// FrameAssembler (net/codec.h): the operator's collection of decoded chunks into
// frames, completed by their summary or by a newer frame. Apart from the decoder
// because it is the bookkeeping of frames and counters around it, not decoding.
#include "net/codec.h"

#include <algorithm>
#include <string>

#include "net/chunk_decoder.h"
#include "net/chunk_header.h"

namespace fovea::net {

FrameAssembler::FrameAssembler(std::size_t max_points) : seen_(65536, 0) {
  for (pipeline::FoveatedCloud& c : clouds_) c = pipeline::FoveatedCloud(max_points);
}

Result<FrameAssembler> FrameAssembler::create(std::size_t max_points) {
  if (max_points == 0 || max_points > (std::size_t{1} << 26)) {
    return Result<FrameAssembler>(ErrorCode::kInvalidArgument,
                                  "assembler: max_points " + std::to_string(max_points) + " is outside [1, 2^26]");
  }
  // Warm the per-thread decompression context of the calling thread.
  codec_detail::warmThreadDecoder();
  return FrameAssembler(max_points);
}

void FrameAssembler::startFrame(uint32_t frame_id) {
  current_ = AssembledFrame{};
  current_.frame_id = frame_id;
  // A cloud no ready frame uses.
  for (std::size_t i = 0; i < clouds_.size(); ++i) {
    bool used = false;
    for (std::size_t j = 0; j < ready_count_; ++j) used = used || ready_[j].cloud == &clouds_[i];
    if (!used) {
      current_cloud_ = i;
      break;
    }
  }
  clouds_[current_cloud_].clear();
  current_.cloud = &clouds_[current_cloud_];
  std::fill(seen_.begin(), seen_.end(), uint8_t{0});
  has_current_ = true;
}

void FrameAssembler::completeCurrent(bool summary_received) {
  if (!has_current_) return;
  current_.summary_received = summary_received;
  ready_[ready_count_++] = current_;
  last_completed_id_ = current_.frame_id;
  has_last_completed_ = true;
  has_current_ = false;
  ++counters_.frames;
}

void FrameAssembler::flush() {
  ready_count_ = 0;
  completeCurrent(false);
}

Status FrameAssembler::addChunk(std::span<const uint8_t> payload, int64_t received_ns) {
  ready_count_ = 0;
  // Peek at the frame id through a verified decode into the current cloud; a
  // chunk of a newer frame first completes the current one.
  if (payload.size() < 8 || payload.size() > codec_detail::kMaxPayload) {
    ++counters_.bad_chunks;
    return {ErrorCode::kParseError, "chunk: payload size out of range"};
  }
  if (!isPayloadAligned(payload.data())) {
    ++counters_.bad_chunks;
    return {ErrorCode::kParseError, "chunk: payload not aligned (net/wire.h kPayloadAlignment)"};
  }
  codec_detail::HeaderFields h;
  std::size_t header_size = 0;
  if (const char* why = codec_detail::readHeader(payload, h, header_size); why != nullptr) {
    ++counters_.bad_chunks;
    return {ErrorCode::kParseError, std::string("chunk: ") + why};
  }
  if (h.has_brick) {
    ++counters_.bad_chunks;
    return {ErrorCode::kParseError, "chunk: a brick chunk is no part of a frame"};
  }
  const uint32_t id = h.frame_id;
  if (has_current_ && id != current_.frame_id) {
    if (!serialNewer(id, current_.frame_id)) {
      ++counters_.late_chunks;
      return Status::ok();
    }
    completeCurrent(false);
  } else if (!has_current_ && has_last_completed_ && !serialNewer(id, last_completed_id_)) {
    ++counters_.late_chunks;
    return Status::ok();
  }
  if (!has_current_) startFrame(id);
  const uint16_t index = h.chunk_index;
  if (seen_[index] != 0) {
    ++counters_.duplicate_chunks;
    return Status::ok();
  }
  Result<DecodedChunk> d = decodeChunk(payload, clouds_[current_cloud_]);
  if (!d) {
    ++counters_.bad_chunks;
    return d.status();
  }
  seen_[index] = 1;
  ++counters_.chunks;
  current_.capture_time_ns = d->capture_time_ns;
  current_.chunk_count = d->chunk_count;
  current_.points[d->region] += static_cast<uint32_t>(d->points);
  current_.step_m[d->region] = d->step_m;
  ++current_.chunks_received[d->region];
  current_.last_chunk_received_ns = received_ns;
  return Status::ok();
}

Status FrameAssembler::addSummary(std::span<const uint8_t> payload) {
  ready_count_ = 0;
  Result<FrameSummaryInfo> s = decodeSummary(payload);
  if (!s) {
    ++counters_.bad_summaries;
    return s.status();
  }
  const uint32_t id = s->frame_id;
  if (has_current_ && id != current_.frame_id) {
    if (!serialNewer(id, current_.frame_id)) {
      ++counters_.late_summaries;
      return Status::ok();
    }
    completeCurrent(false);
  } else if (!has_current_ && has_last_completed_ && !serialNewer(id, last_completed_id_)) {
    ++counters_.late_summaries;
    return Status::ok();
  }
  if (!has_current_) startFrame(id);  // every chunk of this frame was lost
  current_.chunk_count = s->chunk_count;
  for (int r = 0; r < s->region_count; ++r) {
    current_.chunks_expected[static_cast<std::size_t>(r)] = s->chunks_sent[static_cast<std::size_t>(r)];
    current_.chunks_cut[static_cast<std::size_t>(r)] = s->chunks_cut[static_cast<std::size_t>(r)];
  }
  completeCurrent(true);
  return Status::ok();
}

}  // namespace fovea::net

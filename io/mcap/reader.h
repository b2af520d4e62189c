// Reads MCAP v0 files sequentially, for replay (io/mcap/format.h). It needs no
// summary, so a file cut off by a power failure reads up to its last complete
// chunk. Every length is checked against what is left of its record, chunk
// CRCs are checked, decompressed sizes are bounded, unknown opcodes are
// skipped, and nothing a file holds, however hostile, crashes it: the reader
// gives every schema, channel and message it could read, in file order, then
// stops with "stopped at byte N: reason" (or reaches the Footer and the closing
// magic: complete()).
//
// The file's bytes are the caller's (a span; readFile loads one); a message's
// data span points into them or into the reader's chunk buffer and stays valid
// until the next call to next().
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.h"

namespace fovea::mcap {

struct SchemaRecord {
  uint16_t id = 0;
  std::string name;
  std::string encoding;
  std::vector<uint8_t> data;
};

struct ChannelRecord {
  uint16_t id = 0;
  uint16_t schema_id = 0;
  std::string topic;
  std::string message_encoding;
  std::vector<std::pair<std::string, std::string>> metadata;
};

struct MessageView {
  uint16_t channel_id = 0;
  uint32_t sequence = 0;
  uint64_t log_time_ns = 0;
  uint64_t publish_time_ns = 0;
  std::span<const uint8_t> data;
};

struct ReaderOptions {
  // The largest chunk the reader decompresses (its uncompressed size).
  uint64_t max_chunk_bytes = 256ull << 20;
  // Schemas and channels a file may declare.
  std::size_t max_channels = 4096;
};

class Reader {
 public:
  enum class Item { kSchema, kChannel, kMessage, kEnd };

  explicit Reader(std::span<const uint8_t> file, const ReaderOptions& options = {});
  ~Reader();
  Reader(const Reader&) = delete;
  Reader& operator=(const Reader&) = delete;

  // The next schema, channel or message in file order; kEnd when the file ends
  // or cannot be read further (then see complete() and stopReason()).
  Item next();
  // The item next() returned.
  const SchemaRecord& schema() const { return schemas_.back(); }
  const ChannelRecord& channel() const { return channels_.back(); }
  const MessageView& message() const { return message_; }

  // Every schema and channel read so far.
  const std::vector<SchemaRecord>& schemas() const { return schemas_; }
  const std::vector<ChannelRecord>& channels() const { return channels_; }
  const ChannelRecord* findChannel(uint16_t id) const;
  const SchemaRecord* findSchema(uint16_t id) const;

  // True when the reader reached the Footer and the closing magic.
  bool complete() const { return complete_; }
  // After kEnd on an incomplete file: "stopped at byte N: reason".
  const std::string& stopReason() const { return stop_reason_; }
  uint64_t stopOffset() const { return stop_offset_; }
  uint64_t messagesRead() const { return messages_; }
  uint64_t chunksRead() const { return chunks_; }
  uint64_t unknownRecordsSkipped() const { return unknown_skipped_; }
  // Back to the file's first record, keeping what was learnt: the schemas and
  // channels (met again, they are known and not returned) and the buffers.
  void rewind();

 private:
  struct Cursor;
  Item stop(uint64_t offset, std::string reason);
  // Parses one record's content; kEnd with a stop reason when it is malformed.
  Item onRecord(uint8_t opcode, std::span<const uint8_t> content, uint64_t offset, bool in_chunk);
  Item enterChunk(std::span<const uint8_t> content, uint64_t offset);

  std::span<const uint8_t> file_;
  ReaderOptions options_;
  uint64_t pos_ = 0;            // in the file
  bool started_ = false;
  bool done_ = false;
  bool complete_ = false;
  std::vector<uint8_t> chunk_;  // the current chunk's records, decompressed
  std::span<const uint8_t> chunk_records_;
  uint64_t chunk_pos_ = 0;      // in chunk_records_
  uint64_t chunk_offset_ = 0;   // the chunk record's offset in the file
  bool in_chunk_ = false;
  bool after_data_end_ = false;
  void* zstd_ = nullptr;        // ZSTD_DCtx
  std::vector<SchemaRecord> schemas_;
  std::vector<ChannelRecord> channels_;
  MessageView message_;
  std::string stop_reason_;
  uint64_t stop_offset_ = 0;
  uint64_t messages_ = 0;
  uint64_t chunks_ = 0;
  uint64_t unknown_skipped_ = 0;
};

// A file's bytes, at most max_bytes of them (kCapacityExceeded past it).
Result<std::vector<uint8_t>> readFile(const std::string& path, uint64_t max_bytes = 64ull << 30);

}  // namespace fovea::mcap

#include "io/mcap/reader.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zstd.h>

#include <cerrno>
#include <cstring>

#include "io/mcap/format.h"

namespace fovea::mcap {

// Reads fields from one record's content; any read past its end clears ok.
struct Reader::Cursor {
  std::span<const uint8_t> bytes;
  std::size_t pos = 0;
  bool ok = true;
  const char* what = nullptr;  // the first field that did not fit

  std::size_t left() const { return bytes.size() - pos; }
  bool need(std::size_t n, const char* field) {
    if (!ok) return false;
    if (left() < n) {
      ok = false;
      what = field;
      return false;
    }
    return true;
  }
  uint8_t u8(const char* field) {
    if (!need(1, field)) return 0;
    return bytes[pos++];
  }
  uint16_t u16(const char* field) {
    if (!need(2, field)) return 0;
    pos += 2;
    return loadLe16(bytes.data() + pos - 2);
  }
  uint32_t u32(const char* field) {
    if (!need(4, field)) return 0;
    pos += 4;
    return loadLe32(bytes.data() + pos - 4);
  }
  uint64_t u64(const char* field) {
    if (!need(8, field)) return 0;
    pos += 8;
    return loadLe64(bytes.data() + pos - 8);
  }
  std::span<const uint8_t> take(uint64_t n, const char* field) {
    if (!need(0, field)) return {};
    if (n > left()) {
      ok = false;
      what = field;
      return {};
    }
    pos += static_cast<std::size_t>(n);
    return bytes.subspan(pos - static_cast<std::size_t>(n), static_cast<std::size_t>(n));
  }
  std::string str(const char* field) {
    const uint32_t n = u32(field);
    const std::span<const uint8_t> s = take(n, field);
    return std::string(reinterpret_cast<const char*>(s.data()), s.size());
  }
};

namespace {

std::string malformed(const char* record, const char* field) {
  return std::string("malformed ") + record + " record: its " + (field ? field : "content") +
         " runs past the record's end";
}

}  // namespace

Reader::Reader(std::span<const uint8_t> file, const ReaderOptions& options) : file_(file), options_(options) {}

void Reader::rewind() {
  pos_ = 0;
  started_ = false;
  done_ = false;
  complete_ = false;
  in_chunk_ = false;
  after_data_end_ = false;
  chunk_records_ = {};
  chunk_pos_ = 0;
  chunk_offset_ = 0;
  stop_reason_.clear();
  stop_offset_ = 0;
}

Reader::~Reader() {
  if (zstd_ != nullptr) ZSTD_freeDCtx(static_cast<ZSTD_DCtx*>(zstd_));
}

const ChannelRecord* Reader::findChannel(uint16_t id) const {
  for (const ChannelRecord& c : channels_) {
    if (c.id == id) return &c;
  }
  return nullptr;
}

const SchemaRecord* Reader::findSchema(uint16_t id) const {
  for (const SchemaRecord& s : schemas_) {
    if (s.id == id) return &s;
  }
  return nullptr;
}

Reader::Item Reader::stop(uint64_t offset, std::string reason) {
  done_ = true;
  stop_offset_ = offset;
  stop_reason_ = "stopped at byte " + std::to_string(offset) + ": " + reason;
  return Item::kEnd;
}

Reader::Item Reader::next() {
  if (done_) return Item::kEnd;
  if (!started_) {
    started_ = true;
    if (file_.size() < sizeof(kMagic)) return stop(0, "the file is shorter than the MCAP magic");
    if (std::memcmp(file_.data(), kMagic, sizeof(kMagic)) != 0) return stop(0, "not an MCAP file (wrong magic)");
    pos_ = sizeof(kMagic);
  }
  for (;;) {
    if (in_chunk_) {
      if (chunk_pos_ == chunk_records_.size()) {
        in_chunk_ = false;
        continue;
      }
      const uint64_t left = chunk_records_.size() - chunk_pos_;
      // Made on the error paths only: a replay reads every record without allocating.
      auto where = [this] {
        return "the record at " + std::to_string(chunk_pos_) + " in the chunk at byte " + std::to_string(chunk_offset_);
      };
      if (left < kRecordPrefixBytes) return stop(chunk_offset_, where() + " is cut off");
      const uint8_t opcode = chunk_records_[chunk_pos_];
      const uint64_t length = loadLe64(chunk_records_.data() + chunk_pos_ + 1);
      if (length > left - kRecordPrefixBytes) {
        return stop(chunk_offset_, where() + " claims " + std::to_string(length) + " bytes, " +
                                       std::to_string(left - kRecordPrefixBytes) + " are left");
      }
      const std::span<const uint8_t> content =
          chunk_records_.subspan(chunk_pos_ + kRecordPrefixBytes, static_cast<std::size_t>(length));
      chunk_pos_ += kRecordPrefixBytes + length;
      const Item item = onRecord(opcode, content, chunk_offset_, true);
      if (item != Item::kEnd || done_) return item;
      continue;
    }
    const uint64_t left = file_.size() - pos_;
    if (left == 0) {
      return stop(pos_, "the file ends without a footer (cut off after its last complete record)");
    }
    if (left < kRecordPrefixBytes) return stop(pos_, "the file ends inside a record's opcode and length");
    const uint8_t opcode = file_[pos_];
    const uint64_t length = loadLe64(file_.data() + pos_ + 1);
    if (length > left - kRecordPrefixBytes) {
      return stop(pos_, "a record (opcode 0x" + std::string(1, "0123456789abcdef"[opcode >> 4]) +
                            std::string(1, "0123456789abcdef"[opcode & 15]) + ") claims " + std::to_string(length) +
                            " bytes, the file has " + std::to_string(left - kRecordPrefixBytes) + " left");
    }
    const uint64_t offset = pos_;
    const std::span<const uint8_t> content =
        file_.subspan(static_cast<std::size_t>(pos_ + kRecordPrefixBytes), static_cast<std::size_t>(length));
    pos_ += kRecordPrefixBytes + length;
    if (opcode == kOpFooter) {
      if (file_.size() - pos_ < sizeof(kMagic) ||
          std::memcmp(file_.data() + pos_, kMagic, sizeof(kMagic)) != 0) {
        return stop(pos_, "the footer is not followed by the closing magic");
      }
      done_ = true;
      complete_ = true;
      return Item::kEnd;
    }
    if (opcode == kOpDataEnd) after_data_end_ = true;
    // The summary repeats the data section's schemas and channels: skip it.
    if (after_data_end_) continue;
    if (opcode == kOpChunk) {
      const Item item = enterChunk(content, offset);
      if (done_) return item;
      continue;
    }
    const Item item = onRecord(opcode, content, offset, false);
    if (item != Item::kEnd || done_) return item;
  }
}

Reader::Item Reader::enterChunk(std::span<const uint8_t> content, uint64_t offset) {
  Cursor c{content};
  c.u64("message start time");
  c.u64("message end time");
  const uint64_t uncompressed_size = c.u64("uncompressed size");
  const uint32_t crc = c.u32("uncompressed crc");
  const std::string compression = c.str("compression");
  const uint64_t records_size = c.u64("records length");
  const std::span<const uint8_t> records = c.take(records_size, "records");
  if (!c.ok) return stop(offset, malformed("chunk", c.what));
  if (uncompressed_size > options_.max_chunk_bytes) {
    return stop(offset, "the chunk's uncompressed size " + std::to_string(uncompressed_size) +
                            " is over the reader's limit of " + std::to_string(options_.max_chunk_bytes) + " bytes");
  }
  if (compression.empty()) {
    if (records.size() != uncompressed_size) {
      return stop(offset, "the uncompressed chunk's records length differs from its uncompressed size");
    }
    chunk_records_ = records;
  } else if (compression == "zstd") {
    if (zstd_ == nullptr) zstd_ = ZSTD_createDCtx();
    if (zstd_ == nullptr) return stop(offset, "cannot create a zstd context");
    if (chunk_.size() < uncompressed_size) chunk_.resize(static_cast<std::size_t>(uncompressed_size));
    const std::size_t n = ZSTD_decompressDCtx(static_cast<ZSTD_DCtx*>(zstd_), chunk_.data(),
                                              static_cast<std::size_t>(uncompressed_size), records.data(),
                                              records.size());
    if (ZSTD_isError(n)) return stop(offset, std::string("the chunk does not decompress: ") + ZSTD_getErrorName(n));
    if (n != uncompressed_size) {
      return stop(offset, "the chunk decompresses to " + std::to_string(n) + " bytes, its header says " +
                              std::to_string(uncompressed_size));
    }
    chunk_records_ = std::span<const uint8_t>(chunk_.data(), n);
  } else {
    return stop(offset, "the chunk's compression '" + compression.substr(0, 32) + "' is not supported");
  }
  if (crc != 0) {
    const uint32_t actual = crc32Update(0, chunk_records_);
    if (actual != crc) {
      return stop(offset, "the chunk's CRC fails (" + std::to_string(actual) + ", its header says " +
                              std::to_string(crc) + ")");
    }
  }
  ++chunks_;
  in_chunk_ = true;
  chunk_pos_ = 0;
  chunk_offset_ = offset;
  return Item::kEnd;
}

Reader::Item Reader::onRecord(uint8_t opcode, std::span<const uint8_t> content, uint64_t offset, bool in_chunk) {
  Cursor c{content};
  switch (opcode) {
    case kOpSchema: {
      SchemaRecord s;
      s.id = c.u16("id");
      // Met again (the summary repeats them, a replay's rewind reads them anew): known, and
      // nothing is allocated for them.
      if (c.ok && s.id != 0 && findSchema(s.id) != nullptr) return Item::kEnd;
      s.name = c.str("name");
      s.encoding = c.str("encoding");
      const uint32_t n = c.u32("data length");
      const std::span<const uint8_t> data = c.take(n, "data");
      if (!c.ok) return stop(offset, malformed("schema", c.what));
      if (s.id == 0) return stop(offset, "a schema has the reserved id 0");
      if (findSchema(s.id) != nullptr) return Item::kEnd;  // repeated: already known
      if (schemas_.size() >= options_.max_channels) return stop(offset, "more schemas than the reader's limit");
      s.data.assign(data.begin(), data.end());
      schemas_.push_back(std::move(s));
      return Item::kSchema;
    }
    case kOpChannel: {
      ChannelRecord ch;
      ch.id = c.u16("id");
      if (c.ok && findChannel(ch.id) != nullptr) return Item::kEnd;  // met again: known
      ch.schema_id = c.u16("schema id");
      ch.topic = c.str("topic");
      ch.message_encoding = c.str("message encoding");
      const uint32_t n = c.u32("metadata length");
      Cursor map{c.take(n, "metadata")};
      while (c.ok && map.ok && map.left() > 0) {
        std::string key = map.str("metadata key");
        std::string value = map.str("metadata value");
        if (map.ok) ch.metadata.emplace_back(std::move(key), std::move(value));
      }
      if (!c.ok) return stop(offset, malformed("channel", c.what));
      if (!map.ok) return stop(offset, malformed("channel", map.what));
      if (ch.schema_id != 0 && findSchema(ch.schema_id) == nullptr) {
        return stop(offset, "channel " + std::to_string(ch.id) + " refers to schema " + std::to_string(ch.schema_id) +
                                ", which the file has not declared");
      }
      if (findChannel(ch.id) != nullptr) return Item::kEnd;  // repeated
      if (channels_.size() >= options_.max_channels) return stop(offset, "more channels than the reader's limit");
      channels_.push_back(std::move(ch));
      return Item::kChannel;
    }
    case kOpMessage: {
      message_.channel_id = c.u16("channel id");
      message_.sequence = c.u32("sequence");
      message_.log_time_ns = c.u64("log time");
      message_.publish_time_ns = c.u64("publish time");
      if (!c.ok) return stop(offset, malformed("message", c.what));
      message_.data = content.subspan(c.pos);
      if (findChannel(message_.channel_id) == nullptr) {
        return stop(offset, std::string("a message") + (in_chunk ? " in the chunk" : "") + " is on channel " +
                                std::to_string(message_.channel_id) + ", which the file has not declared");
      }
      ++messages_;
      return Item::kMessage;
    }
    case kOpChunk:
      if (in_chunk) return stop(offset, "a chunk inside a chunk");
      return Item::kEnd;
    case kOpHeader:
    case kOpMessageIndex:
    case kOpChunkIndex:
    case kOpAttachment:
    case kOpAttachmentIndex:
    case kOpStatistics:
    case kOpMetadata:
    case kOpMetadataIndex:
    case kOpSummaryOffset:
    case kOpDataEnd:
      return Item::kEnd;  // known, and nothing replay needs
    default:
      ++unknown_skipped_;
      return Item::kEnd;
  }
}

Result<std::vector<uint8_t>> readFile(const std::string& path, uint64_t max_bytes) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return Status(ErrorCode::kNotFound, "mcap: cannot open " + path + ": " + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0 || st.st_size < 0) {
    ::close(fd);
    return Status(ErrorCode::kIoError, "mcap: cannot stat " + path);
  }
  if (static_cast<uint64_t>(st.st_size) > max_bytes) {
    ::close(fd);
    return Status(ErrorCode::kCapacityExceeded, "mcap: " + path + " is larger than " + std::to_string(max_bytes) +
                                                    " bytes");
  }
  std::vector<uint8_t> bytes(static_cast<std::size_t>(st.st_size));
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::read(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    done += static_cast<std::size_t>(n);
  }
  ::close(fd);
  bytes.resize(done);
  return bytes;
}

}  // namespace fovea::mcap

#include "io/mcap/writer.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>

#include "io/mcap/format.h"

namespace fovea::mcap {

namespace {

constexpr std::array<uint32_t, 256> makeCrcTable() {
  std::array<uint32_t, 256> table{};
  for (uint32_t i = 0; i < 256; ++i) {
    uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    table[i] = c;
  }
  return table;
}
constexpr std::array<uint32_t, 256> kCrcTable = makeCrcTable();

// Appends little-endian fields to a byte vector.
class Builder {
 public:
  explicit Builder(std::vector<uint8_t>& out) : out_(out) {}
  void u8(uint8_t v) { out_.push_back(v); }
  void u16(uint16_t v) { storeLe16(grow(2), v); }
  void u32(uint32_t v) { storeLe32(grow(4), v); }
  void u64(uint64_t v) { storeLe64(grow(8), v); }
  void bytes(std::span<const uint8_t> v) {
    if (!v.empty()) std::memcpy(grow(v.size()), v.data(), v.size());
  }
  void str(std::string_view v) {
    u32(static_cast<uint32_t>(v.size()));
    if (!v.empty()) std::memcpy(grow(v.size()), v.data(), v.size());
  }
  // opcode and a length patched by end().
  std::size_t begin(uint8_t opcode) {
    u8(opcode);
    const std::size_t at = out_.size();
    u64(0);
    return at;
  }
  void end(std::size_t at) { storeLe64(out_.data() + at, out_.size() - at - 8); }
  // A u32 byte length patched by endU32().
  std::size_t beginU32() {
    const std::size_t at = out_.size();
    u32(0);
    return at;
  }
  void endU32(std::size_t at) { storeLe32(out_.data() + at, static_cast<uint32_t>(out_.size() - at - 4)); }
  std::size_t size() const { return out_.size(); }

 private:
  uint8_t* grow(std::size_t n) {
    const std::size_t at = out_.size();
    out_.resize(at + n);
    return out_.data() + at;
  }
  std::vector<uint8_t>& out_;
};


}  // namespace

uint32_t crc32Update(uint32_t crc, std::span<const uint8_t> bytes) {
  uint32_t c = ~crc;
  for (uint8_t b : bytes) c = kCrcTable[(c ^ b) & 0xFF] ^ (c >> 8);
  return ~c;
}

struct Writer::ChannelState {
  std::vector<std::pair<uint64_t, uint64_t>> index;  // this chunk: log time, offset in the chunk
  uint64_t messages = 0;
  uint32_t next_sequence = 1;
};

struct Writer::ChunkIndexEntry {
  uint64_t start_time = 0;
  uint64_t end_time = 0;
  uint64_t chunk_offset = 0;
  uint64_t chunk_length = 0;
  std::size_t offsets_first = 0;  // in Writer::index_offsets_
  std::size_t offsets_count = 0;
  uint64_t index_length = 0;
  uint64_t compressed_size = 0;
  uint64_t uncompressed_size = 0;
};

Result<std::unique_ptr<Writer>> Writer::open(const std::string& path, const WriterOptions& options) {
  std::unique_ptr<Writer> writer(new Writer());
  writer->path_ = path;
  writer->fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (writer->fd_ < 0) {
    return Status(ErrorCode::kIoError, "mcap: cannot create " + path + ": " + std::strerror(errno));
  }
  struct stat st {};
  if (::fstat(writer->fd_, &st) == 0) {
    writer->inode_ = st.st_ino;
    writer->device_ = st.st_dev;
  }
  if (Status s = writer->start(options); !s) return s;
  return writer;
}

Result<std::unique_ptr<Writer>> Writer::openBuffer(std::vector<uint8_t>* out, const WriterOptions& options) {
  std::unique_ptr<Writer> writer(new Writer());
  writer->memory_ = out;
  out->clear();
  if (Status s = writer->start(options); !s) return s;
  return writer;
}

Writer::~Writer() {
  if (fd_ >= 0) ::close(fd_);
  if (zstd_ != nullptr) ZSTD_freeCCtx(static_cast<ZSTD_CCtx*>(zstd_));
}

Status Writer::start(const WriterOptions& options) {
  options_ = options;
  if (options_.chunk_bytes < 64) options_.chunk_bytes = 64;
  if (options_.max_channels < 1 || options_.max_channels > 65535) {
    return invalidArgument("mcap: max_channels must be 1..65535");
  }
  chunk_.reserve(options_.chunk_bytes + kRecordPrefixBytes + kMessageHeaderBytes);
  staged_.reserve(options_.chunk_bytes + 4096);
  if (options_.compression == Compression::kZstd) {
    compressed_.resize(ZSTD_compressBound(chunk_.capacity()));
    zstd_ = ZSTD_createCCtx();
    if (zstd_ == nullptr) return Status(ErrorCode::kIoError, "mcap: cannot create a zstd context");
  }
  schema_records_.reserve(options_.max_channels);
  channel_records_.reserve(options_.max_channels);
  channels_.reserve(options_.max_channels);
  chunk_indexes_.reserve(1024);
  index_offsets_.reserve(1024 * std::min<std::size_t>(options_.max_channels, 8));
  // The magic, then the Header.
  Builder b(staged_);
  b.bytes(kMagic);
  const std::size_t at = b.begin(kOpHeader);
  b.str(options_.profile);
  b.str(options_.library);
  b.end(at);
  return emitStaged(true);
}

Status Writer::fail(Status status) {
  if (failed_) failed_ = status;
  return failed_;
}

Status Writer::emit(std::span<const uint8_t> bytes, bool data_section) {
  if (!failed_) return failed_;
  if (options_.max_file_bytes != 0 && offset_ + bytes.size() > options_.max_file_bytes) {
    return fail(Status(ErrorCode::kIoError, "mcap: writing " + path_ + ": the file size limit (" +
                                                std::to_string(options_.max_file_bytes) + " bytes) is reached"));
  }
  if (data_section) data_crc_ = crc32Update(data_crc_, bytes);
  if (memory_ != nullptr) {
    memory_->insert(memory_->end(), bytes.begin(), bytes.end());
  } else {
    std::size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
      if (n < 0) {
        if (errno == EINTR) continue;
        const int e = errno;
        offset_ += done;
        stats_.file_bytes = offset_;
        return fail(Status(ErrorCode::kIoError, "mcap: writing " + path_ + ": " + std::strerror(e)));
      }
      done += static_cast<std::size_t>(n);
    }
  }
  offset_ += bytes.size();
  stats_.file_bytes = offset_;
  return Status::ok();
}

Status Writer::emitStaged(bool data_section) {
  Status s = emit(staged_, data_section);
  staged_.clear();
  return s;
}

Result<uint16_t> Writer::addSchema(std::string_view name, std::string_view encoding, std::span<const uint8_t> data) {
  if (!failed_) return failed_;
  if (closed_) return Status(ErrorCode::kInvalidArgument, "mcap: the writer is closed");
  if (schema_records_.size() >= options_.max_channels) {
    return Status(ErrorCode::kCapacityExceeded, "mcap: more schemas than max_channels");
  }
  const auto id = static_cast<uint16_t>(schema_records_.size() + 1);
  std::vector<uint8_t> record;
  Builder b(record);
  const std::size_t at = b.begin(kOpSchema);
  b.u16(id);
  b.str(name);
  b.str(encoding);
  b.u32(static_cast<uint32_t>(data.size()));
  b.bytes(data);
  b.end(at);
  if (Status s = emit(record, true); !s) return s;
  schema_records_.push_back(std::move(record));
  return id;
}

Result<uint16_t> Writer::addChannel(std::string_view topic, std::string_view message_encoding, uint16_t schema_id,
                                    std::span<const std::pair<std::string, std::string>> metadata) {
  if (!failed_) return failed_;
  if (closed_) return Status(ErrorCode::kInvalidArgument, "mcap: the writer is closed");
  if (schema_id > schema_records_.size()) {
    return Status(ErrorCode::kInvalidArgument, "mcap: channel " + std::string(topic) + ": unknown schema id");
  }
  if (channel_records_.size() >= options_.max_channels) {
    return Status(ErrorCode::kCapacityExceeded, "mcap: more channels than max_channels");
  }
  const auto id = static_cast<uint16_t>(channel_records_.size() + 1);
  std::vector<uint8_t> record;
  Builder b(record);
  const std::size_t at = b.begin(kOpChannel);
  b.u16(id);
  b.u16(schema_id);
  b.str(topic);
  b.str(message_encoding);
  const std::size_t map_at = b.beginU32();
  for (const auto& [key, value] : metadata) {
    b.str(key);
    b.str(value);
  }
  b.endU32(map_at);
  b.end(at);
  if (Status s = emit(record, true); !s) return s;
  channel_records_.push_back(std::move(record));
  channels_.emplace_back();
  channels_.back().index.reserve(options_.index_entries_per_chunk);
  return id;
}

Status Writer::write(uint16_t channel_id, uint64_t log_time_ns, uint64_t publish_time_ns,
                     std::span<const uint8_t> data, uint32_t sequence) {
  if (!failed_) return failed_;
  if (closed_) return Status(ErrorCode::kInvalidArgument, "mcap: the writer is closed");
  if (channel_id == 0 || channel_id > channels_.size()) {
    return Status(ErrorCode::kInvalidArgument, "mcap: unknown channel id " + std::to_string(channel_id));
  }
  const std::size_t record_bytes = kRecordPrefixBytes + kMessageHeaderBytes + data.size();
  if (!chunk_.empty() && chunk_.size() + record_bytes > options_.chunk_bytes) {
    if (Status s = flushChunk(); !s) return s;
  }
  ChannelState& channel = channels_[channel_id - 1];
  if (sequence == 0) sequence = channel.next_sequence++;
  channel.index.emplace_back(log_time_ns, chunk_.size());
  Builder b(chunk_);
  b.u8(kOpMessage);
  b.u64(kMessageHeaderBytes + data.size());
  b.u16(channel_id);
  b.u32(sequence);
  b.u64(log_time_ns);
  b.u64(publish_time_ns);
  b.bytes(data);
  if (chunk_messages_ == 0 || log_time_ns < chunk_start_time_) chunk_start_time_ = log_time_ns;
  if (chunk_messages_ == 0 || log_time_ns > chunk_end_time_) chunk_end_time_ = log_time_ns;
  if (stats_.messages == 0 || log_time_ns < message_start_time_) message_start_time_ = log_time_ns;
  if (stats_.messages == 0 || log_time_ns > message_end_time_) message_end_time_ = log_time_ns;
  ++chunk_messages_;
  ++channel.messages;
  ++stats_.messages;
  stats_.message_bytes += data.size();
  if (chunk_.size() >= options_.chunk_bytes) return flushChunk();
  return Status::ok();
}

Status Writer::flushChunk() {
  if (!failed_) return failed_;
  if (chunk_.empty()) return Status::ok();
  std::span<const uint8_t> records(chunk_);
  const char* compression = "";
  if (options_.compression == Compression::kZstd) {
    const std::size_t bound = ZSTD_compressBound(chunk_.size());
    if (compressed_.size() < bound) compressed_.resize(bound);
    const std::size_t n = ZSTD_compressCCtx(static_cast<ZSTD_CCtx*>(zstd_), compressed_.data(), compressed_.size(),
                                            chunk_.data(), chunk_.size(), options_.zstd_level);
    if (ZSTD_isError(n)) {
      return fail(Status(ErrorCode::kIoError, std::string("mcap: zstd: ") + ZSTD_getErrorName(n)));
    }
    records = std::span<const uint8_t>(compressed_.data(), n);
    compression = "zstd";
  }
  ChunkIndexEntry entry;
  entry.start_time = chunk_start_time_;
  entry.end_time = chunk_end_time_;
  entry.chunk_offset = offset_;
  entry.compressed_size = records.size();
  entry.uncompressed_size = chunk_.size();
  Builder b(staged_);
  const std::size_t at = b.begin(kOpChunk);
  b.u64(chunk_start_time_);
  b.u64(chunk_end_time_);
  b.u64(chunk_.size());
  b.u32(crc32Update(0, chunk_));
  b.str(compression);
  b.u64(records.size());
  b.bytes(records);
  b.end(at);
  entry.chunk_length = staged_.size();
  entry.offsets_first = index_offsets_.size();
  for (std::size_t i = 0; i < channels_.size(); ++i) {
    ChannelState& channel = channels_[i];
    if (channel.index.empty()) continue;
    index_offsets_.emplace_back(static_cast<uint16_t>(i + 1), offset_ + staged_.size());
    ++entry.offsets_count;
    const std::size_t index_at = b.begin(kOpMessageIndex);
    b.u16(static_cast<uint16_t>(i + 1));
    b.u32(static_cast<uint32_t>(channel.index.size() * 16));
    for (const auto& [time, position] : channel.index) {
      b.u64(time);
      b.u64(position);
    }
    b.end(index_at);
    channel.index.clear();
  }
  entry.index_length = staged_.size() - entry.chunk_length;
  chunk_.clear();
  chunk_messages_ = 0;
  ++stats_.chunks;
  // The chunk and its indexes in one write.
  if (Status s = emitStaged(true); !s) return s;
  chunk_indexes_.push_back(entry);
  return Status::ok();
}

Status Writer::close() {
  if (closed_) return Status(ErrorCode::kInvalidArgument, "mcap: the writer is closed");
  if (Status s = flushChunk(); !s) return s;
  closed_ = true;
  if (Status s = emitDataEnd(); !s) return s;
  stageSummary(offset_);
  if (Status s = emitStaged(false); !s) return s;
  return closeFile();
}

Status Writer::emitDataEnd() {
  Builder b(staged_);
  const uint32_t crc = data_crc_;
  const std::size_t at = b.begin(kOpDataEnd);
  b.u32(crc);
  b.end(at);
  return emitStaged(false);
}

void Writer::stageSummary(uint64_t summary_start) {
  Builder b(staged_);
  struct Group {
    uint8_t opcode;
    uint64_t start;
    uint64_t length;
  };
  Group groups[4];
  int group_count = 0;
  auto group = [&](uint8_t opcode, std::size_t from) {
    if (b.size() > from) groups[group_count++] = {opcode, summary_start + from, b.size() - from};
  };
  std::size_t from = b.size();
  for (const auto& record : schema_records_) b.bytes(record);
  group(kOpSchema, from);
  from = b.size();
  for (const auto& record : channel_records_) b.bytes(record);
  group(kOpChannel, from);
  from = b.size();
  stageStatistics();
  group(kOpStatistics, from);
  from = b.size();
  stageChunkIndexes();
  group(kOpChunkIndex, from);
  const uint64_t summary_offset_start = summary_start + b.size();
  for (int i = 0; i < group_count; ++i) {
    const std::size_t at = b.begin(kOpSummaryOffset);
    b.u8(groups[i].opcode);
    b.u64(groups[i].start);
    b.u64(groups[i].length);
    b.end(at);
  }
  // Footer: its CRC covers the summary, the offsets and the footer up to the CRC.
  b.u8(kOpFooter);
  b.u64(8 + 8 + 4);
  b.u64(summary_start);
  b.u64(summary_offset_start);
  b.u32(crc32Update(0, staged_));
  b.bytes(kMagic);
}

void Writer::stageStatistics() {
  Builder b(staged_);
  const std::size_t at = b.begin(kOpStatistics);
  b.u64(stats_.messages);
  b.u16(static_cast<uint16_t>(schema_records_.size()));
  b.u32(static_cast<uint32_t>(channel_records_.size()));
  b.u32(0);  // attachments
  b.u32(0);  // metadata
  b.u32(static_cast<uint32_t>(chunk_indexes_.size()));
  b.u64(message_start_time_);
  b.u64(message_end_time_);
  const std::size_t map_at = b.beginU32();
  for (std::size_t i = 0; i < channels_.size(); ++i) {
    b.u16(static_cast<uint16_t>(i + 1));
    b.u64(channels_[i].messages);
  }
  b.endU32(map_at);
  b.end(at);
}

void Writer::stageChunkIndexes() {
  Builder b(staged_);
  for (const ChunkIndexEntry& entry : chunk_indexes_) {
    const std::size_t at = b.begin(kOpChunkIndex);
    b.u64(entry.start_time);
    b.u64(entry.end_time);
    b.u64(entry.chunk_offset);
    b.u64(entry.chunk_length);
    const std::size_t map_at = b.beginU32();
    for (std::size_t i = 0; i < entry.offsets_count; ++i) {
      b.u16(index_offsets_[entry.offsets_first + i].first);
      b.u64(index_offsets_[entry.offsets_first + i].second);
    }
    b.endU32(map_at);
    b.u64(entry.index_length);
    b.str(options_.compression == Compression::kZstd ? "zstd" : "");
    b.u64(entry.compressed_size);
    b.u64(entry.uncompressed_size);
    b.end(at);
  }
}

Status Writer::closeFile() {
  if (fd_ < 0) return Status::ok();
  const int fd = fd_;
  fd_ = -1;
  if (::fsync(fd) != 0 && errno != EINVAL && errno != EROFS) {
    const int e = errno;
    ::close(fd);
    return fail(Status(ErrorCode::kIoError, "mcap: syncing " + path_ + ": " + std::strerror(e)));
  }
  if (::close(fd) != 0) {
    return fail(Status(ErrorCode::kIoError, "mcap: closing " + path_ + ": " + std::strerror(errno)));
  }
  return Status::ok();
}

bool Writer::fileStillThere() const {
  if (memory_ != nullptr || path_.empty()) return true;
  struct stat st {};
  if (::stat(path_.c_str(), &st) != 0) return false;
  return st.st_ino == inode_ && st.st_dev == device_;
}

}  // namespace fovea::mcap

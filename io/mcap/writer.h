// Writes MCAP v0 files (io/mcap/format.h, https://mcap.dev/spec): Header,
// Schema and Channel records, Message records gathered into Chunk records
// (zstd or uncompressed) each followed by one MessageIndex per channel it
// holds, DataEnd with the data section's CRC, and the summary (Schema, Channel,
// Statistics, ChunkIndex records and their SummaryOffsets) with the Footer, so
// indexed readers can seek.
//
// Power cuts. A chunk and its message indexes are built in memory and handed to
// the kernel in one write() (a loop only when the kernel takes part of it), and
// schemas and channels are written when they are added, so a file cut at any
// byte holds whole records up to its last complete chunk and a sequential reader
// (io/mcap/reader.h) returns every message of those chunks.
//
// Memory. The chunk buffer (chunk_bytes), the compression buffer and the
// per-channel index tables are reserved at open; they grow only for a message
// bigger than a chunk or a chunk with more messages than reserved, and only in
// the thread that calls the Writer (the Recorder's writer thread, never a hot
// path). A failed write is sticky: every later call returns the same error.
//
// Not thread-safe: one thread calls everything.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/result.h"

namespace fovea::mcap {

enum class Compression { kNone, kZstd };

struct WriterOptions {
  // Uncompressed bytes of records gathered before a chunk is written.
  std::size_t chunk_bytes = 1 << 20;
  Compression compression = Compression::kZstd;
  int zstd_level = 1;
  // Channels (and schemas) the file may have; ids are 1..max_channels.
  std::size_t max_channels = 64;
  // Message index entries reserved per channel and chunk (grows past it).
  std::size_t index_entries_per_chunk = 1024;
  // The file may not grow past this many bytes (0: no limit): a write that
  // would is refused as a full disk is (kIoError), the file keeps its whole
  // chunks. For disk budgets, and for testing the full-disk path.
  uint64_t max_file_bytes = 0;
  std::string profile;
  std::string library = "fovea";
};

struct WriterStatistics {
  uint64_t messages = 0;
  uint64_t chunks = 0;
  uint64_t file_bytes = 0;   // bytes handed to the file so far
  uint64_t message_bytes = 0;  // payload bytes of the messages
};

class Writer {
 public:
  // Creates (truncates) `path` and writes the magic and the Header.
  static Result<std::unique_ptr<Writer>> open(const std::string& path, const WriterOptions& options = {});
  // Writes into `out` instead of a file (tests, fuzz seeds); `out` must outlive the Writer.
  static Result<std::unique_ptr<Writer>> openBuffer(std::vector<uint8_t>* out, const WriterOptions& options = {});
  ~Writer();
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  // A schema (encoding e.g. "protobuf", "jsonschema", or fovea's own); its id (>= 1).
  Result<uint16_t> addSchema(std::string_view name, std::string_view encoding, std::span<const uint8_t> data);
  // A channel; schema_id 0 means none. metadata: key/value pairs.
  Result<uint16_t> addChannel(std::string_view topic, std::string_view message_encoding, uint16_t schema_id,
                              std::span<const std::pair<std::string, std::string>> metadata = {});
  // One message; sequence 0 lets the writer number the channel's messages 1, 2, ...
  Status write(uint16_t channel_id, uint64_t log_time_ns, uint64_t publish_time_ns, std::span<const uint8_t> data,
               uint32_t sequence = 0);
  // Writes the open chunk (if it has records) and its message indexes now.
  Status flushChunk();
  // Writes the last chunk, DataEnd, the summary, the Footer and the magic, and
  // closes the file. Further calls return an error.
  Status close();

  const WriterStatistics& statistics() const { return stats_; }
  const Status& failure() const { return failed_; }
  // False when the file's path no longer names the file written (deleted, or
  // its directory removed): the bytes then go nowhere anyone can read.
  bool fileStillThere() const;

 private:
  Writer() = default;
  struct ChannelState;
  struct ChunkIndexEntry;
  Status start(const WriterOptions& options);
  Status emit(std::span<const uint8_t> bytes, bool data_section);
  Status emitStaged(bool data_section);
  Status fail(Status status);
  // The steps of close(): DataEnd written; the summary, its offsets and the
  // Footer staged (the Statistics and ChunkIndex records by their own steps);
  // the file synced and closed.
  Status emitDataEnd();
  void stageSummary(uint64_t summary_start);
  void stageStatistics();
  void stageChunkIndexes();
  Status closeFile();

  WriterOptions options_;
  std::string path_;
  int fd_ = -1;
  uint64_t inode_ = 0;
  uint64_t device_ = 0;
  std::vector<uint8_t>* memory_ = nullptr;
  bool closed_ = false;
  Status failed_;
  uint64_t offset_ = 0;
  uint32_t data_crc_ = 0;

  std::vector<uint8_t> staged_;      // records on their way to the file
  std::vector<uint8_t> chunk_;       // the open chunk's records, uncompressed
  std::vector<uint8_t> compressed_;  // the open chunk's records, compressed
  uint64_t chunk_start_time_ = 0;
  uint64_t chunk_end_time_ = 0;
  uint64_t chunk_messages_ = 0;
  void* zstd_ = nullptr;  // ZSTD_CCtx

  std::vector<std::vector<uint8_t>> schema_records_;   // kept for the summary
  std::vector<std::vector<uint8_t>> channel_records_;  // kept for the summary
  std::vector<ChannelState> channels_;                 // index = channel id - 1
  std::vector<ChunkIndexEntry> chunk_indexes_;
  // Every chunk's (channel, message index offset) pairs, one run per chunk.
  std::vector<std::pair<uint16_t, uint64_t>> index_offsets_;
  uint64_t message_start_time_ = 0;
  uint64_t message_end_time_ = 0;
  WriterStatistics stats_;
};

}  // namespace fovea::mcap

// Records messages into an MCAP file from hot paths: each producer thread has
// its own preallocated ring of slots (core/ring.h's SlotRing, slot count and
// bytes from the config), record() copies the bytes into a slot and publishes
// it, and one writer thread takes from every ring and writes with the Writer
// (io/mcap/writer.h).
//
// record() never blocks and never allocates. It drops and counts instead:
//   ring_full  the writer thread fell behind (the ring drops its oldest queued
//              message, or no slot was free);
//   too_big    the message is bigger than a slot;
//   disk       the file cannot be written (full disk, size limit, the file or
//              its directory removed): one log line when it happens, then every
//              message is dropped and counted;
//   closed     record() after close() began.
// The writer thread also writes the open chunk every flush_interval_ms, so a
// power cut loses at most that much (io/mcap/writer.h: whole chunks survive).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "core/result.h"
#include "core/ring.h"
#include "io/mcap/writer.h"

namespace fovea::mcap {

struct RecorderConfig {
  std::size_t slots = 256;           // per producer: messages queued at most
  std::size_t slot_bytes = 64 << 10;  // the largest message recorded
  uint32_t flush_interval_ms = 1000;  // the open chunk is written at least this often
  WriterOptions writer;
};

struct RecorderCounters {
  uint64_t messages_written = 0;
  uint64_t bytes_written = 0;  // file bytes
  uint64_t dropped_ring_full = 0;
  uint64_t dropped_too_big = 0;
  uint64_t dropped_disk = 0;
  uint64_t dropped_closed = 0;
  uint64_t dropped_transcode = 0;  // a channel's transcoder made nothing of a message
  double mb_per_minute = 0;  // file bytes (1e6) per minute since start()
  uint64_t dropped() const {
    return dropped_ring_full + dropped_too_big + dropped_disk + dropped_closed + dropped_transcode;
  }
};

class Recorder;

// One producer thread's way in. Only that thread calls record().
class RecorderProducer {
 public:
  // Copies `data` (or the concatenation of `head` and `data`) into a slot.
  // False when dropped (counted). Never blocks, never allocates.
  bool record(uint16_t channel_id, uint64_t log_time_ns, std::span<const uint8_t> data) {
    return record(channel_id, log_time_ns, {}, data);
  }
  bool record(uint16_t channel_id, uint64_t log_time_ns, std::span<const uint8_t> head,
              std::span<const uint8_t> data) {
    const std::span<const uint8_t> parts[] = {head, data};
    return record(channel_id, log_time_ns, parts);
  }
  // The concatenation of `parts` as one message (a frame's header and images).
  bool record(uint16_t channel_id, uint64_t log_time_ns, std::span<const std::span<const uint8_t>> parts);

 private:
  friend class Recorder;
  struct Meta {
    uint16_t channel = 0;
    uint32_t size = 0;
    uint64_t log_time_ns = 0;
  };
  RecorderProducer(Recorder& owner, std::size_t slots, std::size_t slot_bytes);
  static void bump(std::atomic<uint64_t>& c) { c.store(c.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed); }

  Recorder& owner_;
  SlotRing ring_;
  const std::size_t slot_bytes_;
  std::unique_ptr<uint8_t[]> arena_;
  std::unique_ptr<Meta[]> meta_;
  std::atomic<uint64_t> too_big_{0};
  std::atomic<uint64_t> disk_{0};
  std::atomic<uint64_t> closed_{0};
};

class Recorder {
 public:
  using LogFn = std::function<void(std::string_view line)>;
  // Turns what a producer recorded on a channel into the message written, on
  // the writer thread: a hot path hands over its raw bytes (a cloud's arrays, a
  // pose) and the costly encoding (Protobuf for Foxglove) happens off it. The
  // returned bytes stay valid until the next call; empty: dropped and counted
  // (dropped_transcode).
  using Transcoder = std::function<std::span<const uint8_t>(std::span<const uint8_t> raw, uint64_t log_time_ns)>;

  // Creates the file (an error when it cannot: no such directory, no
  // permission). `log` gets the one line about a failing disk, from the writer
  // thread.
  static Result<std::unique_ptr<Recorder>> open(const std::string& path, const RecorderConfig& config, LogFn log);
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  // Before start(): schemas, channels and producers.
  Result<uint16_t> addSchema(std::string_view name, std::string_view encoding, std::span<const uint8_t> data);
  // Before start(): what the writer thread makes of a channel's messages.
  Status setTranscoder(uint16_t channel_id, Transcoder transcoder);
  Result<uint16_t> addChannel(std::string_view topic, std::string_view message_encoding, uint16_t schema_id,
                              std::span<const std::pair<std::string, std::string>> metadata = {});
  // A producer with its own ring of `slots` slots of `slot_bytes` (0: the
  // config's); the Recorder owns it.
  RecorderProducer* addProducer(std::size_t slots = 0, std::size_t slot_bytes = 0);
  // Bytes the rings hold (for the caller's memory budget).
  std::size_t ringBytes() const;

  // Starts the writer thread.
  Status start();
  // Drains the rings, writes the summary and the footer, closes the file.
  // Idempotent; the first call's status is returned again.
  Status close();

  RecorderCounters counters() const;
  const std::string& path() const { return path_; }

 private:
  friend class RecorderProducer;
  Recorder() = default;
  void run();
  bool drainOnce();
  void onWriteFailure(const Status& status);

  std::string path_;
  RecorderConfig config_;
  LogFn log_;
  std::unique_ptr<Writer> writer_;
  std::vector<std::unique_ptr<RecorderProducer>> producers_;
  std::vector<std::pair<uint16_t, Transcoder>> transcoders_;
  std::atomic<uint64_t> dropped_transcode_{0};
  std::thread thread_;
  bool started_ = false;
  bool closed_ = false;
  Status close_status_;
  std::atomic<bool> stopping_{false};
  std::atomic<bool> failed_{false};
  std::atomic<uint64_t> written_{0};
  std::atomic<uint64_t> bytes_written_{0};
  std::atomic<uint64_t> dropped_disk_writer_{0};  // taken by the writer thread after a failure
  std::atomic<int64_t> start_ns_{0};
};

}  // namespace fovea::mcap

#include "io/mcap/recorder.h"

#include <pthread.h>

#include <chrono>
#include <cstring>

namespace fovea::mcap {

namespace {

int64_t nowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

RecorderProducer::RecorderProducer(Recorder& owner, std::size_t slots, std::size_t slot_bytes)
    : owner_(owner),
      ring_(slots, 1),
      slot_bytes_(slot_bytes),
      arena_(new uint8_t[ring_.slotCount() * slot_bytes]),
      meta_(new Meta[ring_.slotCount()]) {}

bool RecorderProducer::record(uint16_t channel_id, uint64_t log_time_ns,
                              std::span<const std::span<const uint8_t>> parts) {
  if (owner_.stopping_.load(std::memory_order_acquire)) {
    bump(closed_);
    return false;
  }
  if (owner_.failed_.load(std::memory_order_relaxed)) {
    bump(disk_);
    return false;
  }
  std::size_t size = 0;
  for (std::span<const uint8_t> p : parts) size += p.size();
  if (size > slot_bytes_) {
    bump(too_big_);
    return false;
  }
  SlotIndex slot = 0;
  if (!ring_.tryAcquire(slot)) return false;  // counted by the ring (acquire_failures)
  uint8_t* dst = arena_.get() + static_cast<std::size_t>(slot) * slot_bytes_;
  for (std::span<const uint8_t> p : parts) {
    if (!p.empty()) std::memcpy(dst, p.data(), p.size());
    dst += p.size();
  }
  meta_[slot] = Meta{channel_id, static_cast<uint32_t>(size), log_time_ns};
  ring_.publish(slot);  // drops the oldest queued message when full (counted by the ring)
  return true;
}

Result<std::unique_ptr<Recorder>> Recorder::open(const std::string& path, const RecorderConfig& config, LogFn log) {
  if (config.slots < 1 || config.slot_bytes < 1) return invalidArgument("recorder: slots and slot_bytes must be >= 1");
  Result<std::unique_ptr<Writer>> writer = Writer::open(path, config.writer);
  if (!writer) return writer.status();
  std::unique_ptr<Recorder> recorder(new Recorder());
  recorder->path_ = path;
  recorder->config_ = config;
  recorder->log_ = std::move(log);
  recorder->writer_ = std::move(writer.value());
  return recorder;
}

Recorder::~Recorder() { (void)close(); }

Result<uint16_t> Recorder::addSchema(std::string_view name, std::string_view encoding, std::span<const uint8_t> data) {
  if (started_) return Status(ErrorCode::kInvalidArgument, "recorder: schemas are added before start()");
  return writer_->addSchema(name, encoding, data);
}

Result<uint16_t> Recorder::addChannel(std::string_view topic, std::string_view message_encoding, uint16_t schema_id,
                                      std::span<const std::pair<std::string, std::string>> metadata) {
  if (started_) return Status(ErrorCode::kInvalidArgument, "recorder: channels are added before start()");
  return writer_->addChannel(topic, message_encoding, schema_id, metadata);
}

Status Recorder::setTranscoder(uint16_t channel_id, Transcoder transcoder) {
  if (started_) return Status(ErrorCode::kInvalidArgument, "recorder: transcoders are set before start()");
  transcoders_.emplace_back(channel_id, std::move(transcoder));
  return Status::ok();
}

RecorderProducer* Recorder::addProducer(std::size_t slots, std::size_t slot_bytes) {
  if (started_) return nullptr;
  producers_.emplace_back(new RecorderProducer(*this, slots ? slots : config_.slots,
                                               slot_bytes ? slot_bytes : config_.slot_bytes));
  return producers_.back().get();
}

std::size_t Recorder::ringBytes() const {
  std::size_t bytes = 0;
  for (const auto& p : producers_) bytes += p->ring_.slotCount() * (p->slot_bytes_ + sizeof(RecorderProducer::Meta));
  return bytes;
}

Status Recorder::start() {
  if (started_) return Status(ErrorCode::kInvalidArgument, "recorder: already started");
  started_ = true;
  start_ns_.store(nowNs(), std::memory_order_relaxed);
  thread_ = std::thread([this] { run(); });
  return Status::ok();
}

void Recorder::onWriteFailure(const Status& status) {
  if (failed_.exchange(true)) return;
  if (log_) {
    log_("recording to " + path_ + " stopped: " + status.message() +
         "; from now on every message is dropped and counted (dropped_disk)");
  }
}

bool Recorder::drainOnce() {
  bool took = false;
  for (const auto& producer : producers_) {
    SlotIndex slot = 0;
    // A bounded batch per producer, so one busy producer cannot starve the others.
    for (int i = 0; i < 64 && producer->ring_.tryTake(slot); ++i) {
      took = true;
      const RecorderProducer::Meta meta = producer->meta_[slot];
      if (failed_.load(std::memory_order_relaxed)) {
        dropped_disk_writer_.fetch_add(1, std::memory_order_relaxed);
      } else {
        std::span<const uint8_t> bytes(producer->arena_.get() + static_cast<std::size_t>(slot) * producer->slot_bytes_,
                                       meta.size);
        for (const auto& [channel, transcode] : transcoders_) {
          if (channel == meta.channel) bytes = transcode(bytes, meta.log_time_ns);
        }
        const Status s = bytes.empty() && meta.size > 0
                             ? Status(ErrorCode::kInvalidInput, "transcoded to nothing")
                             : writer_->write(meta.channel, meta.log_time_ns, meta.log_time_ns, bytes);
        if (s) {
          written_.fetch_add(1, std::memory_order_relaxed);
        } else if (s.code() == ErrorCode::kInvalidInput) {
          dropped_transcode_.fetch_add(1, std::memory_order_relaxed);
        } else if (s.code() == ErrorCode::kInvalidArgument) {
          dropped_disk_writer_.fetch_add(1, std::memory_order_relaxed);  // an unknown channel: a caller's bug
        } else {
          dropped_disk_writer_.fetch_add(1, std::memory_order_relaxed);
          onWriteFailure(s);
        }
      }
      (void)producer->ring_.release(slot);
    }
  }
  bytes_written_.store(writer_->statistics().file_bytes, std::memory_order_relaxed);
  return took;
}

void Recorder::run() {
  pthread_setname_np(pthread_self(), "fovea-mcap");  // at most 15 characters
  auto last_flush = std::chrono::steady_clock::now();
  const auto interval = std::chrono::milliseconds(config_.flush_interval_ms);
  for (;;) {
    const bool stopping = stopping_.load(std::memory_order_acquire);
    const bool took = drainOnce();
    const auto now = std::chrono::steady_clock::now();
    if (now - last_flush >= interval) {
      last_flush = now;
      if (!failed_.load(std::memory_order_relaxed)) {
        if (!writer_->fileStillThere()) {
          onWriteFailure(Status(ErrorCode::kIoError, "the file " + path_ + " was removed (or its directory)"));
        } else if (Status s = writer_->flushChunk(); !s) {
          onWriteFailure(s);
        }
        bytes_written_.store(writer_->statistics().file_bytes, std::memory_order_relaxed);
      }
    }
    if (stopping && !took) break;  // drained after the stop was seen
    if (!took) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

Status Recorder::close() {
  if (closed_) return close_status_;
  closed_ = true;
  stopping_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
  if (!started_) (void)drainOnce();
  if (failed_.load()) {
    close_status_ = writer_->failure().isOk()
                        ? Status(ErrorCode::kIoError, "recording to " + path_ + " failed")
                        : writer_->failure();
    (void)writer_->close();  // what can still be written (a removed file's summary)
  } else {
    close_status_ = writer_->close();
    if (!close_status_) onWriteFailure(close_status_);
  }
  bytes_written_.store(writer_->statistics().file_bytes, std::memory_order_relaxed);
  return close_status_;
}

RecorderCounters Recorder::counters() const {
  RecorderCounters c;
  c.messages_written = written_.load(std::memory_order_relaxed);
  c.bytes_written = bytes_written_.load(std::memory_order_relaxed);
  c.dropped_disk = dropped_disk_writer_.load(std::memory_order_relaxed);
  c.dropped_transcode = dropped_transcode_.load(std::memory_order_relaxed);
  for (const auto& p : producers_) {
    const RingCounters rc = p->ring_.counters();
    c.dropped_ring_full += rc.dropped + rc.acquire_failures;
    c.dropped_too_big += p->too_big_.load(std::memory_order_relaxed);
    c.dropped_disk += p->disk_.load(std::memory_order_relaxed);
    c.dropped_closed += p->closed_.load(std::memory_order_relaxed);
  }
  const int64_t start = start_ns_.load(std::memory_order_relaxed);
  if (start != 0) {
    const double minutes = static_cast<double>(nowNs() - start) / 60e9;
    if (minutes > 0) c.mb_per_minute = static_cast<double>(c.bytes_written) / 1e6 / minutes;
  }
  return c;
}

}  // namespace fovea::mcap

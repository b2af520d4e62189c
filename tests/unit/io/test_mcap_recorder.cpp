// The Recorder (io/mcap/recorder.h): record() never allocates and never blocks,
// drops are counted by reason, a full disk is one log line, close() leaves a
// complete file.
#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <mutex>
#include <string>
#include <vector>

#include "io/mcap/reader.h"
#include "io/mcap/recorder.h"
#include "tests/support/alloc_counter.h"
#include "tests/support/test_time.h"

namespace fovea::mcap {
namespace {

std::string tempPath(const char* name) {
  const char* dir = std::getenv("TMPDIR");
  return std::string(dir && *dir ? dir : "/tmp") + "/fovea-test-" + std::to_string(::getpid()) + "-" + name;
}

struct Log {
  std::mutex mutex;
  std::vector<std::string> lines;
  Recorder::LogFn fn() {
    return [this](std::string_view line) {
      std::lock_guard<std::mutex> lock(mutex);
      lines.emplace_back(line);
    };
  }
  std::size_t count() {
    std::lock_guard<std::mutex> lock(mutex);
    return lines.size();
  }
};

TEST(McapRecorder, RecordsEverythingAndClosesACompleteFile) {
  const std::string path = tempPath("rec.mcap");
  Log log;
  RecorderConfig config;
  config.slots = 64;
  config.slot_bytes = 256;
  auto recorder = Recorder::open(path, config, log.fn());
  ASSERT_TRUE(recorder.isOk()) << recorder.status().toString();
  auto channel = (*recorder)->addChannel("/t", "raw", 0);
  ASSERT_TRUE(channel.isOk());
  RecorderProducer* producer = (*recorder)->addProducer();
  ASSERT_NE(producer, nullptr);
  ASSERT_TRUE((*recorder)->start().isOk());
  const int n = 500;
  int recorded = 0;
  for (int i = 0; i < n; ++i) {
    uint8_t head[4] = {static_cast<uint8_t>(i), static_cast<uint8_t>(i >> 8), 0xAB, 0xCD};
    const uint8_t body[3] = {1, 2, 3};
    // Wait for room rather than drop: this test checks the contents.
    ASSERT_TRUE(test::waitUntil([&] { return (*recorder)->counters().messages_written + 60 > static_cast<uint64_t>(i); },
                                std::chrono::seconds(5)));
    if (producer->record(*channel, 1000 + static_cast<uint64_t>(i), head, body)) ++recorded;
  }
  ASSERT_TRUE((*recorder)->close().isOk());
  const RecorderCounters c = (*recorder)->counters();
  EXPECT_EQ(c.messages_written + c.dropped(), static_cast<uint64_t>(n));
  EXPECT_EQ(c.dropped(), 0u);
  EXPECT_GT(c.bytes_written, 0u);
  EXPECT_EQ(log.count(), 0u);
  auto bytes = readFile(path);
  ASSERT_TRUE(bytes.isOk());
  Reader reader(*bytes);
  uint64_t messages = 0;
  while (reader.next() != Reader::Item::kEnd) {
    if (reader.messagesRead() > messages) {
      const MessageView& m = reader.message();
      ASSERT_EQ(m.data.size(), 7u);
      EXPECT_EQ(m.data[0], static_cast<uint8_t>(messages));
      EXPECT_EQ(m.data[6], 3);
      EXPECT_EQ(m.log_time_ns, 1000 + messages);
      messages = reader.messagesRead();
    }
  }
  EXPECT_TRUE(reader.complete()) << reader.stopReason();
  EXPECT_EQ(messages, c.messages_written);
  std::remove(path.c_str());
}

TEST(McapRecorder, RecordNeverAllocates) {
  const std::string path = tempPath("alloc.mcap");
  RecorderConfig config;
  config.slots = 8;
  config.slot_bytes = 1024;
  auto recorder = Recorder::open(path, config, nullptr);
  ASSERT_TRUE(recorder.isOk());
  auto channel = (*recorder)->addChannel("/t", "raw", 0);
  RecorderProducer* producer = (*recorder)->addProducer();
  ASSERT_TRUE((*recorder)->start().isOk());
  const std::vector<uint8_t> small(100, 7);
  const std::vector<uint8_t> big(5000, 7);
  uint64_t thread_allocations = 0;
  {
    test::AllocationScope scope;
    const uint64_t before = test::threadAllocationCount();
    for (int i = 0; i < test::repetitions(20000, 2000); ++i) {
      (void)producer->record(*channel, static_cast<uint64_t>(i), small);
      if (i % 100 == 0) (void)producer->record(*channel, static_cast<uint64_t>(i), big);  // too big: dropped
    }
    thread_allocations = test::threadAllocationCount() - before;
  }
  EXPECT_EQ(thread_allocations, 0u) << "record() allocated";
  ASSERT_TRUE((*recorder)->close().isOk());
  const RecorderCounters c = (*recorder)->counters();
  EXPECT_EQ(c.dropped_too_big, static_cast<uint64_t>(test::repetitions(20000, 2000) / 100));
  EXPECT_GT(c.messages_written, 0u);
  // After close: counted as closed.
  EXPECT_FALSE(producer->record(*channel, 0, small));
  EXPECT_EQ((*recorder)->counters().dropped_closed, 1u);
  std::remove(path.c_str());
}

TEST(McapRecorder, AFullRingDropsAndCounts) {
  const std::string path = tempPath("full.mcap");
  RecorderConfig config;
  config.slots = 2;
  config.slot_bytes = 64 << 10;
  config.writer.compression = Compression::kZstd;
  config.writer.zstd_level = 19;  // a slow writer
  auto recorder = Recorder::open(path, config, nullptr);
  ASSERT_TRUE(recorder.isOk());
  auto channel = (*recorder)->addChannel("/t", "raw", 0);
  RecorderProducer* producer = (*recorder)->addProducer();
  ASSERT_TRUE((*recorder)->start().isOk());
  std::vector<uint8_t> data(60 << 10);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<uint8_t>((i * 2654435761u) >> 13);
  const int n = 3000;
  for (int i = 0; i < n; ++i) (void)producer->record(*channel, static_cast<uint64_t>(i), data);
  ASSERT_TRUE((*recorder)->close().isOk());
  const RecorderCounters c = (*recorder)->counters();
  EXPECT_GT(c.dropped_ring_full, 0u);
  EXPECT_EQ(c.messages_written + c.dropped_ring_full, static_cast<uint64_t>(n));
  std::remove(path.c_str());
}

TEST(McapRecorder, AFullDiskIsOneLogLineThenCountedDrops) {
  const std::string path = tempPath("limit.mcap");
  Log log;
  RecorderConfig config;
  config.slots = 16;
  config.slot_bytes = 2048;
  config.writer.chunk_bytes = 4096;
  config.writer.compression = Compression::kNone;
  config.writer.max_file_bytes = 20000;  // the "disk" is full after 20 kB
  auto recorder = Recorder::open(path, config, log.fn());
  ASSERT_TRUE(recorder.isOk());
  auto channel = (*recorder)->addChannel("/t", "raw", 0);
  RecorderProducer* producer = (*recorder)->addProducer();
  ASSERT_TRUE((*recorder)->start().isOk());
  const std::vector<uint8_t> data(1000, 3);
  for (int i = 0; i < 200; ++i) {
    (void)producer->record(*channel, static_cast<uint64_t>(i), data);
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  EXPECT_FALSE((*recorder)->close().isOk());
  const RecorderCounters c = (*recorder)->counters();
  EXPECT_EQ(log.count(), 1u);
  if (log.count() == 1) {
    EXPECT_NE(log.lines[0].find("size limit"), std::string::npos) << log.lines[0];
  }
  EXPECT_GT(c.dropped_disk, 0u);
  EXPECT_EQ(c.messages_written + c.dropped(), 200u);
  // What reached the file reads up to its last complete chunk.
  auto bytes = readFile(path);
  ASSERT_TRUE(bytes.isOk());
  Reader reader(*bytes);
  while (reader.next() != Reader::Item::kEnd) {
  }
  EXPECT_FALSE(reader.complete());
  EXPECT_GT(reader.messagesRead(), 0u);
  EXPECT_LE(reader.messagesRead(), c.messages_written);
  std::remove(path.c_str());
}

TEST(McapRecorder, ARemovedFileIsOneLogLine) {
  const std::string dir = tempPath("dir");
  ASSERT_EQ(::mkdir(dir.c_str(), 0700), 0);
  const std::string path = dir + "/x.mcap";
  Log log;
  RecorderConfig config;
  config.flush_interval_ms = 10;
  auto recorder = Recorder::open(path, config, log.fn());
  ASSERT_TRUE(recorder.isOk());
  auto channel = (*recorder)->addChannel("/t", "raw", 0);
  RecorderProducer* producer = (*recorder)->addProducer();
  ASSERT_TRUE((*recorder)->start().isOk());
  const uint8_t byte = 1;
  (void)producer->record(*channel, 1, {&byte, 1});
  ASSERT_EQ(std::remove(path.c_str()), 0);
  ASSERT_EQ(::rmdir(dir.c_str()), 0);
  EXPECT_TRUE(test::waitUntil([&] { return log.count() > 0; }, std::chrono::seconds(2)));
  (void)producer->record(*channel, 2, {&byte, 1});
  EXPECT_FALSE((*recorder)->close().isOk());
  EXPECT_EQ(log.count(), 1u);
  if (log.count() == 1) {
    EXPECT_NE(log.lines[0].find("removed"), std::string::npos) << log.lines[0];
  }
  EXPECT_GE((*recorder)->counters().dropped_disk, 1u);
}

TEST(McapRecorder, OpenFailsClearly) {
  auto missing = Recorder::open("/nonexistent-dir-fovea/x.mcap", {}, nullptr);
  ASSERT_FALSE(missing.isOk());
  EXPECT_NE(missing.status().message().find("No such file"), std::string::npos) << missing.status().message();
}

// A channel's transcoder runs on the writer thread: what it returns is written,
// in parts gathered by record(); an empty result is dropped and counted.
TEST(McapRecorder, TranscodersMakeTheMessagesWrittenOffTheHotPath) {
  const std::string path = tempPath("transcode.mcap");
  Log log;
  RecorderConfig config;
  config.slots = 64;
  config.slot_bytes = 64;
  auto recorder = Recorder::open(path, config, log.fn());
  ASSERT_TRUE(recorder.isOk());
  const uint16_t doubled = (*recorder)->addChannel("/doubled", "raw", 0).value();
  const uint16_t plain = (*recorder)->addChannel("/plain", "raw", 0).value();
  std::vector<uint8_t> out;  // the writer thread's buffer
  std::atomic<int> calls{0};
  ASSERT_TRUE((*recorder)->setTranscoder(doubled, [&](std::span<const uint8_t> raw, uint64_t t) {
    ++calls;
    out.clear();
    if (raw.size() == 1 && raw[0] == 0xFF) return std::span<const uint8_t>();  // nothing to make of it
    for (uint8_t b : raw) out.insert(out.end(), {b, b});
    out.push_back(static_cast<uint8_t>(t));
    return std::span<const uint8_t>(out);
  }));
  RecorderProducer* producer = (*recorder)->addProducer();
  ASSERT_TRUE((*recorder)->start());
  EXPECT_FALSE((*recorder)->setTranscoder(plain, [](std::span<const uint8_t> raw, uint64_t) { return raw; }));
  const uint8_t a[] = {1, 2}, b[] = {3}, bad[] = {0xFF};
  const std::span<const uint8_t> parts[] = {a, b};
  ASSERT_TRUE(producer->record(doubled, 7, parts));
  ASSERT_TRUE(producer->record(plain, 8, parts));
  ASSERT_TRUE(producer->record(doubled, 9, bad));
  ASSERT_TRUE((*recorder)->close());
  const RecorderCounters c = (*recorder)->counters();
  EXPECT_EQ(c.messages_written, 2u);
  EXPECT_EQ(c.dropped_transcode, 1u);
  EXPECT_EQ(calls.load(), 2);
  auto bytes = readFile(path);
  ASSERT_TRUE(bytes.isOk());
  Reader reader(*bytes);
  std::vector<std::vector<uint8_t>> got;
  for (Reader::Item item = reader.next(); item != Reader::Item::kEnd; item = reader.next()) {
    if (item == Reader::Item::kMessage) got.emplace_back(reader.message().data.begin(), reader.message().data.end());
  }
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0], (std::vector<uint8_t>{1, 1, 2, 2, 3, 3, 7}));
  EXPECT_EQ(got[1], (std::vector<uint8_t>{1, 2, 3}));
  std::remove(path.c_str());
}

}  // namespace
}  // namespace fovea::mcap

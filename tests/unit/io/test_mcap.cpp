// The MCAP Writer and Reader (io/mcap/): round trips, hard cases, files cut at
// every byte, and corrupted files that must stop cleanly, never crash.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "io/mcap/format.h"
#include "io/mcap/reader.h"
#include "io/mcap/writer.h"
#include "tests/support/programs.h"
#include "tests/support/test_time.h"

namespace fovea::mcap {
namespace {

struct Sent {
  uint16_t channel;
  uint64_t time;
  std::vector<uint8_t> data;
};

std::vector<uint8_t> payload(std::size_t n, uint32_t seed) {
  std::vector<uint8_t> v(n);
  std::mt19937 rng(seed);
  for (auto& b : v) b = static_cast<uint8_t>(rng() & 0x0F);  // compressible
  return v;
}

// A file with `channels` channels and `messages` messages spread over them.
std::vector<uint8_t> writeSample(const WriterOptions& options, int channels, int messages, std::vector<Sent>* sent,
                                 std::size_t bytes_each = 100) {
  std::vector<uint8_t> out;
  auto writer = Writer::openBuffer(&out, options);
  EXPECT_TRUE(writer.isOk());
  const std::string text = "fovea test schema";
  auto schema = (*writer)->addSchema("fovea.Test", "text", {reinterpret_cast<const uint8_t*>(text.data()), text.size()});
  EXPECT_TRUE(schema.isOk());
  for (int c = 0; c < channels; ++c) {
    const std::pair<std::string, std::string> meta[] = {{"index", std::to_string(c)}};
    auto id = (*writer)->addChannel("/test/" + std::to_string(c), "fovea", *schema, meta);
    EXPECT_TRUE(id.isOk());
    EXPECT_EQ(*id, c + 1);
  }
  for (int i = 0; i < messages; ++i) {
    Sent s{static_cast<uint16_t>(1 + i % channels), 1000u * static_cast<uint64_t>(i),
           payload(bytes_each + static_cast<std::size_t>(i % 7), static_cast<uint32_t>(i))};
    EXPECT_TRUE((*writer)->write(s.channel, s.time, s.time, s.data).isOk());
    if (sent) sent->push_back(std::move(s));
  }
  EXPECT_TRUE((*writer)->close().isOk());
  return out;
}

struct ReadBack {
  std::vector<Sent> messages;
  std::size_t schemas = 0;
  std::size_t channels = 0;
  bool complete = false;
  std::string reason;
};

ReadBack readAll(std::span<const uint8_t> file, const ReaderOptions& options = {}) {
  ReadBack r;
  Reader reader(file, options);
  for (;;) {
    const Reader::Item item = reader.next();
    if (item == Reader::Item::kEnd) break;
    if (item == Reader::Item::kSchema) ++r.schemas;
    if (item == Reader::Item::kChannel) ++r.channels;
    if (item == Reader::Item::kMessage) {
      const MessageView& m = reader.message();
      r.messages.push_back({m.channel_id, m.log_time_ns, {m.data.begin(), m.data.end()}});
    }
  }
  r.complete = reader.complete();
  r.reason = reader.stopReason();
  return r;
}

TEST(McapCrc, KnownValues) {
  const std::string check = "123456789";
  EXPECT_EQ(crc32Update(0, {reinterpret_cast<const uint8_t*>(check.data()), check.size()}), 0xCBF43926u);
  EXPECT_EQ(crc32Update(0, {}), 0u);
  const std::string fox = "The quick brown fox jumps over the lazy dog";
  EXPECT_EQ(crc32Update(0, {reinterpret_cast<const uint8_t*>(fox.data()), fox.size()}), 0x414FA339u);
  // Chained updates equal one update over the whole.
  const uint32_t part = crc32Update(0, {reinterpret_cast<const uint8_t*>(fox.data()), 10});
  EXPECT_EQ(crc32Update(part, {reinterpret_cast<const uint8_t*>(fox.data()) + 10, fox.size() - 10}), 0x414FA339u);
}

TEST(McapWriter, RoundTripZstdAndUncompressed) {
  for (Compression compression : {Compression::kZstd, Compression::kNone}) {
    WriterOptions options;
    options.compression = compression;
    options.chunk_bytes = 2000;  // many chunks
    std::vector<Sent> sent;
    const std::vector<uint8_t> file = writeSample(options, 3, 200, &sent);
    const ReadBack r = readAll(file);
    EXPECT_TRUE(r.complete) << r.reason;
    EXPECT_EQ(r.schemas, 1u);
    EXPECT_EQ(r.channels, 3u);
    ASSERT_EQ(r.messages.size(), sent.size());
    for (std::size_t i = 0; i < sent.size(); ++i) {
      EXPECT_EQ(r.messages[i].channel, sent[i].channel);
      EXPECT_EQ(r.messages[i].time, sent[i].time);
      EXPECT_EQ(r.messages[i].data, sent[i].data);
    }
    // The file ends in the footer and the magic.
    ASSERT_GE(file.size(), 16u);
    EXPECT_EQ(0, std::memcmp(file.data() + file.size() - 8, kMagic, 8));
  }
}

TEST(McapWriter, SequenceNumbersCountPerChannel) {
  std::vector<uint8_t> out;
  auto writer = Writer::openBuffer(&out);
  ASSERT_TRUE(writer.isOk());
  auto a = (*writer)->addChannel("/a", "raw", 0);
  auto b = (*writer)->addChannel("/b", "raw", 0);
  const uint8_t byte = 7;
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE((*writer)->write(*a, 1, 1, {&byte, 1}).isOk());
    ASSERT_TRUE((*writer)->write(*b, 1, 1, {&byte, 1}).isOk());
  }
  ASSERT_TRUE((*writer)->close().isOk());
  Reader reader(out);
  std::vector<uint32_t> seq_a;
  while (reader.next() != Reader::Item::kEnd) {
    if (reader.messagesRead() > 0 && reader.message().channel_id == *a && seq_a.size() < reader.messagesRead()) {
      seq_a.push_back(reader.message().sequence);
    }
  }
  EXPECT_TRUE(reader.complete());
  EXPECT_EQ(seq_a, (std::vector<uint32_t>{1, 2, 3}));
}

TEST(McapWriter, HardCases) {
  // Zero messages, no channels: still a complete file.
  {
    std::vector<uint8_t> out;
    auto writer = Writer::openBuffer(&out);
    ASSERT_TRUE(writer.isOk());
    ASSERT_TRUE((*writer)->close().isOk());
    const ReadBack r = readAll(out);
    EXPECT_TRUE(r.complete) << r.reason;
    EXPECT_TRUE(r.messages.empty());
    EXPECT_FALSE((*writer)->close().isOk());  // a second close is refused
  }
  // One message far bigger than a chunk.
  {
    WriterOptions options;
    options.chunk_bytes = 4096;
    std::vector<Sent> sent;
    const std::vector<uint8_t> file = writeSample(options, 1, 3, &sent, 3 << 20);
    const ReadBack r = readAll(file);
    EXPECT_TRUE(r.complete) << r.reason;
    ASSERT_EQ(r.messages.size(), 3u);
    EXPECT_EQ(r.messages[1].data, sent[1].data);
  }
  // Many channels; one more than max_channels is refused.
  {
    WriterOptions options;
    options.max_channels = 300;
    std::vector<Sent> sent;
    const std::vector<uint8_t> file = writeSample(options, 299, 900, &sent);
    const ReadBack r = readAll(file);
    EXPECT_TRUE(r.complete) << r.reason;
    EXPECT_EQ(r.channels, 299u);
    EXPECT_EQ(r.messages.size(), 900u);
    std::vector<uint8_t> out;
    options.max_channels = 2;
    auto writer = Writer::openBuffer(&out, options);
    ASSERT_TRUE((*writer)->addChannel("/1", "raw", 0).isOk());
    ASSERT_TRUE((*writer)->addChannel("/2", "raw", 0).isOk());
    EXPECT_EQ((*writer)->addChannel("/3", "raw", 0).status().code(), ErrorCode::kCapacityExceeded);
    EXPECT_FALSE((*writer)->write(9, 0, 0, {}).isOk());  // an unknown channel
    EXPECT_FALSE((*writer)->addChannel("/x", "raw", 5).isOk());  // an unknown schema
  }
  // An empty message.
  {
    std::vector<uint8_t> out;
    auto writer = Writer::openBuffer(&out);
    auto c = (*writer)->addChannel("/empty", "raw", 0);
    ASSERT_TRUE((*writer)->write(*c, 5, 5, {}).isOk());
    ASSERT_TRUE((*writer)->close().isOk());
    const ReadBack r = readAll(out);
    ASSERT_EQ(r.messages.size(), 1u);
    EXPECT_TRUE(r.messages[0].data.empty());
  }
}

TEST(McapWriter, FileErrorsAreClear) {
  auto missing = Writer::open("/nonexistent-dir-fovea/x.mcap");
  ASSERT_FALSE(missing.isOk());
  EXPECT_NE(missing.status().message().find("/nonexistent-dir-fovea/x.mcap"), std::string::npos);
  // /dev/full: every write fails with ENOSPC.
  auto full = Writer::open("/dev/full");
  if (full.isOk()) {
    ADD_FAILURE() << "writing the header to /dev/full succeeded";
  } else {
    EXPECT_NE(full.status().message().find("No space"), std::string::npos) << full.status().message();
  }
  // A size limit: refused like a full disk; the file keeps its whole chunks.
  WriterOptions options;
  options.max_file_bytes = 5000;
  options.chunk_bytes = 1000;
  options.compression = Compression::kNone;
  std::vector<uint8_t> out;
  auto writer = Writer::openBuffer(&out, options);
  auto c = (*writer)->addChannel("/x", "raw", 0);
  Status status;
  int written = 0;
  const std::vector<uint8_t> data(300, 1);
  for (int i = 0; i < 100 && status.isOk(); ++i) {
    status = (*writer)->write(*c, static_cast<uint64_t>(i), 0, data);
    if (status) ++written;
  }
  EXPECT_EQ(status.code(), ErrorCode::kIoError);
  EXPECT_NE(status.message().find("size limit"), std::string::npos);
  EXPECT_LE(out.size(), 5000u);
  EXPECT_FALSE((*writer)->write(*c, 0, 0, data).isOk());  // sticky
  const ReadBack r = readAll(out);
  EXPECT_FALSE(r.complete);
  EXPECT_GT(r.messages.size(), 0u);
  EXPECT_LT(r.messages.size(), static_cast<std::size_t>(written));
}

// A file cut at every byte reads its complete chunks, and only whole messages.
TEST(McapReader, TruncatedAtEveryOffset) {
  WriterOptions options;
  options.chunk_bytes = 600;
  std::vector<Sent> sent;
  const std::vector<uint8_t> file = writeSample(options, 2, 40, &sent, 40);
  // The end of each chunk record: the cuts at which its messages become readable.
  std::vector<std::size_t> chunk_ends;
  for (std::size_t pos = 8; pos + 9 <= file.size() && file[pos] != kOpDataEnd;) {
    const std::size_t end = pos + 9 + static_cast<std::size_t>(loadLe64(file.data() + pos + 1));
    if (file[pos] == kOpChunk) chunk_ends.push_back(end);
    pos = end;
  }
  ASSERT_GE(chunk_ends.size(), 3u);
  std::size_t previous = 0;
  std::size_t last_complete_count = 0;
  for (std::size_t cut = 0; cut <= file.size(); ++cut) {
    const ReadBack r = readAll(std::span<const uint8_t>(file.data(), cut));
    ASSERT_LE(r.messages.size(), sent.size());
    ASSERT_GE(r.messages.size(), previous) << "cut at " << cut << " lost messages a shorter cut had";
    for (std::size_t i = 0; i < r.messages.size(); ++i) ASSERT_EQ(r.messages[i].data, sent[i].data);
    const bool at_chunk_end = std::find(chunk_ends.begin(), chunk_ends.end(), cut) != chunk_ends.end();
    if (at_chunk_end) {
      ASSERT_GT(r.messages.size(), previous) << "the chunk ending at " << cut << " did not read";
    } else {
      ASSERT_EQ(r.messages.size(), previous) << "messages appeared at " << cut << ", not a chunk's end";
    }
    previous = r.messages.size();
    if (cut < file.size()) {
      ASSERT_FALSE(r.complete);
      ASSERT_NE(r.reason.find("stopped at byte"), std::string::npos);
    } else {
      ASSERT_TRUE(r.complete) << r.reason;
    }
    last_complete_count = r.messages.size();
  }
  EXPECT_EQ(last_complete_count, sent.size());
  // Cut just before DataEnd (all chunks complete): every message.
  const std::size_t data_end = file.size() - 1;  // not exact; any cut in the summary keeps all
  EXPECT_EQ(readAll(std::span<const uint8_t>(file.data(), data_end)).messages.size(), sent.size());
}

TEST(McapReader, BitFlipsNeverCrash) {
  WriterOptions options;
  options.chunk_bytes = 800;
  const std::vector<uint8_t> file = writeSample(options, 3, 60, nullptr, 30);
  std::mt19937 rng(28);
  int stopped = 0;
  for (int trial = 0; trial < test::repetitions(3000, 300); ++trial) {
    std::vector<uint8_t> bad = file;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int f = 0; f < flips; ++f) bad[rng() % bad.size()] ^= static_cast<uint8_t>(1u << (rng() % 8));
    // A flipped size may claim up to the limit: keep it small (the sanitizer trees).
    ReaderOptions options;
    options.max_chunk_bytes = 1 << 20;
    const ReadBack r = readAll(bad, options);
    if (!r.complete) {
      ++stopped;
      EXPECT_NE(r.reason.find("stopped at byte"), std::string::npos);
    }
  }
  EXPECT_GT(stopped, 0);
}

TEST(McapReader, HostileFiles) {
  // Empty, too short, wrong magic.
  EXPECT_NE(readAll({}).reason.find("shorter than the MCAP magic"), std::string::npos);
  const std::vector<uint8_t> wrong = {'P', 'K', 3, 4, 0, 0, 0, 0, 0};
  EXPECT_NE(readAll(wrong).reason.find("wrong magic"), std::string::npos);

  std::vector<uint8_t> base(kMagic, kMagic + 8);
  auto record = [](std::vector<uint8_t>& f, uint8_t op, const std::vector<uint8_t>& content, uint64_t length) {
    f.push_back(op);
    uint8_t len[8];
    storeLe64(len, length);
    f.insert(f.end(), len, len + 8);
    f.insert(f.end(), content.begin(), content.end());
  };
  // A huge length.
  {
    std::vector<uint8_t> f = base;
    record(f, kOpSchema, {1, 0}, ~0ull);
    const ReadBack r = readAll(f);
    EXPECT_FALSE(r.complete);
    EXPECT_NE(r.reason.find("stopped at byte 8"), std::string::npos) << r.reason;
    EXPECT_NE(r.reason.find("claims"), std::string::npos) << r.reason;
  }
  // Unknown opcodes are skipped.
  {
    std::vector<uint8_t> f = base;
    record(f, 0x80, {1, 2, 3}, 3);
    record(f, 0x00, {}, 0);
    Reader reader(f);
    EXPECT_EQ(reader.next(), Reader::Item::kEnd);
    EXPECT_EQ(reader.unknownRecordsSkipped(), 2u);
    EXPECT_NE(reader.stopReason().find("without a footer"), std::string::npos);
  }
  // A malformed schema: its name's length runs past the record.
  {
    std::vector<uint8_t> f = base;
    record(f, kOpSchema, {1, 0, 200, 0, 0, 0, 'a'}, 7);
    const ReadBack r = readAll(f);
    EXPECT_NE(r.reason.find("malformed schema"), std::string::npos) << r.reason;
  }
  // A chunk whose CRC fails, and one claiming a huge uncompressed size.
  {
    WriterOptions options;
    options.compression = Compression::kNone;
    std::vector<Sent> sent;
    std::vector<uint8_t> f = writeSample(options, 1, 5, &sent, 20);
    // Find the chunk (the first 0x06 record after the channel) by walking records.
    std::size_t pos = 8;
    while (pos + 9 <= f.size() && f[pos] != kOpChunk) pos += 9 + loadLe64(f.data() + pos + 1);
    ASSERT_LT(pos + 9, f.size());
    std::vector<uint8_t> bad_crc = f;
    bad_crc[pos + 9 + 8 + 8 + 8 + 4 + 4 + 8 + 30] ^= 1;  // a byte inside the records
    ReadBack r = readAll(bad_crc);
    EXPECT_NE(r.reason.find("CRC fails"), std::string::npos) << r.reason;
    EXPECT_NE(r.reason.find("stopped at byte " + std::to_string(pos)), std::string::npos) << r.reason;
    EXPECT_TRUE(r.messages.empty());
    ReaderOptions small;
    small.max_chunk_bytes = 16;
    r = readAll(f, small);
    EXPECT_NE(r.reason.find("over the reader's limit"), std::string::npos) << r.reason;
  }
  // A message on a channel the file never declared.
  {
    std::vector<uint8_t> f = base;
    std::vector<uint8_t> msg(22, 0);
    msg[0] = 9;
    record(f, kOpMessage, msg, msg.size());
    EXPECT_NE(readAll(f).reason.find("has not declared"), std::string::npos);
  }
}

}  // namespace
}  // namespace fovea::mcap

namespace fovea::mcap {
namespace {

// Files of another writer (tests/fuzz/corpus/fuzz_mcap_reader/, which
// @mcap/core's stream reader reads as described): an uncompressed chunk, an
// unknown opcode, an attachment, metadata and a message outside any chunk; and
// a chunk compressed with lz4, which fovea does not read.
TEST(McapReader, FilesOfAnotherWriter) {
  const std::string dir = test::sourceDir() + "/" + FOVEA_MCAP_CORPUS_DIR + "/";
  auto plain = readFile(dir + "uncompressed_unknown_opcodes.mcap");
  ASSERT_TRUE(plain.isOk()) << plain.status().toString();
  Reader reader(*plain);
  std::vector<std::string> lines;
  while (reader.next() != Reader::Item::kEnd) {
    if (reader.messagesRead() > lines.size()) {
      lines.emplace_back(reinterpret_cast<const char*>(reader.message().data.data()), reader.message().data.size());
    }
  }
  EXPECT_TRUE(reader.complete()) << reader.stopReason();
  EXPECT_EQ(reader.unknownRecordsSkipped(), 1u);
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_EQ(lines[0], "{\"line\":\"a\"}");
  EXPECT_EQ(lines[2], "{\"line\":\"outside a chunk\"}");
  ASSERT_EQ(reader.channels().size(), 1u);
  EXPECT_EQ(reader.channels()[0].topic, "/fovea/status");
  ASSERT_EQ(reader.channels()[0].metadata.size(), 1u);
  EXPECT_EQ(reader.schemas()[0].encoding, "jsonschema");

  auto lz4 = readFile(dir + "lz4_chunk.mcap");
  ASSERT_TRUE(lz4.isOk());
  Reader lz4_reader(*lz4);
  while (lz4_reader.next() != Reader::Item::kEnd) {
  }
  EXPECT_FALSE(lz4_reader.complete());
  EXPECT_NE(lz4_reader.stopReason().find("'lz4' is not supported"), std::string::npos) << lz4_reader.stopReason();
}

}  // namespace
}  // namespace fovea::mcap

// Fuzz target for the MCAP reader (io/mcap/reader.h) that replay uses: the
// bytes are a file's contents. Oracles: a message's data lies inside the file
// or the reader's chunk buffer and is on a declared channel; a prefix of the
// file never reads more messages than the whole; what was read, written again
// with the Writer, reads back to the same messages.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "io/mcap/reader.h"
#include "io/mcap/writer.h"
#include "tests/fuzz/fuzz_target.h"

namespace {

using namespace fovea;
using namespace fovea::mcap;

[[noreturn]] void fail(const char* what) {
  std::fprintf(stderr, "fuzz_mcap_reader: %s\n", what);
  std::abort();
}

struct Message {
  uint16_t channel;
  uint64_t log_time;
  std::vector<uint8_t> data;
};

ReaderOptions options() {
  ReaderOptions o;
  o.max_chunk_bytes = 1 << 20;  // keep hostile sizes cheap
  o.max_channels = 256;
  return o;
}

std::vector<Message> readAll(std::span<const uint8_t> bytes, Reader& reader) {
  std::vector<Message> out;
  for (;;) {
    const Reader::Item item = reader.next();
    if (item == Reader::Item::kEnd) break;
    if (item != Reader::Item::kMessage) continue;
    const MessageView& m = reader.message();
    if (reader.findChannel(m.channel_id) == nullptr) fail("a message on an undeclared channel");
    out.push_back({m.channel_id, m.log_time_ns, {m.data.begin(), m.data.end()}});
  }
  if (!reader.complete() && reader.stopReason().rfind("stopped at byte ", 0) != 0) fail("no stop reason");
  if (reader.stopOffset() > bytes.size()) fail("a stop offset past the file");
  return out;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::span<const uint8_t> bytes(data, size);
  Reader reader(bytes, options());
  const std::vector<Message> messages = readAll(bytes, reader);
  if (size > 0) {
    Reader prefix_reader(bytes.first(size - 1 - (data[0] % size)), options());
    if (readAll(bytes.first(size - 1 - (data[0] % size)), prefix_reader).size() > messages.size()) {
      fail("a prefix read more messages than the whole file");
    }
  }
  // Written again, read back the same.
  std::vector<uint8_t> again;
  WriterOptions wo;
  wo.chunk_bytes = 4096;
  wo.max_channels = 256;
  auto writer = Writer::openBuffer(&again, wo);
  if (!writer) fail("openBuffer failed");
  for (const ChannelRecord& c : reader.channels()) {
    (void)c;
    if (!(*writer)->addChannel("/c", "raw", 0)) fail("addChannel failed");
  }
  // Channel ids in the rewrite are 1..n in the order read.
  for (const Message& m : messages) {
    uint16_t id = 0;
    for (std::size_t i = 0; i < reader.channels().size(); ++i) {
      if (reader.channels()[i].id == m.channel) id = static_cast<uint16_t>(i + 1);
    }
    if (!(*writer)->write(id, m.log_time, m.log_time, m.data)) fail("write failed");
  }
  if (!(*writer)->close()) fail("close failed");
  Reader back(again, options());
  const std::vector<Message> reread = readAll(again, back);
  if (!back.complete()) fail("a rewritten file does not read to its end");
  if (reread.size() != messages.size()) fail("a rewritten file reads a different number of messages");
  for (std::size_t i = 0; i < reread.size(); ++i) {
    if (reread[i].data != messages[i].data || reread[i].log_time != messages[i].log_time) {
      fail("a rewritten message differs");
    }
  }
  return 0;
}

// Files written by fovea's Writer: compressed and not, with schemas, metadata,
// several chunks, and one cut in the middle of a chunk.
std::vector<fuzz::Input> fuzz::seeds() {
  std::vector<Input> seeds;
  for (int variant = 0; variant < 3; ++variant) {
    std::vector<uint8_t> out;
    WriterOptions wo;
    wo.chunk_bytes = 300;
    wo.compression = variant == 1 ? Compression::kNone : Compression::kZstd;
    auto writer = Writer::openBuffer(&out, wo);
    const std::string text = "fovea chunk v2";
    auto schema = (*writer)->addSchema("fovea.Chunk", "fovea.chunk",
                                       {reinterpret_cast<const uint8_t*>(text.data()), text.size()});
    const std::pair<std::string, std::string> meta[] = {{"k", "v"}};
    auto a = (*writer)->addChannel("/fovea/chunks", "fovea.chunk", *schema, meta);
    auto b = (*writer)->addChannel("/fovea/status", "text", 0);
    for (int i = 0; i < 12; ++i) {
      std::vector<uint8_t> payload(static_cast<std::size_t>(10 + 7 * i), static_cast<uint8_t>(i));
      (void)(*writer)->write(i % 2 ? *a : *b, static_cast<uint64_t>(i) * 1000, 0, payload);
    }
    (void)(*writer)->close();
    if (variant == 2) out.resize(out.size() * 2 / 3);
    seeds.push_back(out);
  }
  return seeds;
}

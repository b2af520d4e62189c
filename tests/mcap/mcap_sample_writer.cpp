// Writes an MCAP file with fovea's Writer (io/mcap/writer.h) and a JSON
// manifest of everything it wrote, for tests/mcap/check_mcap.mjs, which reads
// the file with the reference library (@mcap/core) and compares.
//   fovea-mcap-sample-writer OUT.mcap OUT.json [zstd|none]
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "io/mcap/writer.h"

namespace {

std::string hex(const uint8_t* p, std::size_t n) {
  static const char* digits = "0123456789abcdef";
  std::string s;
  s.reserve(2 * n);
  for (std::size_t i = 0; i < n; ++i) {
    s += digits[p[i] >> 4];
    s += digits[p[i] & 15];
  }
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace fovea::mcap;
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s OUT.mcap OUT.json [zstd|none]\n", argv[0]);
    return 2;
  }
  WriterOptions options;
  options.chunk_bytes = 16 << 10;  // several chunks
  if (argc > 3 && std::strcmp(argv[3], "none") == 0) options.compression = Compression::kNone;
  auto writer = Writer::open(argv[1], options);
  if (!writer) {
    std::fprintf(stderr, "%s\n", writer.status().toString().c_str());
    return 1;
  }
  std::string json = "{\n\"schemas\": [";
  const char* schema_names[] = {"fovea.Test", "fovea.Text"};
  const char* schema_encodings[] = {"fovea.test.v1", "jsonschema"};
  const std::string schema_data[] = {"binary layout: u32 index, then bytes", R"({"type":"object"})"};
  std::vector<uint16_t> schemas;
  for (int i = 0; i < 2; ++i) {
    auto id = (*writer)->addSchema(schema_names[i], schema_encodings[i],
                                   {reinterpret_cast<const uint8_t*>(schema_data[i].data()), schema_data[i].size()});
    if (!id) return 1;
    schemas.push_back(*id);
    json += std::string(i ? "," : "") + "\n {\"id\": " + std::to_string(*id) + ", \"name\": \"" + schema_names[i] +
            "\", \"encoding\": \"" + schema_encodings[i] + "\", \"data_hex\": \"" +
            hex(reinterpret_cast<const uint8_t*>(schema_data[i].data()), schema_data[i].size()) + "\"}";
  }
  json += "],\n\"channels\": [";
  struct Ch {
    const char* topic;
    const char* encoding;
    uint16_t schema;
  };
  const Ch channels[] = {{"/sample/binary", "fovea.test.v1", schemas[0]},
                         {"/sample/json", "json", schemas[1]},
                         {"/sample/raw", "raw", 0},
                         {"/sample/silent", "raw", 0}};  // no messages
  std::vector<uint16_t> ids;
  for (std::size_t i = 0; i < 4; ++i) {
    const std::pair<std::string, std::string> meta[] = {{"written_by", "fovea"}};
    auto id = (*writer)->addChannel(channels[i].topic, channels[i].encoding, channels[i].schema, meta);
    if (!id) return 1;
    ids.push_back(*id);
    json += std::string(i ? "," : "") + "\n {\"id\": " + std::to_string(*id) + ", \"topic\": \"" + channels[i].topic +
            "\", \"message_encoding\": \"" + channels[i].encoding + "\", \"schema_id\": " +
            std::to_string(channels[i].schema) + ", \"metadata\": {\"written_by\": \"fovea\"}}";
  }
  json += "],\n\"messages\": [";
  uint32_t state = 28;
  for (int i = 0; i < 300; ++i) {
    const uint16_t channel = ids[static_cast<std::size_t>(i % 3)];
    std::size_t size = 20 + static_cast<std::size_t>(i * 37 % 900);
    if (i == 150) size = 200000;  // bigger than a chunk
    std::vector<uint8_t> data(size);
    if (channel == ids[1]) {
      const std::string text = "{\"i\":" + std::to_string(i) + "}";
      data.assign(text.begin(), text.end());
    } else {
      for (auto& b : data) {
        state = state * 1664525u + 1013904223u;
        b = static_cast<uint8_t>((state >> 24) & 0x3F);
      }
    }
    const uint64_t log_time = 1'700'000'000'000'000'000ull + static_cast<uint64_t>(i) * 33'000'000ull;
    const uint64_t publish_time = log_time + 5;
    if (!(*writer)->write(channel, log_time, publish_time, data)) return 1;
    json += std::string(i ? "," : "") + "\n {\"channel\": " + std::to_string(channel) + ", \"log_time\": \"" +
            std::to_string(log_time) + "\", \"publish_time\": \"" + std::to_string(publish_time) +
            "\", \"data_hex\": \"" + hex(data.data(), data.size()) + "\"}";
  }
  json += "]\n}\n";
  if (fovea::Status s = (*writer)->close(); !s) {
    std::fprintf(stderr, "%s\n", s.toString().c_str());
    return 1;
  }
  std::ofstream out(argv[2]);
  out << json;
  return out.good() ? 0 : 1;
}

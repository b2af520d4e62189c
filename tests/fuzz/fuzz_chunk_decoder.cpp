// Fuzz target for the operator side of the chunk codec: decodeChunk,
// decodeSummary and FrameAssembler must return, never crash, on any bytes.
//
// Built and run as every target in tests/fuzz/ (fuzz_target.h).
//
// Input: byte 0 picks the mode. Even: the rest is a payload, decoded as is. Odd:
// the rest describes a small cloud (8 bytes per point) that is encoded with the
// real encoder, then the trailing bytes flip bits of the first chunk, so the
// fuzzer reaches past the header checks into the bit stream.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>
#include <vector>

#include "net/codec.h"
#include "tests/fuzz/fuzz_target.h"

namespace {

using namespace fovea;

struct Fixture {
  pipeline::FoveatedCloud out{4096};
  std::unique_ptr<net::ChunkEncoder> encoders[4];
  std::unique_ptr<net::FrameAssembler> assembler;
  Fixture() {
    for (int v = 0; v < 4; ++v) {
      net::CodecConfig config;
      config.max_payload = v % 2 ? 220 : 1164;
      config.halve_peripheral_chroma = v >= 2;
      config.entropy_coding = v == 3;
      encoders[v] = std::make_unique<net::ChunkEncoder>(net::ChunkEncoder::create(config, 512).value());
    }
    assembler = std::make_unique<net::FrameAssembler>(net::FrameAssembler::create(4096).value());
  }
};

// Decodes a copy: the copy starts aligned as the links' receive buffers do
// (the summary is FlatBuffers, read in place; every decoder requires it), and
// ends where the payload ends, so AddressSanitizer sees a read past it.
void decodeAll(Fixture& f, std::span<const uint8_t> bytes) {
  const std::vector<uint8_t> copy(bytes.begin(), bytes.end());
  const std::span<const uint8_t> payload(copy);
  f.out.clear();
  (void)net::decodeChunk(payload, f.out);
  (void)net::decodeSummary(payload);
  (void)f.assembler->addChunk(payload);
  (void)f.assembler->addSummary(payload);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  static Fixture f;
  if (size == 0) return 0;
  if ((data[0] & 1) == 0) {
    decodeAll(f, {data + 1, size - 1});
    return 0;
  }
  // A cloud from the input, encoded, then corrupted by the input's tail.
  const std::size_t points = std::min<std::size_t>((size - 1) / 8, 512);
  pipeline::FoveatedCloud cloud(512);
  for (std::size_t i = 0; i < points; ++i) {
    const uint8_t* p = data + 1 + 8 * i;
    int16_t x, y;
    std::memcpy(&x, p, 2);
    std::memcpy(&y, p + 2, 2);
    (void)cloud.points.push(x * 1e-3f, y * 1e-3f, static_cast<float>(p[4]) * 0.01f,
                            pipeline::packRgb(p[5], p[6], p[7]));
    cloud.region[i] = static_cast<uint8_t>(p[4] & 3);
  }
  net::ChunkEncoder& enc = *f.encoders[(data[0] >> 1) & 3];
  const double voxel[] = {0.0, 0.01, 0.03, 0.2};
  if (!enc.encode(cloud, voxel, data[0], 0).isOk() || enc.chunkCount() == 0) return 0;
  std::vector<uint8_t> chunk(enc.chunk(0).begin(), enc.chunk(0).end());
  for (std::size_t t = 1 + 8 * points; t + 1 < size; t += 2) {
    const std::size_t bit = (std::size_t{data[t]} << 8 | data[t + 1]) % (8 * chunk.size());
    chunk[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
  }
  decodeAll(f, chunk);
  return 0;
}

// Real chunks and summaries of each encoder configuration (mode 0), brick
// chunks, and two clouds for the encoder mode.
std::vector<fuzz::Input> fuzz::seeds() {
  Fixture f;
  std::vector<Input> out;
  pipeline::FoveatedCloud cloud(512);
  for (int i = 0; i < 300; ++i) {
    (void)cloud.points.push(0.01f * static_cast<float>(i % 17), -0.02f * static_cast<float>(i % 11),
                            0.5f + 0.01f * static_cast<float>(i % 7), pipeline::packRgb(i & 255, 40, 200));
    cloud.region[static_cast<std::size_t>(i)] = static_cast<uint8_t>(i % 3);
  }
  const double voxel[] = {0.0, 0.01, 0.03, 0.2};
  for (auto& enc : f.encoders) {
    if (!enc->encode(cloud, voxel, 7, 0).isOk()) continue;
    for (std::size_t c = 0; c < enc->chunkCount() && c < 3; ++c) {
      Input chunk{0};
      chunk.insert(chunk.end(), enc->chunk(c).begin(), enc->chunk(c).end());
      out.push_back(std::move(chunk));
    }
    const uint16_t sent[] = {2, 1, 1};
    const uint16_t cut[] = {0, 0, 1};
    Input summary{0};
    const auto bytes = enc->encodeSummary(7, sent, cut);
    summary.insert(summary.end(), bytes.begin(), bytes.end());
    out.push_back(std::move(summary));
  }
  // A map brick's parts (kBrickChunk: a point chunk with a brick tag).
  const net::BrickTag tag{-3, 7, 1, 41, 2};
  if (f.encoders[0]->encode(cloud, voxel, 7, 0, &tag).isOk()) {
    for (std::size_t c = 0; c < f.encoders[0]->chunkCount() && c < 2; ++c) {
      Input chunk{0};
      chunk.insert(chunk.end(), f.encoders[0]->chunk(c).begin(), f.encoders[0]->chunk(c).end());
      out.push_back(std::move(chunk));
    }
  }
  for (uint8_t mode : {1, 7}) {
    Input in{mode};
    for (int i = 0; i < 40 * 8; ++i) in.push_back(static_cast<uint8_t>(i * 37));
    out.push_back(std::move(in));
  }
  return out;
}

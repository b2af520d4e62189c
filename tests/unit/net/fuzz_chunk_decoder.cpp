// Fuzz target for the operator side of the chunk codec: decodeChunk,
// decodeSummary and FrameAssembler must return, never crash, on any bytes.
//
// Under clang it is a libFuzzer target (-fsanitize=fuzzer); with other compilers
// FOVEA_FUZZ_DRIVER builds a main() that feeds it seeded random inputs, so CTest
// runs it everywhere for a bounded number of iterations.
//
// Input: byte 0 picks the mode. Even: the rest is a payload, decoded as is. Odd:
// the rest describes a small cloud (8 bytes per point) that is encoded with the
// real encoder, then the trailing bytes flip bits of the first chunk, so the
// fuzzer reaches past the FlatBuffers verifier into the bit stream.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>
#include <vector>

#include "net/codec.h"

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

void decodeAll(Fixture& f, std::span<const uint8_t> payload) {
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

#ifdef FOVEA_FUZZ_DRIVER
#include <cstdlib>
#include <random>

// fuzz_chunk_decoder [ITERATIONS]: seeded random inputs of both modes.
int main(int argc, char** argv) {
  const long iterations = argc > 1 ? std::atol(argv[1]) : 100000;
  std::mt19937_64 rng(1);
  std::vector<uint8_t> input;
  for (long i = 0; i < iterations; ++i) {
    input.resize(1 + rng() % 1200);
    for (uint8_t& b : input) b = static_cast<uint8_t>(rng());
    if (i % 2) input[0] |= 1;  // half the inputs go through the encoder
    LLVMFuzzerTestOneInput(input.data(), input.size());
  }
  return 0;
}
#endif

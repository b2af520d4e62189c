// The operator side of the point-chunk codec (net/codec.h): decodeChunk(),
// which verifies a chunk and appends its points to a cloud, and decodeSummary().
// Every byte is checked; malformed input is an error, never a crash.
#include "net/codec.h"

#include <array>
#include <cmath>
#include <string>
#include <vector>

#define ZSTD_STATIC_LINKING_ONLY  // ZSTD_initStaticDCtx: a context that never allocates
#include <zstd.h>

#include "net/bit_io.h"
#include "net/chunk_decoder.h"
#include "net/chunk_header.h"
#include "net/point_coding.h"
#include "net/schema/chunk_generated.h"

namespace fovea::net {
using namespace codec_detail;  // the codec's internal headers (bit_io.h, chunk_header.h, point_coding.h)
namespace {

Status parseError(const char* what) { return {ErrorCode::kParseError, std::string("chunk: ") + what}; }

// Per-thread decompression context and buffer, allocated on first use.
struct ThreadDecoder {
  std::vector<uint8_t> workspace;
  std::vector<uint8_t> buffer;
  ZSTD_DCtx* dctx = nullptr;
  ThreadDecoder() : workspace(ZSTD_estimateDCtxSize()), buffer(kMaxChunkRawBytes) {
    dctx = ZSTD_initStaticDCtx(workspace.data(), workspace.size());
  }
};
ThreadDecoder& threadDecoder() {
  thread_local ThreadDecoder decoder;
  return decoder;
}

// What a chunk's header says, checked: what decodeChunk() reports, and where its
// points' data is.
struct ChunkLayout {
  DecodedChunk info;                 // points still 0
  uint32_t points = 0;               // the header's point count
  bool compressed = false;           // the data is a zstd frame
  bool half = false;                 // chroma shared by pairs of points
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // the chunk's lattice origin, metres
  std::span<const uint8_t> data;     // as stored (raw or zstd)
  std::size_t raw_size = 0;          // its size uncompressed
};

// Reads and checks the payload's size, alignment and header, and the point
// count against the data's size; nullptr, or what is wrong.
const char* readLayout(std::span<const uint8_t> payload, ChunkLayout& c) {
  if (payload.size() < 8 || payload.size() > kMaxPayload) return "payload size out of range";
  if (!isPayloadAligned(payload.data())) return "payload not aligned (net/wire.h kPayloadAlignment)";
  HeaderFields h;
  std::size_t header_size = 0;
  if (const char* why = readHeader(payload, h, header_size); why != nullptr) return why;

  DecodedChunk& info = c.info;
  info.frame_id = h.frame_id;
  info.chunk_index = h.chunk_index;
  info.chunk_count = h.chunk_count;
  info.region = h.region;
  info.capture_time_ns = h.capture_time_ns;
  info.step_m = h.step_m;
  info.has_brick = h.has_brick;
  info.brick = h.brick;
  c.points = h.points;
  if (info.chunk_count == 0 || info.chunk_index >= info.chunk_count) return "chunk index out of range";
  if (!std::isfinite(info.step_m) || !(info.step_m > 0.0)) return "step is not finite and > 0";
  // Exact products: the encoder's origin is the same q * step in double.
  c.origin = Eigen::Vector3d(static_cast<double>(h.origin_q[0]) * info.step_m,
                             static_cast<double>(h.origin_q[1]) * info.step_m,
                             static_cast<double>(h.origin_q[2]) * info.step_m);
  if (!std::isfinite(c.origin.x()) || !std::isfinite(c.origin.y()) || !std::isfinite(c.origin.z())) {
    return "origin not finite";
  }
  c.data = payload.subspan(header_size);
  c.compressed = (h.flags & kChunkFlagZstd) != 0;
  c.raw_size = c.data.size();
  if (c.compressed) {  // zstd frames carry their content size
    const unsigned long long content = ZSTD_getFrameContentSize(c.data.data(), c.data.size());
    if (content == ZSTD_CONTENTSIZE_ERROR || content == ZSTD_CONTENTSIZE_UNKNOWN || content > kMaxChunkRawBytes) {
      return "zstd frame without a valid content size";
    }
    c.raw_size = static_cast<std::size_t>(content);
  }
  c.half = (h.flags & kChunkFlagHalfChroma) != 0;
  // A brick chunk may carry no point: the version of a brick whose surfels all went.
  const uint32_t n = c.points;
  if (c.raw_size < kDataHeader || (n == 0 && !info.has_brick) || n > 8 * (c.raw_size - kDataHeader)) {
    return "point count does not fit the data";
  }
  return nullptr;
}

// The chunk's data uncompressed (zstd into the thread's buffer, if it is a zstd
// frame) in data and size; nullptr, or what is wrong.
const char* uncompressedData(const ChunkLayout& c, const uint8_t*& data, std::size_t& size) {
  data = c.data.data();
  size = c.data.size();
  if (!c.compressed) return nullptr;
  ThreadDecoder& td = threadDecoder();
  if (td.dctx == nullptr) return "zstd context unavailable";
  const std::size_t got = ZSTD_decompressDCtx(td.dctx, td.buffer.data(), c.raw_size, data, size);
  if (ZSTD_isError(got) || got != c.raw_size) return "zstd data corrupt or of the wrong size";
  data = td.buffer.data();
  size = got;
  return nullptr;
}

// ---- the bit stream, point by point ----

// The colour decoder's running values.
struct ColourState {
  uint8_t y = 0;            // Y
  uint8_t co = 0, cg = 0;   // halved chroma: the pair's Co, Cg (offset by 128)
  int fco = 0, fcg = 0;     // full colour: Co, Cg as 9-bit values
};

// Adds an Exp-Golomb coded byte difference (mod 256) to value; false when the
// code is truncated or out of range.
[[gnu::always_inline]] inline bool readByteDelta(BitReader& br, int k, uint8_t& value) {
  uint64_t zz;
  if (!br.getEg(k, zz) || zz > 255) return false;
  value = static_cast<uint8_t>(value + unzigzag8(static_cast<uint32_t>(zz)));
  return true;
}

// Adds an Exp-Golomb coded chroma difference (mod 512) to a 9-bit value.
[[gnu::always_inline]] inline bool readChromaDelta(BitReader& br, int k, int& value) {
  uint64_t zz;
  if (!br.getEg(k, zz) || zz > 511) return false;
  value = (value + unzigzag9(static_cast<uint32_t>(zz))) & 511;
  return true;
}

// Point k's Morton code: the first a 6-bit length and that many bits, every
// later one an Exp-Golomb delta (order kp) from the last; nullptr, or what is wrong.
[[gnu::always_inline]] inline const char* readMortonCode(BitReader& br, uint32_t k, int kp, uint64_t& code) {
  constexpr uint64_t kMaxCode = (uint64_t{1} << 63) - 1;
  if (k == 0) {
    uint64_t len, lo = 0, hi = 0;
    if (!br.get(6, len)) return "position data truncated";
    if (len > 32) {
      if (!br.get(32, lo) || !br.get(static_cast<int>(len - 32), hi)) return "position data truncated";
    } else if (!br.get(static_cast<int>(len), lo)) {
      return "position data truncated";
    }
    code = lo | (hi << 32);
    if (code > kMaxCode) return "Morton code overflow";
    return nullptr;
  }
  uint64_t v;
  if (!br.getEg(kp, v)) return "position data truncated or malformed";
  if (v > kMaxCode - code) return "Morton code overflow";
  code += v;
  return nullptr;
}

// A full-colour point: its lossless YCoCg-R deltas, back to RGB.
[[gnu::always_inline]] inline const char* readFullColour(BitReader& br, const std::array<int, 3>& kc, ColourState& s,
                                                         uint32_t& rgb) {
  if (!readByteDelta(br, kc[0], s.y) || !readChromaDelta(br, kc[1], s.fco) || !readChromaDelta(br, kc[2], s.fcg)) {
    return "colour data truncated or malformed";
  }
  const int co = s.fco >= 256 ? s.fco - 512 : s.fco, cg = s.fcg >= 256 ? s.fcg - 512 : s.fcg;
  const int t = s.y - (cg >> 1), g = cg + t, b = t - (co >> 1), r = b + co;
  if ((r | g | b) < 0 || r > 255 || g > 255 || b > 255) return "colour out of range";
  rgb = pipeline::packRgb(static_cast<uint8_t>(r), static_cast<uint8_t>(g), static_cast<uint8_t>(b));
  return nullptr;
}

// Halved chroma: point k's luma into rgb[k]; after a pair's second point (or a
// lone last one of n) the pair's chroma, which turns the pair's luma into RGB.
[[gnu::always_inline]] inline const char* readHalfColour(BitReader& br, const std::array<int, 3>& kc, uint32_t k,
                                                         uint32_t n, ColourState& s, uint32_t* rgb) {
  if (!readByteDelta(br, kc[0], s.y)) return "colour data truncated or malformed";
  rgb[k] = s.y;  // luma until the pair's chroma arrives
  if (k % 2 == 1 || k + 1 == n) {
    if (!readByteDelta(br, kc[1], s.co) || !readByteDelta(br, kc[2], s.cg)) return "chroma data truncated or malformed";
    for (uint32_t i = k - k % 2; i < k + 1; ++i) {  // the pair's points share (Co, Cg)
      const int Y = static_cast<int>(rgb[i]), Co = int{s.co} - 128, Cg = int{s.cg} - 128;
      rgb[i] = pipeline::packRgb(clampByte(Y + Co - Cg), clampByte(Y + Cg), clampByte(Y - Co - Cg));
    }
  }
  return nullptr;
}

// Decodes the chunk's data (size bytes at data) into pts from index first on,
// relative to an origin `shift` below the chunk's: the orders, then per point
// its position (first: 6-bit length + code; then Exp-Golomb deltas of the Morton
// code) and colour codes. The data must end with the last point.
Status decodePoints(const ChunkLayout& c, const uint8_t* data, std::size_t size, const Eigen::Vector3d& shift,
                    pipeline::PointCloud& pts, std::size_t first) {
  const int kp = data[0];
  const std::array<int, 3> kc = {data[1], data[2], data[3]};
  if (kp > 62 || kc[0] > 7 || kc[1] > 8 || kc[2] > 8) return parseError("Exp-Golomb order out of range");
  BitReader br(data + kDataHeader, size - kDataHeader);
  float* x = pts.x() + first;
  float* y = pts.y() + first;
  float* z = pts.z() + first;
  uint32_t* rgb = pts.rgb() + first;
  const double step_m = c.info.step_m;
  const uint32_t n = c.points;
  const bool half = c.half;
  uint64_t code = 0;
  ColourState colour;
  for (uint32_t k = 0; k < n; ++k) {
    if (const char* why = readMortonCode(br, k, kp, code); why != nullptr) return parseError(why);
    const double wx = shift.x() + compact3(code) * step_m;
    const double wy = shift.y() + compact3(code >> 1) * step_m;
    const double wz = shift.z() + compact3(code >> 2) * step_m;
    constexpr double kFloatMax = 3.0e38;
    if (!(std::fabs(wx) < kFloatMax && std::fabs(wy) < kFloatMax && std::fabs(wz) < kFloatMax)) {
      return {ErrorCode::kRangeExceeded, "chunk: point too far from the output cloud's origin"};
    }
    x[k] = static_cast<float>(wx), y[k] = static_cast<float>(wy), z[k] = static_cast<float>(wz);
    const char* why = half ? readHalfColour(br, kc, k, n, colour, rgb) : readFullColour(br, kc, colour, rgb[k]);
    if (why != nullptr) return parseError(why);
  }
  if ((br.bits() + 7) / 8 != size - kDataHeader) return parseError("data length does not match its points");
  return Status::ok();
}

}  // namespace

void codec_detail::warmThreadDecoder() { (void)threadDecoder(); }

Result<DecodedChunk> decodeChunk(std::span<const uint8_t> payload, pipeline::FoveatedCloud& out) {
  ChunkLayout c;
  if (const char* why = readLayout(payload, c); why != nullptr) return parseError(why);
  const uint8_t* data = nullptr;
  std::size_t size = 0;
  if (const char* why = uncompressedData(c, data, size); why != nullptr) return parseError(why);

  const uint32_t n = c.points;
  pipeline::PointCloud& pts = out.points;
  if (pts.capacity() - pts.size() < n || out.region.size() < pts.size() + n ||
      (out.hasWeights() && out.weight.size() < pts.size() + n)) {
    return Result<DecodedChunk>(ErrorCode::kCapacityExceeded, "chunk: output cloud is full");
  }
  const std::size_t first = pts.size();
  const Eigen::Vector3d base = first == 0 ? c.origin : pts.origin_m;
  if (Status st = decodePoints(c, data, size, c.origin - base, pts, first); !st) return st;

  if (first == 0) pts.origin_m = base;
  for (uint32_t k = 0; k < n; ++k) {
    out.region[first + k] = c.info.region;
    if (out.hasWeights()) out.weight[first + k] = 1;
  }
  (void)pts.resize(first + n);
  c.info.points = n;
  return c.info;
}

Result<FrameSummaryInfo> decodeSummary(std::span<const uint8_t> payload) {
  if (payload.size() < 8 || payload.size() > kMaxPayload) {
    return Result<FrameSummaryInfo>(ErrorCode::kParseError, "summary: payload size out of range");
  }
  if (!isPayloadAligned(payload.data())) {
    return Result<FrameSummaryInfo>(ErrorCode::kParseError, "summary: payload not aligned (net/wire.h)");
  }
  flatbuffers::Verifier verifier(payload.data(), payload.size(), 8, 16);
  if (!verifier.VerifyBuffer<wire::FrameSummary>(nullptr)) {
    return Result<FrameSummaryInfo>(ErrorCode::kParseError, "summary: FlatBuffers verification failed");
  }
  const wire::FrameSummary* s = flatbuffers::GetRoot<wire::FrameSummary>(payload.data());
  FrameSummaryInfo info;
  info.frame_id = s->frame_id();
  info.chunk_count = s->chunk_count();
  const auto* sent = s->chunks_sent();
  const auto* cut = s->chunks_cut();
  if (sent == nullptr || cut == nullptr || sent->size() != cut->size() || sent->size() > pipeline::kMaxRegions) {
    return Result<FrameSummaryInfo>(ErrorCode::kParseError, "summary: per-region counts missing or of different sizes");
  }
  info.region_count = static_cast<int>(sent->size());
  uint32_t total = 0;
  for (flatbuffers::uoffset_t r = 0; r < sent->size(); ++r) {
    info.chunks_sent[r] = sent->Get(r);
    info.chunks_cut[r] = cut->Get(r);
    total += uint32_t{info.chunks_sent[r]} + info.chunks_cut[r];
  }
  if (total > info.chunk_count) {
    return Result<FrameSummaryInfo>(ErrorCode::kParseError, "summary: more chunks sent and cut than encoded");
  }
  return info;
}

}  // namespace fovea::net

// The robot side of the point-chunk codec (net/codec.h): the configuration's
// checks and ChunkEncoder, which cuts a foveated frame into chunks and writes
// the frame summary. Its own file because nothing on the operator side uses it.
#include "net/codec.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <utility>

#define ZSTD_STATIC_LINKING_ONLY  // ZSTD_initStaticCCtx: a context that never allocates
#include <zstd.h>

#include "net/bit_io.h"
#include "net/chunk_header.h"
#include "net/point_coding.h"
#include "net/schema/chunk_generated.h"

namespace fovea::net {
using namespace codec_detail;  // the codec's internal headers (bit_io.h, chunk_header.h, point_coding.h)
namespace {

constexpr std::size_t alignUp(std::size_t n, std::size_t alignment) { return (n + alignment - 1) / alignment * alignment; }
constexpr int kRadixBits = 11;
constexpr uint16_t kChunkCountPlaceholder = 0xffff;
// Lattice coordinates up to 2^50 steps: w + 0.5 stays exact enough in double
// that rounding by truncation keeps |w - q| <= 1/2.
constexpr double kMaxLatticeCoord = 1125899906842624.0;

// The lattice coordinates of p (relative to origin o) at 1 / inv_step steps
// from the world origin, rounded half away from zero (q unset unless kInRange).
// Monotonic in each coordinate, so a region's bounds are those of its points'
// extremes; encode() computes the keys' coordinates again: the same bits.
enum class Lattice { kInRange, kNotFinite, kBeyond };
inline double latticeUnits(double o, float p, double inv_step) { return (o + double{p}) * inv_step; }
inline int64_t roundHalfAway(double w) { return static_cast<int64_t>(w >= 0.0 ? w + 0.5 : w - 0.5); }
inline Lattice latticeCoords(const Eigen::Vector3d& o, const float p[3], double inv_step, int64_t q[3]) {
  for (int a = 0; a < 3; ++a) {
    const double w = latticeUnits(o[a], p[a], inv_step);
    if (!(std::fabs(w) < kMaxLatticeCoord)) return std::isfinite(w) ? Lattice::kBeyond : Lattice::kNotFinite;
    q[a] = roundHalfAway(w);
  }
  return Lattice::kInRange;
}
inline Lattice latticeCoords(const EncodeInput& c, std::size_t i, double inv_step, int64_t q[3]) {
  const float p[3] = {c.x[i], c.y[i], c.z[i]};
  return latticeCoords(c.origin_m, p, inv_step, q);
}

// The order k in [lo, hi] that codes `values` in the fewest bits, among the four
// below the bit width of their mean (on the mock frames the best order was always
// 1 to 4 below it; a fifth candidate saves 0.1 %). Exact counts: an estimate from
// a histogram of bit widths (one bit off when v >> k is all ones) cost 0.7 % more
// bytes. The four candidates are counted in one pass.
inline int bestOrder(const uint64_t* values, std::size_t n, int lo, int hi) {
  if (n == 0) return lo;
  uint64_t sum = 0;
  for (std::size_t i = 0; i < n; ++i) sum += std::min<uint64_t>(values[i], uint64_t{1} << 56);
  const int guess = std::bit_width(sum / n);
  const int k0 = std::max(lo, guess - 4), k1 = std::min(hi, guess - 1);
  if (k1 <= k0) return k0;
  // 2n + 1 + k with n = bit_width(v + 2^k) - k - 1: summing bit_width(v + 2^k) is enough.
  std::array<std::size_t, 4> bits{};
  for (std::size_t i = 0; i < n; ++i) {
    const uint64_t v = std::min<uint64_t>(values[i], uint64_t{1} << 62);
    for (int c = 0; c < 4; ++c) bits[static_cast<std::size_t>(c)] += static_cast<std::size_t>(std::bit_width(v + (uint64_t{1} << std::min(k0 + c, 62))));
  }
  int best = k0;
  std::size_t best_bits = SIZE_MAX;
  for (int k = k0; k <= k1; ++k) {
    const std::size_t total = 2 * bits[static_cast<std::size_t>(k - k0)] - n * static_cast<std::size_t>(k + 1);
    if (total < best_bits) best_bits = total, best = k;
  }
  return best;
}

// ---- encoder steps ----
// The frame being encoded: what each of its chunks carries, and its points per region.
struct FrameInProgress {
  uint32_t frame_id = 0;
  uint64_t capture_time_ns = 0;
  const BrickTag* brick = nullptr;  // every chunk's tag, in a brick encode
  std::size_t arena_used = 0;                                   // bytes of the arena holding chunks
  std::array<uint32_t, pipeline::kMaxRegions + 1> start{};      // region r: order[start[r], start[r + 1])
  std::array<std::array<int64_t, 3>, pipeline::kMaxRegions> qmin{}, qmax{};  // lattice bounds per region
};

// One region's points in Morton order, to be cut into chunks.
struct RegionCut {
  int region;
  const uint64_t* keys;   // Morton keys, sorted
  const uint32_t* order;  // the input index of each key (rgb is gathered in this order)
  std::size_t points;
  bool half;              // chroma shared by pairs of points
  std::array<int64_t, 3> origin_q;  // the region's lattice origin (qmin), steps
  const uint32_t* rgb;    // colour of each key's point
};

// A chunk's Exp-Golomb orders: of the position deltas, and of the three colour codes.
struct Orders {
  int position;
  std::array<int, 3> colour;
};

// The colour coder's previous values (a point's are committed once it fits).
struct ColourPrev {
  uint8_t y = 0;           // previous Y
  int fco = 0, fcg = 0;    // full colour: previous Co, Cg (-255..255)
  uint8_t co = 0, cg = 0;  // halved chroma: the previous pair's Co, Cg
};

// A chunk's first Morton code: a 6-bit length, then that many bits.
[[gnu::always_inline]] inline void putFirstCode(BitWriter& bw, uint64_t code) {
  const std::size_t len = firstCodeBits(code) - 6;
  bw.put(len, 6);
  if (len > 32) {
    bw.put(code & 0xffffffffu, 32);
    bw.put(code >> 32, static_cast<int>(len - 32));
  } else {
    bw.put(code, static_cast<int>(len));
  }
}

// Lossless YCoCg-R deltas of point j as three Exp-Golomb codes (values below 512
// and orders <= 8: at most 27 bits each); `next` gets the point's YCoCg-R.
struct ColourCodes {
  uint64_t code[3];
  int len[3];
  int bits() const { return len[0] + len[1] + len[2]; }
  // The three codes packed from the lowest bit (bits() <= 64 when used whole).
  uint64_t packed() const { return code[0] | (code[1] << len[0]) | (code[2] << (len[0] + len[1])); }
};

[[gnu::always_inline]] inline ColourCodes fullColourCodes(uint32_t c, const Orders& orders, const ColourPrev& prev,
                                                          ColourPrev& next) {
  const Ycocg v = toYcocg(c);
  next.y = static_cast<uint8_t>(v.y);
  next.fco = v.co, next.fcg = v.cg;
  ColourCodes codes;
  codes.code[0] = BitWriter::egCode(zigzag8(static_cast<uint8_t>(next.y - prev.y)), orders.colour[0], codes.len[0]);
  codes.code[1] = BitWriter::egCode(zigzag9(next.fco - prev.fco), orders.colour[1], codes.len[1]);
  codes.code[2] = BitWriter::egCode(zigzag9(next.fcg - prev.fcg), orders.colour[2], codes.len[2]);
  return codes;
}

// The three codes, in one put() when they fit 56 bits (two otherwise).
[[gnu::always_inline]] inline void putColourCodes(BitWriter& bw, const ColourCodes& codes) {
  if (codes.bits() <= 56) {
    bw.put(codes.packed(), codes.bits());
  } else {
    bw.put(codes.code[0] | (codes.code[1] << codes.len[0]), codes.len[0] + codes.len[1]);
    bw.put(codes.code[2], codes.len[2]);
  }
}

// Lossless YCoCg-R deltas of point j.
[[gnu::always_inline]] inline void putFullColour(BitWriter& bw, uint32_t c, const Orders& orders, const ColourPrev& prev,
                                                 ColourPrev& next) {
  putColourCodes(bw, fullColourCodes(c, orders, prev, next));
}

// A point after the first, full colour: its position delta and colour codes, in
// one put() when they fit 56 bits together (nearly always).
[[gnu::always_inline]] inline void putPointFull(BitWriter& bw, uint64_t delta, uint32_t c, const Orders& orders,
                                                const ColourPrev& prev, ColourPrev& next) {
  const int kp = orders.position;
  const int lp = 2 * (std::bit_width((delta >> kp) + 1) - 1) + 1 + kp;
  const ColourCodes codes = fullColourCodes(c, orders, prev, next);
  if (lp + codes.bits() <= 56) {
    int len;
    const uint64_t pc = BitWriter::egCode(delta, kp, len);
    bw.put(pc | (codes.packed() << lp), lp + codes.bits());
    return;
  }
  bw.putEg(delta, kp);
  putColourCodes(bw, codes);
}

// Point j's luma, and after the second point of a pair the pair's chroma. The
// bits a first point's own chroma would take if it stays alone: they must fit too.
[[gnu::always_inline]] inline std::size_t putHalfColour(BitWriter& bw, const RegionCut& cut, std::size_t j,
                                                        std::size_t count, const Orders& orders, const ColourPrev& prev,
                                                        ColourPrev& next) {
  const uint32_t c = cut.rgb[j];
  next.y = static_cast<uint8_t>(luma(c));
  bw.putEg(zigzag8(static_cast<uint8_t>(next.y - prev.y)), orders.colour[0]);
  if (count % 2 == 1) {  // the pair's chroma, after its second point
    const uint32_t c0 = cut.rgb[j - 1];
    next.co = pairCo(c0, c), next.cg = pairCg(c0, c);
    bw.putEg(zigzag8(static_cast<uint8_t>(next.co - prev.co)), orders.colour[1]);
    bw.putEg(zigzag8(static_cast<uint8_t>(next.cg - prev.cg)), orders.colour[2]);
    return 0;
  }
  return egBits(zigzag8(static_cast<uint8_t>(pairCo(c, c) - prev.co)), orders.colour[1]) +
         egBits(zigzag8(static_cast<uint8_t>(pairCg(c, c) - prev.cg)), orders.colour[2]);
}

}  // namespace

// ---- configuration ----

Status validate(const CodecConfig& c) {
  if (c.max_payload < kMinPayload || c.max_payload > kMaxPayload) {
    return {ErrorCode::kInvalidArgument, "codec.max_payload: " + std::to_string(c.max_payload) + " is outside [" +
                                             std::to_string(kMinPayload) + ", " + std::to_string(kMaxPayload) +
                                             "] (MTU minus " + std::to_string(kDatagramOverhead) + " bytes)"};
  }
  if (!std::isfinite(c.fovea_step_m) || c.fovea_step_m < 1e-6 || c.fovea_step_m > 1.0) {
    return {ErrorCode::kInvalidArgument,
            "codec.fovea_step_m: " + std::to_string(c.fovea_step_m) + " is outside [1e-6, 1] m"};
  }
  if (!std::isfinite(c.periphery_step_ratio) || c.periphery_step_ratio < 1.0 / 1024 || c.periphery_step_ratio > 1.0) {
    return {ErrorCode::kInvalidArgument, "codec.periphery_step_ratio: " + std::to_string(c.periphery_step_ratio) +
                                             " is outside [1/1024, 1] (a fraction of the voxel size)"};
  }
  if (c.zstd_level < -7 || c.zstd_level > 9) {
    return {ErrorCode::kInvalidArgument, "codec.zstd_level: " + std::to_string(c.zstd_level) + " is outside [-7, 9]"};
  }
  return Status::ok();
}

// ---- encoder ----

// Per point of the frame, grouped by region; read and written only inside encode().
struct ChunkEncoder::PointScratch {
  explicit PointScratch(std::size_t n) : keys(n), keys_tmp(n), order(n), order_tmp(n), colours(n) {}
  // No lattice coordinates: the key pass quantizes each point again (the same
  // arithmetic, so the same values), which costs less than 24 bytes a point.
  std::vector<uint64_t> keys, keys_tmp;
  std::vector<uint32_t> order, order_tmp;
  std::vector<uint32_t> colours;  // the points' colours in Morton order (a separate gather: more loads in flight)
};

std::shared_ptr<ChunkEncoder::PointScratch> ChunkEncoder::makePointScratch(std::size_t max_points) {
  return std::make_shared<PointScratch>(max_points);
}

struct ChunkEncoder::State {
  explicit State(std::shared_ptr<PointScratch> scratch)
      : points(std::move(scratch)),
        keys(points->keys),
        keys_tmp(points->keys_tmp),
        order(points->order),
        order_tmp(points->order_tmp),
        colours(points->colours),
        summary_fbb(1) {}
  ~State() = default;

  CodecConfig config;
  std::size_t max_points = 0;
  std::size_t budget = 0;  // bytes of data in a chunk of the region in progress (max_payload - its header)
  std::size_t max_chunks = 0;

  // The per-point arrays (this encoder's own, or shared: ChunkEncoder::create).
  std::shared_ptr<PointScratch> points;
  std::vector<uint64_t>& keys;
  std::vector<uint64_t>& keys_tmp;
  std::vector<uint32_t>& order;
  std::vector<uint32_t>& order_tmp;
  std::vector<uint32_t>& colours;
  std::vector<uint32_t> histogram;  // 1 << kRadixBits per radix pass

  // One chunk in the making: 4 order bytes, then the bitstream (+ slack for rollback).
  std::vector<uint8_t> raw;
  std::vector<uint8_t> packed;  // zstd output
  std::vector<uint8_t> zstd_workspace;
  ZSTD_CCtx* cctx = nullptr;
  std::array<uint64_t, 4 * 64> sample{};  // values that choose a chunk's orders

  flatbuffers::FlatBufferBuilder summary_fbb;

  std::vector<uint8_t> arena;  // max_chunks * max_payload
  struct ChunkRef {
    uint32_t offset, size, points;
    uint8_t region;
  };
  std::vector<ChunkRef> chunks;
  std::size_t chunk_count = 0;
  std::array<double, pipeline::kMaxRegions> step{};

  // Writes one chunk (header, then data) at arena[offset]; its size. The chunk
  // count is a placeholder until patchChunkCount().
  std::size_t buildChunk(std::size_t offset, uint32_t frame_id, uint16_t index, uint8_t region, uint64_t capture_ns,
                         const std::array<int64_t, 3>& origin_q, double step_m, uint32_t points, uint8_t flags,
                         const uint8_t* data, std::size_t data_size, const BrickTag* brick) {
    HeaderFields h;
    h.frame_id = frame_id;
    h.capture_time_ns = capture_ns;
    h.chunk_index = index;
    h.chunk_count = kChunkCountPlaceholder;
    h.points = static_cast<uint16_t>(points);
    h.region = region;
    h.flags = flags;
    h.step_m = step_m;
    h.origin_q = origin_q;
    h.has_brick = brick != nullptr;
    if (brick != nullptr) h.brick = *brick;
    uint8_t* out = arena.data() + offset;
    const std::size_t n = writeHeader(out, h);
    std::memcpy(out + n, data, data_size);
    return n + data_size;
  }

  // encode()'s steps, in order.
  Status countRegions(const EncodeInput& cloud, std::span<const double> region_voxel_size_m,
                      FrameInProgress& frame);
  Status quantize(const EncodeInput& cloud, FrameInProgress& frame);
  Status firstPointOutOfRange(const EncodeInput& cloud) const;
  void mortonKeys(const EncodeInput& cloud, const FrameInProgress& frame);
  Status encodeRegion(const EncodeInput& cloud, int r, FrameInProgress& frame);
  std::pair<const uint64_t*, const uint32_t*> sortByMorton(std::size_t begin, std::size_t end, int64_t span);
  Orders chooseOrders(const RegionCut& cut, std::size_t k);
  std::size_t packChunk(const RegionCut& cut, std::size_t k, const Orders& orders, std::size_t& raw_size);
  Status storeChunk(const RegionCut& cut, std::size_t points, std::size_t raw_size, FrameInProgress& frame);
  Status patchChunkCount();

  // zstd of raw[0, size) into packed; 0 when it does not pay or fails.
  std::size_t compress(std::size_t size) {
    const std::size_t c = ZSTD_compressCCtx(cctx, packed.data(), packed.size(), raw.data(), size, config.zstd_level);
    if (ZSTD_isError(c) || c >= size) return 0;
    return c;
  }
};

ChunkEncoder::ChunkEncoder(std::unique_ptr<State> state) : s_(std::move(state)) {}
ChunkEncoder::ChunkEncoder(ChunkEncoder&&) noexcept = default;
ChunkEncoder& ChunkEncoder::operator=(ChunkEncoder&&) noexcept = default;
ChunkEncoder::~ChunkEncoder() = default;

std::size_t zstdWorkspaceBytes(int level, std::size_t max_source_bytes) {
  return ZSTD_estimateCCtxSize_usingCParams(ZSTD_getCParams(level, max_source_bytes, 0));
}

std::size_t maxChunks(const CodecConfig& config, std::size_t points) {
  // Every chunk but a region's last holds more than budget - 23 bytes of at
  // most 23 bytes per point (a 127-bit position code, a 17-bit luma code and two
  // chroma codes of at most 19 bits), budget being at least max_payload - kMaxHeader.
  const std::size_t per_chunk = config.max_payload - kMaxHeader - 23;
  return (23 * points + per_chunk - 1) / per_chunk + pipeline::kMaxRegions + 1;
}

Result<ChunkEncoder> ChunkEncoder::create(const CodecConfig& config, std::size_t max_points,
                                         std::shared_ptr<PointScratch> scratch, std::size_t max_chunks) {
  if (Status st = validate(config); !st) return st;
  if (max_points == 0 || max_points > (std::size_t{1} << 26)) {
    return Result<ChunkEncoder>(ErrorCode::kInvalidArgument,
                                "codec: max_points " + std::to_string(max_points) + " is outside [1, 2^26]");
  }
  if (scratch != nullptr && scratch->keys.size() < max_points) {
    return Result<ChunkEncoder>(ErrorCode::kInvalidArgument, "codec: a shared point scratch of " +
                                                                 std::to_string(scratch->keys.size()) +
                                                                 " points for an encoder of " + std::to_string(max_points));
  }
  auto s = std::make_unique<State>(scratch != nullptr ? std::move(scratch) : makePointScratch(max_points));
  s->config = config;
  s->max_points = max_points;

  // The largest header (a brick tag, origin varints of 8 bytes) leaves room for points.
  static_assert(kMinPayload >= kMaxHeader + 64);
  s->budget = config.max_payload - kMaxHeader;

  const std::size_t most = maxChunks(config, max_points);
  s->max_chunks = max_chunks > 0 ? std::min(max_chunks, most) : most;
  // Each chunk starts at a kPayloadAlignment boundary (net/wire.h): the patch
  // below and every decoder read it in place.
  s->arena.resize(s->max_chunks * alignUp(config.max_payload, kPayloadAlignment));
  s->chunks.resize(s->max_chunks);

  s->histogram.resize(((63 + kRadixBits - 1) / kRadixBits) * (std::size_t{1} << kRadixBits));  // one per pass
  s->raw.resize(config.max_payload + 64);
  s->packed.resize(ZSTD_compressBound(config.max_payload));
  if (config.entropy_coding) {
    s->zstd_workspace.resize(zstdWorkspaceBytes(config.zstd_level, s->raw.size()));
    s->cctx = ZSTD_initStaticCCtx(s->zstd_workspace.data(), s->zstd_workspace.size());
    if (s->cctx == nullptr) return Result<ChunkEncoder>(ErrorCode::kInvalidArgument, "codec: zstd context failed");
  }
  s->summary_fbb = flatbuffers::FlatBufferBuilder(1024);
  // Warm up the summary builder (its first use allocates).
  const std::array<uint16_t, pipeline::kMaxRegions> zeros{};
  ChunkEncoder enc(std::move(s));
  (void)enc.encodeSummary(0, zeros, zeros);
  return enc;
}

const CodecConfig& ChunkEncoder::config() const { return s_->config; }
std::size_t ChunkEncoder::maxChunkCount() const { return s_->max_chunks; }
std::size_t ChunkEncoder::chunkCount() const { return s_->chunk_count; }
std::span<const uint8_t> ChunkEncoder::chunk(std::size_t i) const {
  const State::ChunkRef& c = s_->chunks[i];
  return {s_->arena.data() + c.offset, c.size};
}
uint8_t ChunkEncoder::chunkRegion(std::size_t i) const { return s_->chunks[i].region; }
uint32_t ChunkEncoder::chunkPoints(std::size_t i) const { return s_->chunks[i].points; }
double ChunkEncoder::regionStep(int region) const { return s_->step[static_cast<std::size_t>(region)]; }

Status ChunkEncoder::encode(const EncodeInput& cloud, std::span<const double> region_voxel_size_m, uint32_t frame_id,
                            uint64_t capture_time_ns, const BrickTag* brick) {
  State& s = *s_;
  s.chunk_count = 0;
  if (brick != nullptr && brick->level >= pipeline::kMaxRegions) {
    return {ErrorCode::kInvalidArgument, "codec: brick level " + std::to_string(brick->level) + " is not below " +
                                             std::to_string(pipeline::kMaxRegions)};
  }
  const std::size_t n = cloud.size;
  if (n > s.max_points) {
    return {ErrorCode::kCapacityExceeded, "codec: frame has " + std::to_string(n) + " points, max_points is " +
                                              std::to_string(s.max_points)};
  }
  FrameInProgress frame;
  frame.frame_id = frame_id;
  frame.capture_time_ns = capture_time_ns;
  frame.brick = brick;
  if (Status st = s.countRegions(cloud, region_voxel_size_m, frame); !st) return st;
  if (Status st = s.quantize(cloud, frame); !st) return st;
  s.mortonKeys(cloud, frame);
  for (int r = 0; r < pipeline::kMaxRegions; ++r) {
    if (Status st = s.encodeRegion(cloud, r, frame); !st) return st;
  }
  if (brick != nullptr && s.chunk_count == 0) {
    // A brick version with no points (its surfels all went): one chunk of none,
    // so that the operator replaces what it draws of the brick with nothing.
    std::memset(s.raw.data(), 0, kDataHeader);
    const std::size_t size = s.buildChunk(0, frame_id, 0, brick->level, capture_time_ns, {0, 0, 0},
                                          s.step[brick->level], 0, 0, s.raw.data(), kDataHeader, frame.brick);
    s.chunks[0] = {0, static_cast<uint32_t>(size), 0, brick->level};
    s.chunk_count = 1;
  }
  return s.patchChunkCount();
}

// Points per region (frame.start, as offsets), and the step of each region.
Status ChunkEncoder::State::countRegions(const EncodeInput& cloud,
                                         std::span<const double> region_voxel_size_m, FrameInProgress& frame) {
  std::array<uint32_t, pipeline::kMaxRegions + 1>& start = frame.start;
  for (std::size_t i = 0; i < cloud.size; ++i) {
    const uint8_t r = cloud.region[i];
    if (r >= pipeline::kMaxRegions || r >= region_voxel_size_m.size()) {
      return {ErrorCode::kInvalidInput, "codec: point " + std::to_string(i) + " has region " + std::to_string(r) +
                                            " without a voxel size"};
    }
    ++start[r + 1u];
  }
  for (int r = 0; r < pipeline::kMaxRegions; ++r) {
    start[static_cast<std::size_t>(r) + 1] += start[static_cast<std::size_t>(r)];
    const double voxel = r < static_cast<int>(region_voxel_size_m.size()) ? region_voxel_size_m[static_cast<std::size_t>(r)] : 0.0;
    if (!std::isfinite(voxel) || voxel < 0.0) {
      return {ErrorCode::kInvalidInput, "codec: region " + std::to_string(r) + " voxel size is not finite and >= 0"};
    }
    step[static_cast<std::size_t>(r)] = (r == 0 || voxel == 0.0) ? config.fovea_step_m : voxel * config.periphery_step_ratio;
  }
  return Status::ok();
}

// The lattice coordinates' bounds per region, from the points' extremes;
// `order` gets the points grouped by region.
Status ChunkEncoder::State::quantize(const EncodeInput& cloud, FrameInProgress& frame) {
  std::array<uint32_t, pipeline::kMaxRegions> fill{};
  constexpr float kInf = std::numeric_limits<float>::infinity();
  std::array<std::array<float, 3>, pipeline::kMaxRegions> lo, hi;
  for (auto& l : lo) l.fill(kInf);
  for (auto& h : hi) h.fill(-kInf);
  bool finite = true;
  const float* px[3] = {cloud.x, cloud.y, cloud.z};
  // Run by run of one region (the samplers write the regions in turn), so that
  // the bounds stay in registers.
  for (std::size_t i = 0; i < cloud.size;) {
    const uint8_t r = cloud.region[i];
    std::size_t end = i + 1;
    while (end < cloud.size && cloud.region[end] == r) ++end;
    for (std::size_t a = 0; a < 3; ++a) {
      float l = lo[r][a], h = hi[r][a];
      bool ok = true;
      for (std::size_t k = i; k < end; ++k) {
        const float v = px[a][k];
        ok &= std::isfinite(v);
        l = v < l ? v : l;
        h = v > h ? v : h;
      }
      lo[r][a] = l, hi[r][a] = h;
      finite &= ok;
    }
    for (std::size_t k = i; k < end; ++k) order[frame.start[r] + fill[r]++] = static_cast<uint32_t>(k);
    i = end;
  }
  for (std::size_t r = 0; r < pipeline::kMaxRegions; ++r) {
    if (fill[r] == 0) continue;
    const double inv = 1.0 / step[r];
    if (!finite || latticeCoords(cloud.origin_m, lo[r].data(), inv, frame.qmin[r].data()) != Lattice::kInRange ||
        latticeCoords(cloud.origin_m, hi[r].data(), inv, frame.qmax[r].data()) != Lattice::kInRange) {
      return firstPointOutOfRange(cloud);
    }
  }
  return Status::ok();
}

// The error for the first point with no lattice coordinates (quantize() found one).
Status ChunkEncoder::State::firstPointOutOfRange(const EncodeInput& cloud) const {
  for (std::size_t i = 0; i < cloud.size; ++i) {
    const uint8_t r = cloud.region[i];
    int64_t q[3];
    const Lattice l = latticeCoords(cloud, i, 1.0 / step[r], q);
    if (l == Lattice::kNotFinite) {
      return {ErrorCode::kInvalidInput, "codec: point " + std::to_string(i) + " is not finite"};
    }
    if (l == Lattice::kBeyond) {
      return {ErrorCode::kRangeExceeded, "codec: point " + std::to_string(i) + " is beyond 2^50 steps of " +
                                             std::to_string(step[r]) + " m from the world origin"};
    }
  }
  return {ErrorCode::kInvalidInput, "codec: a region's bounds are out of range (bug: no point is)"};
}

// Every point's Morton key relative to its region's lattice origin, in the
// slots quantize() gave `order` (every point in range: quantize() checked).
// The bits of a region wider than kMaxLatticeSpan are wrong, and unused: its
// encodeRegion() fails first.
void ChunkEncoder::State::mortonKeys(const EncodeInput& cloud, const FrameInProgress& frame) {
  std::array<uint32_t, pipeline::kMaxRegions> fill{};
  const float* px = cloud.x;
  const float* py = cloud.y;
  const float* pz = cloud.z;
  std::array<double, pipeline::kMaxRegions> inv_step;
  for (std::size_t r = 0; r < inv_step.size(); ++r) inv_step[r] = 1.0 / step[r];
  for (std::size_t i = 0; i < cloud.size;) {  // run by run of one region, as quantize()
    const uint8_t r = cloud.region[i];
    std::size_t end = i + 1;
    while (end < cloud.size && cloud.region[end] == r) ++end;
    const std::array<int64_t, 3>& qmin = frame.qmin[r];
    uint64_t* out = keys.data() + frame.start[r] + fill[r];
    const Eigen::Vector3d& o = cloud.origin_m;
    const double inv = inv_step[r];
    for (std::size_t k = i; k < end; ++k) {  // latticeCoords() without its checks
      const int64_t qx = roundHalfAway(latticeUnits(o.x(), px[k], inv));
      const int64_t qy = roundHalfAway(latticeUnits(o.y(), py[k], inv));
      const int64_t qz = roundHalfAway(latticeUnits(o.z(), pz[k], inv));
      out[k - i] = morton(static_cast<uint64_t>(qx - qmin[0]), static_cast<uint64_t>(qy - qmin[1]),
                          static_cast<uint64_t>(qz - qmin[2]));
    }
    fill[r] += static_cast<uint32_t>(end - i);
    i = end;
  }
}

// Region r's points in Morton order, cut greedily into chunks.
Status ChunkEncoder::State::encodeRegion(const EncodeInput& cloud, int r, FrameInProgress& frame) {
  const std::size_t ru = static_cast<std::size_t>(r);
  const std::size_t begin = frame.start[ru], end = frame.start[ru + 1];
  if (begin == end) return Status::ok();
  const std::array<int64_t, 3>& qmin = frame.qmin[ru];
  int64_t span = 0;
  for (int a = 0; a < 3; ++a) span = std::max(span, frame.qmax[ru][static_cast<std::size_t>(a)] - qmin[static_cast<std::size_t>(a)]);
  if (span > kMaxLatticeSpan) {
    chunk_count = 0;
    return {ErrorCode::kRangeExceeded, "codec: region " + std::to_string(r) + " spans " + std::to_string(span) +
                                           " steps of " + std::to_string(step[ru]) + " m, more than " +
                                           std::to_string(kMaxLatticeSpan) + ": raise the step or narrow the depth range"};
  }
  const std::pair<const uint64_t*, const uint32_t*> sorted = sortByMorton(begin, end, span);
  const uint32_t* rgb = cloud.rgb;
  for (std::size_t k = 0; k < end - begin; ++k) colours[begin + k] = rgb[sorted.second[k]];
  const RegionCut cut{r,
                      sorted.first,
                      sorted.second,
                      end - begin,
                      r > 0 && config.halve_peripheral_chroma,
                      qmin,
                      colours.data() + begin};
  budget = config.max_payload - headerBytes(qmin, frame.brick != nullptr);
  for (std::size_t k = 0; k < cut.points;) {
    const Orders orders = chooseOrders(cut, k);
    std::size_t raw_size = 0;
    const std::size_t points = packChunk(cut, k, orders, raw_size);
    if (points == 0) {
      return {ErrorCode::kCapacityExceeded, "codec: a point does not fit a chunk (bug: budget " +
                                                std::to_string(budget) + ")"};
    }
    if (Status st = storeChunk(cut, points, raw_size, frame); !st) return st;
    k += points;
  }
  return Status::ok();
}

// The Morton keys of order[begin, end) (mortonKeys()), radix-sorted (stable);
// the keys and input indices in sorted order (in keys/order or in
// keys_tmp/order_tmp, as the passes end).
std::pair<const uint64_t*, const uint32_t*> ChunkEncoder::State::sortByMorton(std::size_t begin, std::size_t end,
                                                                             int64_t span) {
  // Every pass's histogram in one sweep; then one scatter per pass.
  const int key_bits = 3 * std::bit_width(static_cast<uint64_t>(span));
  const int passes = (key_bits + kRadixBits - 1) / kRadixBits;
  constexpr std::size_t kBins = std::size_t{1} << kRadixBits;
  constexpr uint64_t kMask = kBins - 1;
  std::fill(histogram.begin(), histogram.begin() + static_cast<std::ptrdiff_t>(passes * kBins), 0u);
  const std::size_t m = end - begin;
  // When the key and the point's place in the region fit 64 bits together (always
  // on the mock frames: 33 to 39 bits of key, at most 15 of place), the passes move
  // one word per point instead of a key and an index.
  const int place_bits = std::bit_width(m - 1);
  const bool packed = key_bits + place_bits <= 64;
  for (std::size_t k = begin; k < end; ++k) {
    const uint64_t key = keys[k];
    keys[k] = packed ? (key << place_bits) | (k - begin) : key;
    for (int p = 0; p < passes; ++p) ++histogram[static_cast<std::size_t>(p) * kBins + ((key >> (p * kRadixBits)) & kMask)];
  }
  uint64_t* k_in = keys.data() + begin;
  uint64_t* k_out = keys_tmp.data() + begin;
  uint32_t* o_in = order.data() + begin;
  uint32_t* o_out = order_tmp.data() + begin;
  if (packed) {
    for (int p = 0; p < passes; ++p) {
      uint32_t* h = histogram.data() + static_cast<std::size_t>(p) * kBins;
      const int shift = p * kRadixBits + place_bits;
      if (h[(k_in[0] >> shift) & kMask] == m) continue;  // one digit for all: the pass would not move a key
      uint32_t sum = 0;
      for (std::size_t d = 0; d < kBins; ++d) {
        const uint32_t c = h[d];
        h[d] = sum;
        sum += c;
      }
      for (std::size_t k = 0; k < m; ++k) k_out[h[(k_in[k] >> shift) & kMask]++] = k_in[k];
      std::swap(k_in, k_out);
    }
    // Unpack in place: keys, and the input index of each.
    const uint64_t place_mask = (uint64_t{1} << place_bits) - 1;
    for (std::size_t k = 0; k < m; ++k) {
      const uint64_t v = k_in[k];
      o_out[k] = o_in[v & place_mask];
      k_in[k] = v >> place_bits;
    }
    return {k_in, o_out};
  }
  for (int p = 0; p < passes; ++p) {
    uint32_t* h = histogram.data() + static_cast<std::size_t>(p) * kBins;
    const int shift = p * kRadixBits;
    if (h[(k_in[0] >> shift) & kMask] == m) continue;  // one digit for all: the pass would not move a key
    uint32_t sum = 0;
    for (std::size_t d = 0; d < kBins; ++d) {
      const uint32_t c = h[d];
      h[d] = sum;
      sum += c;
    }
    for (std::size_t k = 0; k < m; ++k) {
      const uint32_t dst = h[(k_in[k] >> shift) & kMask]++;
      k_out[dst] = k_in[k];
      o_out[dst] = o_in[k];
    }
    std::swap(k_in, k_out);
    std::swap(o_in, o_out);
  }
  return {k_in, o_in};
}

// Exp-Golomb orders from the next (up to) 64 points.
Orders ChunkEncoder::State::chooseOrders(const RegionCut& cut, std::size_t k) {
  const std::size_t probe = std::min<std::size_t>(64, cut.points - k);
  uint64_t* sp = sample.data();
  for (std::size_t j = 1; j < probe; ++j) sp[j - 1] = cut.keys[k + j] - cut.keys[k + j - 1];
  if (cut.half) {
    uint32_t c0 = cut.rgb[k];
    for (std::size_t j = 1; j < probe; ++j) {
      const uint32_t c1 = cut.rgb[k + j];
      sp[64 + j - 1] = zigzag8(static_cast<uint8_t>(luma(c1) - luma(c0)));
      sp[128 + j - 1] = zigzag8(static_cast<uint8_t>(pairCo(c1, c1) - pairCo(c0, c0)));
      sp[192 + j - 1] = zigzag8(static_cast<uint8_t>(pairCg(c1, c1) - pairCg(c0, c0)));
      c0 = c1;
    }
  } else {
    Ycocg a = toYcocg(cut.rgb[k]);
    for (std::size_t j = 1; j < probe; ++j) {
      const Ycocg b = toYcocg(cut.rgb[k + j]);
      sp[64 + j - 1] = zigzag8(static_cast<uint8_t>(b.y - a.y));
      sp[128 + j - 1] = zigzag9(b.co - a.co);
      sp[192 + j - 1] = zigzag9(b.cg - a.cg);
      a = b;
    }
  }
  return {bestOrder(sp, probe - 1, 0, 62),
          {bestOrder(sp + 64, probe - 1, 0, 7), bestOrder(sp + 128, probe - 1, 0, 8), bestOrder(sp + 192, probe - 1, 0, 8)}};
}

// Writes a chunk's data into raw: its orders, then the points from k on, greedily
// along the Morton order while they fit (a point that does not is taken back).
// The points written, 0 when not even one fits; raw_size its bytes.
std::size_t ChunkEncoder::State::packChunk(const RegionCut& cut, std::size_t k, const Orders& orders,
                                           std::size_t& raw_size) {
  uint8_t* bytes = raw.data();  // BitWriter stores whole registers: no need to clear it
  bytes[0] = static_cast<uint8_t>(orders.position);
  for (std::size_t c = 0; c < 3; ++c) bytes[1 + c] = static_cast<uint8_t>(orders.colour[c]);
  BitWriter bw(bytes + kDataHeader);
  const std::size_t budget_bits = 8 * (budget - kDataHeader);
  std::size_t count = 0;
  ColourPrev prev;
  const std::size_t last = std::min(cut.points, k + 0xffff);  // point_count is 16 bits
  for (std::size_t j = k; j < last; ++j) {
    const BitWriter::Mark before = bw.mark();
    ColourPrev next = prev;
    std::size_t extra = 0;
    if (!cut.half && count != 0) {  // the common case
      putPointFull(bw, cut.keys[j] - cut.keys[j - 1], cut.rgb[j], orders, prev, next);
    } else {
      if (count == 0) {
        putFirstCode(bw, cut.keys[j]);
      } else {
        bw.putEg(cut.keys[j] - cut.keys[j - 1], orders.position);
      }
      if (cut.half) {
        extra = putHalfColour(bw, cut, j, count, orders, prev, next);
      } else {
        putFullColour(bw, cut.rgb[j], orders, prev, next);
      }
    }
    if (bw.bits() + extra > budget_bits) {
      bw.rewind(before);
      break;
    }
    prev = next;
    ++count;
  }
  if (count == 0) return 0;
  if (cut.half && count % 2 == 1) {  // a lone last point: its own chroma
    const uint32_t c = cut.rgb[k + count - 1];
    bw.putEg(zigzag8(static_cast<uint8_t>(pairCo(c, c) - prev.co)), orders.colour[1]);
    bw.putEg(zigzag8(static_cast<uint8_t>(pairCg(c, c) - prev.cg)), orders.colour[2]);
  }
  bw.finish();
  raw_size = kDataHeader + (bw.bits() + 7) / 8;
  return count;
}

// The packed chunk, compressed where that pays, with its header into the arena.
Status ChunkEncoder::State::storeChunk(const RegionCut& cut, std::size_t points, std::size_t raw_size,
                                       FrameInProgress& frame) {
  const uint8_t* data = raw.data();
  std::size_t data_size = raw_size;
  uint8_t flags = cut.half ? kChunkFlagHalfChroma : 0;
  if (config.entropy_coding) {
    const std::size_t z = compress(raw_size);
    if (z != 0) data = packed.data(), data_size = z, flags |= kChunkFlagZstd;
  }
  if (chunk_count == max_chunks || chunk_count == 0xffff) {
    chunk_count = 0;
    return {ErrorCode::kCapacityExceeded, "codec: frame needs more than " +
                                              std::to_string(std::min<std::size_t>(max_chunks, 0xffff)) + " chunks"};
  }
  const uint8_t region = static_cast<uint8_t>(cut.region);
  const std::size_t size = buildChunk(frame.arena_used, frame.frame_id, static_cast<uint16_t>(chunk_count), region,
                                      frame.capture_time_ns, cut.origin_q, step[region], static_cast<uint32_t>(points),
                                      flags, data, data_size, frame.brick);
  if (size > config.max_payload) {
    chunk_count = 0;
    return {ErrorCode::kCapacityExceeded, "codec: chunk of " + std::to_string(size) + " bytes over max_payload (bug)"};
  }
  chunks[chunk_count++] = {static_cast<uint32_t>(frame.arena_used), static_cast<uint32_t>(size),
                           static_cast<uint32_t>(points), region};
  frame.arena_used += alignUp(size, kPayloadAlignment);
  return Status::ok();
}

// Every chunk now learns the frame's chunk count (the field is stored: placeholder).
Status ChunkEncoder::State::patchChunkCount() {
  for (std::size_t c = 0; c < chunk_count; ++c) {
    putLe<uint16_t>(arena.data() + chunks[c].offset + kChunkCountOffset, static_cast<uint16_t>(chunk_count));
  }
  return Status::ok();
}

std::span<const uint8_t> ChunkEncoder::encodeSummary(uint32_t frame_id, std::span<const uint16_t> chunks_sent_per_region,
                                                     std::span<const uint16_t> chunks_cut_per_region) {
  State& s = *s_;
  const std::size_t regions = std::min<std::size_t>(
      pipeline::kMaxRegions, std::max(chunks_sent_per_region.size(), chunks_cut_per_region.size()));
  std::array<uint16_t, pipeline::kMaxRegions> sent{}, cut{};
  std::copy_n(chunks_sent_per_region.begin(), std::min(regions, chunks_sent_per_region.size()), sent.begin());
  std::copy_n(chunks_cut_per_region.begin(), std::min(regions, chunks_cut_per_region.size()), cut.begin());
  s.summary_fbb.Clear();
  // A summary's largest scalar has 4 bytes; every payload starts at 8 all the same
  // (net/wire.h kPayloadAlignment), so it decodes in place wherever it is handed.
  s.summary_fbb.TrackMinAlign(kPayloadAlignment);
  const auto sent_v = s.summary_fbb.CreateVector(sent.data(), regions);
  const auto cut_v = s.summary_fbb.CreateVector(cut.data(), regions);
  wire::FrameSummaryBuilder b(s.summary_fbb);
  b.add_frame_id(frame_id);
  b.add_chunk_count(static_cast<uint16_t>(s.chunk_count));
  b.add_chunks_sent(sent_v);
  b.add_chunks_cut(cut_v);
  s.summary_fbb.Finish(b.Finish());
  return {s.summary_fbb.GetBufferPointer(), s.summary_fbb.GetSize()};
}

}  // namespace fovea::net

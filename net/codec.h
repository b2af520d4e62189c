// The point-chunk codec: a foveated frame to self-contained chunk payloads (one
// per datagram), and back. Wire layout and rules: docs/protocol-chunks.md.
//
// Robot side: ChunkEncoder allocates everything in create(); encode() and
// encodeSummary() never allocate. Operator side: decodeChunk(), decodeSummary()
// and FrameAssembler verify every byte (the chunk header's structure, the
// summary's FlatBuffers verifier, semantic checks)
// and return an error for any malformed input; they never crash.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "core/result.h"
#include "net/wire.h"
#include "pipeline/acuity.h"
#include "pipeline/point_cloud.h"

namespace fovea::net {

struct CodecConfig {
  // Largest payload of one chunk (bytes: header and data): the datagram adds
  // kDatagramOverhead. In [kMinMtu, kMaxMtu] - kDatagramOverhead.
  std::size_t max_payload = kDefaultMtu - kDatagramOverhead;
  // Quantization step of the fovea (region 0), metres: error <= step / 2 per axis.
  double fovea_step_m = 0.001;
  // Step of every other region as a fraction of its voxel size. The default 1/8
  // puts the quantization error (<= voxel/16 per axis) well under the error the
  // voxel sampling already makes (the voxel itself); docs/protocol-chunks.md.
  double periphery_step_ratio = 0.125;
  // Regions >= 1: luma per point, chroma (Co, Cg) shared by pairs of points
  // (about 0.7 bytes per point less on the mock room). The fovea always keeps
  // exact RGB; otherwise colours are exact (lossless YCoCg-R).
  bool halve_peripheral_chroma = false;
  // zstd over each chunk's data, kept only where it makes the chunk smaller.
  // Off by default: the data is already Exp-Golomb coded; on the mock frames zstd
  // makes no chunk smaller and costs 20-40 % more encoding time (bench/README.md).
  bool entropy_coding = false;
  int zstd_level = 1;  // in [-7, 9]
};

// kInvalidArgument naming the field, e.g. "codec.max_payload: 100 is outside
// [220, 8916] (MTU minus 36 bytes)".
Status validate(const CodecConfig& config);

// Flags of a chunk (DecodedChunk; in the header byte with the region, docs/protocol-chunks.md).
inline constexpr uint8_t kChunkFlagZstd = 1u << 0;
inline constexpr uint8_t kChunkFlagHalfChroma = 1u << 1;
// Positions are 21-bit lattice coordinates per axis (a 63-bit Morton code)
// relative to the region's lattice origin: a region spans at most this many steps.
inline constexpr int64_t kMaxLatticeSpan = (int64_t{1} << 21) - 1;
// Upper bound of a chunk's decompressed data (the decoder rejects more).
inline constexpr std::size_t kMaxChunkRawBytes = 1u << 16;

// Which map brick, and which version of it, a chunk's points belong to
// (the chunk header's brick tag; a kBrickChunk message, docs/protocol-chunks.md).
struct BrickTag {
  int32_t x = 0, y = 0, z = 0;  // the brick's grid key: its origin is key * brick_size_m
  uint32_t version = 0;         // the robot's per-brick counter (serial-number order)
  uint8_t level = 0;            // 0 = raw surfels; n >= 1: ACUITY lattice level n; < kMaxRegions
};

// The points encode() reads, as arrays: positions relative to origin_m,
// colours (packRgb) and regions. A foveated cloud is one (of()); a brick of a
// map's batch is a slice of the batch's arrays, encoded without a copy.
struct EncodeInput {
  Eigen::Vector3d origin_m = Eigen::Vector3d::Zero();
  const float* x = nullptr;
  const float* y = nullptr;
  const float* z = nullptr;
  const uint32_t* rgb = nullptr;
  const uint8_t* region = nullptr;
  std::size_t size = 0;
  static EncodeInput of(const pipeline::FoveatedCloud& cloud) { return slice(cloud, 0, cloud.size()).value(); }
  // Points [first, first + count) of `cloud`; nullopt when they are not all in it.
  static std::optional<EncodeInput> slice(const pipeline::FoveatedCloud& cloud, std::size_t first, std::size_t count) {
    if (first > cloud.size() || count > cloud.size() - first) return std::nullopt;
    const pipeline::PointCloud& p = cloud.points;
    return EncodeInput{p.origin_m,      p.x() + first, p.y() + first, p.z() + first, p.rgb() + first,
                       cloud.region.data() + first, count};
  }
};

// The most chunks one encode() of `points` points can make at
// config.max_payload (every chunk but a region's last is nearly full of the
// costliest points; the encoder's own capacity).
std::size_t maxChunks(const CodecConfig& config, std::size_t points);

// The bytes of a static zstd compression context that compresses every source
// of at most max_source_bytes at `level`: the library's estimate for the
// parameters it picks for a source of that size (a chunk is at most a
// datagram, where ZSTD_estimateCCtxSize(level) allows for sources of any size:
// 48 KiB at level 1 for the default MTU's chunks against 569 KiB, 64 KiB at
// level 9 against 12.5 MiB). The output does not depend on the context's size.
std::size_t zstdWorkspaceBytes(int level, std::size_t max_source_bytes);

class ChunkEncoder {
 public:
  // The per-point arrays encode() sorts in (28 bytes a point),
  // used only while it runs: encoders that never encode at the same time (the
  // streamer's frame and brick encoders, both on its send thread) can share one.
  struct PointScratch;
  static std::shared_ptr<PointScratch> makePointScratch(std::size_t max_points);

  // max_points: points per foveated frame. Allocates every buffer here but the
  // per-point arrays when `scratch` is given (it must hold max_points; the
  // encoder keeps it alive; kInvalidArgument when it is smaller). max_chunks:
  // the most chunks one encode() may make, when the caller cannot take more
  // (a brick version has at most BrickSenderConfig::max_parts parts); the
  // arena is sized for them, and an encode() that needs more fails with
  // kCapacityExceeded. 0: maxChunks(config, max_points), every frame of
  // max_points fits.
  static Result<ChunkEncoder> create(const CodecConfig& config, std::size_t max_points,
                                     std::shared_ptr<PointScratch> scratch = nullptr, std::size_t max_chunks = 0);
  ChunkEncoder(ChunkEncoder&&) noexcept;
  ChunkEncoder& operator=(ChunkEncoder&&) noexcept;
  ~ChunkEncoder();

  // Encodes one foveated frame into chunks: region by region, fovea first; in
  // each region points in Morton order. region_voxel_size_m[r] is region r's
  // voxel size (FoveationStats::regions[r].voxel_size_m; 0 for the fovea) and
  // must cover every region present. Errors: kCapacityExceeded (more than
  // max_points), kInvalidInput (non-finite point, region without a size),
  // kRangeExceeded (a region spans more than kMaxLatticeSpan steps on an axis,
  // or coordinates beyond 2^50 steps): then no chunk is valid. Never allocates.
  // With `brick`, every chunk carries that tag (a map brick's parts: chunk
  // indices and count are the parts of that version; frame_id is the robot's
  // frame when the version was made) and is sized for it, so still fits
  // max_payload; kInvalidArgument if brick->level >= pipeline::kMaxRegions.
  Status encode(const EncodeInput& points, std::span<const double> region_voxel_size_m, uint32_t frame_id,
                uint64_t capture_time_ns, const BrickTag* brick = nullptr);
  Status encode(const pipeline::FoveatedCloud& cloud, std::span<const double> region_voxel_size_m,
                uint32_t frame_id, uint64_t capture_time_ns, const BrickTag* brick = nullptr) {
    return encode(EncodeInput::of(cloud), region_voxel_size_m, frame_id, capture_time_ns, brick);
  }

  // The most chunks one encode() may make (create()'s max_chunks, or
  // maxChunks() of its max_points): what the arena holds.
  std::size_t maxChunkCount() const;
  // The chunks of the last encode(), fovea first then outward.
  std::size_t chunkCount() const;
  std::span<const uint8_t> chunk(std::size_t i) const;
  uint8_t chunkRegion(std::size_t i) const;
  uint32_t chunkPoints(std::size_t i) const;
  // Quantization step (m) each region used in the last encode().
  double regionStep(int region) const;

  // The frame summary for what was actually sent (one entry per region, at most
  // pipeline::kMaxRegions; extra entries are ignored). Valid until the next call.
  std::span<const uint8_t> encodeSummary(uint32_t frame_id, std::span<const uint16_t> chunks_sent_per_region,
                                         std::span<const uint16_t> chunks_cut_per_region);

  const CodecConfig& config() const;

 private:
  struct State;
  explicit ChunkEncoder(std::unique_ptr<State> state);
  std::unique_ptr<State> s_;
};

// ---- operator side ----

struct DecodedChunk {
  uint32_t frame_id = 0;
  uint16_t chunk_index = 0;
  uint16_t chunk_count = 0;
  uint8_t region = 0;
  uint64_t capture_time_ns = 0;
  std::size_t points = 0;
  double step_m = 0.0;
  bool has_brick = false;  // a brick chunk (then `brick` is its tag)
  BrickTag brick;
};

// Verifies and decodes one chunk payload; appends its points to `out` (region
// set, weight 1). When `out` is empty, out.points.origin_m is first set to the
// chunk's lattice origin so float coordinates stay small; otherwise points are
// written relative to the caller's origin. Errors (nothing appended):
// kParseError for malformed payloads, kCapacityExceeded when out is full,
// kRangeExceeded when a point does not fit a float relative to out's origin.
// A brick tag's level must be < pipeline::kMaxRegions (else kParseError).
// Decompression uses a per-thread context (allocated on first use). The payload
// must start at a kPayloadAlignment boundary (net/wire.h), else kParseError;
// this holds for every decoder here (summary, FrameAssembler).
Result<DecodedChunk> decodeChunk(std::span<const uint8_t> payload, pipeline::FoveatedCloud& out);

struct FrameSummaryInfo {
  uint32_t frame_id = 0;
  uint16_t chunk_count = 0;
  int region_count = 0;
  std::array<uint16_t, pipeline::kMaxRegions> chunks_sent{};
  std::array<uint16_t, pipeline::kMaxRegions> chunks_cut{};
};
Result<FrameSummaryInfo> decodeSummary(std::span<const uint8_t> payload);

// One frame as the operator received it.
struct AssembledFrame {
  uint32_t frame_id = 0;
  uint64_t capture_time_ns = 0;
  bool summary_received = false;  // false: completed because a newer frame started
  std::array<uint32_t, pipeline::kMaxRegions> points{};           // decoded, per region
  std::array<uint16_t, pipeline::kMaxRegions> chunks_received{};  // per region (duplicates ignored)
  // From the summary (0 without one): chunks sent per region; lost = sent - received.
  std::array<uint16_t, pipeline::kMaxRegions> chunks_expected{};
  std::array<uint16_t, pipeline::kMaxRegions> chunks_cut{};
  uint16_t chunk_count = 0;  // chunks the encoder made (from any chunk or the summary)
  // Per region, the lattice step of its decoded chunks (0: no chunk of it arrived).
  // For a voxel-sampled region it is CodecConfig::periphery_step_ratio times the
  // voxel size; a viewer sizes a point's splat from it.
  std::array<double, pipeline::kMaxRegions> step_m{};
  // The caller's arrival time of the frame's last decoded chunk (addChunk's
  // received_ns): when the frame was decoded, whatever later event completed it.
  int64_t last_chunk_received_ns = 0;
  const pipeline::FoveatedCloud* cloud = nullptr;  // the decoded points
};

// Collects chunks by frame id (serial-number order, so ids may wrap). A frame
// completes when its summary arrives or a chunk or summary of a newer frame
// arrives; chunks of completed or older frames are dropped and counted. A
// chunk with a brick tag never belongs to a frame: refused, counted as bad.
// All memory is allocated by create().
class FrameAssembler {
 public:
  static Result<FrameAssembler> create(std::size_t max_points);

  // Each call first forgets the frames it last reported ready; after it,
  // readyCount() frames (0, 1 or 2, oldest first) are complete.
  // received_ns: when the chunk arrived (any clock; kept as the frame's
  // last_chunk_received_ns for latency figures).
  Status addChunk(std::span<const uint8_t> payload, int64_t received_ns = 0);
  Status addSummary(std::span<const uint8_t> payload);
  // Completes the frame in progress, if any (end of stream).
  void flush();

  std::size_t readyCount() const { return ready_count_; }
  const AssembledFrame& ready(std::size_t i) const { return ready_[i]; }

  struct Counters {
    uint64_t chunks = 0;           // decoded into a frame
    uint64_t bad_chunks = 0;       // failed verification or decoding, or a brick chunk
    uint64_t late_chunks = 0;      // for a frame already completed
    uint64_t duplicate_chunks = 0;
    uint64_t bad_summaries = 0;
    uint64_t late_summaries = 0;
    uint64_t frames = 0;           // completed
  };
  const Counters& counters() const { return counters_; }

 private:
  explicit FrameAssembler(std::size_t max_points);
  void startFrame(uint32_t frame_id);
  void completeCurrent(bool summary_received);

  std::array<pipeline::FoveatedCloud, 3> clouds_;
  std::size_t current_cloud_ = 0;
  bool has_current_ = false;
  bool has_last_completed_ = false;
  uint32_t last_completed_id_ = 0;
  AssembledFrame current_;
  std::vector<uint8_t> seen_;  // per chunk index of the current frame (65536)
  std::array<AssembledFrame, 2> ready_;
  std::size_t ready_count_ = 0;
  Counters counters_;
};

}  // namespace fovea::net

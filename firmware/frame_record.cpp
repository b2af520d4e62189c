#include "firmware/frame_record.h"

#include <bit>
#include <cstring>
#include <string>

#include "pipeline/backproject.h"

namespace fovea::firmware {
namespace {

static_assert(std::endian::native == std::endian::little, "frame records are written in the host's byte order");

constexpr uint8_t kMagic[4] = {'F', 'V', 'F', 'R'};
constexpr uint16_t kFlagHasRgb = 1;

template <class T>
void put(uint8_t* out, std::size_t offset, T value) {
  std::memcpy(out + offset, &value, sizeof(T));
}

template <class T>
T get(const uint8_t* in, std::size_t offset) {
  T value;
  std::memcpy(&value, in + offset, sizeof(T));
  return value;
}

constexpr char kSchemaText[] =
    "fovea.FrameRecord version 1: one camera frame, little-endian (firmware/frame_record.h)\n"
    "offset size field\n"
    "0 4 magic \"FVFR\"\n"
    "4 2 version (1)\n"
    "6 2 flags: bit 0 has colour\n"
    "8 4 width, uint32\n"
    "12 4 height, uint32\n"
    "16 8 camera sequence, uint64\n"
    "24 8 capture stamp ns, int64 (the camera's clock)\n"
    "32 32 fx fy cx cy, float64\n"
    "64 8 depth scale, metres per depth unit, float64\n"
    "72 72 R_world_cam row-major, float64\n"
    "144 24 t_world_cam metres, float64\n"
    "168 w*h*2 depth, row-major uint16, 0 = no measurement\n"
    "... w*h*3 colour RGB8 registered to the depth (with flag bit 0)\n";

}  // namespace

std::span<const uint8_t> frameRecordSchemaText() {
  return {reinterpret_cast<const uint8_t*>(kSchemaText), sizeof(kSchemaText) - 1};
}

std::size_t frameRecordBytes(int width, int height, bool has_rgb) {
  const std::size_t pixels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  return kFrameRecordHeaderBytes + pixels * 2 + (has_rgb ? pixels * 3 : 0);
}

void encodeFrameRecordHeader(const hal::RgbdFrame& frame, std::span<uint8_t, kFrameRecordHeaderBytes> out) {
  uint8_t* o = out.data();
  std::memcpy(o, kMagic, 4);
  put<uint16_t>(o, 4, kFrameRecordVersion);
  put<uint16_t>(o, 6, frame.has_rgb ? kFlagHasRgb : 0);
  put<uint32_t>(o, 8, static_cast<uint32_t>(frame.width()));
  put<uint32_t>(o, 12, static_cast<uint32_t>(frame.height()));
  put<uint64_t>(o, 16, frame.sequence);
  put<int64_t>(o, 24, frame.stamp_ns);
  const hal::CameraIntrinsics& k = frame.intrinsics;
  put<double>(o, 32, k.fx);
  put<double>(o, 40, k.fy);
  put<double>(o, 48, k.cx);
  put<double>(o, 56, k.cy);
  put<double>(o, 64, frame.depth_scale_m);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) put<double>(o, 72 + 8 * (3 * r + c), frame.T_world_cam.R_world_cam(r, c));
  }
  for (int i = 0; i < 3; ++i) put<double>(o, 144 + 8 * i, frame.T_world_cam.t_world_cam(i));
}

std::size_t encodeFrameRecord(const hal::RgbdFrame& frame, std::span<uint8_t> out) {
  const std::size_t bytes = frameRecordBytes(frame.width(), frame.height(), frame.has_rgb);
  if (out.size() < bytes) return 0;
  encodeFrameRecordHeader(frame, out.first<kFrameRecordHeaderBytes>());
  uint8_t* o = out.data();
  const std::size_t pixels = frame.pixelCount();
  std::memcpy(o + kFrameRecordHeaderBytes, frame.depth(), pixels * 2);
  if (frame.has_rgb) std::memcpy(o + kFrameRecordHeaderBytes + pixels * 2, frame.rgb(), pixels * 3);
  return bytes;
}

Status decodeFrameRecord(std::span<const uint8_t> record, hal::RgbdFrame& frame) {
  auto bad = [](const std::string& why) { return Status(ErrorCode::kInvalidInput, "frame record: " + why); };
  if (record.size() < kFrameRecordHeaderBytes) {
    return bad(std::to_string(record.size()) + " bytes, shorter than its " +
               std::to_string(kFrameRecordHeaderBytes) + "-byte header");
  }
  const uint8_t* in = record.data();
  if (std::memcmp(in, kMagic, 4) != 0) return bad("no FVFR magic");
  const auto version = get<uint16_t>(in, 4);
  if (version != kFrameRecordVersion) {
    return bad("version " + std::to_string(version) + ", this build reads version " +
               std::to_string(kFrameRecordVersion));
  }
  const auto flags = get<uint16_t>(in, 6);
  if ((flags & ~kFlagHasRgb) != 0) return bad("unknown flags " + std::to_string(flags));
  const auto width = get<uint32_t>(in, 8);
  const auto height = get<uint32_t>(in, 12);
  if (width == 0 || height == 0 || width > 16384 || height > 16384) {
    return bad("size " + std::to_string(width) + "x" + std::to_string(height) + " is no camera's");
  }
  const bool has_rgb = (flags & kFlagHasRgb) != 0;
  const std::size_t expected = frameRecordBytes(static_cast<int>(width), static_cast<int>(height), has_rgb);
  if (record.size() != expected) {
    return bad(std::to_string(record.size()) + " bytes where a " + std::to_string(width) + "x" +
               std::to_string(height) + (has_rgb ? " depth and colour" : " depth") + " frame takes " +
               std::to_string(expected));
  }
  if (!frame.setSize(static_cast<int>(width), static_cast<int>(height))) {
    return bad(std::to_string(width) + "x" + std::to_string(height) + " is larger than the frame slot");
  }
  frame.has_rgb = has_rgb;
  frame.sequence = get<uint64_t>(in, 16);
  frame.stamp_ns = get<int64_t>(in, 24);
  frame.intrinsics.width = static_cast<int>(width);
  frame.intrinsics.height = static_cast<int>(height);
  frame.intrinsics.fx = get<double>(in, 32);
  frame.intrinsics.fy = get<double>(in, 40);
  frame.intrinsics.cx = get<double>(in, 48);
  frame.intrinsics.cy = get<double>(in, 56);
  frame.depth_scale_m = get<double>(in, 64);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) frame.T_world_cam.R_world_cam(r, c) = get<double>(in, 72 + 8 * (3 * r + c));
  }
  for (int i = 0; i < 3; ++i) frame.T_world_cam.t_world_cam(i) = get<double>(in, 144 + 8 * i);
  // What the pipeline would refuse is refused here, with its reason (one check, one place).
  if (Status s = pipeline::validateFrame(frame); !s) return bad(s.message());
  const std::size_t pixels = frame.pixelCount();
  std::memcpy(frame.depth(), in + kFrameRecordHeaderBytes, pixels * 2);
  if (has_rgb) std::memcpy(frame.rgb(), in + kFrameRecordHeaderBytes + pixels * 2, pixels * 3);
  return Status::ok();
}

}  // namespace fovea::firmware

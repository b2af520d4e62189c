// V4L2 pixel formats into what hal::RgbdFrame holds (uint16 depth, RGB8):
// pure functions on caller-owned buffers, no allocation, no I/O.
//
// - Z16 (RealSense) and Y16 (Orbbec and other UVC depth modes, vivid) are both
//   little-endian 16-bit samples, one per pixel; V4L2 defines Y16 as
//   greyscale, but a depth camera that sends Y16 puts its depth units there,
//   so both copy unchanged (depth_scale_m says what a unit is).
// - YUYV (Y0 U Y1 V) and UYVY (U Y0 V Y1): 4:2:2, two pixels share U and V.
//   Converted with BT.601 limited range (Y 16..235, UV 16..240), what UVC
//   cameras send, in integer arithmetic (8-bit fixed point, the coefficients
//   1.164, 1.596, 0.391, 0.813, 2.018 scaled by 256 and rounded):
//     C = Y - 16, D = U - 128, E = V - 128
//     R = clamp((298 C + 409 E + 128) >> 8)
//     G = clamp((298 C - 100 D - 208 E + 128) >> 8)
//     B = clamp((298 C + 516 D + 128) >> 8)
// - RGB3 copies, BGR3 swaps R and B.
// - MJPEG: libturbojpeg into the caller's RGB8 buffer (MjpegDecoder).
// Every function takes the row stride the driver reports (bytesperline) and
// the bytes it filled (bytesused), and returns false, writing nothing, when
// the frame is shorter than its size needs.
#pragma once

#include <cstddef>
#include <cstdint>

#include "core/result.h"

namespace fovea::hal::v4l2 {

// Bytes a packed frame of `height` rows of `row_bytes` at `stride` occupies
// (the last row needs no padding); 0 when stride < row_bytes.
std::size_t packedFrameBytes(std::size_t stride, std::size_t row_bytes, int height);

// Z16 / Y16 -> uint16 depth units.
[[nodiscard]] bool depth16ToDepth(const uint8_t* src, std::size_t bytesused, std::size_t stride, int width,
                                  int height, uint16_t* depth);

// YUYV / UYVY -> RGB8 (width even).
[[nodiscard]] bool yuyvToRgb(const uint8_t* src, std::size_t bytesused, std::size_t stride, int width, int height,
                             uint8_t* rgb);
[[nodiscard]] bool uyvyToRgb(const uint8_t* src, std::size_t bytesused, std::size_t stride, int width, int height,
                             uint8_t* rgb);
// One BT.601 limited-range pixel, the arithmetic above (the reference the tests check).
void yuvToRgbPixel(int y, int u, int v, uint8_t* rgb);

// RGB3 -> RGB8, BGR3 -> RGB8.
[[nodiscard]] bool rgb24ToRgb(const uint8_t* src, std::size_t bytesused, std::size_t stride, int width, int height,
                              uint8_t* rgb);
[[nodiscard]] bool bgr24ToRgb(const uint8_t* src, std::size_t bytesused, std::size_t stride, int width, int height,
                              uint8_t* rgb);

// MJPEG frames into RGB8 through libturbojpeg. The handle is made once
// (create(), at open); decode() checks the header's size against the expected
// one and decodes straight into the caller's buffer. A corrupt, truncated or
// wrongly sized JPEG is a false return, never a crash. libjpeg-turbo takes and
// frees its per-image working memory inside each decode (7 mallocs a frame,
// measured by test_v4l2_pixel_formats, the same every frame, all freed before
// it returns) and TurboJPEG 2.1 offers no allocator hook: fovea's own code
// allocates nothing per frame, libjpeg does. Prefer YUYV where the camera offers it.
class MjpegDecoder {
 public:
  MjpegDecoder() = default;
  ~MjpegDecoder();
  MjpegDecoder(const MjpegDecoder&) = delete;
  MjpegDecoder& operator=(const MjpegDecoder&) = delete;
  MjpegDecoder(MjpegDecoder&& other) noexcept;
  MjpegDecoder& operator=(MjpegDecoder&& other) noexcept;

  // kUnavailable when libturbojpeg cannot make a decompressor.
  Status create();
  bool ready() const { return handle_ != nullptr; }
  [[nodiscard]] bool decode(const uint8_t* jpeg, std::size_t size, int width, int height, uint8_t* rgb);

 private:
  void* handle_ = nullptr;  // tjhandle
};

}  // namespace fovea::hal::v4l2

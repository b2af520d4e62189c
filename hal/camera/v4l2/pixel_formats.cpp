#include "hal/camera/v4l2/pixel_formats.h"

#include <turbojpeg.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <utility>

namespace fovea::hal::v4l2 {

namespace {

uint8_t clampByte(int v) { return static_cast<uint8_t>(std::clamp(v, 0, 255)); }

bool fits(std::size_t bytesused, std::size_t stride, std::size_t row_bytes, int width, int height) {
  if (width <= 0 || height <= 0) return false;
  const std::size_t need = packedFrameBytes(stride, row_bytes, height);
  return need != 0 && bytesused >= need;
}

// 4:2:2 packed, byte offsets of Y0, U, Y1, V within each 4-byte pair.
template <int kY0, int kU, int kY1, int kV>
bool yuv422ToRgb(const uint8_t* src, std::size_t bytesused, std::size_t stride, int width, int height, uint8_t* rgb) {
  if (width % 2 != 0) return false;
  const std::size_t row_bytes = static_cast<std::size_t>(width) * 2;
  if (!fits(bytesused, stride, row_bytes, width, height)) return false;
  for (int y = 0; y < height; ++y) {
    const uint8_t* s = src + static_cast<std::size_t>(y) * stride;
    uint8_t* d = rgb + static_cast<std::size_t>(y) * width * 3;
    for (int x = 0; x < width; x += 2, s += 4, d += 6) {
      yuvToRgbPixel(s[kY0], s[kU], s[kV], d);
      yuvToRgbPixel(s[kY1], s[kU], s[kV], d + 3);
    }
  }
  return true;
}

}  // namespace

std::size_t packedFrameBytes(std::size_t stride, std::size_t row_bytes, int height) {
  if (stride < row_bytes || height <= 0) return 0;
  return stride * static_cast<std::size_t>(height - 1) + row_bytes;
}

bool depth16ToDepth(const uint8_t* src, std::size_t bytesused, std::size_t stride, int width, int height,
                    uint16_t* depth) {
  const std::size_t row_bytes = static_cast<std::size_t>(width) * 2;
  if (!fits(bytesused, stride, row_bytes, width, height)) return false;
  for (int y = 0; y < height; ++y) {
    const uint8_t* s = src + static_cast<std::size_t>(y) * stride;
    uint16_t* d = depth + static_cast<std::size_t>(y) * width;
    if constexpr (std::endian::native == std::endian::little) {
      std::memcpy(d, s, row_bytes);
    } else {
      for (int x = 0; x < width; ++x) d[x] = static_cast<uint16_t>(s[2 * x] | (s[2 * x + 1] << 8));
    }
  }
  return true;
}

void yuvToRgbPixel(int y, int u, int v, uint8_t* rgb) {
  const int c = y - 16;
  const int d = u - 128;
  const int e = v - 128;
  rgb[0] = clampByte((298 * c + 409 * e + 128) >> 8);
  rgb[1] = clampByte((298 * c - 100 * d - 208 * e + 128) >> 8);
  rgb[2] = clampByte((298 * c + 516 * d + 128) >> 8);
}

bool yuyvToRgb(const uint8_t* src, std::size_t bytesused, std::size_t stride, int width, int height, uint8_t* rgb) {
  return yuv422ToRgb<0, 1, 2, 3>(src, bytesused, stride, width, height, rgb);
}

bool uyvyToRgb(const uint8_t* src, std::size_t bytesused, std::size_t stride, int width, int height, uint8_t* rgb) {
  return yuv422ToRgb<1, 0, 3, 2>(src, bytesused, stride, width, height, rgb);
}

bool rgb24ToRgb(const uint8_t* src, std::size_t bytesused, std::size_t stride, int width, int height, uint8_t* rgb) {
  const std::size_t row_bytes = static_cast<std::size_t>(width) * 3;
  if (!fits(bytesused, stride, row_bytes, width, height)) return false;
  for (int y = 0; y < height; ++y) std::memcpy(rgb + y * row_bytes, src + static_cast<std::size_t>(y) * stride, row_bytes);
  return true;
}

bool bgr24ToRgb(const uint8_t* src, std::size_t bytesused, std::size_t stride, int width, int height, uint8_t* rgb) {
  const std::size_t row_bytes = static_cast<std::size_t>(width) * 3;
  if (!fits(bytesused, stride, row_bytes, width, height)) return false;
  for (int y = 0; y < height; ++y) {
    const uint8_t* s = src + static_cast<std::size_t>(y) * stride;
    uint8_t* d = rgb + y * row_bytes;
    for (int x = 0; x < width; ++x, s += 3, d += 3) {
      d[0] = s[2];
      d[1] = s[1];
      d[2] = s[0];
    }
  }
  return true;
}

MjpegDecoder::~MjpegDecoder() {
  if (handle_ != nullptr) tjDestroy(handle_);
}

MjpegDecoder::MjpegDecoder(MjpegDecoder&& other) noexcept : handle_(std::exchange(other.handle_, nullptr)) {}

MjpegDecoder& MjpegDecoder::operator=(MjpegDecoder&& other) noexcept {
  if (this != &other) {
    if (handle_ != nullptr) tjDestroy(handle_);
    handle_ = std::exchange(other.handle_, nullptr);
  }
  return *this;
}

Status MjpegDecoder::create() {
  if (handle_ != nullptr) return Status::ok();
  handle_ = tjInitDecompress();
  if (handle_ == nullptr) {
    return {ErrorCode::kUnavailable, std::string("v4l2: libturbojpeg cannot make a JPEG decompressor: ") +
                                         tjGetErrorStr2(nullptr)};
  }
  return Status::ok();
}

bool MjpegDecoder::decode(const uint8_t* jpeg, std::size_t size, int width, int height, uint8_t* rgb) {
  // The smallest JPEG (SOI, a few segments, EOI) is far above 4 bytes; the
  // check keeps a zero-length buffer away from the library.
  if (handle_ == nullptr || jpeg == nullptr || size < 4 || size > 0x7fffffffu) return false;
  int jpeg_width = 0;
  int jpeg_height = 0;
  int subsampling = 0;
  int colourspace = 0;
  if (tjDecompressHeader3(handle_, jpeg, static_cast<unsigned long>(size), &jpeg_width, &jpeg_height, &subsampling,
                          &colourspace) != 0) {
    return false;
  }
  if (jpeg_width != width || jpeg_height != height) return false;
  // STOPONWARNING: a truncated frame is an error, not a grey-padded image.
  return tjDecompress2(handle_, jpeg, static_cast<unsigned long>(size), rgb, width, width * 3, height, TJPF_RGB,
                       TJFLAG_STOPONWARNING) == 0;
}

}  // namespace fovea::hal::v4l2

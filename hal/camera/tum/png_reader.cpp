#include "hal/camera/tum/png_reader.h"

#include <bit>
#include <cerrno>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <vector>

#include <png.h>

namespace fovea::hal::tum {

namespace {

enum class PngKind { kDepth16, kRgb8 };

// libpng reports errors through a callback that must not return; it longjmps
// back to decodeFile()'s setjmp. Only libpng's C frames lie between the two, so
// no C++ destructor is skipped.
struct ErrorSink {
  char message[160] = {};
};

void onPngError(png_structp png, png_const_charp message) {
  auto* sink = static_cast<ErrorSink*>(png_get_error_ptr(png));
  std::snprintf(sink->message, sizeof sink->message, "%s", message ? message : "unknown libpng error");
  png_longjmp(png, 1);
}

void onPngWarning(png_structp, png_const_charp) {}  // ancillary-chunk CRC and the like: not our business

const char* colorTypeName(int color_type) {
  switch (color_type) {
    case PNG_COLOR_TYPE_GRAY: return "grey";
    case PNG_COLOR_TYPE_GRAY_ALPHA: return "grey+alpha";
    case PNG_COLOR_TYPE_PALETTE: return "palette";
    case PNG_COLOR_TYPE_RGB: return "RGB";
    case PNG_COLOR_TYPE_RGB_ALPHA: return "RGBA";
  }
  return "unknown";
}

// Decodes into out; false with sink.message set on any error. rows must hold
// `height` pointers (allocated by the caller, outside the setjmp scope).
bool decodeFile(std::FILE* file, PngKind kind, int width, int height, uint8_t* out, png_bytep* rows,
                ErrorSink& sink) {
  unsigned char signature[8];
  if (std::fread(signature, 1, sizeof signature, file) != sizeof signature ||
      png_sig_cmp(signature, 0, sizeof signature) != 0) {
    std::snprintf(sink.message, sizeof sink.message, "not a PNG file (bad signature)");
    return false;
  }
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &sink, &onPngError, &onPngWarning);
  if (png == nullptr) {
    std::snprintf(sink.message, sizeof sink.message, "libpng: out of memory");
    return false;
  }
  png_infop info = png_create_info_struct(png);
  if (info == nullptr) {
    png_destroy_read_struct(&png, nullptr, nullptr);
    std::snprintf(sink.message, sizeof sink.message, "libpng: out of memory");
    return false;
  }
  // png and info are not modified after setjmp, so they need not be volatile.
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    return false;
  }
  png_init_io(png, file);
  png_set_sig_bytes(png, sizeof signature);
  png_set_user_limits(png, 16384, 16384);
  png_read_info(png, info);

  const png_uint_32 w = png_get_image_width(png, info);
  const png_uint_32 h = png_get_image_height(png, info);
  const int bit_depth = png_get_bit_depth(png, info);
  const int color_type = png_get_color_type(png, info);
  bool ok = true;
  if (w != static_cast<png_uint_32>(width) || h != static_cast<png_uint_32>(height)) {
    std::snprintf(sink.message, sizeof sink.message, "image is %ux%u, expected %dx%d", static_cast<unsigned>(w),
                  static_cast<unsigned>(h), width, height);
    ok = false;
  } else if (kind == PngKind::kDepth16) {
    if (color_type != PNG_COLOR_TYPE_GRAY || bit_depth != 16) {
      std::snprintf(sink.message, sizeof sink.message,
                    "depth image is %d-bit %s, expected 16-bit grey", bit_depth, colorTypeName(color_type));
      ok = false;
    } else {
      // PNG stores 16-bit samples big-endian.
      if constexpr (std::endian::native == std::endian::little) png_set_swap(png);
    }
  } else {
    if (bit_depth == 16) png_set_strip_16(png);
    if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
    if (color_type == PNG_COLOR_TYPE_GRAY && bit_depth < 8) png_set_expand_gray_1_2_4_to_8(png);
    if (color_type == PNG_COLOR_TYPE_GRAY || color_type == PNG_COLOR_TYPE_GRAY_ALPHA) png_set_gray_to_rgb(png);
    if (color_type & PNG_COLOR_MASK_ALPHA) png_set_strip_alpha(png);
    if (png_get_valid(png, info, PNG_INFO_tRNS)) png_set_strip_alpha(png);
  }
  if (ok) {
    png_set_interlace_handling(png);
    png_read_update_info(png, info);
    const std::size_t row_bytes = png_get_rowbytes(png, info);
    const std::size_t expected = static_cast<std::size_t>(width) * (kind == PngKind::kDepth16 ? 2 : 3);
    if (row_bytes != expected) {
      std::snprintf(sink.message, sizeof sink.message, "decoded row has %zu bytes, expected %zu", row_bytes,
                    expected);
      ok = false;
    } else {
      for (int y = 0; y < height; ++y) rows[y] = out + static_cast<std::size_t>(y) * row_bytes;
      png_read_image(png, rows);
      png_read_end(png, nullptr);
    }
  }
  png_destroy_read_struct(&png, &info, nullptr);
  return ok;
}

Status readPng(const std::string& path, PngKind kind, int width, int height, uint8_t* out) {
  if (width <= 0 || height <= 0) {
    return {ErrorCode::kInvalidArgument, "png: bad expected size for " + path};
  }
  std::FILE* file = std::fopen(path.c_str(), "rb");
  if (file == nullptr) {
    const int err = errno;
    return {err == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIoError,
            "cannot open " + path + ": " + std::strerror(err)};
  }
  std::vector<png_bytep> rows(static_cast<std::size_t>(height));
  ErrorSink sink;
  const bool ok = decodeFile(file, kind, width, height, out, rows.data(), sink);
  std::fclose(file);
  if (!ok) return {ErrorCode::kParseError, path + ": " + sink.message};
  return Status::ok();
}

}  // namespace

Status readDepthPng(const std::string& path, int width, int height, uint16_t* out) {
  return readPng(path, PngKind::kDepth16, width, height, reinterpret_cast<uint8_t*>(out));
}

Status readRgbPng(const std::string& path, int width, int height, uint8_t* out) {
  return readPng(path, PngKind::kRgb8, width, height, out);
}

}  // namespace fovea::hal::tum

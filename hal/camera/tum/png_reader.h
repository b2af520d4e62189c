// PNG decoding for the TUM backend, on libpng's classic API (the simplified
// png_image API treats 16-bit samples as linear light and may convert them;
// depth must come through bit for bit).
//
// libpng allocates internally (its structs, zlib's window, row buffers), so these
// functions run at open() time only; acquire() copies from memory.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "core/result.h"

namespace fovea::hal::tum {

// Decodes a 16-bit greyscale PNG (TUM depth) into out (width * height values,
// host byte order). kParseError naming `path` for a corrupt or truncated file,
// another pixel format, or a size other than width x height; kNotFound /
// kIoError when the file cannot be read.
Status readDepthPng(const std::string& path, int width, int height, uint16_t* out);

// Decodes an 8-bit RGB PNG (also RGBA, palette and grey, converted to RGB8) into
// out (width * height * 3 bytes). Errors as readDepthPng.
Status readRgbPng(const std::string& path, int width, int height, uint8_t* out);

}  // namespace fovea::hal::tum

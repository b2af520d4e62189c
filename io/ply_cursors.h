// The PLY data cursors: BinaryCursor (either byte order) and AsciiCursor (one row
// a line) offer the same operations, so the reader is one template over them.
// On failure they return false and leave the reason in error(). Internal to
// fovea::ply (io/ply_reader.cpp); defined here whole so that the reader's loops
// inline them.
#pragma once

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

#include "io/ply_values.h"

namespace fovea::io::ply_detail {

class BinaryCursor {
 public:
  BinaryCursor(std::string_view bytes, std::size_t pos, bool big_endian)
      : bytes_(bytes), pos_(pos), swap_(big_endian != (std::endian::native == std::endian::big)) {}

  bool beginRow() { return true; }
  bool endRow() { return true; }

  bool readValue(ScalarType type, double* out) {
    const std::size_t n = scalarSize(type);
    if (!have(n, type)) return false;
    unsigned char b[8];
    std::memcpy(b, bytes_.data() + pos_, n);
    if (swap_) std::reverse(b, b + n);
    pos_ += n;
    switch (type) {
      case ScalarType::kInt8: *out = load<int8_t>(b); break;
      case ScalarType::kUint8: *out = load<uint8_t>(b); break;
      case ScalarType::kInt16: *out = load<int16_t>(b); break;
      case ScalarType::kUint16: *out = load<uint16_t>(b); break;
      case ScalarType::kInt32: *out = load<int32_t>(b); break;
      case ScalarType::kUint32: *out = load<uint32_t>(b); break;
      case ScalarType::kFloat32: *out = load<float>(b); break;
      case ScalarType::kFloat64: *out = load<double>(b); break;
    }
    return true;
  }

  bool skipValue(ScalarType type) {
    const std::size_t n = scalarSize(type);
    if (!have(n, type)) return false;
    pos_ += n;
    return true;
  }

  bool skipList(ScalarType count_type, ScalarType item_type) {
    double count = 0.0;
    if (!readValue(count_type, &count)) return false;
    if (count < 0.0) {
      error_ = "negative list count " + std::to_string(static_cast<int64_t>(count)) + " at byte " +
               std::to_string(pos_ - scalarSize(count_type));
      return false;
    }
    const uint64_t items = static_cast<uint64_t>(count);
    const uint64_t item_size = scalarSize(item_type);
    if (items > (bytes_.size() - pos_) / item_size) {
      error_ = "a list of " + std::to_string(items) + " " + scalarName(item_type) + " at byte " +
               std::to_string(pos_) + " runs past the end of the data (" +
               std::to_string(bytes_.size()) + " bytes)";
      return false;
    }
    pos_ += static_cast<std::size_t>(items * item_size);
    return true;
  }

  // Skips `rows` rows of `row_bytes` each (an element without lists).
  bool skipRows(uint64_t rows, uint64_t row_bytes) {
    if (row_bytes != 0 && rows > (bytes_.size() - pos_) / row_bytes) {
      error_ = "the data ends at byte " + std::to_string(bytes_.size());
      return false;
    }
    pos_ += static_cast<std::size_t>(rows * row_bytes);
    return true;
  }

  const std::string& error() const { return error_; }

 private:
  template <typename T>
  static double load(const unsigned char* b) {
    T value;
    std::memcpy(&value, b, sizeof value);
    return static_cast<double>(value);
  }

  bool have(std::size_t n, ScalarType type) {
    if (bytes_.size() - pos_ >= n) return true;
    error_ = std::string("the data ends at byte ") + std::to_string(bytes_.size()) +
             " in the middle of a " + scalarName(type) + " starting at byte " + std::to_string(pos_);
    return false;
  }

  std::string_view bytes_;
  std::size_t pos_;
  bool swap_;
  std::string error_;
};

// Ascii rows are whitespace-separated values, one row per line: a line with too
// few or too many values is an error, which catches headers that disagree with
// their data instead of silently misaligning every later vertex.
class AsciiCursor {
 public:
  AsciiCursor(std::string_view bytes, std::size_t pos, std::size_t line)
      : bytes_(bytes), pos_(pos), line_(line) {}

  bool beginRow() {
    while (pos_ < bytes_.size() && isSpace(bytes_[pos_])) {
      if (bytes_[pos_] == '\n') ++line_;
      ++pos_;
    }
    if (pos_ >= bytes_.size()) {
      error_ = "the data ends before this row";
      return false;
    }
    return true;
  }

  bool endRow() {
    while (pos_ < bytes_.size() && isBlank(bytes_[pos_])) ++pos_;
    if (pos_ >= bytes_.size() || bytes_[pos_] == '\n') return true;
    std::string_view extra;
    nextToken(&extra);
    error_ = "line " + std::to_string(line_) + " has more values than the header declares (" +
             quoted(extra) + ")";
    return false;
  }

  bool readValue(ScalarType type, double* out) {
    std::string_view token;
    if (!nextToken(&token)) return false;
    std::string why;
    if (!parseNumber(token, type, out, &why)) {
      error_ = "line " + std::to_string(line_) + ": " + why;
      return false;
    }
    return true;
  }

  bool skipValue(ScalarType type) {
    double ignored = 0.0;
    return readValue(type, &ignored);
  }

  bool skipList(ScalarType count_type, ScalarType item_type) {
    double count = 0.0;
    if (!readValue(count_type, &count)) return false;
    if (count < 0.0) {
      error_ = "line " + std::to_string(line_) + ": negative list count " +
               std::to_string(static_cast<int64_t>(count));
      return false;
    }
    // Bounded by the line: each item is a token, and a missing one is an error.
    const uint64_t items = static_cast<uint64_t>(count);
    for (uint64_t i = 0; i < items; ++i) {
      if (!skipValue(item_type)) return false;
    }
    return true;
  }

  const std::string& error() const { return error_; }

 private:
  bool nextToken(std::string_view* token) {
    while (pos_ < bytes_.size() && isBlank(bytes_[pos_])) ++pos_;
    if (pos_ >= bytes_.size()) {
      error_ = "the data ends in the middle of this row (line " + std::to_string(line_) + ")";
      return false;
    }
    if (bytes_[pos_] == '\n') {
      error_ = "line " + std::to_string(line_) + " has fewer values than the header declares";
      return false;
    }
    const std::size_t start = pos_;
    while (pos_ < bytes_.size() && !isSpace(bytes_[pos_])) ++pos_;
    *token = bytes_.substr(start, pos_ - start);
    return true;
  }

  std::string_view bytes_;
  std::size_t pos_;
  std::size_t line_;
  std::string error_;
};

}  // namespace fovea::io::ply_detail

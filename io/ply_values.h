// The PLY scalar types and the text helpers the header parser, the data cursors
// and the reader share: type names and sizes, error messages that quote the file
// safely, and the parsing of ascii numbers. Internal to fovea::ply (io/ply*.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "core/result.h"

namespace fovea::io::ply_detail {

enum class ScalarType : uint8_t { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

// Both spellings the PLY world uses: the original names and the sized aliases.
std::optional<ScalarType> scalarTypeFromName(std::string_view name);
// The original name ("uchar", "double", ...), for messages.
const char* scalarName(ScalarType type);

// Inline: the binary cursor calls it for every value it reads.
inline std::size_t scalarSize(ScalarType type) {
  switch (type) {
    case ScalarType::kInt8:
    case ScalarType::kUint8: return 1;
    case ScalarType::kInt16:
    case ScalarType::kUint16: return 2;
    case ScalarType::kInt32:
    case ScalarType::kUint32:
    case ScalarType::kFloat32: return 4;
    case ScalarType::kFloat64: return 8;
  }
  return 1;
}

inline bool isFloating(ScalarType type) {
  return type == ScalarType::kFloat32 || type == ScalarType::kFloat64;
}

Status parseError(std::string message);

// A token from the file, made safe to print: binary garbage becomes '?', and
// long tokens are cut.
std::string quoted(std::string_view token);

std::string headerLine(std::size_t line);

// Inline: the ascii cursor calls them for every character it reads.
inline bool isSpace(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f';
}
// Whitespace that does not end a line.
inline bool isBlank(char c) { return c != '\n' && isSpace(c); }

// A whole token as a non-negative integer (an element's count).
std::optional<uint64_t> parseCount(std::string_view token);

// Parses a whole token as a number of `type`. Integers must fit the type; a
// floating-point value beyond the type's range becomes +-inf (or +-0 when too
// small), so an overflowing coordinate is dropped like any other non-finite one.
bool parseNumber(std::string_view token, ScalarType type, double* out, std::string* error);

}  // namespace fovea::io::ply_detail

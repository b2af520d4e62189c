// The PLY scalar types and the parsing of ascii values (ply_values.h): shared by
// the header parser and the ascii data cursor, so both read numbers alike.
#include "io/ply_values.h"

#include <array>
#include <charconv>
#include <limits>
#include <system_error>
#include <utility>

namespace fovea::io::ply_detail {

namespace {

struct TypeName {
  std::string_view name;
  ScalarType type;
};

// Both spellings the PLY world uses: the original names and the sized aliases.
constexpr std::array<TypeName, 16> kTypeNames = {{
    {"char", ScalarType::kInt8},     {"int8", ScalarType::kInt8},
    {"uchar", ScalarType::kUint8},   {"uint8", ScalarType::kUint8},
    {"short", ScalarType::kInt16},   {"int16", ScalarType::kInt16},
    {"ushort", ScalarType::kUint16}, {"uint16", ScalarType::kUint16},
    {"int", ScalarType::kInt32},     {"int32", ScalarType::kInt32},
    {"uint", ScalarType::kUint32},   {"uint32", ScalarType::kUint32},
    {"float", ScalarType::kFloat32}, {"float32", ScalarType::kFloat32},
    {"double", ScalarType::kFloat64}, {"float64", ScalarType::kFloat64},
}};

// from_chars does not take a leading '+', which some writers emit.
std::string_view stripPlus(std::string_view token) {
  if (token.size() > 1 && token[0] == '+' && token[1] != '+' && token[1] != '-') {
    token.remove_prefix(1);
  }
  return token;
}

// parseNumber for the integer types: the value must fit the type.
bool parseInteger(std::string_view token, ScalarType type, double* out, std::string* error) {
  const char* begin = token.data();
  const char* end = token.data() + token.size();
  int64_t value = 0;
  const auto [stop, ec] = std::from_chars(begin, end, value);
  if (ec == std::errc::result_out_of_range && stop == end) {
    *error = "value " + quoted(token) + " is out of range for " + scalarName(type);
    return false;
  }
  if (ec != std::errc() || stop != end) {
    *error = quoted(token) + " is not an integer (property type " + scalarName(type) + ")";
    return false;
  }
  int64_t lo = 0;
  int64_t hi = 0;
  switch (type) {
    case ScalarType::kInt8: lo = -128; hi = 127; break;
    case ScalarType::kUint8: lo = 0; hi = 255; break;
    case ScalarType::kInt16: lo = -32768; hi = 32767; break;
    case ScalarType::kUint16: lo = 0; hi = 65535; break;
    case ScalarType::kInt32: lo = -2147483648LL; hi = 2147483647LL; break;
    case ScalarType::kUint32: lo = 0; hi = 4294967295LL; break;
    case ScalarType::kFloat32:
    case ScalarType::kFloat64: break;
  }
  if (value < lo || value > hi) {
    *error = "value " + quoted(token) + " is out of range for " + scalarName(type);
    return false;
  }
  *out = static_cast<double>(value);
  return true;
}

// parseNumber for float and double: out of range becomes +-inf or +-0.
bool parseFloating(std::string_view token, ScalarType type, double* out, std::string* error) {
  const char* begin = token.data();
  const char* end = token.data() + token.size();
  std::from_chars_result result{};
  double value = 0.0;
  if (type == ScalarType::kFloat32) {
    // Parsed as float directly, so an ascii file gives the same bits as a binary one.
    float f = 0.0f;
    result = std::from_chars(begin, end, f);
    value = f;
  } else {
    result = std::from_chars(begin, end, value);
  }
  if (result.ptr != end || (result.ec != std::errc() && result.ec != std::errc::result_out_of_range)) {
    *error = quoted(token) + " is not a number (property type " + scalarName(type) + ")";
    return false;
  }
  if (result.ec == std::errc::result_out_of_range) {
    const bool negative = token[0] == '-';
    const std::size_t e = token.find_first_of("eE");
    const bool tiny = e != std::string_view::npos && e + 1 < token.size() && token[e + 1] == '-';
    value = tiny ? 0.0 : std::numeric_limits<double>::infinity();
    if (negative) value = -value;
  }
  *out = value;
  return true;
}

}  // namespace

std::optional<ScalarType> scalarTypeFromName(std::string_view name) {
  for (const TypeName& t : kTypeNames) {
    if (t.name == name) return t.type;
  }
  return std::nullopt;
}

const char* scalarName(ScalarType type) {
  switch (type) {
    case ScalarType::kInt8: return "char";
    case ScalarType::kUint8: return "uchar";
    case ScalarType::kInt16: return "short";
    case ScalarType::kUint16: return "ushort";
    case ScalarType::kInt32: return "int";
    case ScalarType::kUint32: return "uint";
    case ScalarType::kFloat32: return "float";
    case ScalarType::kFloat64: return "double";
  }
  return "?";
}

Status parseError(std::string message) {
  return Status(ErrorCode::kParseError, std::move(message));
}

std::string quoted(std::string_view token) {
  constexpr std::size_t kMaxShown = 40;
  std::string out = "'";
  for (std::size_t i = 0; i < token.size() && i < kMaxShown; ++i) {
    const unsigned char c = static_cast<unsigned char>(token[i]);
    out += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
  }
  if (token.size() > kMaxShown) out += "...";
  out += "'";
  return out;
}

std::string headerLine(std::size_t line) { return "header line " + std::to_string(line) + ": "; }

std::optional<uint64_t> parseCount(std::string_view token) {
  token = stripPlus(token);
  uint64_t value = 0;
  const auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
  if (ec != std::errc() || end != token.data() + token.size()) return std::nullopt;
  return value;
}

bool parseNumber(std::string_view token, ScalarType type, double* out, std::string* error) {
  token = stripPlus(token);
  if (!isFloating(type)) return parseInteger(token, type, out, error);
  return parseFloating(token, type, out, error);
}

}  // namespace fovea::io::ply_detail

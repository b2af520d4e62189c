#include "io/ply.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <optional>
#include <system_error>
#include <type_traits>
#include <utility>

namespace fovea::io {

using pipeline::packRgb;
using pipeline::rgbBlue;
using pipeline::rgbGreen;
using pipeline::rgbRed;

namespace {

// ---------------------------------------------------------------------------
// Types and header model

enum class ScalarType : uint8_t { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

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

std::optional<ScalarType> scalarTypeFromName(std::string_view name) {
  for (const TypeName& t : kTypeNames) {
    if (t.name == name) return t.type;
  }
  return std::nullopt;
}

std::size_t scalarSize(ScalarType type) {
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

bool isFloating(ScalarType type) {
  return type == ScalarType::kFloat32 || type == ScalarType::kFloat64;
}

// What the reader does with a vertex property.
enum class Role : uint8_t { kSkip, kX, kY, kZ, kRed, kGreen, kBlue, kRegion };

struct PropertyDef {
  std::string name;
  ScalarType type = ScalarType::kUint8;        // the item type, for a list
  bool is_list = false;
  ScalarType count_type = ScalarType::kUint8;  // lists only
  std::size_t header_line = 0;
  Role role = Role::kSkip;
};

struct ElementDef {
  std::string name;
  uint64_t count = 0;
  std::size_t header_line = 0;
  std::vector<PropertyDef> properties;
};

struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<ElementDef> elements;
  std::size_t data_offset = 0;   // first byte after the end_header line
  std::size_t line_count = 0;    // lines in the header, end_header included
};

// ---------------------------------------------------------------------------
// Small helpers

Status parseError(std::string message) {
  return Status(ErrorCode::kParseError, std::move(message));
}

// A token from the file, made safe to print: binary garbage becomes '?', and
// long tokens are cut.
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

bool isSpace(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f';
}
// Whitespace that does not end a line.
bool isBlank(char c) { return c != '\n' && isSpace(c); }

std::vector<std::string_view> splitTokens(std::string_view line) {
  std::vector<std::string_view> tokens;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && isSpace(line[i])) ++i;
    const std::size_t start = i;
    while (i < line.size() && !isSpace(line[i])) ++i;
    if (i > start) tokens.push_back(line.substr(start, i - start));
  }
  return tokens;
}

// from_chars does not take a leading '+', which some writers emit.
std::string_view stripPlus(std::string_view token) {
  if (token.size() > 1 && token[0] == '+' && token[1] != '+' && token[1] != '-') {
    token.remove_prefix(1);
  }
  return token;
}

std::optional<uint64_t> parseCount(std::string_view token) {
  token = stripPlus(token);
  uint64_t value = 0;
  const auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
  if (ec != std::errc() || end != token.data() + token.size()) return std::nullopt;
  return value;
}

// Parses a whole token as a number of `type`. Integers must fit the type; a
// floating-point value beyond the type's range becomes +-inf (or +-0 when too
// small), so an overflowing coordinate is dropped like any other non-finite one.
bool parseNumber(std::string_view token, ScalarType type, double* out, std::string* error) {
  token = stripPlus(token);
  const char* begin = token.data();
  const char* end = token.data() + token.size();
  if (!isFloating(type)) {
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

// ---------------------------------------------------------------------------
// Header

Result<PlyHeader> parseHeader(std::string_view bytes) {
  PlyHeader header;
  bool have_format = false;
  std::size_t pos = 0;
  std::size_t line_number = 0;
  while (true) {
    if (pos >= bytes.size()) {
      if (line_number == 0) return parseError("empty input: missing 'ply' magic");
      return parseError(headerLine(line_number) + "the data ends before an 'end_header' line");
    }
    std::size_t eol = bytes.find('\n', pos);
    if (eol == std::string_view::npos) eol = bytes.size();
    std::string_view line = bytes.substr(pos, eol - pos);
    pos = eol < bytes.size() ? eol + 1 : bytes.size();
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);

    if (line_number == 1) {
      if (line != "ply") {
        return parseError(headerLine(1) + "missing 'ply' magic (found " + quoted(line) + "): not a PLY file");
      }
      continue;
    }

    const std::vector<std::string_view> tokens = splitTokens(line);
    if (tokens.empty()) continue;  // tolerated, though the format has no blank lines
    const std::string_view keyword = tokens[0];

    if (keyword == "comment" || keyword == "obj_info") continue;

    if (keyword == "format") {
      if (have_format) return parseError(headerLine(line_number) + "a second 'format' line");
      if (tokens.size() != 3) {
        return parseError(headerLine(line_number) +
                          "expected 'format <ascii|binary_little_endian|binary_big_endian> 1.0'");
      }
      if (tokens[1] == "ascii") {
        header.format = PlyFormat::kAscii;
      } else if (tokens[1] == "binary_little_endian") {
        header.format = PlyFormat::kBinaryLittleEndian;
      } else if (tokens[1] == "binary_big_endian") {
        header.format = PlyFormat::kBinaryBigEndian;
      } else {
        return parseError(headerLine(line_number) + "unknown format " + quoted(tokens[1]) +
                          " (expected ascii, binary_little_endian or binary_big_endian)");
      }
      if (tokens[2] != "1.0") {
        return parseError(headerLine(line_number) + "unsupported PLY version " + quoted(tokens[2]) +
                          " (expected 1.0)");
      }
      have_format = true;
      continue;
    }

    if (keyword == "element") {
      if (tokens.size() != 3) {
        return parseError(headerLine(line_number) + "expected 'element <name> <count>'");
      }
      const std::optional<uint64_t> count = parseCount(tokens[2]);
      if (!count) {
        return parseError(headerLine(line_number) + "element count " + quoted(tokens[2]) +
                          " is not a non-negative integer");
      }
      for (const ElementDef& e : header.elements) {
        if (e.name == tokens[1] && e.name == "vertex") {
          return parseError(headerLine(line_number) + "a second 'vertex' element (the first is on line " +
                            std::to_string(e.header_line) + ")");
        }
      }
      ElementDef element;
      element.name = std::string(tokens[1]);
      element.count = *count;
      element.header_line = line_number;
      header.elements.push_back(std::move(element));
      continue;
    }

    if (keyword == "property") {
      if (header.elements.empty()) {
        return parseError(headerLine(line_number) + "'property' before any 'element'");
      }
      PropertyDef property;
      property.header_line = line_number;
      if (tokens.size() >= 2 && tokens[1] == "list") {
        if (tokens.size() != 5) {
          return parseError(headerLine(line_number) +
                            "expected 'property list <count type> <item type> <name>'");
        }
        const std::optional<ScalarType> count_type = scalarTypeFromName(tokens[2]);
        const std::optional<ScalarType> item_type = scalarTypeFromName(tokens[3]);
        if (!count_type) {
          return parseError(headerLine(line_number) + "unknown type " + quoted(tokens[2]));
        }
        if (!item_type) {
          return parseError(headerLine(line_number) + "unknown type " + quoted(tokens[3]));
        }
        if (isFloating(*count_type)) {
          return parseError(headerLine(line_number) + "list count type " + quoted(tokens[2]) +
                            " is not an integer type");
        }
        property.is_list = true;
        property.count_type = *count_type;
        property.type = *item_type;
        property.name = std::string(tokens[4]);
      } else {
        if (tokens.size() != 3) {
          return parseError(headerLine(line_number) + "expected 'property <type> <name>'");
        }
        const std::optional<ScalarType> type = scalarTypeFromName(tokens[1]);
        if (!type) return parseError(headerLine(line_number) + "unknown type " + quoted(tokens[1]));
        property.type = *type;
        property.name = std::string(tokens[2]);
      }
      header.elements.back().properties.push_back(std::move(property));
      continue;
    }

    if (keyword == "end_header") {
      if (!have_format) return parseError(headerLine(line_number) + "no 'format' line before 'end_header'");
      header.data_offset = pos;
      header.line_count = line_number;
      return header;
    }

    return parseError(headerLine(line_number) + "unknown keyword " + quoted(keyword));
  }
}

// Marks the vertex properties the reader uses. Returns the index of the vertex
// element, or an error when it or its coordinates are missing or unusable.
Result<std::size_t> assignVertexRoles(PlyHeader& header, bool* has_color, bool* has_region,
                                      bool* coords_were_double) {
  std::size_t vertex_index = header.elements.size();
  for (std::size_t i = 0; i < header.elements.size(); ++i) {
    if (header.elements[i].name == "vertex") vertex_index = i;
  }
  if (vertex_index == header.elements.size()) {
    return parseError("header: no 'vertex' element");
  }
  ElementDef& vertex = header.elements[vertex_index];

  constexpr std::array<std::string_view, 3> kAxes = {"x", "y", "z"};
  std::array<PropertyDef*, 3> axis = {nullptr, nullptr, nullptr};
  // red, green, blue: the plain names win over the diffuse_ ones.
  std::array<PropertyDef*, 3> plain = {nullptr, nullptr, nullptr};
  std::array<PropertyDef*, 3> diffuse = {nullptr, nullptr, nullptr};
  constexpr std::array<std::string_view, 3> kPlain = {"red", "green", "blue"};
  constexpr std::array<std::string_view, 3> kDiffuse = {"diffuse_red", "diffuse_green", "diffuse_blue"};
  PropertyDef* region = nullptr;

  for (PropertyDef& p : vertex.properties) {
    for (std::size_t a = 0; a < 3; ++a) {
      if (p.name != kAxes[a]) continue;
      if (axis[a] != nullptr) {
        return parseError(headerLine(p.header_line) + "a second vertex property '" + p.name +
                          "' (the first is on line " + std::to_string(axis[a]->header_line) + ")");
      }
      if (p.is_list || !isFloating(p.type)) {
        return parseError(headerLine(p.header_line) + "vertex property '" + p.name + "' has type " +
                          (p.is_list ? std::string("list") : std::string(scalarName(p.type))) +
                          "; expected float or double");
      }
      axis[a] = &p;
    }
    const bool is_uchar = !p.is_list && p.type == ScalarType::kUint8;
    for (std::size_t c = 0; c < 3; ++c) {
      if (is_uchar && p.name == kPlain[c] && plain[c] == nullptr) plain[c] = &p;
      if (is_uchar && p.name == kDiffuse[c] && diffuse[c] == nullptr) diffuse[c] = &p;
    }
    if (is_uchar && p.name == "region" && region == nullptr) region = &p;
  }

  for (std::size_t a = 0; a < 3; ++a) {
    if (axis[a] == nullptr) {
      return parseError(headerLine(vertex.header_line) + "the vertex element has no property '" +
                        std::string(kAxes[a]) + "'");
    }
  }
  axis[0]->role = Role::kX;
  axis[1]->role = Role::kY;
  axis[2]->role = Role::kZ;
  *coords_were_double = axis[0]->type == ScalarType::kFloat64 ||
                        axis[1]->type == ScalarType::kFloat64 ||
                        axis[2]->type == ScalarType::kFloat64;

  std::array<PropertyDef*, 3> color = {nullptr, nullptr, nullptr};
  for (std::size_t c = 0; c < 3; ++c) color[c] = plain[c] != nullptr ? plain[c] : diffuse[c];
  *has_color = color[0] != nullptr && color[1] != nullptr && color[2] != nullptr;
  if (*has_color) {
    color[0]->role = Role::kRed;
    color[1]->role = Role::kGreen;
    color[2]->role = Role::kBlue;
  }
  *has_region = region != nullptr;
  if (*has_region) region->role = Role::kRegion;
  return vertex_index;
}

// The fewest bytes one row of `element` can take in the data: each binary
// scalar or list count its size; each ascii value a character and a separator.
uint64_t minRowBytes(const ElementDef& element, bool ascii) {
  uint64_t bytes = 0;
  for (const PropertyDef& p : element.properties) {
    bytes += ascii ? 2 : scalarSize(p.is_list ? p.count_type : p.type);
  }
  return bytes;
}

// Rejects counts the data cannot possibly hold, before anything is allocated or
// looped over: elements up to and including the vertex element must fit.
Status checkCounts(const PlyHeader& header, std::size_t vertex_index, std::size_t data_bytes) {
  const bool ascii = header.format == PlyFormat::kAscii;
  // The last ascii value needs no separator after it.
  const uint64_t available = ascii ? uint64_t{data_bytes} + 1 : uint64_t{data_bytes};
  uint64_t needed = 0;
  for (std::size_t i = 0; i <= vertex_index; ++i) {
    const ElementDef& e = header.elements[i];
    const uint64_t row = minRowBytes(e, ascii);
    if (row == 0 || e.count == 0) continue;
    if (e.count > (available - needed) / row) {
      return parseError(headerLine(e.header_line) + "element '" + e.name + "' declares " +
                        std::to_string(e.count) + " rows of at least " + std::to_string(row) +
                        " bytes each, but only " + std::to_string(data_bytes) +
                        " bytes of data follow the header" +
                        (i > 0 ? " (after earlier elements)" : ""));
    }
    needed += e.count * row;
  }
  return Status::ok();
}

// ---------------------------------------------------------------------------
// Data cursors. Both offer the same operations; on failure they return false
// and leave the reason in error().

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

std::string rowName(const ElementDef& element, uint64_t row) {
  const std::string of = std::to_string(row) + " of " + std::to_string(element.count);
  if (element.name == "vertex") return "vertex index " + of;
  return "element '" + element.name + "' row " + of;
}

template <typename Cursor>
Status rowError(const Cursor& cursor, const ElementDef& element, uint64_t row,
                const PropertyDef* property) {
  std::string message = rowName(element, row);
  if (property != nullptr) message += ", property '" + property->name + "'";
  return parseError(message + ": " + cursor.error());
}

template <typename Cursor>
Status skipElement(Cursor& cursor, const ElementDef& element) {
  if (element.properties.empty()) return Status::ok();  // no data at all
  if constexpr (std::is_same_v<Cursor, BinaryCursor>) {
    const bool has_list = std::any_of(element.properties.begin(), element.properties.end(),
                                      [](const PropertyDef& p) { return p.is_list; });
    if (!has_list) {
      if (!cursor.skipRows(element.count, minRowBytes(element, false))) {
        return rowError(cursor, element, 0, nullptr);
      }
      return Status::ok();
    }
  }
  // Every row consumes at least one byte or fails, so this ends within the data.
  for (uint64_t row = 0; row < element.count; ++row) {
    if (!cursor.beginRow()) return rowError(cursor, element, row, nullptr);
    for (const PropertyDef& p : element.properties) {
      const bool ok = p.is_list ? cursor.skipList(p.count_type, p.type) : cursor.skipValue(p.type);
      if (!ok) return rowError(cursor, element, row, &p);
    }
    if (!cursor.endRow()) return rowError(cursor, element, row, nullptr);
  }
  return Status::ok();
}

// The valid vertices in world coordinates, before the origin is chosen.
struct VertexData {
  std::vector<double> xyz;  // 3 per stored point
  std::vector<uint32_t> rgb;
  std::vector<uint8_t> region;
  std::size_t valid = 0;    // finite vertices, stored or not (beyond max_points)
  std::size_t dropped = 0;  // non-finite vertices
};

template <typename Cursor>
Status readVertices(Cursor& cursor, const ElementDef& element, bool has_color, bool has_region,
                    std::size_t max_points, VertexData* out) {
  // checkCounts() has bounded element.count by the data size.
  std::size_t reserve = static_cast<std::size_t>(element.count);
  if (max_points > 0) reserve = std::min(reserve, max_points);
  out->xyz.reserve(3 * reserve);
  if (has_color) out->rgb.reserve(reserve);
  if (has_region) out->region.reserve(reserve);

  for (uint64_t row = 0; row < element.count; ++row) {
    std::array<double, 3> xyz = {0.0, 0.0, 0.0};
    std::array<uint8_t, 3> color = {0, 0, 0};
    uint8_t region = 0;
    if (!cursor.beginRow()) return rowError(cursor, element, row, nullptr);
    for (const PropertyDef& p : element.properties) {
      bool ok = true;
      double value = 0.0;
      switch (p.role) {
        case Role::kSkip:
          ok = p.is_list ? cursor.skipList(p.count_type, p.type) : cursor.skipValue(p.type);
          break;
        case Role::kX: ok = cursor.readValue(p.type, &xyz[0]); break;
        case Role::kY: ok = cursor.readValue(p.type, &xyz[1]); break;
        case Role::kZ: ok = cursor.readValue(p.type, &xyz[2]); break;
        // uchar by construction (assignVertexRoles), so value is in 0..255.
        case Role::kRed:
          ok = cursor.readValue(p.type, &value);
          color[0] = static_cast<uint8_t>(value);
          break;
        case Role::kGreen:
          ok = cursor.readValue(p.type, &value);
          color[1] = static_cast<uint8_t>(value);
          break;
        case Role::kBlue:
          ok = cursor.readValue(p.type, &value);
          color[2] = static_cast<uint8_t>(value);
          break;
        case Role::kRegion:
          ok = cursor.readValue(p.type, &value);
          region = static_cast<uint8_t>(value);
          break;
      }
      if (!ok) return rowError(cursor, element, row, &p);
    }
    if (!cursor.endRow()) return rowError(cursor, element, row, nullptr);

    if (!std::isfinite(xyz[0]) || !std::isfinite(xyz[1]) || !std::isfinite(xyz[2])) {
      ++out->dropped;
      continue;
    }
    ++out->valid;
    if (max_points > 0 && out->valid > max_points) continue;  // counted, not stored
    out->xyz.insert(out->xyz.end(), xyz.begin(), xyz.end());
    if (has_color) out->rgb.push_back(packRgb(color[0], color[1], color[2]));
    if (has_region) out->region.push_back(region);
  }
  return Status::ok();
}

template <typename Cursor>
Status readData(Cursor& cursor, const PlyHeader& header, std::size_t vertex_index, bool has_color,
                bool has_region, std::size_t max_points, VertexData* out) {
  for (std::size_t i = 0; i < vertex_index; ++i) {
    Status skipped = skipElement(cursor, header.elements[i]);
    if (!skipped) return skipped;
  }
  // Elements after the vertex element are not read: a point cloud needs none of them.
  return readVertices(cursor, header.elements[vertex_index], has_color, has_region, max_points, out);
}

// ---------------------------------------------------------------------------
// Writing

template <typename T>
void appendLittleEndian(std::string* out, T value) {
  char b[sizeof(T)];
  std::memcpy(b, &value, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(b, b + sizeof(T));
  out->append(b, sizeof(T));
}

template <typename T>
void appendAscii(std::string* out, T value) {
  // Shortest representation that reads back to the same bits.
  char buf[64];
  const auto [end, ec] = std::to_chars(buf, buf + sizeof buf, value);
  if (ec != std::errc()) {
    out->append("nan");  // cannot happen with a 64-byte buffer
    return;
  }
  out->append(buf, end);
}

}  // namespace

// ---------------------------------------------------------------------------
// Public API

Result<PlyCloud> parsePly(std::string_view bytes, const PlyReadOptions& options) {
  Result<PlyHeader> parsed = parseHeader(bytes);
  if (!parsed) return parsed.status();
  PlyHeader& header = parsed.value();

  PlyCloud cloud;
  cloud.format = header.format;
  Result<std::size_t> vertex_index =
      assignVertexRoles(header, &cloud.has_color, &cloud.has_region, &cloud.coords_were_double);
  if (!vertex_index) return vertex_index.status();
  const ElementDef& vertex = header.elements[*vertex_index];
  cloud.vertex_count_in_file = static_cast<std::size_t>(vertex.count);

  Status counts = checkCounts(header, *vertex_index, bytes.size() - header.data_offset);
  if (!counts) return counts;

  VertexData data;
  Status read;
  if (header.format == PlyFormat::kAscii) {
    AsciiCursor cursor(bytes, header.data_offset, header.line_count + 1);
    read = readData(cursor, header, *vertex_index, cloud.has_color, cloud.has_region,
                    options.max_points, &data);
  } else {
    BinaryCursor cursor(bytes, header.data_offset, header.format == PlyFormat::kBinaryBigEndian);
    read = readData(cursor, header, *vertex_index, cloud.has_color, cloud.has_region,
                    options.max_points, &data);
  }
  if (!read) return read;

  if (options.max_points > 0 && data.valid > options.max_points) {
    return Result<PlyCloud>(ErrorCode::kCapacityExceeded,
                            "the file has " + std::to_string(data.valid) + " valid points (of " +
                                std::to_string(vertex.count) + " vertices), more than max_points = " +
                                std::to_string(options.max_points) +
                                ": raise max_points or downsample the file");
  }
  cloud.dropped_nonfinite = data.dropped;

  // origin_m: the bounding-box centre, rounded to a whole metre.
  const std::size_t n = data.valid;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  if (n > 0) {
    for (int a = 0; a < 3; ++a) {
      double lo = data.xyz[a];
      double hi = data.xyz[a];
      for (std::size_t i = 1; i < n; ++i) {
        lo = std::min(lo, data.xyz[3 * i + a]);
        hi = std::max(hi, data.xyz[3 * i + a]);
      }
      origin[a] = std::round(0.5 * lo + 0.5 * hi);  // halves first: no overflow
    }
  }

  PointCloud points(n);
  if (!points.resize(n)) {
    return Result<PlyCloud>(ErrorCode::kCapacityExceeded, "internal: point cloud capacity");
  }
  points.origin_m = origin;
  points.has_color = cloud.has_color;
  for (std::size_t i = 0; i < n; ++i) {
    const float x = static_cast<float>(data.xyz[3 * i + 0] - origin.x());
    const float y = static_cast<float>(data.xyz[3 * i + 1] - origin.y());
    const float z = static_cast<float>(data.xyz[3 * i + 2] - origin.z());
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
      return Result<PlyCloud>(
          ErrorCode::kRangeExceeded,
          "a vertex at (" + std::to_string(data.xyz[3 * i]) + ", " + std::to_string(data.xyz[3 * i + 1]) +
              ", " + std::to_string(data.xyz[3 * i + 2]) + ") is too far from the centre of the cloud (" +
              std::to_string(origin.x()) + ", " + std::to_string(origin.y()) + ", " +
              std::to_string(origin.z()) + ") to store as a float: the cloud spans more than 3.4e38 m");
    }
    points.x()[i] = x;
    points.y()[i] = y;
    points.z()[i] = z;
    points.rgb()[i] = cloud.has_color ? data.rgb[i] : 0u;
  }
  cloud.points = std::move(points);
  if (cloud.has_region) cloud.region = std::move(data.region);
  return cloud;
}

Result<PlyCloud> readPly(const std::string& path, const PlyReadOptions& options) {
  std::FILE* file = std::fopen(path.c_str(), "rb");
  if (file == nullptr) {
    const int err = errno;
    const ErrorCode code = (err == ENOENT || err == ENOTDIR) ? ErrorCode::kNotFound : ErrorCode::kIoError;
    return Result<PlyCloud>(code, "cannot open PLY file '" + path + "': " + std::strerror(err));
  }
  std::string bytes;
  std::string chunk(std::size_t{1} << 16, '\0');
  std::size_t got = 0;
  while ((got = std::fread(chunk.data(), 1, chunk.size(), file)) > 0) bytes.append(chunk.data(), got);
  const bool failed = std::ferror(file) != 0;
  const int err = errno;
  std::fclose(file);
  if (failed) {
    return Result<PlyCloud>(ErrorCode::kIoError,
                            "cannot read PLY file '" + path + "': " + std::strerror(err));
  }
  Result<PlyCloud> result = parsePly(bytes, options);
  if (!result) {
    return Result<PlyCloud>(result.status().code(), "PLY file '" + path + "': " + result.status().message());
  }
  return result;
}

std::string serializePly(const PointCloud& cloud, const uint8_t* region, const PlyWriteOptions& options) {
  const bool color = options.write_color && cloud.has_color;
  const std::size_t n = cloud.size();
  const char* coord_type = options.double_coords ? "double" : "float";

  std::string out;
  out += "ply\n";
  out += options.binary ? "format binary_little_endian 1.0\n" : "format ascii 1.0\n";
  out += "comment generated by fovea\n";
  out += "element vertex " + std::to_string(n) + "\n";
  for (const char* axis : {"x", "y", "z"}) out += std::string("property ") + coord_type + " " + axis + "\n";
  if (color) out += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  if (region != nullptr) out += "property uchar region\n";
  out += "end_header\n";

  const std::size_t row_bytes = options.binary
      ? (options.double_coords ? 24 : 12) + (color ? 3 : 0) + (region != nullptr ? 1 : 0)
      : (options.double_coords ? 75 : 45) + (color ? 12 : 0) + (region != nullptr ? 4 : 0);
  out.reserve(out.size() + n * row_bytes);

  const Eigen::Vector3d& origin = cloud.origin_m;
  for (std::size_t i = 0; i < n; ++i) {
    // World coordinates, summed in double.
    const std::array<double, 3> world = {origin.x() + static_cast<double>(cloud.x()[i]),
                                         origin.y() + static_cast<double>(cloud.y()[i]),
                                         origin.z() + static_cast<double>(cloud.z()[i])};
    const uint32_t rgb = cloud.rgb()[i];
    const std::array<uint8_t, 3> channels = {rgbRed(rgb), rgbGreen(rgb), rgbBlue(rgb)};
    if (options.binary) {
      for (double w : world) {
        if (options.double_coords) {
          appendLittleEndian(&out, w);
        } else {
          appendLittleEndian(&out, static_cast<float>(w));
        }
      }
      if (color) {
        for (uint8_t c : channels) out.push_back(static_cast<char>(c));
      }
      if (region != nullptr) out.push_back(static_cast<char>(region[i]));
    } else {
      for (std::size_t a = 0; a < 3; ++a) {
        if (a > 0) out.push_back(' ');
        if (options.double_coords) {
          appendAscii(&out, world[a]);
        } else {
          appendAscii(&out, static_cast<float>(world[a]));
        }
      }
      if (color) {
        for (uint8_t c : channels) {
          out.push_back(' ');
          appendAscii(&out, static_cast<unsigned>(c));
        }
      }
      if (region != nullptr) {
        out.push_back(' ');
        appendAscii(&out, static_cast<unsigned>(region[i]));
      }
      out.push_back('\n');
    }
  }
  return out;
}

namespace {

// Writes bytes beside path and renames them over it, so no reader sees half a file.
Status writeFileAtomically(const std::string& path, const std::string& bytes) {
  if (path.empty()) return Status(ErrorCode::kIoError, "cannot write PLY file: the path is empty");
  const std::string tmp_path = path + ".tmp";
  std::FILE* file = std::fopen(tmp_path.c_str(), "wb");
  if (file == nullptr) {
    const int err = errno;
    return Status(ErrorCode::kIoError, "cannot write PLY file '" + path + "': cannot create '" +
                                           tmp_path + "': " + std::strerror(err));
  }
  int err = 0;
  const std::size_t written = std::fwrite(bytes.data(), 1, bytes.size(), file);
  if (written != bytes.size()) err = errno != 0 ? errno : EIO;
  if (std::fflush(file) != 0 && err == 0) err = errno;
  if (std::fclose(file) != 0 && err == 0) err = errno;
  if (err != 0) {
    std::remove(tmp_path.c_str());
    return Status(ErrorCode::kIoError,
                  "cannot write PLY file '" + tmp_path + "': " + std::strerror(err));
  }
  std::error_code ec;
  std::filesystem::rename(tmp_path, path, ec);
  if (ec) {
    std::remove(tmp_path.c_str());
    return Status(ErrorCode::kIoError, "cannot write PLY file '" + path + "': renaming '" + tmp_path +
                                           "' failed: " + ec.message());
  }
  return Status::ok();
}

}  // namespace

Status writePly(const std::string& path, const PointCloud& cloud, const uint8_t* region,
                const PlyWriteOptions& options) {
  return writeFileAtomically(path, serializePly(cloud, region, options));
}

std::string serializeSurfelPly(const pipeline::map::SurfelMap& map, bool stable_only) {
  using pipeline::map::kSurfelStable;
  std::size_t n = 0;
  for (std::size_t slot = 0; slot < map.slotCount(); ++slot) {
    n += map.live(slot) && (!stable_only || (map.surfel(slot).flags & kSurfelStable));
  }
  std::string out;
  out += "ply\nformat binary_little_endian 1.0\ncomment generated by fovea: a surfel map\n";
  out += "element vertex " + std::to_string(n) + "\n";
  out += "property double x\nproperty double y\nproperty double z\n";
  out += "property float nx\nproperty float ny\nproperty float nz\n";
  out += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  out += "property float radius\nproperty float confidence\nend_header\n";
  out.reserve(out.size() + n * 47);
  for (std::size_t slot = 0; slot < map.slotCount(); ++slot) {
    if (!map.live(slot)) continue;
    const pipeline::map::Surfel& s = map.surfel(slot);
    if (stable_only && !(s.flags & kSurfelStable)) continue;
    const Eigen::Vector3d p = map.worldPosition(slot);
    for (int a = 0; a < 3; ++a) appendLittleEndian(&out, p[a]);
    const Eigen::Vector3f normal = pipeline::map::surfelNormal(s);
    for (int a = 0; a < 3; ++a) appendLittleEndian(&out, normal[a]);
    for (uint8_t c : {s.red, s.green, s.blue}) out.push_back(static_cast<char>(c));
    appendLittleEndian(&out, pipeline::map::surfelRadius(s));
    appendLittleEndian(&out, pipeline::map::decodeConfidence(s.confidence));
  }
  return out;
}

Status writeSurfelPly(const std::string& path, const pipeline::map::SurfelMap& map, bool stable_only) {
  return writeFileAtomically(path, serializeSurfelPly(map, stable_only));
}

}  // namespace fovea::io

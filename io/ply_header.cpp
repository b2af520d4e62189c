// The PLY header parser (ply_header.h): the header read line by line, one named
// step per keyword, then the reader's checks of the vertex element and the counts.
#include "io/ply_header.h"

#include <array>
#include <optional>
#include <utility>

namespace fovea::io::ply_detail {

namespace {

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

// The line that starts at *pos, without its '\n' or "\r\n"; moves *pos past it.
std::string_view nextHeaderLine(std::string_view bytes, std::size_t* pos) {
  std::size_t eol = bytes.find('\n', *pos);
  if (eol == std::string_view::npos) eol = bytes.size();
  std::string_view line = bytes.substr(*pos, eol - *pos);
  *pos = eol < bytes.size() ? eol + 1 : bytes.size();
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  return line;
}

// `format <ascii|binary_little_endian|binary_big_endian> 1.0`, once.
Status parseFormatLine(const std::vector<std::string_view>& tokens, std::size_t line_number,
                       bool* have_format, PlyFormat* format) {
  if (*have_format) return parseError(headerLine(line_number) + "a second 'format' line");
  if (tokens.size() != 3) {
    return parseError(headerLine(line_number) +
                      "expected 'format <ascii|binary_little_endian|binary_big_endian> 1.0'");
  }
  if (tokens[1] == "ascii") {
    *format = PlyFormat::kAscii;
  } else if (tokens[1] == "binary_little_endian") {
    *format = PlyFormat::kBinaryLittleEndian;
  } else if (tokens[1] == "binary_big_endian") {
    *format = PlyFormat::kBinaryBigEndian;
  } else {
    return parseError(headerLine(line_number) + "unknown format " + quoted(tokens[1]) +
                      " (expected ascii, binary_little_endian or binary_big_endian)");
  }
  if (tokens[2] != "1.0") {
    return parseError(headerLine(line_number) + "unsupported PLY version " + quoted(tokens[2]) +
                      " (expected 1.0)");
  }
  *have_format = true;
  return Status::ok();
}

// `element <name> <count>`: a new element, at most one of them 'vertex'.
Status parseElementLine(const std::vector<std::string_view>& tokens, std::size_t line_number,
                        std::vector<ElementDef>* elements) {
  if (tokens.size() != 3) {
    return parseError(headerLine(line_number) + "expected 'element <name> <count>'");
  }
  const std::optional<uint64_t> count = parseCount(tokens[2]);
  if (!count) {
    return parseError(headerLine(line_number) + "element count " + quoted(tokens[2]) +
                      " is not a non-negative integer");
  }
  for (const ElementDef& e : *elements) {
    if (e.name == tokens[1] && e.name == "vertex") {
      return parseError(headerLine(line_number) + "a second 'vertex' element (the first is on line " +
                        std::to_string(e.header_line) + ")");
    }
  }
  ElementDef element;
  element.name = std::string(tokens[1]);
  element.count = *count;
  element.header_line = line_number;
  elements->push_back(std::move(element));
  return Status::ok();
}

// `property list <count type> <item type> <name>` into *property.
Status parseListProperty(const std::vector<std::string_view>& tokens, std::size_t line_number,
                         PropertyDef* property) {
  if (tokens.size() != 5) {
    return parseError(headerLine(line_number) + "expected 'property list <count type> <item type> <name>'");
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
  property->is_list = true;
  property->count_type = *count_type;
  property->type = *item_type;
  property->name = std::string(tokens[4]);
  return Status::ok();
}

// `property <type> <name>` into *property.
Status parseScalarProperty(const std::vector<std::string_view>& tokens, std::size_t line_number,
                           PropertyDef* property) {
  if (tokens.size() != 3) {
    return parseError(headerLine(line_number) + "expected 'property <type> <name>'");
  }
  const std::optional<ScalarType> type = scalarTypeFromName(tokens[1]);
  if (!type) return parseError(headerLine(line_number) + "unknown type " + quoted(tokens[1]));
  property->type = *type;
  property->name = std::string(tokens[2]);
  return Status::ok();
}

// A `property` line: a property of the last element declared.
Status parsePropertyLine(const std::vector<std::string_view>& tokens, std::size_t line_number,
                         std::vector<ElementDef>* elements) {
  if (elements->empty()) {
    return parseError(headerLine(line_number) + "'property' before any 'element'");
  }
  PropertyDef property;
  property.header_line = line_number;
  const bool is_list = tokens.size() >= 2 && tokens[1] == "list";
  Status parsed = is_list ? parseListProperty(tokens, line_number, &property)
                          : parseScalarProperty(tokens, line_number, &property);
  if (!parsed) return parsed;
  elements->back().properties.push_back(std::move(property));
  return Status::ok();
}

}  // namespace

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
    const std::string_view line = nextHeaderLine(bytes, &pos);
    ++line_number;

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

    if (keyword == "end_header") {
      if (!have_format) return parseError(headerLine(line_number) + "no 'format' line before 'end_header'");
      header.data_offset = pos;
      header.line_count = line_number;
      return header;
    }

    Status parsed;
    if (keyword == "format") {
      parsed = parseFormatLine(tokens, line_number, &have_format, &header.format);
    } else if (keyword == "element") {
      parsed = parseElementLine(tokens, line_number, &header.elements);
    } else if (keyword == "property") {
      parsed = parsePropertyLine(tokens, line_number, &header.elements);
    } else {
      return parseError(headerLine(line_number) + "unknown keyword " + quoted(keyword));
    }
    if (!parsed) return parsed;
  }
}

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

uint64_t minRowBytes(const ElementDef& element, bool ascii) {
  uint64_t bytes = 0;
  for (const PropertyDef& p : element.properties) {
    bytes += ascii ? 2 : scalarSize(p.is_list ? p.count_type : p.type);
  }
  return bytes;
}

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

}  // namespace fovea::io::ply_detail

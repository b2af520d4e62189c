// The PLY header: its model (elements and their properties), its parser, and the
// checks the reader makes on it before it touches the data (which vertex
// properties it reads, and whether the declared counts can fit the data).
// Internal to fovea::ply (io/ply*.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.h"
#include "io/ply.h"
#include "io/ply_values.h"

namespace fovea::io::ply_detail {

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

// The header at the start of bytes, up to and including its end_header line.
Result<PlyHeader> parseHeader(std::string_view bytes);

// Marks the vertex properties the reader uses. Returns the index of the vertex
// element, or an error when it or its coordinates are missing or unusable.
Result<std::size_t> assignVertexRoles(PlyHeader& header, bool* has_color, bool* has_region,
                                      bool* coords_were_double);

// The fewest bytes one row of `element` can take in the data: each binary
// scalar or list count its size; each ascii value a character and a separator.
uint64_t minRowBytes(const ElementDef& element, bool ascii);

// Rejects counts the data cannot possibly hold, before anything is allocated or
// looped over: elements up to and including the vertex element must fit.
Status checkCounts(const PlyHeader& header, std::size_t vertex_index, std::size_t data_bytes);

}  // namespace fovea::io::ply_detail

// The PLY reader: parsePly and readPly (ply.h). The header is parsed and checked
// first (ply_header.h); then the elements before the vertex element are skipped and
// the vertices read through a data cursor (ply_cursors.h), and the valid ones
// stored relative to the cloud's centre.
#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <type_traits>
#include <utility>

#include "io/ply.h"
#include "io/ply_cursors.h"
#include "io/ply_header.h"

namespace fovea::io {

using pipeline::packRgb;

namespace ply_detail {
namespace {

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

// The vertices of the file through the cursor its format needs.
Status readVertexData(std::string_view bytes, const PlyHeader& header, std::size_t vertex_index,
                      const PlyCloud& cloud, std::size_t max_points, VertexData* data) {
  if (header.format == PlyFormat::kAscii) {
    AsciiCursor cursor(bytes, header.data_offset, header.line_count + 1);
    return readData(cursor, header, vertex_index, cloud.has_color, cloud.has_region, max_points, data);
  }
  BinaryCursor cursor(bytes, header.data_offset, header.format == PlyFormat::kBinaryBigEndian);
  return readData(cursor, header, vertex_index, cloud.has_color, cloud.has_region, max_points, data);
}

// origin_m: the bounding-box centre of the n stored points, rounded to a whole metre.
Eigen::Vector3d boundingBoxOrigin(const VertexData& data, std::size_t n) {
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
  return origin;
}

// The n stored points as floats relative to origin, into cloud->points.
Status storePoints(const VertexData& data, std::size_t n, const Eigen::Vector3d& origin, PlyCloud* cloud) {
  PointCloud points(n);
  if (!points.resize(n)) {
    return Status(ErrorCode::kCapacityExceeded, "internal: point cloud capacity");
  }
  points.origin_m = origin;
  points.has_color = cloud->has_color;
  for (std::size_t i = 0; i < n; ++i) {
    const float x = static_cast<float>(data.xyz[3 * i + 0] - origin.x());
    const float y = static_cast<float>(data.xyz[3 * i + 1] - origin.y());
    const float z = static_cast<float>(data.xyz[3 * i + 2] - origin.z());
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
      return Status(
          ErrorCode::kRangeExceeded,
          "a vertex at (" + std::to_string(data.xyz[3 * i]) + ", " + std::to_string(data.xyz[3 * i + 1]) +
              ", " + std::to_string(data.xyz[3 * i + 2]) + ") is too far from the centre of the cloud (" +
              std::to_string(origin.x()) + ", " + std::to_string(origin.y()) + ", " +
              std::to_string(origin.z()) + ") to store as a float: the cloud spans more than 3.4e38 m");
    }
    points.x()[i] = x;
    points.y()[i] = y;
    points.z()[i] = z;
    points.rgb()[i] = cloud->has_color ? data.rgb[i] : 0u;
  }
  cloud->points = std::move(points);
  return Status::ok();
}

}  // namespace
}  // namespace ply_detail

Result<PlyCloud> parsePly(std::string_view bytes, const PlyReadOptions& options) {
  Result<ply_detail::PlyHeader> parsed = ply_detail::parseHeader(bytes);
  if (!parsed) return parsed.status();
  ply_detail::PlyHeader& header = parsed.value();

  PlyCloud cloud;
  cloud.format = header.format;
  Result<std::size_t> vertex_index =
      ply_detail::assignVertexRoles(header, &cloud.has_color, &cloud.has_region, &cloud.coords_were_double);
  if (!vertex_index) return vertex_index.status();
  const ply_detail::ElementDef& vertex = header.elements[*vertex_index];
  cloud.vertex_count_in_file = static_cast<std::size_t>(vertex.count);

  Status counts = ply_detail::checkCounts(header, *vertex_index, bytes.size() - header.data_offset);
  if (!counts) return counts;

  ply_detail::VertexData data;
  Status read = ply_detail::readVertexData(bytes, header, *vertex_index, cloud, options.max_points, &data);
  if (!read) return read;

  if (options.max_points > 0 && data.valid > options.max_points) {
    return Result<PlyCloud>(ErrorCode::kCapacityExceeded,
                            "the file has " + std::to_string(data.valid) + " valid points (of " +
                                std::to_string(vertex.count) + " vertices), more than max_points = " +
                                std::to_string(options.max_points) +
                                ": raise max_points or downsample the file");
  }
  cloud.dropped_nonfinite = data.dropped;

  const std::size_t n = data.valid;
  Status stored = ply_detail::storePoints(data, n, ply_detail::boundingBoxOrigin(data, n), &cloud);
  if (!stored) return stored;
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

}  // namespace fovea::io

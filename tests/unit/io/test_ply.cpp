// PLY reading and writing: hand-written files parsed to exact values, round trips
// in every format, far-from-origin precision, and malformed input of every kind
// (including every truncation of a valid file and random byte corruption).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include <unistd.h>

#include <gtest/gtest.h>

#include "io/ply.h"

namespace fovea::io {
namespace {

using pipeline::packRgb;

// --- byte builders with explicit byte order (independent of the host's) -------

void putBits(std::string& out, uint64_t bits, int bytes, bool big_endian) {
  for (int i = 0; i < bytes; ++i) {
    const int shift = 8 * (big_endian ? bytes - 1 - i : i);
    out.push_back(static_cast<char>((bits >> shift) & 0xff));
  }
}
void putFloat(std::string& out, float f, bool big_endian) {
  uint32_t bits = 0;
  std::memcpy(&bits, &f, 4);
  putBits(out, bits, 4, big_endian);
}
void putDouble(std::string& out, double d, bool big_endian) {
  uint64_t bits = 0;
  std::memcpy(&bits, &d, 8);
  putBits(out, bits, 8, big_endian);
}
void putU8(std::string& out, uint8_t v) { out.push_back(static_cast<char>(v)); }

PointCloud makeCloud(std::size_t n, const Eigen::Vector3d& origin, uint32_t seed, float half_extent_m = 2.0f) {
  PointCloud cloud(n);
  cloud.origin_m = origin;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> coord(-half_extent_m, half_extent_m);
  std::uniform_int_distribution<uint32_t> color(0, 0xffffff);
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_TRUE(cloud.push(coord(rng), coord(rng), coord(rng), color(rng)));
  }
  return cloud;
}

std::vector<uint8_t> makeRegions(std::size_t n) {
  std::vector<uint8_t> region(n);
  for (std::size_t i = 0; i < n; ++i) region[i] = static_cast<uint8_t>((i * 37 + 5) % 256);
  return region;
}

PlyCloud parseOk(std::string_view bytes, const PlyReadOptions& options = {}) {
  Result<PlyCloud> result = parsePly(bytes, options);
  EXPECT_TRUE(result.isOk()) << result.status().toString();
  if (!result.isOk()) return PlyCloud{};
  return std::move(result).value();
}

// Expects kParseError and returns the message.
std::string parseFails(std::string_view bytes) {
  Result<PlyCloud> result = parsePly(bytes);
  EXPECT_FALSE(result.isOk()) << "parsed a malformed file";
  if (result.isOk()) return "";
  EXPECT_EQ(result.status().code(), ErrorCode::kParseError) << result.status().toString();
  return result.status().message();
}

// Every stored point of a successful parse is finite and consistent.
void expectSane(const PlyCloud& cloud) {
  ASSERT_EQ(cloud.points.size(), cloud.points.capacity());
  ASSERT_LE(cloud.points.size() + cloud.dropped_nonfinite, cloud.vertex_count_in_file);
  if (cloud.has_region) {
    ASSERT_EQ(cloud.region.size(), cloud.points.size());
  }
  for (std::size_t i = 0; i < cloud.points.size(); ++i) {
    ASSERT_TRUE(std::isfinite(cloud.points.x()[i]));
    ASSERT_TRUE(std::isfinite(cloud.points.y()[i]));
    ASSERT_TRUE(std::isfinite(cloud.points.z()[i]));
  }
}

// --- hand-written files ---------------------------------------------------------

TEST(PlyRead, HandWrittenAsciiParsesToExactValues) {
  const std::string text =
      "ply\n"
      "format ascii 1.0\n"
      "comment made by hand\n"
      "obj_info a test object\n"
      "element vertex 3\n"
      "property float x\n"
      "property float y\n"
      "property float z\n"
      "property uchar red\n"
      "property uchar green\n"
      "property uchar blue\n"
      "end_header\n"
      "1.5 2.25 -3 255 0 16\n"
      "0.5 0.25 1.0 1 2 3\n"
      "1 1 0 10 20 30\n";
  const PlyCloud cloud = parseOk(text);
  EXPECT_EQ(cloud.format, PlyFormat::kAscii);
  EXPECT_EQ(cloud.vertex_count_in_file, 3u);
  EXPECT_EQ(cloud.dropped_nonfinite, 0u);
  EXPECT_TRUE(cloud.has_color);
  EXPECT_TRUE(cloud.points.has_color);
  EXPECT_FALSE(cloud.coords_were_double);
  EXPECT_FALSE(cloud.has_region);
  ASSERT_EQ(cloud.points.size(), 3u);
  // Bounding box x [0.5, 1.5], y [0.25, 2.25], z [-3, 1]: centres 1, 1.25, -1,
  // rounded to whole metres: (1, 1, -1).
  EXPECT_EQ(cloud.points.origin_m, Eigen::Vector3d(1.0, 1.0, -1.0));
  const float ex[] = {0.5f, -0.5f, 0.0f};
  const float ey[] = {1.25f, -0.75f, 0.0f};
  const float ez[] = {-2.0f, 2.0f, 1.0f};
  const uint32_t ergb[] = {0xff0010u, 0x010203u, 0x0a141eu};
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(cloud.points.x()[i], ex[i]) << i;
    EXPECT_EQ(cloud.points.y()[i], ey[i]) << i;
    EXPECT_EQ(cloud.points.z()[i], ez[i]) << i;
    EXPECT_EQ(cloud.points.rgb()[i], ergb[i]) << i;
  }
  EXPECT_EQ(cloud.points.world(0), Eigen::Vector3d(1.5, 2.25, -3.0));
}

TEST(PlyRead, AsciiWithCrLfAndDiffuseColourAndPlusSigns) {
  const std::string text =
      "ply\r\n"
      "format ascii 1.0\r\n"
      "element vertex 2\r\n"
      "property double x\r\n"
      "property double y\r\n"
      "property double z\r\n"
      "property uchar diffuse_red\r\n"
      "property uchar diffuse_green\r\n"
      "property uchar diffuse_blue\r\n"
      "end_header\r\n"
      "+1 -2 3e0 7 8 9\r\n"
      "\r\n"
      "3 -4 5 100 101 102\r\n";
  const PlyCloud cloud = parseOk(text);
  ASSERT_EQ(cloud.points.size(), 2u);
  EXPECT_TRUE(cloud.coords_were_double);
  EXPECT_TRUE(cloud.has_color);
  EXPECT_EQ(cloud.points.origin_m, Eigen::Vector3d(2.0, -3.0, 4.0));
  EXPECT_EQ(cloud.points.world(0), Eigen::Vector3d(1.0, -2.0, 3.0));
  EXPECT_EQ(cloud.points.world(1), Eigen::Vector3d(3.0, -4.0, 5.0));
  EXPECT_EQ(cloud.points.rgb()[0], packRgb(7, 8, 9));
  EXPECT_EQ(cloud.points.rgb()[1], packRgb(100, 101, 102));
}

TEST(PlyRead, NoColourGivesZeroRgbAndHasColorFalse) {
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 1\n"
      "property float x\nproperty float y\nproperty float z\nproperty uchar red\n"  // red alone
      "end_header\n"
      "1 2 3 200\n";
  const PlyCloud cloud = parseOk(text);
  ASSERT_EQ(cloud.points.size(), 1u);
  EXPECT_FALSE(cloud.has_color);
  EXPECT_FALSE(cloud.points.has_color);
  EXPECT_EQ(cloud.points.rgb()[0], 0u);
  EXPECT_EQ(cloud.points.world(0), Eigen::Vector3d(1.0, 2.0, 3.0));
}

TEST(PlyRead, InterleavedPropertiesAndFaceAfterVertexAscii) {
  const std::string text =
      "ply\n"
      "format ascii 1.0\n"
      "element vertex 3\n"
      "property int32 label\n"
      "property float z\n"
      "property list uchar int neighbours\n"
      "property double x\n"
      "property uint16 intensity\n"
      "property uchar blue\n"
      "property float y\n"
      "property char tag\n"
      "property uchar green\n"
      "property uchar red\n"
      "property float64 confidence\n"
      "element face 2\n"
      "property list uchar int vertex_indices\n"
      "end_header\n"
      "-7 3.5 2 1 2 10.25 65535 1 -1 -128 2 3 0.5\n"
      "2147483647 4.5 0 11.25 0 4 -2 127 5 6 1e-3\n"
      "0 5.5 3 0 1 2 12.25 7 7 -3 0 8 9 -0\n"
      "3 0 1 2\n"
      "3 2 1 0\n";
  const PlyCloud cloud = parseOk(text);
  ASSERT_EQ(cloud.points.size(), 3u);
  EXPECT_EQ(cloud.vertex_count_in_file, 3u);
  EXPECT_TRUE(cloud.has_color);
  EXPECT_TRUE(cloud.coords_were_double);  // x is double
  EXPECT_EQ(cloud.points.world(0), Eigen::Vector3d(10.25, -1.0, 3.5));
  EXPECT_EQ(cloud.points.world(1), Eigen::Vector3d(11.25, -2.0, 4.5));
  EXPECT_EQ(cloud.points.world(2), Eigen::Vector3d(12.25, -3.0, 5.5));
  EXPECT_EQ(cloud.points.rgb()[0], packRgb(3, 2, 1));
  EXPECT_EQ(cloud.points.rgb()[1], packRgb(6, 5, 4));
  EXPECT_EQ(cloud.points.rgb()[2], packRgb(9, 8, 7));
}

TEST(PlyRead, BigEndianBinaryBuiltByHand) {
  std::string bytes =
      "ply\n"
      "format binary_big_endian 1.0\n"
      "comment hand-built big-endian file\n"
      "element vertex 2\n"
      "property uchar flags\n"
      "property double x\n"
      "property int16 s\n"
      "property float y\n"
      "property list uchar int extra\n"
      "property float z\n"
      "property uchar red\n"
      "property uchar green\n"
      "property uchar blue\n"
      "element face 1\n"
      "property list uchar uint vertex_indices\n"
      "end_header\n";
  const bool be = true;
  // vertex 0
  putU8(bytes, 0xAA);
  putDouble(bytes, 10000.125, be);
  putBits(bytes, 0x1234, 2, be);
  putFloat(bytes, -2.5f, be);
  putU8(bytes, 2);
  putBits(bytes, 7, 4, be);
  putBits(bytes, 8, 4, be);
  putFloat(bytes, 0.75f, be);
  putU8(bytes, 1);
  putU8(bytes, 2);
  putU8(bytes, 3);
  // vertex 1
  putU8(bytes, 0x55);
  putDouble(bytes, 10001.875, be);
  putBits(bytes, 0xfffe, 2, be);
  putFloat(bytes, -0.5f, be);
  putU8(bytes, 0);
  putFloat(bytes, 1.75f, be);
  putU8(bytes, 250);
  putU8(bytes, 251);
  putU8(bytes, 252);
  // face
  putU8(bytes, 2);
  putBits(bytes, 0, 4, be);
  putBits(bytes, 1, 4, be);

  const PlyCloud cloud = parseOk(bytes);
  EXPECT_EQ(cloud.format, PlyFormat::kBinaryBigEndian);
  ASSERT_EQ(cloud.points.size(), 2u);
  EXPECT_TRUE(cloud.coords_were_double);
  EXPECT_TRUE(cloud.has_color);
  // Centre x 10001, y -1.5 -> -2 (round half away from zero), z 1.25 -> 1.
  EXPECT_EQ(cloud.points.origin_m, Eigen::Vector3d(10001.0, -2.0, 1.0));
  EXPECT_EQ(cloud.points.x()[0], -0.875f);
  EXPECT_EQ(cloud.points.y()[0], -0.5f);
  EXPECT_EQ(cloud.points.z()[0], -0.25f);
  EXPECT_EQ(cloud.points.x()[1], 0.875f);
  EXPECT_EQ(cloud.points.y()[1], 1.5f);
  EXPECT_EQ(cloud.points.z()[1], 0.75f);
  EXPECT_EQ(cloud.points.rgb()[0], packRgb(1, 2, 3));
  EXPECT_EQ(cloud.points.rgb()[1], packRgb(250, 251, 252));
}

// A little-endian file with a face element *before* the vertices: its lists must
// be parsed to find where the vertices start.
std::string littleEndianFaceFirst() {
  std::string bytes =
      "ply\n"
      "format binary_little_endian 1.0\n"
      "element face 3\n"
      "property list uchar int vertex_indices\n"
      "property uchar material\n"
      "element vertex 2\n"
      "property float x\n"
      "property uint8 region\n"
      "property float y\n"
      "property float z\n"
      "element edge 1\n"
      "property int vertex1\n"
      "property int vertex2\n"
      "end_header\n";
  const bool le = false;
  putU8(bytes, 3);
  for (uint32_t v : {0u, 1u, 0u}) putBits(bytes, v, 4, le);
  putU8(bytes, 9);
  putU8(bytes, 0);
  putU8(bytes, 9);
  putU8(bytes, 1);
  putBits(bytes, 1, 4, le);
  putU8(bytes, 9);
  putFloat(bytes, 1.0f, le);
  putU8(bytes, 4);
  putFloat(bytes, 2.0f, le);
  putFloat(bytes, 3.0f, le);
  putFloat(bytes, -1.0f, le);
  putU8(bytes, 200);
  putFloat(bytes, -2.0f, le);
  putFloat(bytes, -3.0f, le);
  putBits(bytes, 0, 4, le);
  putBits(bytes, 1, 4, le);
  return bytes;
}

TEST(PlyRead, BinaryFaceElementBeforeVertexIsSkipped) {
  const PlyCloud cloud = parseOk(littleEndianFaceFirst());
  EXPECT_EQ(cloud.format, PlyFormat::kBinaryLittleEndian);
  ASSERT_EQ(cloud.points.size(), 2u);
  EXPECT_FALSE(cloud.has_color);
  EXPECT_FALSE(cloud.coords_were_double);
  EXPECT_EQ(cloud.points.origin_m, Eigen::Vector3d(0.0, 0.0, 0.0));
  EXPECT_EQ(cloud.points.world(0), Eigen::Vector3d(1.0, 2.0, 3.0));
  EXPECT_EQ(cloud.points.world(1), Eigen::Vector3d(-1.0, -2.0, -3.0));
  ASSERT_TRUE(cloud.has_region);
  ASSERT_EQ(cloud.region.size(), 2u);
  EXPECT_EQ(cloud.region[0], 4);
  EXPECT_EQ(cloud.region[1], 200);
}

TEST(PlyRead, AsciiFaceElementBeforeVertexIsSkipped) {
  const std::string text =
      "ply\nformat ascii 1.0\n"
      "element face 2\nproperty list uchar int vertex_indices\n"
      "element vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
      "end_header\n"
      "3 0 1 2\n"
      "4 0 1 2 3\n"
      "7 8 9\n";
  const PlyCloud cloud = parseOk(text);
  ASSERT_EQ(cloud.points.size(), 1u);
  EXPECT_EQ(cloud.points.world(0), Eigen::Vector3d(7.0, 8.0, 9.0));
}

TEST(PlyRead, EmptyVertexElementGivesEmptyCloudAtZero) {
  const PlyCloud cloud = parseOk(
      "ply\nformat binary_little_endian 1.0\nelement vertex 0\n"
      "property float x\nproperty float y\nproperty float z\nend_header\n");
  EXPECT_EQ(cloud.points.size(), 0u);
  EXPECT_EQ(cloud.points.origin_m, Eigen::Vector3d::Zero());
}

TEST(PlyRead, FarCoordinatesKeepMicrometresRelativeToTheChosenOrigin) {
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 2\n"
      "property double x\nproperty double y\nproperty double z\nend_header\n"
      "10000.123456 -20000.654321 5000.000001\n"
      "10001.123457 -20001.654322 5000.500002\n";
  const PlyCloud cloud = parseOk(text);
  ASSERT_EQ(cloud.points.size(), 2u);
  EXPECT_EQ(cloud.points.origin_m, Eigen::Vector3d(10001.0, -20001.0, 5000.0));
  const Eigen::Vector3d a(10000.123456, -20000.654321, 5000.000001);
  const Eigen::Vector3d b(10001.123457, -20001.654322, 5000.500002);
  EXPECT_LT((cloud.points.world(0) - a).cwiseAbs().maxCoeff(), 1e-7);
  EXPECT_LT((cloud.points.world(1) - b).cwiseAbs().maxCoeff(), 1e-7);
  EXPECT_LT(std::abs(cloud.points.x()[0]), 1.0f);  // stored relative, not absolute
}

TEST(PlyRead, NonFiniteVerticesAreDroppedAndCounted) {
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 6\n"
      "property float x\nproperty float y\nproperty float z\nproperty uchar region\nend_header\n"
      "1 2 3 10\n"
      "nan 2 3 11\n"
      "1 inf 3 12\n"
      "1 2 -inf 13\n"
      "4 5 6 14\n"
      "1e39 0 0 15\n";  // overflows float: infinite, dropped
  const PlyCloud cloud = parseOk(text);
  EXPECT_EQ(cloud.vertex_count_in_file, 6u);
  EXPECT_EQ(cloud.dropped_nonfinite, 4u);
  ASSERT_EQ(cloud.points.size(), 2u);
  EXPECT_EQ(cloud.points.world(0), Eigen::Vector3d(1.0, 2.0, 3.0));
  EXPECT_EQ(cloud.points.world(1), Eigen::Vector3d(4.0, 5.0, 6.0));
  // The origin comes from the finite points only.
  EXPECT_EQ(cloud.points.origin_m, Eigen::Vector3d(3.0, 4.0, 5.0));  // 2.5, 3.5, 4.5 rounded away
  ASSERT_EQ(cloud.region.size(), 2u);
  EXPECT_EQ(cloud.region[0], 10);
  EXPECT_EQ(cloud.region[1], 14);
}

TEST(PlyRead, NonFiniteBinaryVerticesAreDroppedAndCounted) {
  std::string bytes =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\n"
      "property double x\nproperty double y\nproperty double z\nend_header\n";
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (double v : {1.0, 2.0, 3.0, nan, 0.0, 0.0, 7.0, 8.0, 9.0}) putDouble(bytes, v, false);
  const PlyCloud cloud = parseOk(bytes);
  EXPECT_EQ(cloud.dropped_nonfinite, 1u);
  ASSERT_EQ(cloud.points.size(), 2u);
  EXPECT_EQ(cloud.points.world(0), Eigen::Vector3d(1.0, 2.0, 3.0));
  EXPECT_EQ(cloud.points.world(1), Eigen::Vector3d(7.0, 8.0, 9.0));
}

TEST(PlyRead, MaxPointsExceededNamesBothNumbers) {
  const PointCloud source = makeCloud(10, Eigen::Vector3d::Zero(), 1);
  const std::string bytes = serializePly(source, nullptr, PlyWriteOptions{});
  PlyReadOptions options;
  options.max_points = 7;
  Result<PlyCloud> result = parsePly(bytes, options);
  ASSERT_FALSE(result.isOk());
  EXPECT_EQ(result.status().code(), ErrorCode::kCapacityExceeded);
  EXPECT_NE(result.status().message().find("10"), std::string::npos) << result.status().message();
  EXPECT_NE(result.status().message().find("7"), std::string::npos) << result.status().message();

  options.max_points = 10;
  EXPECT_EQ(parseOk(bytes, options).points.size(), 10u);
  options.max_points = 0;  // no limit
  EXPECT_EQ(parseOk(bytes, options).points.size(), 10u);
}

TEST(PlyRead, MaxPointsCountsOnlyValidPoints) {
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 3\n"
      "property float x\nproperty float y\nproperty float z\nend_header\n"
      "1 2 3\nnan 0 0\n4 5 6\n";
  PlyReadOptions options;
  options.max_points = 2;
  const PlyCloud cloud = parseOk(text, options);
  EXPECT_EQ(cloud.points.size(), 2u);
  EXPECT_EQ(cloud.dropped_nonfinite, 1u);
  options.max_points = 1;
  Result<PlyCloud> result = parsePly(text, options);
  ASSERT_FALSE(result.isOk());
  EXPECT_EQ(result.status().code(), ErrorCode::kCapacityExceeded);
}

// --- round trips ------------------------------------------------------------------

class PlyRoundTrip : public ::testing::TestWithParam<std::tuple<bool, bool, bool, bool>> {};

TEST_P(PlyRoundTrip, PreservesPointsColourAndRegion) {
  const auto [binary, double_coords, with_color, with_region] = GetParam();
  PointCloud source = makeCloud(200, Eigen::Vector3d(12.0, -3.0, 1.0), 42);
  source.has_color = with_color;
  const std::vector<uint8_t> regions = makeRegions(source.size());
  PlyWriteOptions options;
  options.binary = binary;
  options.double_coords = double_coords;
  const std::string bytes = serializePly(source, with_region ? regions.data() : nullptr, options);

  EXPECT_NE(bytes.find("comment generated by fovea\n"), std::string::npos);
  EXPECT_EQ(bytes.find(binary ? "format binary_little_endian 1.0\n" : "format ascii 1.0\n"), 4u);
  EXPECT_EQ(bytes.find("property uchar red") != std::string::npos, with_color);
  EXPECT_EQ(bytes.find("property uchar region") != std::string::npos, with_region);
  EXPECT_NE(bytes.find(double_coords ? "property double x" : "property float x"), std::string::npos);

  const PlyCloud cloud = parseOk(bytes);
  ASSERT_EQ(cloud.points.size(), source.size());
  EXPECT_EQ(cloud.format, binary ? PlyFormat::kBinaryLittleEndian : PlyFormat::kAscii);
  EXPECT_EQ(cloud.coords_were_double, double_coords);
  EXPECT_EQ(cloud.has_color, with_color);
  EXPECT_EQ(cloud.has_region, with_region);
  EXPECT_EQ(cloud.dropped_nonfinite, 0u);
  // World coordinates near 12 m: a float's spacing there is about 1e-6 m.
  const double tolerance_m = double_coords ? 1e-6 : 4e-6;
  for (std::size_t i = 0; i < source.size(); ++i) {
    const Eigen::Vector3d error = cloud.points.world(i) - source.world(i);
    ASSERT_LT(error.cwiseAbs().maxCoeff(), tolerance_m) << "point " << i;
    EXPECT_EQ(cloud.points.rgb()[i], with_color ? source.rgb()[i] : 0u) << "point " << i;
    if (with_region) {
      EXPECT_EQ(cloud.region[i], regions[i]) << "point " << i;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(AllFormats, PlyRoundTrip,
                         ::testing::Combine(::testing::Bool(), ::testing::Bool(), ::testing::Bool(),
                                            ::testing::Bool()),
                         [](const auto& info) {
                           return std::string(std::get<0>(info.param) ? "Binary" : "Ascii") +
                                  (std::get<1>(info.param) ? "Double" : "Float") +
                                  (std::get<2>(info.param) ? "Colour" : "NoColour") +
                                  (std::get<3>(info.param) ? "Region" : "NoRegion");
                         });

TEST(PlyRoundTrip, WriteColorFalseOmitsColour) {
  const PointCloud source = makeCloud(5, Eigen::Vector3d::Zero(), 3);
  PlyWriteOptions options;
  options.write_color = false;
  const std::string bytes = serializePly(source, nullptr, options);
  EXPECT_EQ(bytes.find("red"), std::string::npos);
  const PlyCloud cloud = parseOk(bytes);
  EXPECT_FALSE(cloud.has_color);
  EXPECT_EQ(cloud.points.size(), 5u);
}

TEST(PlyRoundTrip, FloatAsciiIsBitExactForSmallCoordinates) {
  // With origin 0 the written float is the stored float; the reader's origin is
  // whole metres, so small binary fractions come back exactly.
  PointCloud source(3);
  ASSERT_TRUE(source.push(0.125f, -0.5f, 0.75f, 0x010203));
  ASSERT_TRUE(source.push(1.0f, 0.25f, -0.75f, 0x040506));
  ASSERT_TRUE(source.push(-1.0f, 0.0f, 0.25f, 0x070809));
  PlyWriteOptions options;
  options.binary = false;
  const PlyCloud cloud = parseOk(serializePly(source, nullptr, options));
  ASSERT_EQ(cloud.points.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(cloud.points.world(i), source.world(i)) << i;
}

TEST(PlyRoundTrip, TenKilometreOffsetSurvivesDoubleToAMicrometre) {
  for (const bool binary : {true, false}) {
    for (const Eigen::Vector3d& origin :
         {Eigen::Vector3d(1e4, -1e4, 1e4), Eigen::Vector3d(-12345.0, 9876.0, 10000.0)}) {
      const PointCloud source = makeCloud(500, origin, 7, 1.5f);
      PlyWriteOptions options;
      options.binary = binary;
      options.double_coords = true;
      const PlyCloud cloud = parseOk(serializePly(source, nullptr, options));
      ASSERT_EQ(cloud.points.size(), source.size());
      // The reader re-centres the cloud: the origin lands within a metre of the
      // source's and the stored floats stay metre-scale.
      EXPECT_LT((cloud.points.origin_m - origin).cwiseAbs().maxCoeff(), 1.0 + 1e-9);
      double worst_m = 0.0;
      for (std::size_t i = 0; i < source.size(); ++i) {
        worst_m = std::max(worst_m, (cloud.points.world(i) - source.world(i)).cwiseAbs().maxCoeff());
        ASSERT_LT(std::abs(cloud.points.x()[i]), 3.0f);
      }
      EXPECT_LT(worst_m, 1e-6) << (binary ? "binary" : "ascii");
    }
  }
}

TEST(PlyRoundTrip, EmptyCloud) {
  PointCloud source;
  source.origin_m = Eigen::Vector3d(5.0, 6.0, 7.0);
  for (const bool binary : {true, false}) {
    PlyWriteOptions options;
    options.binary = binary;
    const PlyCloud cloud = parseOk(serializePly(source, nullptr, options));
    EXPECT_EQ(cloud.points.size(), 0u);
    EXPECT_EQ(cloud.vertex_count_in_file, 0u);
    EXPECT_EQ(cloud.points.origin_m, Eigen::Vector3d::Zero());
  }
}

// --- files --------------------------------------------------------------------------

class PlyFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::path(::testing::TempDir()) /
           ("fovea_test_ply_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

TEST_F(PlyFiles, WriteThenReadGivesTheSameCloud) {
  const PointCloud source = makeCloud(50, Eigen::Vector3d(100.0, 200.0, -300.0), 11);
  const std::vector<uint8_t> regions = makeRegions(source.size());
  const std::string path = (dir_ / "cloud.ply").string();
  PlyWriteOptions options;
  options.double_coords = true;
  const Status written = writePly(path, source, regions.data(), options);
  ASSERT_TRUE(written.isOk()) << written.toString();
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));

  Result<PlyCloud> result = readPly(path);
  ASSERT_TRUE(result.isOk()) << result.status().toString();
  ASSERT_EQ(result->points.size(), source.size());
  for (std::size_t i = 0; i < source.size(); ++i) {
    EXPECT_LT((result->points.world(i) - source.world(i)).cwiseAbs().maxCoeff(), 1e-6);
    EXPECT_EQ(result->points.rgb()[i], source.rgb()[i]);
    EXPECT_EQ(result->region[i], regions[i]);
  }
  // Overwriting an existing file works too.
  const Status again = writePly(path, makeCloud(3, Eigen::Vector3d::Zero(), 2), nullptr, options);
  ASSERT_TRUE(again.isOk()) << again.toString();
  Result<PlyCloud> reread = readPly(path);
  ASSERT_TRUE(reread.isOk());
  EXPECT_EQ(reread->points.size(), 3u);
}

TEST_F(PlyFiles, MissingFileIsNotFoundAndNamesThePath) {
  const std::string path = (dir_ / "absent.ply").string();
  Result<PlyCloud> result = readPly(path);
  ASSERT_FALSE(result.isOk());
  EXPECT_EQ(result.status().code(), ErrorCode::kNotFound);
  EXPECT_NE(result.status().message().find(path), std::string::npos) << result.status().message();
}

TEST_F(PlyFiles, DirectoryIsAnIoError) {
  Result<PlyCloud> result = readPly(dir_.string());
  ASSERT_FALSE(result.isOk());
  EXPECT_EQ(result.status().code(), ErrorCode::kIoError);
  EXPECT_NE(result.status().message().find(dir_.string()), std::string::npos);
}

TEST_F(PlyFiles, MalformedFileIsAParseErrorNamingThePath) {
  const std::string path = (dir_ / "bad.ply").string();
  std::ofstream(path) << "not a ply file\n";
  Result<PlyCloud> result = readPly(path);
  ASSERT_FALSE(result.isOk());
  EXPECT_EQ(result.status().code(), ErrorCode::kParseError);
  EXPECT_NE(result.status().message().find(path), std::string::npos);
  EXPECT_NE(result.status().message().find("line 1"), std::string::npos) << result.status().message();
}

TEST_F(PlyFiles, WritingIntoAMissingDirectoryIsAnIoError) {
  const std::string path = (dir_ / "no" / "such" / "dir" / "cloud.ply").string();
  const Status status = writePly(path, makeCloud(3, Eigen::Vector3d::Zero(), 2), nullptr, PlyWriteOptions{});
  ASSERT_FALSE(status.isOk());
  EXPECT_EQ(status.code(), ErrorCode::kIoError);
  EXPECT_NE(status.message().find(path), std::string::npos) << status.message();
}

TEST_F(PlyFiles, WritingOverADirectoryIsAnIoErrorAndLeavesNoTemporary) {
  const std::filesystem::path target = dir_ / "occupied";
  std::filesystem::create_directories(target / "child");
  const Status status =
      writePly(target.string(), makeCloud(3, Eigen::Vector3d::Zero(), 2), nullptr, PlyWriteOptions{});
  ASSERT_FALSE(status.isOk());
  EXPECT_EQ(status.code(), ErrorCode::kIoError);
  EXPECT_FALSE(std::filesystem::exists(target.string() + ".tmp"));
}

// --- malformed input ------------------------------------------------------------

const char kXyzHeader[] =
    "element vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n";

TEST(PlyMalformed, MissingMagic) {
  EXPECT_NE(parseFails("").find("magic"), std::string::npos);
  EXPECT_NE(parseFails("plx\nformat ascii 1.0\n").find("line 1"), std::string::npos);
  EXPECT_NE(parseFails("PLY\nformat ascii 1.0\n").find("magic"), std::string::npos);
  EXPECT_NE(parseFails("ply format ascii 1.0\n").find("magic"), std::string::npos);
  parseFails(std::string("\0\0\0\0", 4));
}

TEST(PlyMalformed, BadFormatLine) {
  const std::string tail = std::string(kXyzHeader) + "1 2 3\n4 5 6\n";
  EXPECT_NE(parseFails("ply\nformat binary 1.0\n" + tail).find("header line 2"), std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 2.0\n" + tail).find("header line 2"), std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii\n" + tail).find("header line 2"), std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 1.0 extra\n" + tail).find("header line 2"), std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nformat ascii 1.0\n" + tail).find("header line 3"),
            std::string::npos);
  EXPECT_NE(parseFails("ply\n" + tail).find("format"), std::string::npos);  // no format line
}

TEST(PlyMalformed, UnknownTypeOrKeyword) {
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelement vertex 1\nproperty flaot x\n"
                       "property float y\nproperty float z\nend_header\n1 2 3\n")
                .find("header line 4: unknown type 'flaot'"),
            std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                       "property float y\nproperty float z\nproperty list float int l\nend_header\n1 2 3 0\n")
                .find("header line 7"),
            std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                       "property float y\nproperty float z\nproperty list uchar int128 l\nend_header\n1 2 3 0\n")
                .find("unknown type 'int128'"),
            std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelemnt vertex 1\nend_header\n").find("header line 3"),
            std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nproperty float x\n" + std::string(kXyzHeader))
                .find("header line 3"),
            std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelement vertex 1\nproperty float\nend_header\n")
                .find("header line 4"),
            std::string::npos);
}

TEST(PlyMalformed, MissingOrBadCoordinates) {
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                       "property float z\nend_header\n1 2\n")
                .find("'y'"),
            std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelement vertex 1\nproperty int x\n"
                       "property float y\nproperty float z\nend_header\n1 2 3\n")
                .find("header line 4"),
            std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float x\n"
                       "property float y\nproperty float z\nend_header\n1 1 2 3\n")
                .find("header line 5"),
            std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n"
                       "end_header\n3 0 1 2\n")
                .find("vertex"),
            std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                       "property float z\nelement vertex 1\nproperty float x\nproperty float y\n"
                       "property float z\nend_header\n1 2 3\n4 5 6\n")
                .find("header line 7"),
            std::string::npos);
}

TEST(PlyMalformed, HeaderWithoutEnd) {
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n").find("end_header"),
            std::string::npos);
}

TEST(PlyMalformed, BadElementCounts) {
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelement vertex -1\nend_header\n").find("header line 3"),
            std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelement vertex many\nend_header\n").find("header line 3"),
            std::string::npos);
  EXPECT_NE(parseFails("ply\nformat ascii 1.0\nelement vertex 100000000000000000000000000000\n"
                       "property float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n")
                .find("header line 3"),
            std::string::npos);
}

TEST(PlyMalformed, AbsurdCountsAreRejectedBeforeAllocating) {
  for (const char* format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    const std::string header = std::string("ply\nformat ") + format +
                               " 1.0\nelement vertex 1000000000000000\nproperty float x\nproperty float y\n"
                               "property float z\nend_header\n";
    const std::string message = parseFails(header + "1 2 3\n");
    EXPECT_NE(message.find("1000000000000000"), std::string::npos) << message;
    EXPECT_NE(message.find("header line 3"), std::string::npos) << message;
    // The largest count a uint64 can hold: rows * row size must not overflow.
    parseFails(std::string("ply\nformat ") + format +
               " 1.0\nelement vertex 18446744073709551615\nproperty double x\nproperty double y\n"
               "property double z\nend_header\n1 2 3\n");
  }
  // A huge element before the vertices, and a huge list inside one.
  parseFails("ply\nformat binary_little_endian 1.0\nelement face 1000000000000000\n"
             "property list uchar int vertex_indices\n" + std::string(kXyzHeader) + "abc");
  std::string bytes = "ply\nformat binary_little_endian 1.0\nelement face 1\n"
                      "property list uint int vertex_indices\n" + std::string(kXyzHeader);
  putBits(bytes, 0xffffffffu, 4, false);
  for (int i = 0; i < 6; ++i) putFloat(bytes, 1.0f, false);
  EXPECT_NE(parseFails(bytes).find("element 'face' row 0"), std::string::npos);
  // Negative list count.
  bytes = "ply\nformat binary_little_endian 1.0\nelement face 1\n"
          "property list int int vertex_indices\n" + std::string(kXyzHeader);
  putBits(bytes, 0xffffffffu, 4, false);
  for (int i = 0; i < 6; ++i) putFloat(bytes, 1.0f, false);
  EXPECT_NE(parseFails(bytes).find("negative"), std::string::npos);
  // Elements without properties take no bytes, whatever their count.
  const PlyCloud cloud = parseOk("ply\nformat ascii 1.0\nelement nothing 1000000000000000000\n" +
                                 std::string(kXyzHeader) + "1 2 3\n4 5 6\n");
  EXPECT_EQ(cloud.points.size(), 2u);
}

TEST(PlyMalformed, VertexCountLargerThanTheData) {
  const std::string header3 =
      "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
  // ascii: passes the size check but the data runs out at vertex 2.
  std::string message =
      parseFails("ply\nformat ascii 1.0\n" + header3 + "1.000 2.000 3.000\n4.000 5.000 6.000\n");
  EXPECT_NE(message.find("vertex index 2 of 3"), std::string::npos) << message;
  // binary: 24 bytes for 36 needed.
  std::string bytes = "ply\nformat binary_little_endian 1.0\n" + header3;
  for (int i = 0; i < 6; ++i) putFloat(bytes, 1.0f, false);
  message = parseFails(bytes);
  EXPECT_NE(message.find("'vertex' declares 3 rows"), std::string::npos) << message;
  EXPECT_NE(message.find("24 bytes"), std::string::npos) << message;
}

TEST(PlyMalformed, TruncatedBinaryInsideAList) {
  // The size check passes (it assumes empty lists); the list itself runs out.
  std::string bytes = "ply\nformat binary_little_endian 1.0\nelement vertex 2\n"
                      "property float x\nproperty float y\nproperty float z\n"
                      "property list uchar float normals\nend_header\n";
  for (int row = 0; row < 2; ++row) {
    for (int i = 0; i < 3; ++i) putFloat(bytes, 1.0f, false);
    putU8(bytes, 3);
    for (int i = 0; i < (row == 0 ? 3 : 1); ++i) putFloat(bytes, 0.5f, false);  // row 1: cut short
  }
  const std::string message = parseFails(bytes);
  EXPECT_NE(message.find("vertex index 1 of 2, property 'normals'"), std::string::npos) << message;
}

TEST(PlyMalformed, NonNumericAsciiValues) {
  const std::string head = "ply\nformat ascii 1.0\n" + std::string(kXyzHeader);
  std::string message = parseFails(head + "1 2 3\n4 abc 6\n");
  EXPECT_NE(message.find("vertex index 1 of 2, property 'y'"), std::string::npos) << message;
  EXPECT_NE(message.find("'abc'"), std::string::npos) << message;
  EXPECT_NE(message.find("line 9"), std::string::npos) << message;  // the file's line number
  parseFails(head + "1 2 3\n4 5 6x\n");
  parseFails(head + "1 2 3\n4 5 0x10\n");
  parseFails(head + "1 2 3\n4 5 --6\n");
  parseFails(head + "1 2 3\n4 5 " + std::string("6\0", 2) + "\n");
  // Integer properties must be integers in range.
  const std::string with_red = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                               "property float z\nproperty uchar red\nproperty uchar green\n"
                               "property uchar blue\nend_header\n";
  EXPECT_NE(parseFails(with_red + "1 2 3 256 0 0\n").find("out of range"), std::string::npos);
  EXPECT_NE(parseFails(with_red + "1 2 3 -1 0 0\n").find("out of range"), std::string::npos);
  EXPECT_NE(parseFails(with_red + "1 2 3 1.5 0 0\n").find("not an integer"), std::string::npos);
}

TEST(PlyMalformed, AsciiRowsMustMatchTheHeader) {
  const std::string head = "ply\nformat ascii 1.0\n" + std::string(kXyzHeader);
  EXPECT_NE(parseFails(head + "1.0 2.0\n3.0 4.0 5.0\n").find("fewer values"), std::string::npos);
  EXPECT_NE(parseFails(head + "1 2 3 4\n5 6 7\n").find("more values"), std::string::npos);
}

// --- never crash ------------------------------------------------------------------

std::string faceAfterVertexBinary(bool big_endian) {
  std::string bytes = std::string("ply\nformat ") +
                      (big_endian ? "binary_big_endian" : "binary_little_endian") +
                      " 1.0\ncomment truncation test\nelement vertex 4\n"
                      "property double x\nproperty float y\nproperty list uchar short extra\n"
                      "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
                      "element face 2\nproperty list uchar int vertex_indices\nend_header\n";
  for (int i = 0; i < 4; ++i) {
    putDouble(bytes, 1000.0 + i, big_endian);
    putFloat(bytes, -0.5f * static_cast<float>(i), big_endian);
    putU8(bytes, static_cast<uint8_t>(i % 3));
    for (int k = 0; k < i % 3; ++k) putBits(bytes, static_cast<uint64_t>(k), 2, big_endian);
    putFloat(bytes, 0.25f * static_cast<float>(i), big_endian);
    putU8(bytes, static_cast<uint8_t>(10 * i));
    putU8(bytes, static_cast<uint8_t>(10 * i + 1));
    putU8(bytes, static_cast<uint8_t>(10 * i + 2));
  }
  for (int f = 0; f < 2; ++f) {
    putU8(bytes, 3);
    for (int k = 0; k < 3; ++k) putBits(bytes, static_cast<uint64_t>(f + k), 4, big_endian);
  }
  return bytes;
}

TEST(PlyNeverCrashes, EveryTruncationOfABinaryFile) {
  for (const bool big_endian : {false, true}) {
    const std::string full = faceAfterVertexBinary(big_endian);
    const PlyCloud reference = parseOk(full);
    ASSERT_EQ(reference.points.size(), 4u);
    EXPECT_EQ(reference.points.world(3), Eigen::Vector3d(1003.0, -1.5, 0.75));
    EXPECT_EQ(reference.points.rgb()[2], packRgb(20, 21, 22));
    // The vertex data ends 2 face rows (2 * 13 bytes) before the end of the file.
    const std::size_t vertices_end = full.size() - 26;
    std::size_t successes = 0;
    for (std::size_t length = 0; length < full.size(); ++length) {
      Result<PlyCloud> result = parsePly(std::string_view(full).substr(0, length));
      if (!result.isOk()) {
        ASSERT_EQ(result.status().code(), ErrorCode::kParseError) << "length " << length;
        ASSERT_FALSE(result.status().message().empty());
        continue;
      }
      // Only the face data may be cut: the vertices must then all be there.
      ASSERT_GE(length, vertices_end) << "parsed a file cut inside its header or vertices";
      ASSERT_EQ(result->points.size(), 4u);
      for (std::size_t i = 0; i < 4; ++i) {
        ASSERT_EQ(result->points.world(i), reference.points.world(i));
        ASSERT_EQ(result->points.rgb()[i], reference.points.rgb()[i]);
      }
      ++successes;
    }
    EXPECT_EQ(successes, 26u);
  }
}

TEST(PlyNeverCrashes, EveryTruncationOfAnAsciiFile) {
  PlyWriteOptions options;
  options.binary = false;
  const PointCloud source = makeCloud(6, Eigen::Vector3d(3.0, 4.0, 5.0), 5);
  const std::vector<uint8_t> regions = makeRegions(source.size());
  const std::string full = serializePly(source, regions.data(), options);
  for (std::size_t length = 0; length <= full.size(); ++length) {
    Result<PlyCloud> result = parsePly(std::string_view(full).substr(0, length));
    if (!result.isOk()) {
      ASSERT_EQ(result.status().code(), ErrorCode::kParseError) << "length " << length;
      continue;
    }
    // A cut inside the last line's last value can still parse; nothing else can.
    ASSERT_GE(length, full.rfind('\n', full.size() - 2)) << "length " << length;
    ASSERT_EQ(result->points.size(), source.size());
    expectSane(*result);
  }
}

TEST(PlyNeverCrashes, RandomByteCorruption) {
  PlyWriteOptions ascii;
  ascii.binary = false;
  PlyWriteOptions binary_double;
  binary_double.double_coords = true;
  const PointCloud source = makeCloud(8, Eigen::Vector3d(1e4, 0.0, -1e4), 9);
  const std::vector<uint8_t> regions = makeRegions(source.size());
  const std::vector<std::string> seeds = {
      serializePly(source, regions.data(), PlyWriteOptions{}),
      serializePly(source, regions.data(), ascii),
      serializePly(source, nullptr, binary_double),
      faceAfterVertexBinary(true),
      littleEndianFaceFirst(),
  };
  std::mt19937 rng(1234);
  const char kInteresting[] = {'\0', '\n', ' ', '-', '9', 'e', '\xff', '\x7f', 'x', '.'};
  for (int iteration = 0; iteration < 20000; ++iteration) {
    std::string bytes = seeds[iteration % seeds.size()];
    const int edits = 1 + static_cast<int>(rng() % 4);
    for (int e = 0; e < edits && !bytes.empty(); ++e) {
      const std::size_t at = rng() % bytes.size();
      switch (rng() % 4) {
        case 0: bytes[at] = static_cast<char>(rng()); break;
        case 1: bytes[at] = kInteresting[rng() % sizeof kInteresting]; break;
        case 2: bytes.erase(at, 1 + rng() % 8); break;
        case 3: bytes.insert(at, 1, kInteresting[rng() % sizeof kInteresting]); break;
      }
    }
    Result<PlyCloud> result = parsePly(bytes);
    if (result.isOk()) {
      expectSane(*result);
    } else {
      ASSERT_NE(result.status().code(), ErrorCode::kOk);
      ASSERT_FALSE(result.status().message().empty());
    }
  }
}

}  // namespace
}  // namespace fovea::io

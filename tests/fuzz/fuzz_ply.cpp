// Fuzz target for the PLY reader (io/ply.h): the bytes are a file's
// contents, read by parsePly as readPly does after reading the file. Oracles:
// a cloud that reads has as many regions as points when it has regions, and
// what serializePly writes of it (double coordinates) reads back to as many
// points with the same colour and region flags.
#include <cstdio>
#include <cstdlib>
#include <string_view>

#include "io/ply.h"
#include "tests/fuzz/fuzz_target.h"

namespace {

using namespace fovea;
using namespace fovea::pipeline;
using namespace fovea::io;

[[noreturn]] void fail(const char* what) {
  std::fprintf(stderr, "fuzz_ply: %s\n", what);
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  Result<PlyCloud> cloud = parsePly(bytes);
  if (!cloud) return 0;
  const std::size_t n = cloud->points.size();
  if (cloud->has_region && cloud->region.size() != n) fail("region count differs from the point count");
  if (n + cloud->dropped_nonfinite > cloud->vertex_count_in_file) fail("more points than vertices");
  // The cap: one point fewer than the file has must be refused.
  if (n > 1) {
    PlyReadOptions capped;
    capped.max_points = n - 1;
    Result<PlyCloud> refused = parsePly(bytes, capped);
    if (refused || refused.status().code() != ErrorCode::kCapacityExceeded) fail("max_points was not enforced");
  }
  PlyWriteOptions options;
  options.double_coords = true;
  options.binary = (data[size / 2] & 1) != 0;
  // serializePly writes a region property when given a pointer, even to no points.
  const uint8_t no_region = 0;
  const uint8_t* region = cloud->has_region ? (n > 0 ? cloud->region.data() : &no_region) : nullptr;
  const std::string written = serializePly(cloud->points, region, options);
  Result<PlyCloud> again = parsePly(written);
  if (!again) {
    std::fprintf(stderr, "%s\n", again.status().message().c_str());
    fail("what serializePly wrote does not read back");
  }
  if (again->points.size() != n || again->has_color != cloud->has_color || again->has_region != cloud->has_region) {
    fail("what serializePly wrote reads back differently");
  }
  return 0;
}

// Clouds written by fovea itself, in each format; the corpus adds files of
// other writers (lists, faces, big endian, comments).
std::vector<fuzz::Input> fuzz::seeds() {
  PointCloud cloud(4);
  (void)cloud.resize(4);
  cloud.has_color = true;
  for (std::size_t i = 0; i < 4; ++i) {
    cloud.x()[i] = 0.25f * static_cast<float>(i);
    cloud.y()[i] = -1.5f;
    cloud.z()[i] = 2.0f + static_cast<float>(i);
    cloud.rgb()[i] = packRgb(static_cast<uint8_t>(60 * i), 128, 255);
  }
  const uint8_t region[4] = {0, 1, 2, 3};
  std::vector<Input> seeds;
  for (int variant = 0; variant < 4; ++variant) {
    PlyWriteOptions options;
    options.binary = variant & 1;
    options.double_coords = variant & 2;
    const std::string bytes = serializePly(cloud, variant == 3 ? region : nullptr, options);
    seeds.emplace_back(bytes.begin(), bytes.end());
  }
  return seeds;
}

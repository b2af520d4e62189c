// Where the tests find the recorded TUM RGB-D frames (fr3/teddy: README.md,
// "The recorded frames"): $FOVEA_SHARED_DIR/data/tum-fr3-teddy, which CTest
// points at the shared folder beside the clone (tests/CMakeLists.txt). A clone
// without them skips every test that needs them, with the one reason below; in
// CI (CI=true) toolchain/check-skips fails such a skip, since CI has them.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <string>

namespace fovea::test {

// The sequence's folder, or "" when it is not there (sequence, ground truth
// and associations all present).
inline std::string tumTeddyPath() {
  const char* shared = std::getenv("FOVEA_SHARED_DIR");
  if (shared == nullptr || *shared == '\0') return "";
  const std::filesystem::path path = std::filesystem::path(shared) / "data" / "tum-fr3-teddy";
  std::error_code ec;
  if (!std::filesystem::exists(path / "associations.txt", ec) || !std::filesystem::exists(path / "groundtruth.txt", ec)) {
    return "";
  }
  return path.string();
}

}  // namespace fovea::test

// In a test body: `path` is the sequence's folder, or the test skips.
#define FOVEA_REQUIRE_TUM_TEDDY(path)                         \
  const std::string path = ::fovea::test::tumTeddyPath();     \
  if (path.empty()) GTEST_SKIP() << "no tum-fr3-teddy under $FOVEA_SHARED_DIR/data"

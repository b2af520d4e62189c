// Where board profiles are (config.h's boardDirectory), alone in its file: the
// build defines FOVEA_BOARD_DIR (in a build tree, the source tree's board/) on
// this file only (firmware/CMakeLists.txt), so that only this small file misses
// the compiler cache in another clone.
#include "firmware/config.h"

#include <cstdlib>
#include <filesystem>
#include <string>
#include <system_error>

#ifndef FOVEA_BOARD_DIR
#define FOVEA_BOARD_DIR "board"
#endif
#ifndef FOVEA_INSTALLED_BOARD_DIR
#define FOVEA_INSTALLED_BOARD_DIR "share/fovea/board"  // relative to the installation prefix
#endif

namespace fovea::firmware {

std::string boardDirectory() {
  if (const char* env = std::getenv("FOVEA_BOARD_DIR"); env && *env) return env;
  // Installed: PREFIX/bin/fovead beside PREFIX/share/fovea/board (wherever PREFIX is).
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const std::filesystem::path installed = exe.parent_path().parent_path() / FOVEA_INSTALLED_BOARD_DIR;
    if (std::filesystem::is_regular_file(installed / (std::string(kDefaultBoard) + ".toml"), ec)) {
      return installed.lexically_normal().string();
    }
  }
  return FOVEA_BOARD_DIR;
}

}  // namespace fovea::firmware

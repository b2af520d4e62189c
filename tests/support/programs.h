// The project's programs and trees as the tests that run them as processes find
// them: from the test binary's own place in its build tree (/proc/self/exe, which
// qemu-user reports as the emulated binary), not from absolute paths compiled in.
// A test's object then names no folder of the clone that built it, and a clone in
// another folder is answered by the compiler cache the working tree filled
// (docs/ci.md, "The compiler cache").
//
// A test that starts programs is declared with fovea_test_runs_programs
// (tests/CMakeLists.txt), which defines FOVEA_EMULATOR ("" natively, qemu in the
// cross tree) and the programs' paths inside the build tree (FOVEAD_PATH...);
// emulated() and program() exist only there.
#pragma once

#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

namespace fovea::test {

// The build tree holding this test binary: the nearest folder above it with a CMakeCache.txt.
inline std::string buildDir() {
  namespace fs = std::filesystem;
  const fs::path self = fs::read_symlink("/proc/self/exe");
  for (fs::path dir = self.parent_path(); !dir.empty() && dir != dir.root_path(); dir = dir.parent_path()) {
    if (fs::exists(dir / "CMakeCache.txt")) return dir.string();
  }
  throw std::runtime_error("no CMakeCache.txt in any folder above " + self.string());
}

// The source tree that build tree was configured from (its CMakeCache.txt's CMAKE_HOME_DIRECTORY).
inline std::string sourceDir() {
  const std::string cache = buildDir() + "/CMakeCache.txt";
  std::ifstream in(cache);
  const std::string key = "CMAKE_HOME_DIRECTORY:INTERNAL=";
  for (std::string line; std::getline(in, line);) {
    if (line.rfind(key, 0) == 0) return line.substr(key.size());
  }
  throw std::runtime_error(cache + " names no CMAKE_HOME_DIRECTORY");
}

#ifdef FOVEA_EMULATOR
// Whether the programs run through an emulator (the cross-compiled tree under qemu).
inline bool emulated() { return std::string(FOVEA_EMULATOR) != ""; }

// The command line that starts the program at `path_in_build_dir` (FOVEAD_PATH and the
// like), through the build's emulator when there is one.
inline std::string program(const std::string& path_in_build_dir) {
  const std::string path = buildDir() + "/" + path_in_build_dir;
  return emulated() ? std::string(FOVEA_EMULATOR) + " " + path : path;
}
#endif

}  // namespace fovea::test

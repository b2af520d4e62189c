// Fuzz target for the calibration parser (hal/calibration_file.h): any bytes
// must give a calibration or an error value, never a crash, a hang or an
// exception. Under clang it is a libFuzzer target (-fsanitize=fuzzer); with
// other compilers FOVEA_FUZZ_DRIVER builds a main() that feeds it random bytes
// and byte-level mutations of valid files of each format (random bytes alone
// rarely get past the YAML parser).
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "hal/calibration_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  // base_dir "/nonexistent": a combined file naming other files finds none (no file-system walk).
  (void)fovea::hal::parseCalibration(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.yaml",
                                     "/nonexistent");
  return 0;
}

#ifdef FOVEA_FUZZ_DRIVER
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

namespace {

const char* const kSeeds[] = {
    "image_width: 640\nimage_height: 480\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [615.9, 0, 319.5, 0, 616.1, "
    "240.6, 0, 0, 1]\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0.1, 0, "
    "0, 0, 0]\nrectification_matrix: {rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0, 0, 0, 1]}\n",
    "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\nK1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   "
    "data: [ 577., 0., 319.5, 0., 577., 239.5, 0., 0., 1. ]\nD1: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n"
    "   data: [ 0., 0., 0., 0., 0. ]\nK2: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 525., 0., "
    "319.5, 0., 525., 239.5, 0., 0., 1. ]\nR: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1., 0., "
    "0., 0., 1., 0., 0., 0., 1. ]\nT: !!opencv-matrix\n   rows: 3\n   cols: 1\n   dt: d\n   data: [ -0.025, 0., 0. ]\n",
    "colour: {image_width: 640, image_height: 480, camera_matrix: [500, 0, 320, 0, 500, 240, 0, 0, 1]}\n"
    "T_colour_depth:\n  rotation_xyzw: [0, 0, 0, 1]\n  translation_m: [0.015, 0, 0]\ndepth_scale_m: 0.001\n",
};

}  // namespace

// fuzz_calibration [ITERATIONS]: random bytes, and valid files with bytes
// replaced, inserted, deleted or cut.
int main(int argc, char** argv) {
  const long iterations = argc > 1 ? std::atol(argv[1]) : 20000;
  std::mt19937_64 rng(1);
  const char alphabet[] = " \n:-[]{},.!#%&*|>'\"0123456789eE+nNaA";
  std::string input;
  for (long i = 0; i < iterations; ++i) {
    if (i % 4 == 0) {
      input.resize(rng() % 300);
      for (char& c : input) c = static_cast<char>(rng());
    } else {
      input = kSeeds[rng() % std::size(kSeeds)];
      const int edits = 1 + static_cast<int>(rng() % 6);
      for (int e = 0; e < edits && !input.empty(); ++e) {
        const std::size_t at = rng() % input.size();
        const char c = rng() % 2 ? alphabet[rng() % (sizeof alphabet - 1)] : static_cast<char>(rng());
        switch (rng() % 4) {
          case 0: input[at] = c; break;
          case 1: input.insert(input.begin() + static_cast<std::ptrdiff_t>(at), c); break;
          case 2: input.erase(at, 1 + rng() % 8); break;
          default: input.resize(at); break;
        }
      }
    }
    LLVMFuzzerTestOneInput(reinterpret_cast<const uint8_t*>(input.data()), input.size());
  }
  return 0;
}
#endif

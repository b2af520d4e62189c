// Fuzz target for the calibration parser (hal/calibration_file.h): any bytes
// must give a calibration or an error value, never a crash, a hang or an
// exception. Built and run as every target in tests/fuzz/ (fuzz_target.h);
// the corpus holds a file of each format (random bytes alone rarely get past
// the YAML parser), the dictionary their keys.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "hal/calibration_file.h"
#include "tests/fuzz/fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  // base_dir "/nonexistent": a combined file naming other files finds none (no file-system walk).
  (void)fovea::hal::parseCalibration(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.yaml",
                                     "/nonexistent");
  return 0;
}

// The seeds are files of each format: corpus/fuzz_calibration/.
std::vector<fovea::fuzz::Input> fovea::fuzz::seeds() { return {}; }

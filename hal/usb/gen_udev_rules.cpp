// Writes fovea's udev rules (hal/usb/usb_ids.h: udevRules()) to the file named
// on the command line, or to stdout. Run by the build; installed nowhere.
#include <cstdio>
#include <string>

#include "hal/usb/usb_ids.h"

int main(int argc, char** argv) {
  const std::string rules = fovea::hal::usb::udevRules();
  if (argc < 2) return std::fwrite(rules.data(), 1, rules.size(), stdout) == rules.size() ? 0 : 1;
  std::FILE* f = std::fopen(argv[1], "w");
  if (f == nullptr) {
    std::perror(argv[1]);
    return 1;
  }
  const bool ok = std::fwrite(rules.data(), 1, rules.size(), f) == rules.size();
  return std::fclose(f) == 0 && ok ? 0 : 1;
}

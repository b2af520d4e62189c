#include "tools/common/host.h"

#include <cstdio>
#include <limits>

namespace fovea::tools {

const char* cpuArchitecture() {
#if defined(__x86_64__)
  return "x86-64";
#elif defined(__aarch64__)
  return "aarch64";
#else
  return "unknown";
#endif
}

double loadAverage() {
  std::FILE* f = std::fopen("/proc/loadavg", "r");
  if (!f) return std::numeric_limits<double>::quiet_NaN();
  double one = 0.0;
  const int n = std::fscanf(f, "%lf", &one);
  std::fclose(f);
  return n == 1 ? one : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace fovea::tools

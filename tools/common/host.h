// What the report tools say about the machine they ran on.
#pragma once

#include <string>

namespace fovea::tools {

// "x86-64", "aarch64" or "unknown": what this program was built for.
const char* cpuArchitecture();
// The 1-minute load average; NaN where /proc is absent.
double loadAverage();

}  // namespace fovea::tools

// The service threads' one way to wait: a plain nanosleep, for a stage with
// nothing to do and for the supervisor's pace (a condition variable would put a
// lock on the frame path).
#pragma once

#include <cstdint>
#include <ctime>

namespace fovea::firmware {

inline void sleepNs(int64_t ns) {
  const timespec pause{static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
  nanosleep(&pause, nullptr);
}

}  // namespace fovea::firmware

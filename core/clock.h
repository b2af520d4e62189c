// The one monotonic clock: CLOCK_MONOTONIC in nanoseconds. Frames are stamped
// on it (V4L2 and libcamera buffers, OpenNI2 through a measured offset), the
// protocol's timestamps and the service's deadlines use it, and so do the
// foveator's stage timings. (std::chrono::steady_clock reads the same clock on
// Linux; this is its integer form, which crosses threads and the wire as is.)
#pragma once

#include <cstdint>
#include <ctime>

namespace fovea {

inline int64_t monotonicNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// Wall-clock time, CLOCK_REALTIME in nanoseconds since the epoch: only where a
// person or another program reads the time of day, as recordings' log times
// (MCAP viewers show them on their timeline). Never for durations: it jumps.
inline int64_t wallClockNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace fovea

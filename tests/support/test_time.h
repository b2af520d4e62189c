// Timeouts of tests that wait for threads or processes, scaled for slow runs.
//
// Under an emulator (qemu-aarch64) or a sanitizer the same frames take several
// times longer, so CTest sets FOVEA_TEST_TIME_SCALE for those builds
// (tests/CMakeLists.txt): scaled() multiplies a bound the code must meet ("stops
// within a second") by it. A wait's timeout is only an upper bound (a passing
// run never reaches it), so waitUntil() allows kWaitMargin times more on top,
// for a machine loaded by other builds (CI runs stages side by side). Fixed
// sleeps that mean "let this much time pass" are not scaled.
#pragma once

#include <chrono>
#include <cstdlib>
#include <thread>

namespace fovea::test {

// FOVEA_TEST_TIME_SCALE, a number in [1, 100]; 1 when unset or invalid.
// Neither this nor the waits allocate (the allocation-counting tests use them).
inline double timeScale() {
  static const double scale = [] {
    const char* text = std::getenv("FOVEA_TEST_TIME_SCALE");
    if (text == nullptr) return 1.0;
    char* end = nullptr;
    const double value = std::strtod(text, &end);
    return (end != text && *end == '\0' && value >= 1.0 && value <= 100.0) ? value : 1.0;
  }();
  return scale;
}

// How many times a test repeats what each repetition shows on its own (frames
// through a path that must not allocate, cameras that must agree frame by
// frame): `native` in a native optimised build, `slow` where a repetition costs
// 10 to 40 times as much (sanitizers, qemu: timeScale() > 1). The work, not a
// wait: it keeps those trees' CI stages in their time (docs/ci.md).
inline int repetitions(int native, int slow) { return timeScale() > 1.0 ? slow : native; }

// Under qemu-user (the cross tree's tests, FOVEA_TESTS_IN_QEMU_USER) a case whose
// point is an accuracy figure over a long sequence of frames skips: it takes a
// minute or more there, and adds nothing arm64's own. The scalar code is the same
// IEEE arithmetic on both (-ffp-contract=off), the SIMD kernels are compared with
// it on NEON, SVE and SVE2 (tests/equivalence), and the short cases run the same
// code under qemu; the long ones run natively and under ASan+UBSan (docs/ci.md).
#ifdef FOVEA_TESTS_IN_QEMU_USER
#define FOVEA_SKIP_LONG_SEQUENCE_UNDER_QEMU() \
  GTEST_SKIP() << "a long sequence's accuracy: natively and under ASan+UBSan, not under qemu"
#else
#define FOVEA_SKIP_LONG_SEQUENCE_UNDER_QEMU() (void)0
#endif

template <class Rep, class Period>
std::chrono::milliseconds scaled(std::chrono::duration<Rep, Period> timeout) {
  const double ms = std::chrono::duration<double, std::milli>(timeout).count() * timeScale();
  return std::chrono::milliseconds(static_cast<int64_t>(ms));
}

inline constexpr int kWaitMargin = 3;

// The longest a wait for something expected within `seconds` may take: scaled, times
// kWaitMargin (what waitUntil allows; for waits that take a time in seconds, such as
// a process's exit).
inline double waitLimitSeconds(double seconds) { return seconds * timeScale() * kWaitMargin; }

// Polls `done` every few milliseconds until it holds (true) or the scaled
// timeout, times kWaitMargin, passes (false).
template <class Predicate, class Rep, class Period>
bool waitUntil(Predicate&& done, std::chrono::duration<Rep, Period> timeout) {
  const auto end = std::chrono::steady_clock::now() + kWaitMargin * scaled(timeout);
  while (!done()) {
    if (std::chrono::steady_clock::now() > end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return true;
}

}  // namespace fovea::test

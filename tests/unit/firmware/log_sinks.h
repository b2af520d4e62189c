// Test doubles of the logger shared by test_log and test_log_alloc.
#pragma once

#include <cstdint>
#include <string_view>

#include "firmware/log.h"

namespace fovea::test {

using firmware::LogLevel;
using firmware::LogSink;
using firmware::Logger;
using firmware::kLogLineBytes;

// Keeps only the last line, in a fixed buffer (allocation-free).
class LastLineSink final : public LogSink {
 public:
  void write(LogLevel, int64_t, std::string_view line) override {
    size = line.copy(text, sizeof text);
    ++count;
  }
  char text[kLogLineBytes] = {};
  std::size_t size = 0;
  uint64_t count = 0;
};

// A clock the test moves by hand.
struct FakeClock {
  int64_t now_ns = 0;
  Logger::Clock clock() {
    return [this] { return now_ns; };
  }
};

}  // namespace fovea::test

// Test doubles of the logger shared by test_log and test_log_alloc.
#pragma once

#include <cstdint>
#include <mutex>
#include <regex>
#include <string>
#include <string_view>
#include <vector>

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

// Keeps every line, from any thread (allocation does not matter where it is used).
class RecordingSink final : public LogSink {
 public:
  void write(LogLevel, int64_t, std::string_view line) override {
    std::lock_guard<std::mutex> lock(mutex_);
    lines_.emplace_back(line);
  }
  bool contains(const std::string& text) const {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const std::string& line : lines_) {
      if (line.find(text) != std::string::npos) return true;
    }
    return false;
  }
  // The lines that contain `text`.
  std::size_t countOf(const std::string& text) const {
    std::lock_guard<std::mutex> lock(mutex_);
    std::size_t n = 0;
    for (const std::string& line : lines_) n += line.find(text) != std::string::npos ? 1 : 0;
    return n;
  }
  // A line with a match of `pattern` (ECMAScript).
  bool matches(const std::string& pattern) const {
    const std::regex re(pattern);
    std::lock_guard<std::mutex> lock(mutex_);
    for (const std::string& line : lines_) {
      if (std::regex_search(line, re)) return true;
    }
    return false;
  }

 private:
  mutable std::mutex mutex_;
  std::vector<std::string> lines_;
};

// A clock the test moves by hand.
struct FakeClock {
  int64_t now_ns = 0;
  Logger::Clock clock() {
    return [this] { return now_ns; };
  }
};

}  // namespace fovea::test

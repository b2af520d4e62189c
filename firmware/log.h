// Logging for the service: levels, one line per event, rate limited per call
// site (or per key), to stderr or to the systemd journal.
//
// Where lines go (makeDefaultLogSink()):
//  - under systemd (JOURNAL_STREAM names the device and inode of our stderr):
//    to the journal with the level as its priority; through libsystemd's
//    sd_journal_print when built with it (FOVEA_HAVE_SYSTEMD), else as "<N>line"
//    on stderr, which journald reads as priority N. Never both: systemd already
//    connects stderr to the journal, a copy there would double every line.
//  - otherwise to stderr as "[   12.345678] warning: camera: frame timeout",
//    the stamp in seconds of the logger's clock (CLOCK_MONOTONIC by default).
//
// Rate limiting: logLimited() with a LogRateLimit per call site (the
// FOVEA_LOG_LIMITED macro makes one static per site) or per key (the caller
// keeps one per camera, per fault kind...). The first event logs; repeats within
// the site's interval (1 s by default) are only counted; the next event after
// the interval logs with " (repeated N times)", N the events suppressed since
// the site's previous line. So a fault repeating 1000 times a second logs once
// a second. Events suppressed after a site's last line are not reported.
//
// No heap allocation when logging: a suppressed event is two atomic
// operations, an emitted one is formatted into a fixed buffer of kLogLineBytes
// (longer lines end in "...") and written with one write(2), so lines from
// several threads never interleave. Time comes from an injectable clock.
#pragma once

#include <atomic>
#include <cstdarg>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string_view>
#include <utility>

#include "core/result.h"

namespace fovea::firmware {

// Numerically the syslog priorities, which the journal uses.
enum class LogLevel : int { kError = 3, kWarning = 4, kNotice = 5, kInfo = 6, kDebug = 7 };

const char* logLevelName(LogLevel level);  // "error", "warning", "notice", "info", "debug"
Result<LogLevel> parseLogLevel(std::string_view name);

inline constexpr std::size_t kLogLineBytes = 512;

// Receives complete lines (no newline). Called from any thread: write() must be
// safe to call concurrently and must not allocate.
class LogSink {
 public:
  virtual ~LogSink() = default;
  virtual void write(LogLevel level, int64_t stamp_ns, std::string_view line) = 0;
};

// Writes lines to a file descriptor, one write(2) per line.
class FdLogSink final : public LogSink {
 public:
  enum class Style {
    kPlain,          // "[   12.345678] warning: line"
    kJournalStream,  // "<4>line": journald's priority prefix
  };
  FdLogSink(int fd, Style style) : fd_(fd), style_(style) {}
  void write(LogLevel level, int64_t stamp_ns, std::string_view line) override;

 private:
  int fd_;
  Style style_;
};

// True when JOURNAL_STREAM (its value passed in, "DEV:INO") names fd's file:
// systemd connected our stderr to the journal.
bool isJournalStream(const char* journal_stream, int fd);

// The sink for this process, as described at the top of this file.
std::unique_ptr<LogSink> makeDefaultLogSink();

// One call site's (or key's) rate-limit state. Constant-initialisable, so a
// function-local static costs no allocation and no guard after the first call.
class LogRateLimit {
 public:
  constexpr explicit LogRateLimit(int64_t interval_ns = 1'000'000'000) : interval_ns_(interval_ns) {}
  LogRateLimit(const LogRateLimit&) = delete;
  LogRateLimit& operator=(const LogRateLimit&) = delete;

 private:
  friend class Logger;
  static constexpr int64_t kNever = std::numeric_limits<int64_t>::min();
  const int64_t interval_ns_;
  std::atomic<int64_t> last_emit_ns_{kNever};
  std::atomic<uint64_t> suppressed_{0};
};

class Logger {
 public:
  using Clock = std::function<int64_t()>;  // nanoseconds, monotonic
  static int64_t monotonicNowNs();

  // sink must outlive the logger.
  explicit Logger(LogSink& sink, Clock clock = &Logger::monotonicNowNs, LogLevel level = LogLevel::kInfo)
      : sink_(&sink), clock_(std::move(clock)), level_(static_cast<int>(level)) {}

  void setLevel(LogLevel level) { level_.store(static_cast<int>(level), std::memory_order_relaxed); }
  LogLevel level() const { return static_cast<LogLevel>(level_.load(std::memory_order_relaxed)); }
  bool enabled(LogLevel level) const {
    return static_cast<int>(level) <= level_.load(std::memory_order_relaxed);
  }

  // One event, one line. printf-style (checked by the compiler).
  void log(LogLevel level, const char* format, ...) __attribute__((format(printf, 3, 4)));
  // One event at a rate-limited site (see the top of this file). Returns true
  // when it produced a line.
  bool logLimited(LogRateLimit& site, LogLevel level, const char* format, ...)
      __attribute__((format(printf, 4, 5)));

  // Lines this logger wrote and events its rate limits suppressed.
  uint64_t linesWritten() const { return lines_written_.load(std::memory_order_relaxed); }
  uint64_t eventsSuppressed() const { return events_suppressed_.load(std::memory_order_relaxed); }

 private:
  void emit(LogLevel level, int64_t now_ns, uint64_t repeated, const char* format, va_list args);

  LogSink* sink_;
  Clock clock_;
  std::atomic<int> level_;
  std::atomic<uint64_t> lines_written_{0};
  std::atomic<uint64_t> events_suppressed_{0};
};

// The process's logger (default sink, monotonic clock, level info), created on
// first use.
Logger& logger();

}  // namespace fovea::firmware

#define FOVEA_LOG(level, ...) ::fovea::firmware::logger().log(level, __VA_ARGS__)
// Rate limited per call site: at most one line a second from this line of code.
#define FOVEA_LOG_LIMITED(level, ...)                                                  \
  do {                                                                                 \
    static ::fovea::firmware::LogRateLimit fovea_log_site_;                            \
    (void)::fovea::firmware::logger().logLimited(fovea_log_site_, level, __VA_ARGS__); \
  } while (0)

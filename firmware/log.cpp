#include "firmware/log.h"

#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>

#ifdef FOVEA_HAVE_SYSTEMD
#include <systemd/sd-journal.h>
#endif

namespace fovea::firmware {

const char* logLevelName(LogLevel level) {
  switch (level) {
    case LogLevel::kError: return "error";
    case LogLevel::kWarning: return "warning";
    case LogLevel::kNotice: return "notice";
    case LogLevel::kInfo: return "info";
    case LogLevel::kDebug: return "debug";
  }
  return "?";
}

Result<LogLevel> parseLogLevel(std::string_view name) {
  for (LogLevel level : {LogLevel::kError, LogLevel::kWarning, LogLevel::kNotice, LogLevel::kInfo, LogLevel::kDebug}) {
    if (name == logLevelName(level)) return level;
  }
  return Result<LogLevel>(ErrorCode::kInvalidArgument, "log level: unknown '" + std::string(name) +
                                                           "'; accepted: error|warning|notice|info|debug");
}

namespace {

// Writes all of [data, data + size) (a pipe may take a line in pieces).
void writeAll(int fd, const char* data, std::size_t size) {
  while (size > 0) {
    const ssize_t n = ::write(fd, data, size);
    if (n < 0) {
      if (errno == EINTR) continue;
      return;  // nowhere left to report it
    }
    data += n;
    size -= static_cast<std::size_t>(n);
  }
}

#ifdef FOVEA_HAVE_SYSTEMD
// Native journal entries; if the journal socket refuses one, the line goes to
// stderr (which systemd connected to the journal) with its priority prefix.
class JournalLogSink final : public LogSink {
 public:
  void write(LogLevel level, int64_t stamp_ns, std::string_view line) override {
    if (sd_journal_print(static_cast<int>(level), "%.*s", static_cast<int>(line.size()), line.data()) < 0) {
      fallback_.write(level, stamp_ns, line);
    }
  }

 private:
  FdLogSink fallback_{STDERR_FILENO, FdLogSink::Style::kJournalStream};
};
#endif

}  // namespace

void FdLogSink::write(LogLevel level, int64_t stamp_ns, std::string_view line) {
  char buffer[kLogLineBytes + 48];
  int prefix = 0;
  if (style_ == Style::kJournalStream) {
    prefix = std::snprintf(buffer, sizeof buffer, "<%d>", static_cast<int>(level));
  } else {
    const int64_t s = stamp_ns / 1'000'000'000;
    const int64_t us = (stamp_ns % 1'000'000'000) / 1000;
    prefix = std::snprintf(buffer, sizeof buffer, "[%5lld.%06lld] %s: ", static_cast<long long>(s),
                           static_cast<long long>(us < 0 ? -us : us), logLevelName(level));
  }
  std::size_t size = prefix > 0 ? static_cast<std::size_t>(prefix) : 0;
  const std::size_t room = sizeof buffer - size - 1;
  const std::size_t n = line.size() < room ? line.size() : room;
  std::memcpy(buffer + size, line.data(), n);
  size += n;
  buffer[size++] = '\n';
  writeAll(fd_, buffer, size);
}

bool isJournalStream(const char* journal_stream, int fd) {
  if (journal_stream == nullptr) return false;
  unsigned long long dev = 0, ino = 0;
  if (std::sscanf(journal_stream, "%llu:%llu", &dev, &ino) != 2) return false;
  struct stat st {};
  if (::fstat(fd, &st) != 0) return false;
  return static_cast<unsigned long long>(st.st_dev) == dev && static_cast<unsigned long long>(st.st_ino) == ino;
}

std::unique_ptr<LogSink> makeDefaultLogSink() {
  if (isJournalStream(std::getenv("JOURNAL_STREAM"), STDERR_FILENO)) {
#ifdef FOVEA_HAVE_SYSTEMD
    // libsystemd drops entries silently when the journal's socket is missing.
    if (::access("/run/systemd/journal/socket", W_OK) == 0) return std::make_unique<JournalLogSink>();
#endif
    return std::make_unique<FdLogSink>(STDERR_FILENO, FdLogSink::Style::kJournalStream);
  }
  return std::make_unique<FdLogSink>(STDERR_FILENO, FdLogSink::Style::kPlain);
}

int64_t Logger::monotonicNowNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

void Logger::emit(LogLevel level, int64_t now_ns, uint64_t repeated, const char* format, va_list args) {
  char line[kLogLineBytes];
  constexpr std::size_t kSuffixRoom = 40;  // " (repeated 18446744073709551615 times)"
  const std::size_t body_room = sizeof line - kSuffixRoom;
  const int written = std::vsnprintf(line, body_room, format, args);
  std::size_t size = 0;
  if (written < 0) {
    size = static_cast<std::size_t>(std::snprintf(line, body_room, "(bad log format: %s)", format));
    if (size >= body_room) size = body_room - 1;
  } else if (static_cast<std::size_t>(written) >= body_room) {
    size = body_room - 1;
    std::memcpy(line + size - 3, "...", 3);
  } else {
    size = static_cast<std::size_t>(written);
  }
  // One event, one line.
  for (std::size_t i = 0; i < size; ++i) {
    if (line[i] == '\n' || line[i] == '\r') line[i] = ' ';
  }
  if (repeated > 0) {
    const int n = std::snprintf(line + size, sizeof line - size, " (repeated %llu times)",
                                static_cast<unsigned long long>(repeated));
    if (n > 0) size += static_cast<std::size_t>(n);
  }
  sink_->write(level, now_ns, std::string_view(line, size));
  lines_written_.fetch_add(1, std::memory_order_relaxed);
}

void Logger::log(LogLevel level, const char* format, ...) {
  if (!enabled(level)) return;
  va_list args;
  va_start(args, format);
  emit(level, clock_(), 0, format, args);
  va_end(args);
}

bool Logger::logLimited(LogRateLimit& site, LogLevel level, const char* format, ...) {
  if (!enabled(level)) return false;
  const int64_t now = clock_();
  int64_t last = site.last_emit_ns_.load(std::memory_order_relaxed);
  // The CAS lets one thread of several emit; the others count themselves.
  if ((last != LogRateLimit::kNever && now - last < site.interval_ns_) ||
      !site.last_emit_ns_.compare_exchange_strong(last, now, std::memory_order_relaxed)) {
    site.suppressed_.fetch_add(1, std::memory_order_relaxed);
    events_suppressed_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  const uint64_t repeated = site.suppressed_.exchange(0, std::memory_order_relaxed);
  va_list args;
  va_start(args, format);
  emit(level, now, repeated, format, args);
  va_end(args);
  return true;
}

Logger& logger() {
  static const std::unique_ptr<LogSink> sink = makeDefaultLogSink();
  static Logger instance(*sink);
  return instance;
}

}  // namespace fovea::firmware

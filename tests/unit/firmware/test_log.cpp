// Logging: levels, the line format of each sink style, rate limiting on a fake
// clock, journal detection (no heap allocation: test_log_alloc.cpp).
#include "firmware/log.h"
#include "tests/unit/firmware/log_sinks.h"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

namespace fovea::firmware {
namespace {

using fovea::test::FakeClock;
using fovea::test::LastLineSink;

constexpr int64_t kMs = 1'000'000;

struct Line {
  LogLevel level;
  int64_t stamp_ns;
  std::string text;
};

class CaptureSink final : public LogSink {
 public:
  void write(LogLevel level, int64_t stamp_ns, std::string_view line) override {
    lines.push_back({level, stamp_ns, std::string(line)});
  }
  std::vector<Line> lines;
};

TEST(Log, LevelsFilterAndNameTheSeverity) {
  CaptureSink sink;
  FakeClock clock;
  Logger log(sink, clock.clock(), LogLevel::kWarning);
  log.log(LogLevel::kInfo, "not shown");
  log.log(LogLevel::kDebug, "not shown");
  log.log(LogLevel::kWarning, "camera: %s", "timeout");
  log.log(LogLevel::kError, "camera: gone");
  log.setLevel(LogLevel::kDebug);
  log.log(LogLevel::kDebug, "shown %d", 7);
  ASSERT_EQ(sink.lines.size(), 3u);
  EXPECT_EQ(sink.lines[0].text, "camera: timeout");
  EXPECT_EQ(sink.lines[0].level, LogLevel::kWarning);
  EXPECT_EQ(sink.lines[1].level, LogLevel::kError);
  EXPECT_EQ(sink.lines[2].text, "shown 7");
  EXPECT_EQ(log.linesWritten(), 3u);
  EXPECT_EQ(static_cast<int>(LogLevel::kError), 3);  // syslog priorities
  EXPECT_EQ(static_cast<int>(LogLevel::kDebug), 7);

  EXPECT_EQ(parseLogLevel("notice").value(), LogLevel::kNotice);
  auto bad = parseLogLevel("loud");
  ASSERT_FALSE(bad.isOk());
  EXPECT_EQ(bad.status().message(), "log level: unknown 'loud'; accepted: error|warning|notice|info|debug");
}

TEST(Log, OneLinePerEventAndLongLinesAreCut) {
  CaptureSink sink;
  FakeClock clock;
  Logger log(sink, clock.clock());
  log.log(LogLevel::kInfo, "two\nlines\r");
  EXPECT_EQ(sink.lines.back().text, "two lines ");
  const std::string long_text(2000, 'x');
  log.log(LogLevel::kInfo, "%s", long_text.c_str());
  const std::string& cut = sink.lines.back().text;
  EXPECT_LT(cut.size(), kLogLineBytes);
  EXPECT_EQ(cut.substr(cut.size() - 3), "...");
}

std::string readBack(int fd) {
  std::string out;
  char buffer[1024];
  ::lseek(fd, 0, SEEK_SET);
  ssize_t n = 0;
  while ((n = ::read(fd, buffer, sizeof buffer)) > 0) out.append(buffer, static_cast<std::size_t>(n));
  return out;
}

TEST(Log, PlainAndJournalStreamFormats) {
  std::FILE* file = std::tmpfile();
  ASSERT_NE(file, nullptr);
  const int fd = ::fileno(file);
  FdLogSink plain(fd, FdLogSink::Style::kPlain);
  plain.write(LogLevel::kWarning, 12'345'678'901, "camera: frame timeout");
  plain.write(LogLevel::kInfo, 5 * kMs, "started");
  FdLogSink journal(fd, FdLogSink::Style::kJournalStream);
  journal.write(LogLevel::kError, 0, "gpio: gone");
  EXPECT_EQ(readBack(fd),
            "[   12.345678] warning: camera: frame timeout\n"
            "[    0.005000] info: started\n"
            "<3>gpio: gone\n");
  std::fclose(file);
}

TEST(Log, AnEventRepeating1000TimesASecondLogsOnceASecondWithACount) {
  CaptureSink sink;
  FakeClock clock;
  Logger log(sink, clock.clock());
  LogRateLimit site;
  for (int64_t t_ms = 0; t_ms < 3500; ++t_ms) {
    clock.now_ns = t_ms * kMs;
    (void)log.logLimited(site, LogLevel::kWarning, "camera: frame timeout after %d ms", 100);
  }
  ASSERT_EQ(sink.lines.size(), 4u);
  EXPECT_EQ(sink.lines[0].text, "camera: frame timeout after 100 ms");
  EXPECT_EQ(sink.lines[0].stamp_ns, 0);
  for (int i = 1; i < 4; ++i) {
    EXPECT_EQ(sink.lines[i].text, "camera: frame timeout after 100 ms (repeated 999 times)") << i;
    EXPECT_EQ(sink.lines[i].stamp_ns, i * 1000 * kMs);
  }
  EXPECT_EQ(log.eventsSuppressed(), 3500u - 4u);
}

TEST(Log, SitesAndKeysAreLimitedIndependentlyAndIntervalsAreTheirs) {
  CaptureSink sink;
  FakeClock clock;
  Logger log(sink, clock.clock());
  LogRateLimit per_camera[2];
  LogRateLimit fast(100 * kMs);
  for (int64_t t_ms = 0; t_ms < 250; t_ms += 10) {
    clock.now_ns = t_ms * kMs;
    for (int cam = 0; cam < 2; ++cam) {
      (void)log.logLimited(per_camera[cam], LogLevel::kWarning, "camera %d: stall", cam);
    }
    (void)log.logLimited(fast, LogLevel::kNotice, "gaze: stale");
  }
  std::vector<std::string> texts;
  for (const Line& l : sink.lines) texts.push_back(l.text);
  EXPECT_EQ(texts, (std::vector<std::string>{"camera 0: stall", "camera 1: stall", "gaze: stale",
                                             "gaze: stale (repeated 9 times)", "gaze: stale (repeated 9 times)"}));
}

TEST(Log, FilteredEventsAreNotCountedAsRepeats) {
  CaptureSink sink;
  FakeClock clock;
  Logger log(sink, clock.clock(), LogLevel::kWarning);
  LogRateLimit site;
  EXPECT_FALSE(log.logLimited(site, LogLevel::kDebug, "noise"));
  EXPECT_TRUE(log.logLimited(site, LogLevel::kWarning, "real"));
  EXPECT_EQ(sink.lines.back().text, "real");
}

TEST(Log, ThreadsSharingASiteLoseNoCount) {
  LastLineSink sink;
  FakeClock clock;  // time stands still: only the first event logs
  Logger log(sink, clock.clock());
  LogRateLimit site;
  auto hammer = [&] {
    for (int i = 0; i < 100'000; ++i) (void)log.logLimited(site, LogLevel::kWarning, "flood");
  };
  std::thread a(hammer), b(hammer);
  a.join();
  b.join();
  EXPECT_EQ(sink.count, 1u);
  EXPECT_EQ(log.linesWritten() + log.eventsSuppressed(), 200'000u);
  clock.now_ns = 2'000 * kMs;
  EXPECT_TRUE(log.logLimited(site, LogLevel::kWarning, "flood"));
  EXPECT_EQ(std::string(sink.text, sink.size), "flood (repeated 199999 times)");
}

TEST(Log, TheMacroGivesEachCallSiteItsOwnLimit) {
  Logger& global = logger();
  const uint64_t lines = global.linesWritten();
  const uint64_t suppressed = global.eventsSuppressed();
  for (int i = 0; i < 10; ++i) FOVEA_LOG_LIMITED(LogLevel::kWarning, "test_log: site one, event %d", i);
  for (int i = 0; i < 10; ++i) FOVEA_LOG_LIMITED(LogLevel::kWarning, "test_log: site two, event %d", i);
  EXPECT_EQ(global.linesWritten() - lines, 2u);  // on stderr, in well under a second
  EXPECT_EQ(global.eventsSuppressed() - suppressed, 18u);
}

TEST(Log, JournalStreamIsDetectedFromDeviceAndInode) {
  std::FILE* file = std::tmpfile();
  ASSERT_NE(file, nullptr);
  const int fd = ::fileno(file);
  struct stat st {};
  ASSERT_EQ(::fstat(fd, &st), 0);
  const std::string match = std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino);
  const std::string other = std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino + 1);
  EXPECT_TRUE(isJournalStream(match.c_str(), fd));
  EXPECT_FALSE(isJournalStream(other.c_str(), fd));
  EXPECT_FALSE(isJournalStream(nullptr, fd));
  EXPECT_FALSE(isJournalStream("garbage", fd));
  std::fclose(file);
}

}  // namespace
}  // namespace fovea::firmware

// Logging allocates nothing: a binary of its own, because it replaces the
// allocator (tests/support/alloc_counter.cpp), which sanitizers do too.
#include <fcntl.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cstdlib>
#include <string_view>

#include "firmware/log.h"
#include "tests/unit/firmware/log_sinks.h"
#include "tests/support/alloc_counter.h"

namespace fovea::firmware {
namespace {

using fovea::test::FakeClock;
using fovea::test::LastLineSink;

constexpr int64_t kMs = 1'000'000;

TEST(Log, LoggingDoesNotAllocate) {
  {
    test::AllocationScope check;  // the counter works
    void* volatile raw = std::malloc(10);
    std::free(raw);
    ASSERT_GE(check.allocations(), 1u);
  }
  LastLineSink sink;
  FakeClock clock;
  Logger log(sink, clock.clock(), LogLevel::kDebug);
  LogRateLimit site;
  const int null_fd = ::open("/dev/null", O_WRONLY);
  ASSERT_GE(null_fd, 0);
  FdLogSink devnull(null_fd, FdLogSink::Style::kPlain);
  Logger to_fd(devnull, clock.clock());
  log.log(LogLevel::kInfo, "warm-up %d", 1);  // first use of anything lazily set up

  uint64_t allocations = 0;
  {
    test::AllocationScope scope;
    for (int64_t t_ms = 0; t_ms < 5000; ++t_ms) {
      clock.now_ns = t_ms * kMs;
      (void)log.logLimited(site, LogLevel::kWarning, "camera %s: %d bad frames, %.1f%%", "mock", 12, 3.5);
      if (t_ms % 500 == 0) {
        log.log(LogLevel::kInfo, "status: %d fps", 30);
        to_fd.log(LogLevel::kInfo, "status: %d fps", 30);
      }
    }
    allocations = scope.allocations();
  }
  ::close(null_fd);
  EXPECT_EQ(allocations, 0u);
  EXPECT_EQ(sink.count, 1u + 5u + 10u);
}

}  // namespace
}  // namespace fovea::firmware

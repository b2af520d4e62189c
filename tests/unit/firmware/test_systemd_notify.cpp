// SystemdNotifier's own datagram path (built here without FOVEA_HAVE_SYSTEMD,
// whatever the build found; test_service covers the build's choice): messages
// reach a fake NOTIFY_SOCKET, path or abstract; WATCHDOG_USEC is read.
#include "firmware/systemd_notify.h"

#include <stdlib.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include "tests/support/process.h"
#include "tests/support/service_doubles.h"

namespace fovea::firmware {
namespace {

#ifdef FOVEA_HAVE_SYSTEMD
#error "this test builds the fallback: it must not see FOVEA_HAVE_SYSTEMD"
#endif

TEST(SystemdNotify, WithoutNotifySocketEverythingIsANoOp) {
  unsetenv("NOTIFY_SOCKET");
  unsetenv("WATCHDOG_USEC");
  SystemdNotifier notifier;
  EXPECT_FALSE(notifier.active());
  EXPECT_EQ(notifier.watchdogNs(), 0);
  EXPECT_FALSE(notifier.notify("READY=1"));
}

TEST(SystemdNotify, SendsDatagramsToThePathInNotifySocket) {
  test::TempDir dir;
  test::FakeNotifySocket systemd(dir.file("notify"));
  ASSERT_TRUE(systemd.bound());
  setenv("NOTIFY_SOCKET", systemd.path().c_str(), 1);
  setenv("WATCHDOG_USEC", "5000000", 1);
  setenv("WATCHDOG_PID", std::to_string(getpid()).c_str(), 1);
  SystemdNotifier notifier;
  unsetenv("NOTIFY_SOCKET");
  unsetenv("WATCHDOG_USEC");
  unsetenv("WATCHDOG_PID");
  EXPECT_TRUE(notifier.active());
  EXPECT_EQ(notifier.watchdogNs(), 5'000'000'000);
  EXPECT_TRUE(notifier.notify("READY=1"));
  EXPECT_TRUE(notifier.notify("STATUS=status: fps in 30.0"));
  EXPECT_TRUE(notifier.notify("WATCHDOG=1"));
  const std::vector<std::string> got = systemd.receive(100);
  ASSERT_EQ(got.size(), 3u);
  EXPECT_EQ(got[0], "READY=1");
  EXPECT_EQ(got[1], "STATUS=status: fps in 30.0");
  EXPECT_EQ(got[2], "WATCHDOG=1");
  EXPECT_EQ(notifier.sent(), 3u);
}

TEST(SystemdNotify, WatchdogForAnotherPidIsNotOurs) {
  setenv("WATCHDOG_USEC", "5000000", 1);
  setenv("WATCHDOG_PID", "1", 1);
  SystemdNotifier notifier;
  unsetenv("WATCHDOG_USEC");
  unsetenv("WATCHDOG_PID");
  EXPECT_EQ(notifier.watchdogNs(), 0);
}

TEST(SystemdNotify, AMissingSocketCountsAnError) {
  setenv("NOTIFY_SOCKET", "/nonexistent/fovea-notify", 1);
  SystemdNotifier notifier;
  unsetenv("NOTIFY_SOCKET");
  EXPECT_FALSE(notifier.notify("READY=1"));
  EXPECT_EQ(notifier.errors(), 1u);
}

}  // namespace
}  // namespace fovea::firmware

// fovea-operator --view as a process, with a tab on its WebSocket: the states
// the page shows as the robot refuses (busy with another operator), accepts,
// streams and goes away, and the operator reconnecting throughout; and that
// the operator started with --view and no robot keeps serving the page.
#include <gtest/gtest.h>

#include <signal.h>

#include <regex>
#include <string>

#include "tests/support/process.h"
#include "tests/support/test_time.h"
#include "tests/support/websocket_tab.h"

namespace fovea {
namespace {

using namespace std::chrono_literals;
using test::waitUntil;

std::string program(const char* path) {
  const std::string emulator = FOVEA_EMULATOR;
  return emulator.empty() ? std::string(path) : emulator + " " + path;
}

// The port in "viewer: open http://127.0.0.1:PORT/".
int viewerPort(test::BackgroundProcess& op) {
  if (!op.waitFor("viewer: open http://127.0.0.1:", 10) || !op.waitFor("/\n", 2)) return -1;
  std::smatch m;
  const std::string out = op.output();
  return std::regex_search(out, m, std::regex("viewer: open http://127\\.0\\.0\\.1:(\\d+)/")) ? std::stoi(m[1].str()) : -1;
}

class OperatorView : public ::testing::Test {
 protected:
  void SetUp() override {
    test::initTabs();
    const test::ProcessResult keygen = test::runCommand(program(FOVEAD_PATH) + " keygen " + dir_.file("key"));
    ASSERT_EQ(keygen.exit_code, 0) << keygen.output;
  }
  std::string operatorCommand(const std::string& address, const std::string& flags) {
    return program(FOVEA_OPERATOR_PATH) + " --connect " + address + " --key-file " + dir_.file("key") + " " + flags;
  }
  test::TempDir dir_;
};

TEST_F(OperatorView, ThePageFollowsTheRobotRefusingStreamingAndGoingAway) {
  test::BackgroundProcess robot(program(FOVEAD_PATH) + " run --camera mock:living-room,size=160x120,fps=15 --every 0 " +
                                "--listen 127.0.0.1:0 --key-file " + dir_.file("key"));
  ASSERT_TRUE(robot.waitFor("streaming: listening on ", 10) && robot.waitFor(" (", 2))
      << robot.output();
  std::smatch m;
  const std::string robot_out = robot.output();
  ASSERT_TRUE(std::regex_search(robot_out, m, std::regex("listening on (\\S+) \\(")));
  const std::string address = m[1].str();

  // Another operator holds the robot: the viewer's operator is refused, and says why.
  test::BackgroundProcess first(operatorCommand(address, "--name alice --gaze 'fixed:3,0.35,1.55>3,2.25,1.35' --quiet"));
  ASSERT_TRUE(first.waitFor("connected to", 10)) << first.output();
  test::BackgroundProcess op(operatorCommand(address, "--name viewer --view 127.0.0.1:0 --quiet --summary " +
                                                          dir_.file("summary.json")));
  const int port = viewerPort(op);
  ASSERT_GT(port, 0) << op.output();
  test::Tab tab(port);
  ASSERT_TRUE(tab.connected()) << tab.error();
  ASSERT_TRUE(waitUntil([&] { return tab.hasText("\"state\":\"refused\""); }, 10s)) << op.output();
  EXPECT_TRUE(tab.hasText("alice")) << "the robot's reason names who it serves";

  // The first operator leaves: the viewer's operator gets in and frames flow to the tab.
  // (Its exit status says whether a frame reached it before it left: not the point here.)
  EXPECT_NE(first.stop(SIGTERM, 10), -1) << first.output();
  ASSERT_TRUE(waitUntil([&] { return tab.hasText("\"state\":\"streaming\""); }, 10s)) << op.output();
  ASSERT_TRUE(waitUntil([&] { return tab.frames() >= 3; }, 10s)) << op.output();
  const std::vector<uint8_t> frame = tab.lastFrame();
  ASSERT_GE(frame.size(), 136u);
  EXPECT_EQ(std::string(frame.begin(), frame.begin() + 4), "FVF2");

  // The robot stops (it says Bye): the page shows it gone, the operator keeps trying.
  EXPECT_EQ(robot.stop(SIGTERM, 10), 0) << robot.output();
  ASSERT_TRUE(waitUntil([&] { return tab.hasText("\"state\":\"robot-gone\""); }, 10s)) << op.output();
  ASSERT_TRUE(op.waitFor("reconnecting", 5)) << op.output();
  EXPECT_FALSE(tab.closedByServer());

  tab.close();
  EXPECT_EQ(op.stop(SIGTERM, 20), 0) << op.output();  // it received frames: success
  const std::string out = op.output();
  EXPECT_NE(out.find("viewer: 1 tabs served"), std::string::npos) << out;
}

TEST_F(OperatorView, WithoutARobotThePageStaysUpAndSaysSo) {
  // A port nobody listens on (the robot is not up yet).
  test::BackgroundProcess op(operatorCommand("127.0.0.1:9", "--view 127.0.0.1:0 --quiet --duration 30"));
  const int port = viewerPort(op);
  ASSERT_GT(port, 0) << op.output();
  test::Tab tab(port);
  ASSERT_TRUE(waitUntil([&] { return tab.hasText("\"type\":\"hello\""); }, 10s));
  ASSERT_TRUE(waitUntil([&] { return tab.hasText("\"state\":\"connecting\""); }, 10s));
  ASSERT_TRUE(op.waitFor("trying again in 1 s", 10)) << op.output();
  // Still serving after a failed attempt; SIGTERM ends it, with no frames: exit 1.
  tab.send(R"({"type":"gaze","origin":[0,0,1],"direction":[0,1,0]})");
  EXPECT_EQ(op.stop(SIGTERM, 20), 1) << op.output();
  EXPECT_NE(op.output().find("viewer: 1 tabs served (0 refused)"), std::string::npos) << op.output();
}

TEST_F(OperatorView, BadViewAddressesAreUsageErrors) {
  for (const char* view : {"robot:80", "99999", "1.2.3.4.5:80"}) {
    const test::ProcessResult r = test::runCommand(operatorCommand("127.0.0.1:9", std::string("--view ") + view) + " 2>&1");
    EXPECT_EQ(r.exit_code, 2) << view << ": " << r.output;
    EXPECT_NE(r.output.find("--view: "), std::string::npos) << r.output;
  }
  const test::ProcessResult r = test::runCommand(operatorCommand("127.0.0.1:9", "") + " 2>&1");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--gaze SCRIPT is required (or --view"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace fovea

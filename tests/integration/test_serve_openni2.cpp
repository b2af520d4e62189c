// fovead serve on a real camera backend, as processes over loopback: OpenNI2's
// synthetic Dummy device (openni2:Dummy) foveated by the service and decoded by
// fovea-operator. And the clear refusals: an .oni recording, no device.
#include <signal.h>

#include <regex>
#include <string>

#include <gtest/gtest.h>

#include "tests/support/process.h"
#include "tests/support/programs.h"
#include "tests/support/test_time.h"

namespace fovea {
namespace {

std::string fovead() { return test::program(FOVEAD_PATH); }
std::string foveaOperator() { return test::program(FOVEA_OPERATOR_PATH); }

std::string readFile(const std::string& path) {
  const test::ProcessResult cat = test::runCommand("cat " + path);
  return cat.output;
}

TEST(ServeOpenNI2, DummyDeviceIsFoveatedAndStreamedToTheOperator) {
  if (test::emulated()) {
    GTEST_SKIP() << "OpenNI2\'s runtime hangs under qemu-user: runs natively only";
  }
  test::TempDir dir;
  test::BackgroundProcess serve(fovead() +
                                " serve --camera openni2:Dummy --listen 127.0.0.1:0 --insecure --status-interval-ms 500");
  ASSERT_TRUE(serve.started());
  ASSERT_TRUE(serve.waitFor("running", 20.0)) << serve.output();
  const std::string out = serve.output();
  EXPECT_NE(out.find("camera openni2:Dummy"), std::string::npos) << out;
  std::smatch port;
  ASSERT_TRUE(std::regex_search(out, port, std::regex("listening on 127\\.0\\.0\\.1:([0-9]+)"))) << out;
  // The Dummy is the camera's frame (no pose): look down its optical axis,
  // where its depth lies (1 to 2 m).
  const std::string summary_path = dir.file("summary.json");
  const test::ProcessResult op =
      test::runCommand(foveaOperator() + " --connect 127.0.0.1:" + port[1].str() +
                       " --insecure --gaze 'fixed:0,0,0>0,0,1.5' --duration 3 --summary " + summary_path);
  EXPECT_EQ(op.exit_code, 0) << op.output << "\n--- service:\n" << serve.output();
  std::smatch m;
  ASSERT_TRUE(std::regex_search(op.output, m, std::regex("summary: ([0-9]+) frames"))) << op.output;
  // 30 fps for 3 s natively. A sanitized service on a loaded 2-core machine
  // managed 4; three frames still show the stream decodes end to end.
  EXPECT_GE(std::stoi(m[1].str()), test::repetitions(10, 3)) << op.output;
  EXPECT_NE(op.output.find(" 0 bad"), std::string::npos) << op.output;

  // Points decoded: the summary's per-region points per frame add up to more than 0.
  const std::string summary = readFile(summary_path);
  ASSERT_TRUE(std::regex_search(summary, m, std::regex("\"points_per_frame_by_region\": \\[([^\\]]*)\\]")))
      << summary;
  double points = 0;
  const std::string list = m[1].str();
  const std::regex number("[0-9.e+-]+");
  for (std::sregex_iterator it(list.begin(), list.end(), number), end; it != end; ++it) {
    points += std::stod(it->str());
  }
  EXPECT_GT(points, 0.0) << summary;
  EXPECT_NE(summary.find("\"datagrams_invalid\": 0"), std::string::npos) << summary;

  ASSERT_TRUE(serve.waitFor("out ", 5.0)) << serve.output();
  // Under ASan the OPENNI2 tests unwind slowly (tests/CMakeLists.txt), and
  // LeakSanitizer's check at exit then takes 1.5 s on an idle 2-core host; stop()
  // scales the wait for that build and a loaded machine. A hang still fails.
  const int exit_code = serve.stop(SIGTERM, 5.0);
  EXPECT_EQ(exit_code, 0) << serve.output();
  EXPECT_NE(serve.output().find("gaze: operator"), std::string::npos) << serve.output();
}

TEST(ServeOpenNI2, FrameLimitOnTheDummy) {
  if (test::emulated()) {
    GTEST_SKIP() << "OpenNI2\'s runtime hangs under qemu-user: runs natively only";
  }
  const test::ProcessResult done = test::runCommand(fovead() + " serve --camera openni2:Dummy --frames 20");
  EXPECT_EQ(done.exit_code, 0) << done.output;
  EXPECT_NE(done.output.find("stopped: 20 frames captured"), std::string::npos) << done.output;
  EXPECT_NE(done.output.find("no field of view"), std::string::npos) << done.output;  // said once, at open
}

TEST(ServeOpenNI2, OniRecordingIsRefusedNotHung) {
  const test::ProcessResult oni = test::runCommand(fovead() + " serve --camera openni2:session.oni --frames 5");
  EXPECT_NE(oni.exit_code, 0) << oni.output;
  EXPECT_NE(oni.output.find(".oni recording"), std::string::npos) << oni.output;
  EXPECT_NE(oni.output.find("tum:PATH"), std::string::npos) << oni.output;
}

TEST(ServeOpenNI2, NoDeviceSaysWhatToDo) {
  if (test::emulated()) {
    GTEST_SKIP() << "OpenNI2\'s runtime hangs under qemu-user: runs natively only";
  }
  const test::ProcessResult none = test::runCommand(fovead() + " serve --camera openni2: --frames 5");
  if (none.exit_code == 0) GTEST_SKIP() << "an OpenNI2 device is plugged in: " << none.output;
  EXPECT_NE(none.output.find("no OpenNI2 device found"), std::string::npos) << none.output;
  EXPECT_NE(none.output.find("lsusb"), std::string::npos) << none.output;
}

}  // namespace
}  // namespace fovea

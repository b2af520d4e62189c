// The session recording's per-frame pose message (firmware/session_recorder.h,
// docs/recording.md): with tracking it says the frame's outcome, why a lost
// frame was lost, and its moving share; without, none of these.
#include "firmware/session_recorder.h"

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "io/mcap/reader.h"
#include "tests/unit/firmware/log_sinks.h"

namespace fovea::firmware {
namespace {

std::string tempPath(const char* name) {
  const char* tmp = std::getenv("TMPDIR");
  return std::string(tmp && *tmp ? tmp : "/tmp") + "/fovea-" + name + "-" + std::to_string(::getpid()) + ".mcap";
}

// The /fovea/camera_pose messages' JSON, in file order.
std::vector<std::string> cameraPoses(const std::string& path) {
  std::vector<std::string> out;
  Result<std::vector<uint8_t>> bytes = mcap::readFile(path);
  EXPECT_TRUE(bytes.isOk());
  if (!bytes.isOk()) return out;
  mcap::Reader reader(*bytes);
  while (reader.next() != mcap::Reader::Item::kEnd) {
    if (reader.messagesRead() == 0 || reader.message().data.data() == nullptr) continue;
    const mcap::ChannelRecord* channel = reader.findChannel(reader.message().channel_id);
    if (channel == nullptr || channel->topic != "/fovea/camera_pose") continue;
    const auto& data = reader.message().data;
    out.emplace_back(reinterpret_cast<const char*>(data.data()), data.size());
  }
  EXPECT_TRUE(reader.complete()) << reader.stopReason();
  return out;
}

TEST(SessionRecorder, TheCameraPoseSaysTheTrackingOutcomeAndTheMovingShare) {
  test::RecordingSink sink;
  Logger log(sink);
  RecordSettings settings;
  settings.path = tempPath("recorder-tracking");
  Result<std::unique_ptr<SessionRecorder>> created = SessionRecorder::create(settings, log);
  ASSERT_TRUE(created.isOk()) << created.status().toString();
  SessionRecorder& recorder = *created.value();
  ASSERT_TRUE(recorder.start().isOk());
  hal::RgbdFrame frame(8, 8);
  pipeline::FoveatedCloud cloud(4);
  pipeline::map::TrackStats tracked;
  tracked.outcome = pipeline::map::TrackOutcome::kTracked;
  tracked.moving_share = 0.3125;
  pipeline::map::TrackStats lost;
  lost.outcome = pipeline::map::TrackOutcome::kLost;
  lost.lost_reason = pipeline::map::LostReason::kMostlyMoving;
  lost.moving_share = 0.875;
  recorder.onFrame(1, 100, frame, true, cloud, &tracked);
  recorder.onFrame(2, 200, frame, true, cloud, &lost);
  recorder.onFrame(3, 300, frame, true, cloud, nullptr);
  ASSERT_TRUE(recorder.close().isOk());
  const std::vector<std::string> poses = cameraPoses(settings.path);
  std::remove(settings.path.c_str());
  ASSERT_EQ(poses.size(), 3u);
  EXPECT_NE(poses[0].find(R"("tracking":"tracked","moving_share":0.3125})"), std::string::npos) << poses[0];
  EXPECT_NE(poses[1].find(R"("tracking":"lost","lost_reason":"mostly-moving","moving_share":0.8750})"),
            std::string::npos)
      << poses[1];
  EXPECT_EQ(poses[2].find("tracking"), std::string::npos) << poses[2];
  EXPECT_EQ(poses[2].find("moving_share"), std::string::npos) << poses[2];
  EXPECT_EQ(poses[2].back(), '}');
}

}  // namespace
}  // namespace fovea::firmware

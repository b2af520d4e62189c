// The mcap: camera (firmware/mcap_camera.h): frames recorded from the TUM camera
// into an MCAP file come back bit for bit, in order, looped with increasing
// stamps; a file cut off plays to its last whole chunk and says where it
// stopped; files without frames and bad specs are clear errors; and acquire()
// allocates nothing once started.
#include "firmware/mcap_camera.h"

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "firmware/frame_record.h"
#include "io/mcap/writer.h"
#include "tests/support/alloc_counter.h"
#include "tests/support/tum_frames.h"

namespace fovea::firmware {
namespace {

using namespace std::chrono_literals;

std::string tempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("fovea_mcap_camera_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

// Records `count` frames of the TUM camera (the sequence at `sequence`) into `path` (as fovead serve
// --record-frames does: one FrameRecord message each), returning the frames.
std::vector<hal::RgbdFrame> recordTum(const std::string& sequence, const std::string& path, int count,
                                      std::size_t chunk_bytes = 1 << 20) {
  Result<std::unique_ptr<hal::Camera>> tum = hal::createCamera("tum:" + sequence + ",loop=off");
  EXPECT_TRUE(tum) << tum.status().message();
  hal::Camera& camera = *tum.value();
  EXPECT_TRUE(camera.open()) << camera.open().message();
  EXPECT_TRUE(camera.start());
  mcap::WriterOptions options;
  options.chunk_bytes = chunk_bytes;
  std::unique_ptr<mcap::Writer> writer = mcap::Writer::open(path, options).value();
  const uint16_t schema = writer->addSchema(kFrameRecordSchemaName, "fovea.frame_record", frameRecordSchemaText()).value();
  const uint16_t other = writer->addSchema("fovea.Other", "json", {}).value();
  const uint16_t frames = writer->addChannel(kFramesTopic, "fovea.frame_record", schema).value();
  const uint16_t noise = writer->addChannel("/fovea/other", "json", other).value();
  std::vector<hal::RgbdFrame> recorded;
  std::vector<uint8_t> bytes;
  for (int i = 0; i < count; ++i) {
    hal::RgbdFrame frame(640, 480);
    EXPECT_TRUE(camera.acquire(frame, 1s));
    bytes.resize(frameRecordBytes(frame.width(), frame.height(), frame.has_rgb));
    EXPECT_EQ(encodeFrameRecord(frame, bytes), bytes.size());
    const auto t = static_cast<uint64_t>(frame.stamp_ns);
    EXPECT_TRUE(writer->write(frames, t, t, bytes));
    const uint8_t other_message[] = {'{', '}'};
    EXPECT_TRUE(writer->write(noise, t, t, other_message));  // another channel between the frames
    recorded.push_back(std::move(frame));
  }
  EXPECT_TRUE(writer->close());
  return recorded;
}

void expectSame(const hal::RgbdFrame& a, const hal::RgbdFrame& b, int64_t stamp_offset_ns, uint64_t sequence_offset) {
  ASSERT_EQ(a.width(), b.width());
  ASSERT_EQ(a.height(), b.height());
  EXPECT_EQ(0, std::memcmp(a.depth(), b.depth(), a.pixelCount() * 2));
  EXPECT_EQ(0, std::memcmp(a.rgb(), b.rgb(), a.pixelCount() * 3));
  EXPECT_EQ(a.intrinsics.fx, b.intrinsics.fx);
  EXPECT_EQ(a.intrinsics.cx, b.intrinsics.cx);
  EXPECT_EQ(a.depth_scale_m, b.depth_scale_m);
  EXPECT_EQ(a.T_world_cam.R_world_cam, b.T_world_cam.R_world_cam);
  EXPECT_EQ(a.T_world_cam.t_world_cam, b.T_world_cam.t_world_cam);
  EXPECT_EQ(a.stamp_ns + stamp_offset_ns, b.stamp_ns);
  EXPECT_EQ(a.sequence + sequence_offset, b.sequence);
}

TEST(McapCamera, ReplaysTheRecordedTumFramesBitForBitAndLoops) {
  FOVEA_REQUIRE_TUM_TEDDY(tum);
  const std::string path = tempPath("tum.mcap");
  const std::vector<hal::RgbdFrame> recorded = recordTum(tum, path, 5);
  std::unique_ptr<hal::Camera> camera = createCamera("mcap:" + path).value();
  ASSERT_TRUE(camera->open()) << camera->open().message();
  EXPECT_EQ(camera->info().intrinsics.width, 640);
  EXPECT_NEAR(camera->info().fps, 30.0, 3.0);
  EXPECT_NE(camera->info().model.find("5 frames"), std::string::npos) << camera->info().model;
  ASSERT_TRUE(camera->start());
  hal::RgbdFrame slot(640, 480);
  for (const hal::RgbdFrame& f : recorded) {
    ASSERT_TRUE(camera->acquire(slot, 1s));
    expectSame(f, slot, 0, 0);
  }
  // The second pass: the same images, stamps one recording length (and a period) on.
  const int64_t span = recorded.back().stamp_ns - recorded.front().stamp_ns;
  const int64_t loop = span + span / 4;
  for (const hal::RgbdFrame& f : recorded) {
    ASSERT_TRUE(camera->acquire(slot, 1s));
    expectSame(f, slot, loop, 5);
  }
  EXPECT_EQ(camera->counters().frames_delivered, 10u);
  std::filesystem::remove(path);
}

TEST(McapCamera, WithoutLoopTheEndIsTheEnd) {
  FOVEA_REQUIRE_TUM_TEDDY(tum);
  const std::string path = tempPath("once.mcap");
  recordTum(tum, path, 2);
  std::unique_ptr<hal::Camera> camera = createCamera("mcap:" + path + ",loop=off").value();
  ASSERT_TRUE(camera->open());
  ASSERT_TRUE(camera->start());
  hal::RgbdFrame slot(640, 480);
  EXPECT_TRUE(camera->acquire(slot, 1s));
  EXPECT_TRUE(camera->acquire(slot, 1s));
  const Status end = camera->acquire(slot, 1s);
  EXPECT_EQ(end.code(), ErrorCode::kUnavailable);
  EXPECT_EQ(end.message(), "end of record");
  EXPECT_TRUE(static_cast<McapCamera&>(*camera).finished());
  std::filesystem::remove(path);
}

// A power cut: the file ends inside its last chunk. What came before plays, and
// the camera says where the file stopped being readable.
TEST(McapCamera, ACutOffFilePlaysToItsLastWholeChunk) {
  FOVEA_REQUIRE_TUM_TEDDY(tum);
  const std::string path = tempPath("cut.mcap");
  recordTum(tum, path, 4, 1);  // a chunk per message
  const auto size = std::filesystem::file_size(path);
  std::filesystem::resize_file(path, size * 3 / 4);
  std::unique_ptr<hal::Camera> camera = createCamera("mcap:" + path + ",loop=off").value();
  ASSERT_TRUE(camera->open()) << camera->open().message();
  const auto& mcap_camera = static_cast<const McapCamera&>(*camera);
  EXPECT_GE(mcap_camera.frameCount(), 2u);
  EXPECT_LT(mcap_camera.frameCount(), 4u);
  EXPECT_NE(mcap_camera.stopReason().find("stopped at byte"), std::string::npos) << mcap_camera.stopReason();
  EXPECT_NE(camera->info().model.find("cut short"), std::string::npos) << camera->info().model;
  ASSERT_TRUE(camera->start());
  hal::RgbdFrame slot(640, 480);
  for (std::size_t i = 0; i < mcap_camera.frameCount(); ++i) EXPECT_TRUE(camera->acquire(slot, 1s)) << i;
  EXPECT_EQ(camera->acquire(slot, 1s).message(), "end of record");
  std::filesystem::remove(path);
}

TEST(McapCamera, FilesWithoutFramesAndBadSpecsAreClearErrors) {
  EXPECT_EQ(createCamera("mcap:").status().code(), ErrorCode::kInvalidArgument);
  EXPECT_NE(createCamera("mcap:x.mcap,speed=2").status().message().find("unknown option 'speed'"), std::string::npos);
  EXPECT_NE(createCamera("nosuch:x").status().message().find("mcap:FILE"), std::string::npos);
  // Missing, empty, not MCAP, MCAP without the frames channel.
  {
    std::unique_ptr<hal::Camera> camera = createCamera("mcap:/nonexistent/x.mcap").value();
    EXPECT_EQ(camera->open().code(), ErrorCode::kNotFound);
  }
  const std::string empty = tempPath("empty.mcap");
  std::ofstream(empty).close();
  EXPECT_FALSE(createCamera("mcap:" + empty).value()->open());
  const std::string text = tempPath("text.mcap");
  std::ofstream(text) << "not an mcap file at all";
  const Status not_mcap = createCamera("mcap:" + text).value()->open();
  EXPECT_NE(not_mcap.message().find("wrong magic"), std::string::npos) << not_mcap.message();
  const std::string no_frames = tempPath("noframes.mcap");
  {
    std::unique_ptr<mcap::Writer> writer = mcap::Writer::open(no_frames).value();
    const uint16_t s = writer->addSchema("fovea.Other", "json", {}).value();
    const uint16_t c = writer->addChannel("/fovea/status", "json", s).value();
    const uint8_t m[] = {'{', '}'};
    ASSERT_TRUE(writer->write(c, 1, 1, m));
    ASSERT_TRUE(writer->close());
  }
  const Status none = createCamera("mcap:" + no_frames).value()->open();
  EXPECT_EQ(none.code(), ErrorCode::kNotFound);
  EXPECT_NE(none.message().find("--record-frames"), std::string::npos) << none.message();
  for (const std::string& p : {empty, text, no_frames}) std::filesystem::remove(p);
}

TEST(McapCamera, ASlotTooSmallKeepsTheFrameForTheNextCall) {
  FOVEA_REQUIRE_TUM_TEDDY(tum);
  const std::string path = tempPath("small.mcap");
  const std::vector<hal::RgbdFrame> recorded = recordTum(tum, path, 1);
  std::unique_ptr<hal::Camera> camera = createCamera("mcap:" + path).value();
  ASSERT_TRUE(camera->open());
  ASSERT_TRUE(camera->start());
  hal::RgbdFrame small(320, 240), slot(640, 480);
  EXPECT_EQ(camera->acquire(small, 1s).code(), ErrorCode::kCapacityExceeded);
  ASSERT_TRUE(camera->acquire(slot, 1s));
  expectSame(recorded[0], slot, 0, 0);
  std::filesystem::remove(path);
}

TEST(McapCamera, AcquireAllocatesNothingOnceStarted) {
  FOVEA_REQUIRE_TUM_TEDDY(tum);
  const std::string path = tempPath("alloc.mcap");
  recordTum(tum, path, 3);
  std::unique_ptr<hal::Camera> camera = createCamera("mcap:" + path + ",loop=off").value();
  ASSERT_TRUE(camera->open());
  ASSERT_TRUE(camera->start());
  hal::RgbdFrame slot(640, 480);
  uint64_t allocations = 0;
  {
    test::AllocationScope scope;
    for (int i = 0; i < 3; ++i) ASSERT_TRUE(camera->acquire(slot, 1s));
    allocations = scope.allocations();
  }
  EXPECT_EQ(allocations, 0u);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace fovea::firmware

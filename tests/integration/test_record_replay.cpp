// Recording and replay as a user runs them (docs/recording.md), service and
// operator as processes over loopback:
// - fovead serve --record-frames on the TUM sequence, then fovead run on the
//   recording (mcap: camera) gives the TUM camera's foveation, frame for frame and
//   bit for bit in the last frame's PLY;
// - fovea-operator --replay of the operator's own recording gives the live run's
//   figures frame for frame; of the service's recording, every frame the live
//   operator received whole, with its points;
// - a recording cut short replays up to where it stops and says where.
#include <gtest/gtest.h>

#include <signal.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "io/mcap/reader.h"
#include "tests/support/process.h"
#include "tests/support/programs.h"
#include "tests/support/test_time.h"
#include "tests/support/tum_frames.h"

namespace fovea {
namespace {

std::string readFile(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// fovead run's per-frame lines (frame index .. kept), without the timings.
std::vector<std::string> frameLines(const std::string& output) {
  std::vector<std::string> lines;
  std::istringstream in(output);
  const std::regex frame_line("^\\s+\\d+\\s+\\d+\\s+[0-9.]+ .*\\|");
  for (std::string line; std::getline(in, line);) {
    if (std::regex_search(line, frame_line)) lines.push_back(line.substr(0, line.find('|')));
  }
  return lines;
}

// A --frame-log's lines as frame id -> "points,chunks_received,chunks_expected,summary_received".
std::map<long, std::string> frameFigures(const std::string& path) {
  std::map<long, std::string> figures;
  std::istringstream in(readFile(path));
  std::string line;
  std::getline(in, line);  // the header
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::stringstream cells(line);
    for (std::string c; std::getline(cells, c, ',');) f.push_back(c);
    if (f.size() >= 8) figures[std::stol(f[0])] = f[4] + "," + f[5] + "," + f[6] + "," + f[7];
  }
  return figures;
}

// The number after `what` in the service's "recording FILE: ... dropped: ring
// full A, too big B, disk C, after close D" line (-1: no such line).
long dropped(const std::string& output, const std::string& what) {
  std::smatch m;
  if (!std::regex_search(output, m, std::regex(what + " (\\d+)"))) return -1;
  return std::stol(m[1].str());
}

long recorderDrops(const std::string& output) {
  long total = 0;
  for (const char* what : {"ring full", "too big", "disk", "after close"}) {
    const long n = dropped(output, what);
    if (n < 0) return -1;
    total += n;
  }
  return total;
}

// fovead run's frame lines by camera sequence (their first column).
std::map<long, std::string> bySequence(const std::vector<std::string>& lines) {
  std::map<long, std::string> out;
  for (const std::string& l : lines) out[std::stol(l)] = l;
  return out;
}

TEST(RecordReplay, ATumRecordingIsACameraBitForBit) {
  FOVEA_REQUIRE_TUM_TEDDY(tum_path);
  test::TempDir dir;
  const int frames = test::repetitions(20, 5);
  const std::string rec = dir.file("tum.mcap");
  const test::ProcessResult serve =
      test::runCommand(test::program(FOVEAD_PATH) + " serve --camera tum:" + tum_path + ",loop=off,realtime=on --frames " +
                       std::to_string(frames) + " --record " + rec + " --record-frames");
  ASSERT_EQ(serve.exit_code, 0) << serve.output;
  // The recorder never blocks the camera: on a loaded machine its writer may fall
  // behind and drop (counted). The frames in the file are then compared.
  const long drops = recorderDrops(serve.output);
  ASSERT_GE(drops, 0) << serve.output;
  const test::ProcessResult replay = test::runCommand(test::program(FOVEAD_PATH) + " run --camera mcap:" + rec +
                                                      ",loop=off --frames " + std::to_string(frames) + " --save-ply " +
                                                      dir.file("mcap.ply"));
  ASSERT_EQ(replay.exit_code, 0) << replay.output;
  const std::map<long, std::string> replayed = bySequence(frameLines(replay.output));
  ASSERT_FALSE(replayed.empty()) << replay.output;
  if (drops == 0) {
    EXPECT_EQ(replayed.size(), static_cast<std::size_t>(frames)) << replay.output;
  }
  EXPECT_GE(replayed.size(), static_cast<std::size_t>(frames) / 4) << serve.output;
  // The TUM camera up to the last frame recorded: the same lines, frame by frame,
  // and the same last frame, byte for byte.
  const long last = replayed.rbegin()->first;
  const test::ProcessResult tum = test::runCommand(test::program(FOVEAD_PATH) + " run --camera tum:" + tum_path +
                                                   ",loop=off --frames " + std::to_string(last + 1) + " --save-ply " +
                                                   dir.file("tum.ply"));
  ASSERT_EQ(tum.exit_code, 0) << tum.output;
  const std::map<long, std::string> live = bySequence(frameLines(tum.output));
  ASSERT_EQ(live.size(), static_cast<std::size_t>(last + 1)) << tum.output;
  for (const auto& [sequence, line] : replayed) {
    ASSERT_TRUE(live.count(sequence)) << sequence;
    EXPECT_EQ(line, live.at(sequence)) << "frame " << sequence;
  }
  const std::string ply_a = readFile(dir.file("tum.ply")), ply_b = readFile(dir.file("mcap.ply"));
  EXPECT_GT(ply_a.size(), 1000u);
  EXPECT_TRUE(ply_a == ply_b) << "the last frame's PLY differs";
}

// One session streamed and recorded by both ends, shared by the cases below (each
// only reads its files): the streaming is most of this suite's time, and under the
// sanitizers it ran once a case (CTest's case-by-case runs still stream once each).
struct RecordedSession {
  test::TempDir dir;
  std::map<long, std::string> live;
  long service_drops = 0;   // what the service's recorder dropped (a loaded machine)
  long operator_drops = 0;  // what the operator's did
  bool recorded = false;    // false: an assertion of record() failed (reported above)
};

// The service streaming the mock room to an operator, both recording.
void record(RecordedSession& s) {
  test::BackgroundProcess service(test::program(FOVEAD_PATH) +
                                  " serve --camera mock:living-room,size=320x240,fps=15 --listen 127.0.0.1:0 "
                                  "--insecure --record " +
                                  s.dir.file("service.mcap"));
  ASSERT_TRUE(service.waitFor("listening on ", 10) && service.waitFor(" (", 2)) << service.output();
  std::smatch m;
  const std::string out = service.output();
  ASSERT_TRUE(std::regex_search(out, m, std::regex("listening on (\\S+) \\(")));
  test::BackgroundProcess op(test::program(FOVEA_OPERATOR_PATH) + " --connect " + m[1].str() +
                             " --insecure --gaze 'fixed:3,0.35,1.55>3,2.25,1.35' --quiet --duration 120 --record " +
                             s.dir.file("operator.mcap") + " --frame-log " + s.dir.file("live.csv"));
  ASSERT_TRUE(op.waitFor("connected to", 10)) << op.output();
  std::this_thread::sleep_for(std::chrono::duration<double>(test::timeScale() > 1 ? 8.0 : 3.0));
  ASSERT_EQ(service.stop(SIGTERM, 5), 0) << service.output();
  s.service_drops = recorderDrops(service.output());
  ASSERT_GE(s.service_drops, 0) << service.output();
  ASSERT_EQ(op.stop(0, 5), 0) << op.output();  // ends on the service's Bye
  EXPECT_NE(op.output().find("recording " + s.dir.file("operator.mcap")), std::string::npos) << op.output();
  s.operator_drops = dropped(op.output(), "ring full") + dropped(op.output(), "too big") + dropped(op.output(), "disk");
  s.live = frameFigures(s.dir.file("live.csv"));
  ASSERT_GE(s.live.size(), 3u) << op.output();
  s.recorded = true;
}

class StreamRecording : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    session_ = new RecordedSession;
    record(*session_);
  }
  static void TearDownTestSuite() {
    delete session_;
    session_ = nullptr;
  }
  void SetUp() override { ASSERT_TRUE(session_->recorded) << "no session recorded (the suite's failure above)"; }

  test::ProcessResult replay(const std::string& file, const std::string& log) {
    return test::runCommand(test::program(FOVEA_OPERATOR_PATH) + " --replay " + file + " --speed 0 --quiet --frame-log " + log);
  }

  static inline RecordedSession* session_ = nullptr;
  test::TempDir dir_;  // this case's own files
  const std::map<long, std::string>& live_ = session_->live;
  const long& service_drops_ = session_->service_drops;
  const long& operator_drops_ = session_->operator_drops;
  std::string recorded(const char* name) const { return session_->dir.file(name); }
};

TEST_F(StreamRecording, TheOperatorsRecordingReplaysToTheLiveFiguresFrameForFrame) {
  const test::ProcessResult r = replay(recorded("operator.mcap"), dir_.file("replay.csv"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::map<long, std::string> replayed = frameFigures(dir_.file("replay.csv"));
  if (operator_drops_ == 0) {
    EXPECT_EQ(replayed, live_) << r.output;
  } else {
    // The operator's recorder dropped (counted: a loaded machine). How many frames
    // it lost is timing, as for the service's recorder below (the bound of half
    // the frames whole failed there): every frame it kept was a live frame, and
    // it kept some whole.
    std::size_t same = 0;
    for (const auto& [frame, figures] : replayed) {
      EXPECT_TRUE(live_.count(frame)) << "frame " << frame << " replayed but never live";
      same += live_.count(frame) && live_.at(frame) == figures ? 1 : 0;
    }
    EXPECT_GE(same, 1u) << "the operator's recorder dropped " << operator_drops_;
  }
  EXPECT_EQ(r.output.find("stopped at byte"), std::string::npos) << r.output;
}

TEST_F(StreamRecording, TheServicesRecordingHoldsEveryFrameTheOperatorGotWhole) {
  const test::ProcessResult r = replay(recorded("service.mcap"), dir_.file("replay.csv"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::map<long, std::string> replayed = frameFigures(dir_.file("replay.csv"));
  auto whole = [](const std::string& figures) {
    std::vector<std::string> f;
    std::stringstream cells(figures);
    for (std::string c; std::getline(cells, c, ',');) f.push_back(c);
    return f.size() == 4 && f[1] == f[2] && f[3] == "1";
  };
  std::size_t live_whole = 0, both_whole = 0;
  for (const auto& [frame, figures] : live_) {
    if (!whole(figures)) continue;  // the live operator lost part of it
    ++live_whole;
    // Without recorder drops every such frame is in the file whole; with drops
    // (counted, a loaded machine) those the file holds whole.
    if (service_drops_ == 0) {
      ASSERT_TRUE(replayed.count(frame)) << "frame " << frame << "\n" << r.output;
    }
    if (!replayed.count(frame) || !whole(replayed.at(frame))) {
      EXPECT_GT(service_drops_, 0) << "frame " << frame << " is not whole in the service's recording";
      continue;
    }
    ++both_whole;
    EXPECT_EQ(replayed.at(frame), figures) << "frame " << frame;
  }
  EXPECT_GE(live_whole, 3u);
  // With counted drops how many frames the file lost is timing (a CI run's starved
  // writer dropped 20251 records and kept 86 of 183 frames whole), which tests do
  // not bound: what it kept is exact (above), and it kept frames.
  EXPECT_GE(both_whole, service_drops_ == 0 ? live_whole : 1) << "the service's recorder dropped " << service_drops_;
}

// The operator's file also holds Foxglove's messages of what it saw: a cloud per
// frame decoded, its head and gaze per sample sent, its live lines.
TEST_F(StreamRecording, TheOperatorsRecordingHasFoxglovesChannels) {
  Result<std::vector<uint8_t>> file = mcap::readFile(recorded("operator.mcap"));
  ASSERT_TRUE(file) << file.status().message();
  mcap::Reader reader(*file);
  std::map<uint16_t, std::string> topic;
  std::map<std::string, std::size_t> count;
  for (mcap::Reader::Item item = reader.next(); item != mcap::Reader::Item::kEnd; item = reader.next()) {
    if (item == mcap::Reader::Item::kChannel) {
      const mcap::SchemaRecord* schema = reader.findSchema(reader.channel().schema_id);
      topic[reader.channel().id] = reader.channel().topic + " " + (schema ? schema->name : std::string("?"));
    } else if (item == mcap::Reader::Item::kMessage) {
      ++count[topic[reader.message().channel_id]];
    }
  }
  EXPECT_TRUE(reader.complete()) << reader.stopReason();
  if (operator_drops_ == 0) {
    EXPECT_EQ(count["/fovea/cloud foxglove.PointCloud"], live_.size());
  }
  // A loaded machine's recorder drops (counted, never blocking; CI's amd64-tests kept 83
  // clouds of 192 frames): every frame's cloud is either in the file or among the drops.
  EXPECT_GT(count["/fovea/cloud foxglove.PointCloud"], 0u);
  EXPECT_GE(count["/fovea/cloud foxglove.PointCloud"] + static_cast<std::size_t>(operator_drops_), live_.size());
  EXPECT_GT(count["/fovea/head foxglove.FrameTransform"], 10u);
  EXPECT_EQ(count["/fovea/gaze_ray foxglove.SceneUpdate"], count["/fovea/head foxglove.FrameTransform"]);
  // The gaze samples as sent (fovea's own message), one a head pose.
  if (operator_drops_ == 0) {
    EXPECT_EQ(count["/fovea/gaze fovea.net.wire.Gaze"], count["/fovea/head foxglove.FrameTransform"]);
  }
  EXPECT_GT(count["/fovea/gaze fovea.net.wire.Gaze"], 10u);
  EXPECT_GE(count["/fovea/log foxglove.Log"], 1u);
  EXPECT_GT(count["/fovea/chunks fovea.Chunk"], live_.size());
}

TEST_F(StreamRecording, ARecordingCutShortReplaysUpToWhereItStops) {
  const std::string cut = dir_.file("cut.mcap");
  std::filesystem::copy_file(recorded("operator.mcap"), cut);
  std::filesystem::resize_file(cut, std::filesystem::file_size(cut) * 6 / 10);
  const test::ProcessResult r = replay(cut, dir_.file("cut.csv"));
  EXPECT_NE(r.output.find("stopped at byte"), std::string::npos) << r.output;
  const std::map<long, std::string> replayed = frameFigures(dir_.file("cut.csv"));
  EXPECT_LT(replayed.size(), live_.size()) << r.output;
  // What it played is what was live. The cut can split more than the last
  // frame: the recorder's writer drains its producers' rings in turn, so under
  // load a frame's chunks can lie in the file after a later frame's (CI's
  // amd64-tests: frames 219 and 230 of a cut at frame 230 both partial). Every
  // frame played was live and played no more points than it had; most whole.
  std::size_t whole = 0;
  for (const auto& [frame, figures] : replayed) {
    ASSERT_TRUE(live_.count(frame)) << "frame " << frame << " replayed but never live";
    const std::string& live = live_.at(frame);
    EXPECT_LE(std::stol(figures), std::stol(live)) << "frame " << frame << ": " << figures << " against " << live;
    whole += figures == live ? 1 : 0;
  }
  EXPECT_GE(whole * 2, replayed.size()) << whole << " of " << replayed.size() << " frames replayed whole";
  // Not a recording at all: a clear error, not a crash.
  std::ofstream(dir_.file("junk.mcap")) << "junk, not a recording";
  const test::ProcessResult junk = replay(dir_.file("junk.mcap"), dir_.file("junk.csv"));
  EXPECT_NE(junk.exit_code, 0);
  EXPECT_NE(junk.output.find("wrong magic"), std::string::npos) << junk.output;
  EXPECT_EQ(test::runCommand(test::program(FOVEA_OPERATOR_PATH) + " --replay " + cut + " --connect 127.0.0.1:1").exit_code, 2);
}

}  // namespace
}  // namespace fovea

// fovea-operator --view as a process, with a tab on its WebSocket: the states
// the page shows as the robot refuses (busy with another operator), accepts,
// streams and goes away, and the operator reconnecting throughout; and that
// the operator started with --view and no robot keeps serving the page. And,
// against a robot played here (a net::RobotLink), the operator keeping the
// map's bricks: acknowledged, drawn in the page's frames, counted in its logs,
// and saved with a frame by --save-held.
#include <gtest/gtest.h>

#include <signal.h>

#include <cstring>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "core/clock.h"
#include "net/codec.h"
#include "net/robot_link.h"

#include "tests/support/process.h"
#include "tests/support/programs.h"
#include "tests/support/test_time.h"
#include "tests/support/websocket_tab.h"

namespace fovea {
namespace {

using namespace std::chrono_literals;
using test::waitUntil;

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
    const test::ProcessResult keygen = test::runCommand(test::program(FOVEAD_PATH) + " keygen " + dir_.file("key"));
    ASSERT_EQ(keygen.exit_code, 0) << keygen.output;
  }
  std::string operatorCommand(const std::string& address, const std::string& flags) {
    return test::program(FOVEA_OPERATOR_PATH) + " --connect " + address + " --key-file " + dir_.file("key") + " " + flags;
  }
  test::TempDir dir_;
};

TEST_F(OperatorView, ThePageFollowsTheRobotRefusingStreamingAndGoingAway) {
  test::BackgroundProcess robot(test::program(FOVEAD_PATH) + " run --camera mock:living-room,size=160x120,fps=15 --every 0 " +
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

// The points of a slab at a brick (or the live frame), encoded as the robot's service would.
class SlabEncoder {
 public:
  void encode(int points, Eigen::Vector3d origin, const net::BrickTag* tag, uint32_t frame_id) {
    cloud_.clear();
    cloud_.points.origin_m = origin;
    for (int i = 0; i < points; ++i) {
      ASSERT_TRUE(cloud_.points.push(0.004f * static_cast<float>(i % 60), 0.004f * static_cast<float>(i / 60), 0.0f, 0x40a0c0u));
    }
    std::fill_n(cloud_.region.begin(), cloud_.size(), uint8_t{0});
    std::fill_n(cloud_.weight.begin(), cloud_.size(), 1u);
    const double fovea[1] = {0.0};
    ASSERT_TRUE(encoder_.encode(cloud_, fovea, frame_id, static_cast<uint64_t>(monotonicNs()), tag));
  }
  net::ChunkEncoder& encoder() { return encoder_; }

 private:
  net::ChunkEncoder encoder_ = net::ChunkEncoder::create(net::CodecConfig{}, 4096).value();
  pipeline::FoveatedCloud cloud_{4096};
};

// A brick part as the robot sent it and the operator acknowledged it: brick x, version, part.
using PartKey = std::tuple<int, uint32_t, uint16_t>;

// The three brick versions (the first of several parts), then a bad brick
// payload; returns the map's points, and each part sent in `sent_parts`.
void sendThreeBricksAndABadOne(net::RobotLink& robot, SlabEncoder& slabs, std::set<PartKey>& sent_parts, int& map_points) {
  const std::vector<std::pair<net::BrickTag, int>> bricks = {{{0, 4, 2, 1, 0}, 1500}, {{1, 4, 2, 3, 0}, 200}, {{2, 4, 2, 1, 0}, 100}};
  map_points = 0;
  for (const auto& [tag, points] : bricks) {
    ASSERT_NO_FATAL_FAILURE(slabs.encode(points, Eigen::Vector3d(0.5 * tag.x, 0.5 * tag.y, 0.5 * tag.z), &tag, 1));
    for (std::size_t i = 0; i < slabs.encoder().chunkCount(); ++i) {
      ASSERT_EQ(robot.send(net::MessageType::kBrickChunk, slabs.encoder().chunk(i)), net::SendResult::kSent);
      sent_parts.insert({tag.x, tag.version, static_cast<uint16_t>(i)});
    }
    map_points += points;
  }
  ASSERT_GT(sent_parts.size(), 3u) << "the first brick comes in several parts";
  const uint8_t garbage[64] = {1, 2, 3};
  ASSERT_EQ(robot.send(net::MessageType::kBrickChunk, garbage), net::SendResult::kSent);
}

// Live frames, until every part is acknowledged and the page has drawn the map;
// the page's last frame in `frame`.
void streamUntilAcknowledgedAndDrawn(net::RobotLink& robot, SlabEncoder& slabs, test::Tab& tab, test::BackgroundProcess& op,
                                     const std::set<PartKey>& sent_parts, int map_points, std::vector<uint8_t>& frame) {
  std::set<PartKey> acked;
  uint32_t frame_id = 10;
  const bool done = waitUntil([&] {
    slabs.encode(300, Eigen::Vector3d(1.0, 3.0, 1.0), nullptr, ++frame_id);
    net::ChunkEncoder& encoder = slabs.encoder();
    for (std::size_t i = 0; i < encoder.chunkCount(); ++i) (void)robot.send(net::MessageType::kChunk, encoder.chunk(i));
    const uint16_t chunks[1] = {static_cast<uint16_t>(encoder.chunkCount())}, cut[1] = {0};
    (void)robot.send(net::MessageType::kFrameSummary, encoder.encodeSummary(frame_id, chunks, cut));
    robot.poll(30);
    for (const net::BrickPartId& id : robot.brickAcks()) acked.insert({id.key.x, id.version, id.part});
    robot.takeBrickAcks();
    frame = tab.frames() > 0 ? tab.lastFrame() : std::vector<uint8_t>{};
    uint32_t m = 0;
    if (frame.size() >= 16) std::memcpy(&m, frame.data() + 12, 4);
    return acked == sent_parts && m == static_cast<uint32_t>(map_points);
  }, 15s);
  EXPECT_TRUE(done) << acked.size() << " of " << sent_parts.size() << " parts acknowledged\n" << op.output();
  EXPECT_EQ(acked, sent_parts);
}

// The page's frame: every held brick's points, then the live frame's.
void expectTheFrameHoldsTheMapThenTheLivePoints(const std::vector<uint8_t>& frame, int map_points) {
  ASSERT_GE(frame.size(), 136u);
  uint32_t n = 0, m = 0;
  std::memcpy(&n, frame.data() + 8, 4);
  std::memcpy(&m, frame.data() + 12, 4);
  EXPECT_EQ(m, static_cast<uint32_t>(map_points)) << "the page's frame holds every held brick's points";
  EXPECT_EQ(n, m + 300) << "after the live frame's";
}

// The operator's log and its summary count the three bricks, their versions and the bad part.
void expectTheMapCounted(const std::string& out, const std::string& summary_path, int map_points) {
  EXPECT_NE(out.find("map: 3 bricks and " + std::to_string(map_points) + " points held"), std::string::npos) << out;
  std::stringstream summary;
  summary << std::ifstream(summary_path).rdbuf();
  EXPECT_NE(summary.str().find("\"map\": {\"bricks_held\": 3, \"points_held\": " + std::to_string(map_points)),
            std::string::npos) << summary.str();
  EXPECT_NE(summary.str().find("\"versions_completed\": 3"), std::string::npos) << summary.str();
  EXPECT_NE(summary.str().find("\"bad_parts\": 1"), std::string::npos) << summary.str();
}

// The frame log's header ends with the map's columns, and its last line holds the whole map.
void expectTheFrameLogHoldsTheMap(const std::string& log_path, int map_points, std::size_t parts_sent) {
  std::ifstream log(log_path);
  std::string header, line, last;
  std::getline(log, header);
  EXPECT_NE(header.find(",summary_received,map_bricks,map_points,brick_parts,brick_versions,fovea_decoded_ns,fovea_latency_us"),
            std::string::npos)
      << header;
  uint64_t parts_logged = 0;
  while (std::getline(log, line)) {
    last = line;
    // Split at every comma, trailing empty cells included (getline drops the last).
    std::vector<std::string> cells;
    for (std::size_t begin = 0;;) {
      const std::size_t comma = line.find(',', begin);
      cells.push_back(line.substr(begin, comma == std::string::npos ? std::string::npos : comma - begin));
      if (comma == std::string::npos) break;
      begin = comma + 1;
    }
    ASSERT_EQ(cells.size(), 14u) << line;
    parts_logged += std::stoull(cells[10]);
    if (cells[7] == "1") {
      // The frame's one chunk is its fovea: decoded when the frame was (one clock here).
      EXPECT_EQ(cells[12], cells[2]) << line;
      EXPECT_EQ(cells[13], cells[3]) << line;
    } else {
      // Logged without its summary (a slow tree's frame timed out): a frame of one
      // chunk cannot tell that its fovea is whole, so the fovea's columns are empty.
      EXPECT_EQ(cells[12], "") << line;
      EXPECT_EQ(cells[13], "") << line;
    }
  }
  EXPECT_NE(last.find(",3," + std::to_string(map_points) + ","), std::string::npos) << last;
  EXPECT_LE(parts_logged, parts_sent) << "parts since the previous line add up to at most all of them";
}

// --save-held 11: the first live frame (whole, after every brick's parts) and the
// three bricks, as fovea-eval's MAP-DELTA reads them (tools/operator/held_cloud.h).
void expectTheHeldCloudSaved(const std::string& out, const std::string& ply_path, int map_points) {
  const std::string saved = "--save-held: frame 11 (300 live points, " + std::to_string(map_points) + " map points in 3 bricks)";
  EXPECT_NE(out.find(saved), std::string::npos) << out;
  std::stringstream text;
  text << std::ifstream(ply_path + ".txt").rdbuf();
  EXPECT_EQ(text.str().rfind("frame_id 11\nlive_points 300\nmap_points " + std::to_string(map_points) + "\nmap_bricks 3\n", 0), 0u)
      << text.str();
  std::ifstream ply(ply_path, std::ios::binary);
  std::string ply_header, ply_line;
  while (std::getline(ply, ply_line) && ply_line != "end_header") ply_header += ply_line + "\n";
  EXPECT_NE(ply_header.find("element vertex " + std::to_string(300 + map_points) + "\n"), std::string::npos) << ply_header;
  EXPECT_NE(ply_header.find("property uchar region"), std::string::npos) << ply_header;
}

// A robot that streams bricks: three brick versions (one of several parts), a
// bad brick payload and a few live frames, while it takes the acknowledgements.
TEST_F(OperatorView, TheOperatorKeepsTheMapsBricksAcknowledgesAndDrawsThem) {
  net::RobotLinkConfig rc;
  rc.listen = "127.0.0.1:0";
  rc.insecure = true;
  std::unique_ptr<net::RobotLink> robot = net::RobotLink::create(rc).value();
  const std::string address = "127.0.0.1:" + std::to_string(robot->localEndpoint().port());
  test::BackgroundProcess op(test::program(FOVEA_OPERATOR_PATH) + " --connect " + address +
                             " --insecure --view 127.0.0.1:0 --quiet --map-points 65536 --map-bricks 64 --frame-log " +
                             dir_.file("frames.csv") + " --summary " + dir_.file("summary.json") + " --save-held 11:" +
                             dir_.file("held.ply"));
  const int port = viewerPort(op);
  ASSERT_GT(port, 0) << op.output();
  test::Tab tab(port);
  ASSERT_TRUE(tab.connected()) << tab.error();
  ASSERT_TRUE(waitUntil([&] {
    robot->poll(10);
    return robot->hasSession();
  }, 10s)) << op.output();

  SlabEncoder slabs;
  std::set<PartKey> sent_parts;
  int map_points = 0;
  ASSERT_NO_FATAL_FAILURE(sendThreeBricksAndABadOne(*robot, slabs, sent_parts, map_points));
  std::vector<uint8_t> frame;
  streamUntilAcknowledgedAndDrawn(*robot, slabs, tab, op, sent_parts, map_points, frame);
  ASSERT_NO_FATAL_FAILURE(expectTheFrameHoldsTheMapThenTheLivePoints(frame, map_points));

  EXPECT_EQ(op.stop(SIGTERM, 20), 0) << op.output();
  const std::string out = op.output();
  expectTheMapCounted(out, dir_.file("summary.json"), map_points);
  ASSERT_NO_FATAL_FAILURE(expectTheFrameLogHoldsTheMap(dir_.file("frames.csv"), map_points, sent_parts.size()));
  expectTheHeldCloudSaved(out, dir_.file("held.ply"), map_points);
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

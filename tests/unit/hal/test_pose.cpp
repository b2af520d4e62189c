// Poses (hal/pose.h) and the pose source (hal/pose_source.h): interpolation
// against a brute-force computation, the datagram format, the socket receiver
// on a real bound socket (malformed, truncated, NaN, non-unit quaternions, old
// stamps, a flood beyond the ring), staleness, and no allocation per frame.
#include "hal/pose_source.h"

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "hal/camera/tum/tum_camera.h"
#include "tests/support/alloc_counter.h"
#include "tests/support/process.h"

namespace fovea::hal {
namespace {

using test::TempDir;

// Slerp written out (theta = acos of the dot product, the shorter arc), for
// comparison with Eigen's inside interpolatePose.
Eigen::Matrix3d bruteForceRotation(Eigen::Quaterniond a, Eigen::Quaterniond b, double alpha) {
  double dot = a.coeffs().dot(b.coeffs());
  if (dot < 0) {
    b.coeffs() = -b.coeffs();
    dot = -dot;
  }
  Eigen::Vector4d q;
  if (dot > 1.0 - 1e-12) {
    q = (1 - alpha) * a.coeffs() + alpha * b.coeffs();
  } else {
    const double theta = std::acos(dot);
    q = (std::sin((1 - alpha) * theta) * a.coeffs() + std::sin(alpha * theta) * b.coeffs()) / std::sin(theta);
  }
  q.normalize();
  const double x = q[0], y = q[1], z = q[2], w = q[3];  // Eigen's coeffs(): x y z w
  Eigen::Matrix3d R;
  R << 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),  //
      2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),   //
      2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y);
  return R;
}

std::vector<StampedPose> randomTrajectory(std::mt19937_64& rng, std::size_t n) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<StampedPose> poses(n);
  int64_t stamp = 1'000'000'000;
  for (StampedPose& p : poses) {
    stamp += 1 + static_cast<int64_t>(rng() % 20'000'000);
    p.stamp_ns = stamp;
    p.t_world_cam = Eigen::Vector3d(u(rng), u(rng), u(rng)) * 100.0;
    p.q_world_cam = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized();
  }
  return poses;
}

TEST(Pose, InterpolationMatchesABruteForceComputation) {
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < 50; ++trial) {
    const std::vector<StampedPose> poses = randomTrajectory(rng, 1 + rng() % 40);
    const int64_t clamp_ns = 5'000'000;
    const int64_t lo = poses.front().stamp_ns - 2 * clamp_ns, hi = poses.back().stamp_ns + 2 * clamp_ns;
    for (int k = 0; k < 200; ++k) {
      const int64_t stamp = lo + static_cast<int64_t>(rng() % static_cast<uint64_t>(hi - lo + 1));
      // Brute force: a linear scan for the segment.
      bool expect_ok = true;
      Eigen::Vector3d t;
      Eigen::Matrix3d R;
      if (stamp <= poses.front().stamp_ns) {
        expect_ok = poses.front().stamp_ns - stamp <= clamp_ns;
        t = poses.front().t_world_cam;
        R = poses.front().q_world_cam.toRotationMatrix();
      } else if (stamp >= poses.back().stamp_ns) {
        expect_ok = stamp - poses.back().stamp_ns <= clamp_ns;
        t = poses.back().t_world_cam;
        R = poses.back().q_world_cam.toRotationMatrix();
      } else {
        std::size_t i = 0;
        while (poses[i + 1].stamp_ns <= stamp) ++i;
        const StampedPose& a = poses[i];
        const StampedPose& b = poses[i + 1];
        const double alpha =
            static_cast<double>(stamp - a.stamp_ns) / static_cast<double>(b.stamp_ns - a.stamp_ns);
        t = a.t_world_cam * (1 - alpha) + b.t_world_cam * alpha;
        R = bruteForceRotation(a.q_world_cam, b.q_world_cam, alpha);
      }
      Pose got;
      ASSERT_EQ(interpolatePose(poses, stamp, clamp_ns, got), expect_ok) << stamp;
      if (!expect_ok) continue;
      EXPECT_LT((got.t_world_cam - t).norm(), 1e-9);
      EXPECT_LT((got.R_world_cam - R).cwiseAbs().maxCoeff(), 1e-9);
    }
  }
}

TEST(Pose, QuaternionAndRotationChecks) {
  Eigen::Quaterniond q;
  EXPECT_TRUE(normalisedQuaternion(0, 0, 0, 1.2, q));
  EXPECT_DOUBLE_EQ(q.w(), 1.0);
  EXPECT_FALSE(normalisedQuaternion(0, 0, 0, 0, q));
  EXPECT_FALSE(normalisedQuaternion(0, 0, 0, 2, q));
  EXPECT_FALSE(normalisedQuaternion(NAN, 0, 0, 1, q));
  const double three[] = {0, 0, 1};
  EXPECT_EQ(quaternionFromXyzw(three, "x").status().message(), "x: a quaternion is 4 numbers x, y, z, w (got 3)");
  EXPECT_TRUE(checkRotation(Eigen::Matrix3d::Identity(), "R").isOk());
  Eigen::Matrix3d reflection = Eigen::Matrix3d::Identity();
  reflection(2, 2) = -1;
  EXPECT_NE(checkRotation(reflection, "R").message().find("determinant -1"), std::string::npos);
  Eigen::Matrix3d scaled = 1.001 * Eigen::Matrix3d::Identity();
  EXPECT_NE(checkRotation(scaled, "R").message().find("R^T R differs from I"), std::string::npos);
}

// A trajectory line in TUM's format reads back through the ground-truth parser
// the TUM camera uses: the stamp exactly (to the microsecond), the position to
// the printed decimals, the rotation as the same rotation (q and -q alike).
TEST(Pose, TumTrajectoryLineRoundTrips) {
  std::mt19937 rng(29);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::string text = "# timestamp tx ty tz qx qy qz qw\n";
  std::vector<std::pair<int64_t, Pose>> written;
  int64_t stamp = 1341841873405990000;
  for (int i = 0; i < 50; ++i) {
    Eigen::Quaterniond q(u(rng), u(rng), u(rng), u(rng));
    q.normalize();
    const Pose p = poseFromQuaternion(Eigen::Vector3d(u(rng) * 100, u(rng), u(rng) * 1e3), q);
    stamp += 33'333'000 + i;  // microseconds and a few nanoseconds
    char line[160];
    const std::size_t n = formatTumPose(stamp, p, line, sizeof line);
    ASSERT_GT(n, 0u);
    ASSERT_EQ(line[n - 1], '\n');
    text.append(line, n);
    written.emplace_back(stamp, p);
  }
  Result<std::vector<StampedPose>> read = tum::parseGroundTruth(text, "trajectory");
  ASSERT_TRUE(read.isOk()) << read.status().message();
  ASSERT_EQ(read->size(), written.size());
  for (std::size_t i = 0; i < written.size(); ++i) {
    const StampedPose& r = (*read)[i];
    EXPECT_EQ(r.stamp_ns, (written[i].first + 500) / 1000 * 1000);
    EXPECT_LT((r.t_world_cam - written[i].second.t_world_cam).cwiseAbs().maxCoeff(), 0.6e-6);
    EXPECT_LT((r.q_world_cam.toRotationMatrix() - written[i].second.R_world_cam).cwiseAbs().maxCoeff(), 1e-6);
    EXPECT_GE(r.q_world_cam.w(), 0.0);
  }
  char small[20];
  EXPECT_EQ(formatTumPose(stamp, Pose{}, small, sizeof small), 0u);  // does not fit: nothing claimed
  char line[160];
  ASSERT_GT(formatTumPose(-1'500'000, Pose{}, line, sizeof line), 0u);
  EXPECT_EQ(std::string(line).substr(0, 9), "-0.001500");
}

TEST(PoseDatagram, ParsesTheDocumentedFormat) {
  StampedPose p;
  ASSERT_TRUE(parsePoseDatagram("123456789 1.5 -2 3e-1 0 0 0.7071068 0.7071068\n", p));
  EXPECT_EQ(p.stamp_ns, 123456789);
  EXPECT_DOUBLE_EQ(p.t_world_cam.y(), -2.0);
  EXPECT_NEAR(p.q_world_cam.z(), std::sqrt(0.5), 1e-12);
  EXPECT_NEAR(p.q_world_cam.norm(), 1.0, 1e-15);
  EXPECT_TRUE(parsePoseDatagram("  5\t0 0 0 0 0 0 1.0004  ", p));  // rounded quaternion: normalised
  EXPECT_DOUBLE_EQ(p.q_world_cam.w(), 1.0);
  for (const char* bad : {"", "\n", "5 0 0 0 0 0 0", "5 0 0 0 0 0 0 1 map", "5.0 0 0 0 0 0 0 1", "x 0 0 0 0 0 0 1",
                          "5 0 nan 0 0 0 0 1", "5 0 inf 0 0 0 0 1", "5 0 0 0 0 0 0 0", "5 0 0 0 0 0 0 2",
                          "5 0 0 0 0 0 0 1x", "99999999999999999999 0 0 0 0 0 0 1", "5,0,0,0,0,0,0,1"}) {
    EXPECT_FALSE(parsePoseDatagram(bad, p)) << "'" << bad << "'";
  }
}

// A client of the pose socket, as a robot's localisation would be.
struct Sender {
  int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_un to{};
  explicit Sender(const std::string& path) {
    to.sun_family = AF_UNIX;
    std::snprintf(to.sun_path, sizeof to.sun_path, "%s", path.c_str());
  }
  ~Sender() { ::close(fd); }
  void send(const std::string& text) const {
    ASSERT_EQ(::sendto(fd, text.data(), text.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to),
              static_cast<ssize_t>(text.size()))
        << std::strerror(errno);
  }
  void pose(int64_t stamp_ns, double x, double qz = 0.0, double qw = 1.0) const {
    char text[128];
    std::snprintf(text, sizeof text, "%lld %.9g 0 0 0 0 %.9g %.9g\n", static_cast<long long>(stamp_ns), x, qz, qw);
    send(text);
  }
};

PoseSourceConfig socketConfig(const TempDir& dir, std::size_t capacity = 16) {
  PoseSourceConfig config;
  config.kind = PoseSourceConfig::Kind::kSocket;
  config.socket_path = dir.file("pose.sock");
  config.capacity = capacity;
  config.max_age_ns = 50'000'000;
  return config;
}

TEST(PoseSource, ReceivesInterpolatesAndCountsBadDatagrams) {
  TempDir dir;
  Result<std::unique_ptr<PoseSource>> created = PoseSource::create(socketConfig(dir));
  ASSERT_TRUE(created.isOk()) << created.status().message();
  PoseSource& source = *created.value();
  Sender sender(source.config().socket_path);
  sender.pose(1'000'000'000, 0.0);
  sender.pose(1'100'000'000, 1.0);
  sender.send("garbage");                                   // malformed
  sender.send(std::string(300, ' ') + "1200000000 0 0 0 0 0 0 1");  // longer than 255 bytes: truncated
  sender.send("1200000000 nan 0 0 0 0 0 1");                // NaN
  sender.send("1200000000 0 0 0 0 0 0 3");                  // quaternion far from unit length
  sender.pose(1'050'000'000, 9.0);                          // older than the newest: out of order
  sender.pose(1'100'000'000, 9.0);                          // equal: out of order
  sender.pose(1'200'000'000, 2.0, 0.0, 1.0001);             // rounded quaternion: accepted
  RgbdFrame frame(4, 4);
  frame.stamp_ns = 1'025'000'000;
  EXPECT_TRUE(source.apply(frame));
  EXPECT_NEAR(frame.T_world_cam.t_world_cam.x(), 0.25, 1e-12);
  const PoseCounters c = source.counters();
  EXPECT_EQ(c.received, 3u);
  EXPECT_EQ(c.malformed, 4u);
  EXPECT_EQ(c.out_of_order, 2u);
  EXPECT_EQ(c.frames_fresh, 1u);
  EXPECT_EQ(source.size(), 3u);
  EXPECT_FALSE(source.stale());
}

TEST(PoseSource, StalenessHoldsTheNearestPoseAndFlagsIt) {
  TempDir dir;
  Result<std::unique_ptr<PoseSource>> created = PoseSource::create(socketConfig(dir));
  ASSERT_TRUE(created.isOk()) << created.status().message();
  PoseSource& source = *created.value();
  RgbdFrame frame(4, 4);
  frame.T_world_cam.t_world_cam = Eigen::Vector3d(7, 7, 7);  // the camera's own
  frame.stamp_ns = 1'000'000'000;
  EXPECT_FALSE(source.apply(frame));  // nothing received yet: the camera's pose stays
  EXPECT_EQ(frame.T_world_cam.t_world_cam.x(), 7.0);
  EXPECT_TRUE(source.stale());
  Sender sender(source.config().socket_path);
  sender.pose(1'000'000'000, 1.0);
  sender.pose(1'100'000'000, 2.0);
  frame.stamp_ns = 1'100'000'000 + 50'000'000;  // max_age beyond the newest: still fresh (held)
  EXPECT_TRUE(source.apply(frame));
  EXPECT_EQ(frame.T_world_cam.t_world_cam.x(), 2.0);
  frame.stamp_ns = 1'100'000'000 + 50'000'001;  // beyond: stale, holding the newest
  EXPECT_FALSE(source.apply(frame));
  EXPECT_EQ(frame.T_world_cam.t_world_cam.x(), 2.0);
  EXPECT_TRUE(source.stale());
  frame.stamp_ns = 1'000'000'000 - 50'000'001;  // before the oldest kept: stale, the oldest
  EXPECT_FALSE(source.apply(frame));
  EXPECT_EQ(frame.T_world_cam.t_world_cam.x(), 1.0);
  sender.pose(1'200'000'000, 3.0);  // the localisation catches up
  frame.stamp_ns = 1'190'000'000;
  EXPECT_TRUE(source.apply(frame));
  EXPECT_FALSE(source.stale());
  EXPECT_EQ(source.counters().frames_stale, 3u);
  EXPECT_EQ(source.counters().frames_fresh, 2u);
}

TEST(PoseSource, AFloodBeyondTheRingDropsTheOldestAndCountsThem) {
  TempDir dir;
  Result<std::unique_ptr<PoseSource>> created = PoseSource::create(socketConfig(dir, 4));
  ASSERT_TRUE(created.isOk()) << created.status().message();
  PoseSource& source = *created.value();
  Sender sender(source.config().socket_path);
  // The kernel queues at most net.unix.max_dgram_qlen datagrams (10 by default)
  // before a reader takes them; a sender that does not wait (as docs/pose.md
  // asks) sees EAGAIN beyond that. Send until then.
  int sent = 0;
  for (int i = 0; i < 30; ++i) {
    char text[96];
    const int n = std::snprintf(text, sizeof text, "%d %d 0 0 0 0 0 1", 1'000'000'000 + i * 1'000'000, i);
    if (::sendto(sender.fd, text, static_cast<std::size_t>(n), MSG_DONTWAIT, reinterpret_cast<const sockaddr*>(&sender.to),
                 sizeof sender.to) != n) {
      ASSERT_EQ(errno, EAGAIN) << std::strerror(errno);
      break;
    }
    ++sent;
  }
  ASSERT_GT(sent, 4);
  source.drain();
  EXPECT_EQ(source.size(), 4u);
  EXPECT_EQ(source.counters().received, static_cast<uint64_t>(sent));
  EXPECT_EQ(source.counters().overwritten, static_cast<uint64_t>(sent - 4));
  Pose pose;
  const int64_t newest = 1'000'000'000 + (sent - 1) * 1'000'000;
  EXPECT_TRUE(source.poseAt(newest - 500'000, pose));  // within the 4 kept
  EXPECT_NEAR(pose.t_world_cam.x(), sent - 1.5, 1e-9);
  EXPECT_TRUE(source.poseAt(newest - 3'000'000, pose));
  EXPECT_NEAR(pose.t_world_cam.x(), sent - 4, 1e-9);
  EXPECT_FALSE(source.poseAt(newest - 3'000'000 - 50'000'001, pose));  // dropped from the ring long ago
}

TEST(PoseSource, MountComposesWithTheRobotPose) {
  TempDir dir;
  PoseSourceConfig config = socketConfig(dir);
  // The camera 0.2 m ahead of the robot (x), looking along the robot's x axis.
  config.pose.t_world_cam = Eigen::Vector3d(0.2, 0, 0);
  config.pose.R_world_cam << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  Result<std::unique_ptr<PoseSource>> created = PoseSource::create(config);
  ASSERT_TRUE(created.isOk()) << created.status().message();
  Sender sender(config.socket_path);
  sender.pose(1'000, 5.0, std::sin(M_PI / 4), std::cos(M_PI / 4));  // robot at x=5 turned 90 deg about z
  Pose pose;
  ASSERT_TRUE(created.value()->poseAt(1'000, pose));
  EXPECT_LT((pose.t_world_cam - Eigen::Vector3d(5.0, 0.2, 0)).norm(), 1e-12);
  // The camera's optical axis (z) points along the robot's x, which is the world's y.
  EXPECT_LT((pose.R_world_cam.col(2) - Eigen::Vector3d(0, 1, 0)).norm(), 1e-12);
}

TEST(PoseSource, FixedAndNone) {
  PoseSourceConfig config;
  config.kind = PoseSourceConfig::Kind::kFixed;
  config.pose.t_world_cam = Eigen::Vector3d(1, 2, 3);
  Result<std::unique_ptr<PoseSource>> fixed = PoseSource::create(config);
  ASSERT_TRUE(fixed.isOk());
  RgbdFrame frame(4, 4);
  EXPECT_TRUE(fixed.value()->apply(frame));
  EXPECT_EQ(frame.T_world_cam.t_world_cam, Eigen::Vector3d(1, 2, 3));
  EXPECT_NE(fixed.value()->describe().find("fixed mount: t 1.0000 2.0000 3.0000 m"), std::string::npos);
  config.kind = PoseSourceConfig::Kind::kNone;
  Result<std::unique_ptr<PoseSource>> none = PoseSource::create(config);
  ASSERT_TRUE(none.isOk());
  frame.T_world_cam.t_world_cam = Eigen::Vector3d(4, 4, 4);
  EXPECT_TRUE(none.value()->apply(frame));
  EXPECT_EQ(frame.T_world_cam.t_world_cam, Eigen::Vector3d(4, 4, 4));
  config.pose.R_world_cam(0, 0) = 2;
  EXPECT_FALSE(PoseSource::create(config).isOk());
}

TEST(PoseSource, SocketSetUpErrors) {
  TempDir dir;
  PoseSourceConfig config = socketConfig(dir);
  config.socket_path = dir.file("missing/pose.sock");
  Result<std::unique_ptr<PoseSource>> r = PoseSource::create(config);
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().code(), ErrorCode::kNotFound);
  EXPECT_NE(r.status().message().find("does not exist (create it; under systemd RuntimeDirectory=fovea"),
            std::string::npos);
  config.socket_path = std::string(200, 'x');
  EXPECT_EQ(PoseSource::create(config).status().code(), ErrorCode::kInvalidArgument);
  // A plain file in the way is not removed.
  config.socket_path = dir.file("plain");
  { std::FILE* f = std::fopen(config.socket_path.c_str(), "w"); std::fclose(f); }
  EXPECT_NE(PoseSource::create(config).status().message().find("not a socket is in the way"), std::string::npos);
  // A live socket is refused; once its owner is gone, its stale file is replaced.
  config.socket_path = dir.file("pose.sock");
  {
    Result<std::unique_ptr<PoseSource>> first = PoseSource::create(config);
    ASSERT_TRUE(first.isOk());
    Result<std::unique_ptr<PoseSource>> second = PoseSource::create(config);
    ASSERT_FALSE(second.isOk());
    EXPECT_NE(second.status().message().find("is in use by another process"), std::string::npos);
  }
  {
    // A socket file left behind (bound, then the descriptor closed without unlink).
    const int fd = ::socket(AF_UNIX, SOCK_DGRAM, 0);
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::snprintf(a.sun_path, sizeof a.sun_path, "%s", config.socket_path.c_str());
    ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    ::close(fd);
  }
  Result<std::unique_ptr<PoseSource>> again = PoseSource::create(config);
  EXPECT_TRUE(again.isOk()) << again.status().message();
}

TEST(PoseSource, ApplyNeverAllocates) {
  TempDir dir;
  Result<std::unique_ptr<PoseSource>> created = PoseSource::create(socketConfig(dir, 32));
  ASSERT_TRUE(created.isOk());
  PoseSource& source = *created.value();
  Sender sender(source.config().socket_path);
  RgbdFrame frame(4, 4);
  uint64_t allocations = 0;
  for (int i = 0; i < 200; ++i) {
    sender.pose(1'000'000'000 + i * 5'000'000, i);
    if (i % 7 == 0) sender.send("bad datagram");
    frame.stamp_ns = 1'000'000'000 + i * 5'000'000 - 2'500'000;
    test::AllocationScope scope;
    (void)source.apply(frame);
    allocations += scope.allocations();
  }
  EXPECT_EQ(allocations, 0u);
  EXPECT_EQ(source.counters().received, 200u);
  EXPECT_EQ(source.counters().frames_fresh + source.counters().frames_stale, 200u);
}

}  // namespace
}  // namespace fovea::hal

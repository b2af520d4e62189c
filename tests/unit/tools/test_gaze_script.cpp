// fovea-operator's gaze scripts: fixed, scan (fixations and saccades), csv traces.
#include "tools/operator/gaze_script.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

namespace fovea::tools {
namespace {

constexpr int64_t kMs = 1'000'000;

double angleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  // atan2 of the cross and dot products: accurate near 0, unlike acos.
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / M_PI;
}

TEST(GazeScript, FixedLooksFromTheEyeAtTheTarget) {
  auto s = GazeScript::parse("fixed:3,0.35,1.55>3,2.25,1.35");
  ASSERT_TRUE(s.isOk()) << s.status().message();
  const GazePoint g = s->at(12345 * kMs);
  EXPECT_EQ(g.origin_m, Eigen::Vector3d(3, 0.35, 1.55));
  EXPECT_NEAR(g.direction.norm(), 1.0, 1e-15);
  EXPECT_LT(angleDeg(g.direction, Eigen::Vector3d(0, 1.9, -0.2)), 1e-9);
}

TEST(GazeScript, ScanDwellsThenSaccadesAlongTheGreatCircle) {
  // Targets along +x and +y from the origin; dwell 100 ms, saccade 20 ms.
  auto s = GazeScript::parse("scan:0,0,0>1,0,0;0,1,0@100/20");
  ASSERT_TRUE(s.isOk()) << s.status().message();
  EXPECT_LT(angleDeg(s->at(0).direction, Eigen::Vector3d::UnitX()), 1e-9);
  EXPECT_LT(angleDeg(s->at(99 * kMs).direction, Eigen::Vector3d::UnitX()), 1e-9);
  // Halfway through the saccade: 45 degrees between the two.
  const Eigen::Vector3d mid = s->at(110 * kMs).direction;
  EXPECT_NEAR(angleDeg(mid, Eigen::Vector3d::UnitX()), 45.0, 1e-9);
  EXPECT_NEAR(angleDeg(mid, Eigen::Vector3d::UnitY()), 45.0, 1e-9);
  EXPECT_NEAR(mid.norm(), 1.0, 1e-12);
  EXPECT_LT(angleDeg(s->at(120 * kMs).direction, Eigen::Vector3d::UnitY()), 1e-9);
  // The loop comes back to the first target.
  EXPECT_LT(angleDeg(s->at(240 * kMs).direction, Eigen::Vector3d::UnitX()), 1e-9);
}

TEST(GazeScript, CsvTraceHoldsEachSampleUntilTheNext) {
  const std::string path = ::testing::TempDir() + "/gaze_trace.csv";
  {
    std::ofstream f(path);
    f << "t_s,ox,oy,oz,dx,dy,dz\n# a comment\n0.0,0,0,0,0,0,2\n0.5,1,0,0,0,3,0\n1.0,0,1,0,4,0,0\n";
  }
  auto s = GazeScript::parse("csv:" + path);
  ASSERT_TRUE(s.isOk()) << s.status().message();
  EXPECT_EQ(s->at(0).direction, Eigen::Vector3d(0, 0, 1));
  EXPECT_EQ(s->at(499 * kMs).direction, Eigen::Vector3d(0, 0, 1));
  EXPECT_EQ(s->at(500 * kMs).direction, Eigen::Vector3d(0, 1, 0));
  EXPECT_EQ(s->at(500 * kMs).origin_m, Eigen::Vector3d(1, 0, 0));
  EXPECT_EQ(s->at(10'000 * kMs).direction, Eigen::Vector3d(1, 0, 0));
  std::remove(path.c_str());
}

TEST(GazeScript, BadScriptsAreNamedErrors) {
  const char* bad[] = {"", "fixed", "fixed:1,2,3", "fixed:1,2>3,4,5", "fixed:1,2,3>1,2,3", "fixed:1,2,3>4,5,6;7,8,9",
                       "scan:0,0,0>1,0,0@0", "scan:0,0,0>1,0,0@x", "scan:0,0,0>1,0,0@1e300", "scan:0,0,0>1,0,0@100/-1", "scan:0,0,0>", "wobble:1", "fixed:nan,0,0>1,1,1",
                       "csv:/nonexistent/trace.csv"};
  for (const char* text : bad) {
    auto s = GazeScript::parse(text);
    EXPECT_FALSE(s.isOk()) << text;
    if (!s.isOk()) {
      EXPECT_NE(s.status().message().find("--gaze"), std::string::npos) << s.status().message();
    }
  }
  const std::string path = ::testing::TempDir() + "/gaze_bad.csv";
  for (const char* content : {"0,0,0,0,0,0\n", "0,0,0,0,0,0,0\n", "1,0,0,0,0,0,1\n0.5,0,0,0,0,0,1\n", "# only\n",
                              "1e300,0,0,0,0,0,1\n", "-1,0,0,0,0,0,1\n"}) {
    { std::ofstream(path) << content; }
    EXPECT_FALSE(GazeScript::parse("csv:" + path).isOk()) << content;
  }
  std::remove(path.c_str());
}

}  // namespace
}  // namespace fovea::tools

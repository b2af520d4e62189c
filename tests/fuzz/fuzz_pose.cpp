// Fuzz target for the pose socket's datagrams (hal/pose_source.h:
// "stamp_ns tx ty tz qx qy qz qw"): parsePoseDatagram on the bytes as the pose
// source receives them. Oracle: a pose that parses is finite and its
// quaternion has unit length.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string_view>

#include "hal/pose_source.h"
#include "tests/fuzz/fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  fovea::hal::StampedPose pose;
  if (!fovea::hal::parsePoseDatagram(text, pose)) return 0;
  if (!pose.t_world_cam.allFinite() || !pose.q_world_cam.coeffs().allFinite() ||
      std::fabs(pose.q_world_cam.norm() - 1.0) > 1e-9) {
    std::fprintf(stderr, "fuzz_pose: a parsed pose is not finite or its quaternion not unit\n");
    std::abort();
  }
  return 0;
}

// The seeds are datagrams: corpus/fuzz_pose/.
std::vector<fovea::fuzz::Input> fovea::fuzz::seeds() { return {}; }

// The equivalence tests' fixture: each TEST_P(TargetTest, ...) runs once per
// Highway target compiled into the binary and supported by this CPU, with the
// dispatch restricted to that target, and is named after it
// (Targets/TargetTest.<Case>/<TARGET>), so CTest shows which targets ran.
//   INSTANTIATE_TEST_SUITE_P(Targets, TargetTest, ::testing::ValuesIn(fovea::test::simdTargetsHere()),
//                            fovea::test::simdTargetName);
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#if defined(__aarch64__) && defined(__linux__)
#include <sys/prctl.h>
#endif

#include "pipeline/kernels/foveation_simd.h"

namespace fovea::test {

// Restricts Highway's dispatch to one target for the test's duration.
class TargetTest : public ::testing::TestWithParam<int64_t> {
 protected:
  void SetUp() override { pipeline::forceSimdTarget(GetParam()); }
  void TearDown() override { pipeline::forceSimdTarget(0); }
};

// The targets compiled in and supported here, best first.
inline std::vector<int64_t> simdTargetsHere() {
  pipeline::forceSimdTarget(0);
  return pipeline::simdTargets();
}

inline std::string simdTargetName(const ::testing::TestParamInfo<int64_t>& info) {
  return pipeline::simdTargetName(info.param);
}

// The SVE vector length this process runs with, in bytes (0: no SVE here), as
// the kernel reports it: the SVE tests' vectors are this long (under qemu-user,
// QEMU_CPU's sve-default-vector-length; toolchain/run-tests-aarch64 checks it).
inline int sveVectorBytes() {
#if defined(__aarch64__) && defined(__linux__) && defined(PR_SVE_GET_VL)
  const int vl = prctl(PR_SVE_GET_VL, 0, 0, 0, 0);
  return vl < 0 ? 0 : (vl & PR_SVE_VL_LEN_MASK);
#else
  return 0;
#endif
}

}  // namespace fovea::test

// judgeRowSimd (view_judge.h), dynamically dispatched: foreach_target.h
// re-includes this file once per Highway target, compiling
// view_judge_simd-inl.h for each; HWY_EXPORT builds the table and
// HWY_DYNAMIC_DISPATCH calls the best supported target
// (pipeline::forceSimdTarget() restricts it, as for the other kernels).
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/map/view_judge_simd.cpp"
#include "hwy/foreach_target.h"  // IWYU pragma: keep

#include "hwy/highway.h"
#include "pipeline/map/view_judge_simd-inl.h"

#if HWY_ONCE

namespace fovea::pipeline::map {

HWY_EXPORT(JudgeRowT);

void judgeRowSimd(const ViewJudgeParams& p, int v, uint8_t* out) { HWY_DYNAMIC_DISPATCH(JudgeRowT)(p, v, out); }

}  // namespace fovea::pipeline::map

#endif  // HWY_ONCE

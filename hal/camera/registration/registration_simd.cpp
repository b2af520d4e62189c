// Dynamic dispatch of the registration kernel: foreach_target.h re-includes
// this file once per Highway target, compiling registration_simd-inl.h for
// each; HWY_EXPORT builds the table and HWY_DYNAMIC_DISPATCH calls the best
// supported target (forceSimdTarget() in foveation_simd.h restricts it for
// tests: Highway's target choice is global).
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "hal/camera/registration/registration_simd.cpp"
#include "hwy/foreach_target.h"  // IWYU pragma: keep

#include "hwy/highway.h"
#include "hal/camera/registration/registration_simd-inl.h"

#if HWY_ONCE

namespace fovea::hal::kernels {

HWY_EXPORT(RegisterT);

RegistrationCounts registerSimdDispatch(const DepthToColourRegistration::Kernel& k, const uint16_t* depth,
                                        const uint8_t* colour_rgb, uint8_t* out_rgb) {
  return HWY_DYNAMIC_DISPATCH(RegisterT)(k, depth, colour_rgb, out_rgb);
}

}  // namespace fovea::hal::kernels

#endif  // HWY_ONCE

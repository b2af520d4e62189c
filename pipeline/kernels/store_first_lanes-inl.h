// Storing part of a vector without touching the memory after it.
//
// Highway 1.0.3's BlendedStore (and CompressBlendedStore, built on it) is a true
// masked store on x86 and SVE, but on NEON it loads the whole vector, blends and
// stores it all back. Past a buffer's end that reads and rewrites memory that is
// not ours; inside an output shared by threads it can put back a neighbour's
// lanes as they were before the neighbour wrote them (CI caught the threaded
// back-projection losing points that way under qemu-aarch64). The kernels that
// end an output in the middle of a vector go through here instead.

// Per-target include guard (Highway's toggle idiom).
#if defined(FOVEA_PIPELINE_KERNELS_STORE_FIRST_LANES_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef FOVEA_PIPELINE_KERNELS_STORE_FIRST_LANES_INL_H_
#undef FOVEA_PIPELINE_KERNELS_STORE_FIRST_LANES_INL_H_
#else
#define FOVEA_PIPELINE_KERNELS_STORE_FIRST_LANES_INL_H_
#endif

#include <cstddef>
#include <cstring>

#include "hwy/highway.h"

HWY_BEFORE_NAMESPACE();
namespace fovea::pipeline::kernels {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// Lanes [0, count) of v to p[0, count); nothing at p[count] or after is read or written.
template <class D>
HWY_INLINE void StoreFirstLanes(hn::Vec<D> v, D d, std::size_t count, hn::TFromD<D>* p) {
  HWY_ALIGN hn::TFromD<D> staged[hn::MaxLanes(D())];
  hn::Store(v, d, staged);
  std::memcpy(p, staged, count * sizeof(hn::TFromD<D>));
}

}  // namespace HWY_NAMESPACE
}  // namespace fovea::pipeline::kernels
HWY_AFTER_NAMESPACE();

#endif  // include guard

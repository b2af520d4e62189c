// Which implementation of the per-point kernels the pipeline runs.
//
// kRef is the scalar reference (backprojectRef, partitionRef, VoxelSampler): the
// specification. kSimd runs the Highway kernels (pipeline/kernels/foveation_simd.h),
// which reproduce the reference bit for bit, and the hash-table sampler.
// The default is chosen once, at the first call of defaultKernelSet(): kSimd,
// unless the environment variable FOVEA_FORCE_KERNEL says `ref` (or `simd`).
#pragma once

#include <cstdint>
#include <optional>
#include <string_view>

namespace fovea {

enum class KernelSet : uint8_t { kRef, kSimd };

inline constexpr std::string_view kernelSetName(KernelSet k) { return k == KernelSet::kRef ? "ref" : "simd"; }
std::optional<KernelSet> parseKernelSet(std::string_view text);

// FOVEA_FORCE_KERNEL=ref|simd read once; kSimd when unset. An unknown value is
// reported once on stderr and ignored (kSimd).
KernelSet defaultKernelSet();

}  // namespace fovea

#include "core/kernel_set.h"

#include <cstdio>
#include <cstdlib>

namespace fovea {

std::optional<KernelSet> parseKernelSet(std::string_view text) {
  if (text == "ref") return KernelSet::kRef;
  if (text == "simd") return KernelSet::kSimd;
  return std::nullopt;
}

KernelSet defaultKernelSet() {
  // A function-local static: initialised once, thread-safe, at start-up in practice.
  static const KernelSet chosen = [] {
    const char* env = std::getenv("FOVEA_FORCE_KERNEL");
    if (env == nullptr || *env == '\0') return KernelSet::kSimd;
    if (std::optional<KernelSet> k = parseKernelSet(env)) return *k;
    std::fprintf(stderr, "fovea: FOVEA_FORCE_KERNEL='%s' is not ref or simd; using simd\n", env);
    return KernelSet::kSimd;
  }();
  return chosen;
}

}  // namespace fovea

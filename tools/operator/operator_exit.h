// fovea-operator's exit codes and how a step that ends the program reports why:
// shared by the set-up (operator_station.cpp) and the run (operator_run.h).
#pragma once

#include <cstdio>
#include <optional>

#include "core/result.h"

namespace fovea::tools {

inline constexpr int kExitOk = 0, kExitFailure = 1, kExitUsage = 2;

// A step that ends the program returns its exit code; nullopt: carry on.
using Exit = std::optional<int>;

inline int failure(const char* what, const Status& s) {
  std::fprintf(stderr, "fovea-operator: %s%s\n", what, s.message().c_str());
  return kExitFailure;
}

// Bad arguments are the user's (kExitUsage); anything else is the machine's.
inline int startFailure(const Status& s) {
  std::fprintf(stderr, "fovea-operator: %s\n", s.message().c_str());
  return s.code() == ErrorCode::kInvalidArgument ? kExitUsage : kExitFailure;
}

}  // namespace fovea::tools

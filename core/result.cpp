#include "core/result.h"

#include <cstdio>
#include <cstdlib>

namespace fovea {

const char* errorCodeName(ErrorCode code) {
  switch (code) {
    case ErrorCode::kOk: return "ok";
    case ErrorCode::kInvalidArgument: return "invalid-argument";
    case ErrorCode::kInvalidInput: return "invalid-input";
    case ErrorCode::kCapacityExceeded: return "capacity-exceeded";
    case ErrorCode::kRangeExceeded: return "range-exceeded";
    case ErrorCode::kNotFound: return "not-found";
    case ErrorCode::kIoError: return "io-error";
    case ErrorCode::kParseError: return "parse-error";
    case ErrorCode::kUnavailable: return "unavailable";
  }
  return "unknown";
}

std::string Status::toString() const {
  if (isOk()) return "ok";
  return std::string(errorCodeName(code_)) + ": " + message_;
}

void resultValueOfError(const Status& status) {
  std::fprintf(stderr, "fovea: bug: value() of an error result (%s)\n", status.toString().c_str());
  std::abort();
}

}  // namespace fovea

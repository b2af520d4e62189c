// Errors as values. Start-up code returns Status/Result with a message that says
// what to fix; the per-frame path returns Status codes and never throws.
#pragma once

#include <cassert>
#include <optional>
#include <string>
#include <utility>

namespace fovea {

enum class ErrorCode {
  kOk = 0,
  kInvalidArgument,   // a configuration or command-line value is out of range
  kInvalidInput,      // a frame, cloud or gaze sample is unusable (NaN, wrong size...)
  kCapacityExceeded,  // a fixed-capacity buffer is too small for this input
  kRangeExceeded,     // a value does not fit the representation (voxel index span)
  kNotFound,          // a device or file is absent
  kIoError,           // reading or writing failed
  kParseError,        // malformed file contents
  kUnavailable,       // the device exists but cannot deliver now (stopped, timeout)
};

const char* errorCodeName(ErrorCode code);

// A success or an error code with a human-readable message. The message is only
// built on error paths (start-up, file I/O, bad input), never per frame on success.
class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(ErrorCode code, std::string message) : code_(code), message_(std::move(message)) {}
  static Status ok() { return {}; }

  bool isOk() const { return code_ == ErrorCode::kOk; }
  explicit operator bool() const { return isOk(); }
  ErrorCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "invalid-argument: preset: unknown name 'F9'"
  std::string toString() const;

 private:
  ErrorCode code_ = ErrorCode::kOk;
  std::string message_;
};

// The commonest error: a bad value in a configuration, a spec or a flag.
inline Status invalidArgument(std::string message) { return {ErrorCode::kInvalidArgument, std::move(message)}; }

// Prints the status and aborts (Result::value() of an error).
[[noreturn]] void resultValueOfError(const Status& status);

// A value or a Status. (std::expected is C++23 and missing from clang-14 tooling.)
template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : value_(std::move(value)) {}  // NOLINT: implicit by design
  Result(Status status) : status_(std::move(status)) { assert(!status_.isOk()); }  // NOLINT
  Result(ErrorCode code, std::string message) : status_(code, std::move(message)) {}

  bool isOk() const { return value_.has_value(); }
  explicit operator bool() const { return isOk(); }
  const Status& status() const { return status_; }
  // Taking the value of an error is a bug, never bad input: it aborts, in
  // release builds too, rather than read an empty optional.
  T& value() & { checkHasValue(); return *value_; }
  const T& value() const& { checkHasValue(); return *value_; }
  T&& value() && { checkHasValue(); return std::move(*value_); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }

 private:
  void checkHasValue() const {
    if (!value_) [[unlikely]] {
      resultValueOfError(status_);
    }
  }
  std::optional<T> value_;
  Status status_;
};

}  // namespace fovea

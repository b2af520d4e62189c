// Fault injection for the mock camera (issue 5, "Faults"): the spec option
// fault=... lists faults that fire at given frame numbers, so tests are exact.
//
//   fault=none                      no faults (the default)
//   fault=stall:2s@30               from frame 30, no frames for 2 s of clock time
//   fault=disconnect:1.5s@60        from frame 60, the device is gone for 1.5 s
//   fault=wrong-size@90[:N]         frames 90.. (N, default 1) come with a wrong size
//   fault=garbage@120[:N]           frames 120.. (N, default 1) are random bytes
//   fault=stall:500ms@30;garbage@120:3   several, separated by ';'
//
// Durations take s or ms. "Frame F" is the camera's sequence number: a fault
// fires at the first acquire() whose next frame has sequence >= F (with
// realtime=on the sequence may skip; the fault still fires once). Each fault
// fires once. What acquire() does (see MockCamera::acquire):
//  - stall: kUnavailable ("stalled") for the duration, each call blocking for its
//    timeout (or until the stall ends, then it delivers); counted in timeouts and
//    once in stalls.
//  - disconnect: kNotFound ("disconnected") on every acquire() until the camera is
//    stopped, opened and started again; open() and start() fail with kNotFound
//    ("device gone") until the duration has passed. Counted once in disconnects,
//    each failing acquire() in errors.
//  - wrong-size: the device hands over an image larger than the intrinsics say;
//    acquire() checks the size before copying anything and returns kInvalidInput
//    ("wrong size"), the frame's sequence number is consumed, no pixel is copied.
//    Counted in bad_frames and errors.
//  - garbage: a valid-sized frame whose depth is random 16-bit values (an eighth of
//    the pixels 0, an eighth 65535) and whose colour is random, pose and
//    intrinsics intact: downstream must cope. Delivered and counted in
//    injected_garbage.
// Durations run on a MockClock: the process's steady clock, or one a test
// advances by hand (ManualClock) so that a 2 s stall takes no time.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.h"

namespace fovea::hal::mock {

enum class FaultKind : uint8_t { kStall, kDisconnect, kWrongSize, kGarbage };

const char* faultKindName(FaultKind kind);

struct FaultSpec {
  FaultKind kind = FaultKind::kStall;
  uint64_t at_frame = 0;
  int64_t duration_ns = 0;  // stall, disconnect
  uint64_t count = 1;       // wrong-size, garbage: consecutive frames
};

// Parses the value of fault= ("none" or KIND[:DURATION]@FRAME[:N];...).
// kInvalidArgument naming the fault and the expected form on any error.
Result<std::vector<FaultSpec>> parseFaults(std::string_view value);

// The help text's part for fault=.
std::string faultHelp();

// The time that fault durations run on. now is monotonic nanoseconds.
class MockClock {
 public:
  virtual ~MockClock() = default;
  virtual int64_t nowNs() = 0;
  virtual void sleepUntilNs(int64_t t_ns) = 0;
};

// CLOCK_MONOTONIC (std::chrono::steady_clock) and real sleeps.
MockClock& steadyMockClock();

// A clock for tests: time moves only when advanced, or when acquire() "sleeps".
class ManualClock final : public MockClock {
 public:
  explicit ManualClock(int64_t start_ns = 0) : now_ns_(start_ns) {}
  int64_t nowNs() override { return now_ns_; }
  void sleepUntilNs(int64_t t_ns) override {
    if (t_ns > now_ns_) now_ns_ = t_ns;
  }
  void advanceNs(int64_t dt_ns) { now_ns_ += dt_ns; }
  void setNs(int64_t t_ns) { now_ns_ = t_ns; }

 private:
  int64_t now_ns_;
};

}  // namespace fovea::hal::mock

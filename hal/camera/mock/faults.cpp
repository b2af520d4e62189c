#include "hal/camera/mock/faults.h"

#include <charconv>
#include <chrono>
#include <cmath>
#include <thread>

namespace fovea::hal::mock {

namespace {

constexpr std::string_view kForm =
    "expected fault=none or KIND[:DURATION]@FRAME[:N];... with KIND stall:DURATION, "
    "disconnect:DURATION, wrong-size or garbage (DURATION e.g. 2s or 500ms; N frames, "
    "wrong-size and garbage only)";
constexpr double kMaxDurationS = 3600.0;
constexpr uint64_t kMaxCount = 1000000;

Status invalid(std::string_view fault, std::string_view why) {
  return Status(ErrorCode::kInvalidArgument, "mock: fault '" + std::string(fault) + "': " +
                                                 std::string(why) + "; " + std::string(kForm));
}

bool parseUint(std::string_view text, uint64_t& out) {
  if (text.empty()) return false;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), out);
  return ec == std::errc() && end == text.data() + text.size();
}

// "2s", "1.5s", "500ms" -> nanoseconds in (0, 1 h].
bool parseDuration(std::string_view text, int64_t& out_ns) {
  double scale_s = 1.0;
  if (text.size() > 2 && text.substr(text.size() - 2) == "ms") {
    scale_s = 1e-3;
    text.remove_suffix(2);
  } else if (text.size() > 1 && text.back() == 's') {
    text.remove_suffix(1);
  } else {
    return false;
  }
  double value = 0.0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || end != text.data() + text.size() || !std::isfinite(value)) return false;
  const double seconds = value * scale_s;
  if (!(seconds > 0.0 && seconds <= kMaxDurationS)) return false;
  out_ns = static_cast<int64_t>(std::llround(seconds * 1e9));
  return out_ns > 0;
}

Status parseOne(std::string_view text, FaultSpec& out) {
  const std::size_t at = text.find('@');
  if (at == std::string_view::npos) return invalid(text, "missing @FRAME");
  const std::string_view head = text.substr(0, at);
  std::string_view tail = text.substr(at + 1);
  const std::size_t colon = head.find(':');
  const std::string_view kind = head.substr(0, colon);
  const bool has_duration = colon != std::string_view::npos;
  if (kind == "stall") {
    out.kind = FaultKind::kStall;
  } else if (kind == "disconnect") {
    out.kind = FaultKind::kDisconnect;
  } else if (kind == "wrong-size") {
    out.kind = FaultKind::kWrongSize;
  } else if (kind == "garbage") {
    out.kind = FaultKind::kGarbage;
  } else {
    return invalid(text, "unknown kind '" + std::string(kind) + "'");
  }
  const bool timed = out.kind == FaultKind::kStall || out.kind == FaultKind::kDisconnect;
  if (timed) {
    if (!has_duration || !parseDuration(head.substr(colon + 1), out.duration_ns)) {
      return invalid(text, std::string(kind) + " needs a duration in (0, 3600] s, e.g. " +
                               std::string(kind) + ":2s@30");
    }
  } else if (has_duration) {
    return invalid(text, std::string(kind) + " takes no duration");
  }
  const std::size_t count_colon = tail.find(':');
  if (count_colon != std::string_view::npos) {
    if (timed) return invalid(text, std::string(kind) + " takes no frame count");
    if (!parseUint(tail.substr(count_colon + 1), out.count) || out.count == 0 ||
        out.count > kMaxCount) {
      return invalid(text, "N must be a frame count in 1..1000000");
    }
    tail = tail.substr(0, count_colon);
  }
  if (!parseUint(tail, out.at_frame)) return invalid(text, "FRAME must be an unsigned integer");
  return Status::ok();
}

class SteadyClock final : public MockClock {
 public:
  int64_t nowNs() override {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
        .count();
  }
  void sleepUntilNs(int64_t t_ns) override {
    std::this_thread::sleep_until(std::chrono::steady_clock::time_point(
        std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::nanoseconds(t_ns))));
  }
};

}  // namespace

Result<std::vector<FaultSpec>> parseFaults(std::string_view value) {
  std::vector<FaultSpec> faults;
  if (value == "none") return faults;
  if (value.empty()) return invalid(value, "empty");
  std::size_t start = 0;
  while (start <= value.size()) {
    const std::size_t semi = std::min(value.find(';', start), value.size());
    const std::string_view one = value.substr(start, semi - start);
    start = semi + 1;
    if (one.empty()) {
      if (start > value.size() && !faults.empty()) break;  // a trailing ';'
      return invalid(one, "empty fault in the list");
    }
    FaultSpec spec;
    if (Status s = parseOne(one, spec); !s) return s;
    faults.push_back(spec);
  }
  return faults;
}

std::string faultHelp() {
  return "fault=none|KIND[:DURATION]@FRAME[:N];... (none): stall:2s@30 (no frames for 2 s), "
         "disconnect:1.5s@60 (kNotFound until reopened after 1.5 s), wrong-size@90[:N] "
         "(kInvalidInput), garbage@120[:N] (random depth and colour)";
}

MockClock& steadyMockClock() {
  static SteadyClock clock;
  return clock;
}

}  // namespace fovea::hal::mock

// The viewer's WebSocket messages (docs/viewer.md): what a browser tab may send
// its operator process (gaze, gaze mode), parsed and validated here so the
// server never trusts a tab; and the JSON the operator sends the tabs (hello,
// connection state, figures). Binary frames are in view_frame.h.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.h"

namespace fovea::tools {

enum class GazeMode { kCursor, kScript };
std::string_view gazeModeName(GazeMode mode);

// A tab's gaze: the operator's eye (the gaze origin and HMD position), the unit
// ray through the cursor (or the headset's forward ray) and the eye's
// orientation (unit quaternion, w first), all in the world frame (z up).
struct ViewerGaze {
  std::array<double, 3> origin_m{};
  std::array<double, 3> direction{0, 0, 1};
  std::array<double, 4> orientation{1, 0, 0, 0};
};

struct ViewerMessage {
  enum class Kind { kGaze, kMode };
  Kind kind = Kind::kGaze;
  ViewerGaze gaze;
  GazeMode mode = GazeMode::kCursor;
};

// Largest text message a tab may send (a gaze message is about 150 bytes).
inline constexpr std::size_t kMaxViewerMessageBytes = 4096;

// Parses one text message from a tab. Errors (kParseError or kInvalidArgument)
// say what is wrong; the caller counts them and keeps the connection.
// Directions are normalised (any non-zero finite length is accepted); origins
// must lie within 1e6 m of the world origin.
Result<ViewerMessage> parseViewerMessage(std::string_view text);

// What the operator knows about its robot, for the tabs' overlay.
enum class LinkState { kConnecting, kRefused, kStreaming, kRobotGone };
std::string_view linkStateName(LinkState state);

std::string helloJson(int tab, double gaze_hz, GazeMode mode, const std::string& script,
                      const std::optional<std::array<double, 6>>& initial_eye);  // origin, target
std::string stateJson(LinkState state, const std::string& detail, const std::string& robot);

// One second of figures (NaN or a negative age: not measured yet, sent as null).
struct ViewerFigures {
  double fps = 0.0;
  double wire_mb_per_s = 0.0;
  double latency_p50_ms = 0.0;
  double latency_p99_ms = 0.0;
  uint64_t datagrams_lost = 0;
  std::vector<uint64_t> points_per_region;
  GazeMode gaze_mode = GazeMode::kCursor;
  uint64_t gaze_sent = 0;
  std::optional<ViewerGaze> gaze_last;  // what the operator sent last
  double robot_gaze_age_ms = -1.0;
  std::optional<std::array<double, 3>> robot_gaze_origin_m;
  std::optional<std::array<double, 3>> robot_gaze_direction;
  double robot_rtt_ms = -1.0;
  uint64_t tabs = 0;
  uint64_t malformed = 0;  // all tabs' malformed messages
};
// The stats message for one tab (its own dropped-frame count).
std::string statsJson(const ViewerFigures& figures, uint64_t frames_dropped_for_tab);

}  // namespace fovea::tools

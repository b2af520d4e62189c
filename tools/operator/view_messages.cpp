#include "tools/operator/view_messages.h"

#include <algorithm>
#include <cmath>

#include <nlohmann/json.hpp>

namespace fovea::tools {

namespace {

using nlohmann::json;

constexpr double kMaxCoordinateM = 1e6;

Result<ViewerMessage> invalid(const std::string& what) { return Result<ViewerMessage>(ErrorCode::kInvalidArgument, what); }

// Reads an array of N finite numbers at key; the error names the key.
template <std::size_t N>
Status readNumbers(const json& message, const char* key, std::array<double, N>& out) {
  const auto it = message.find(key);
  if (it == message.end()) return {ErrorCode::kInvalidArgument, std::string("'") + key + "' is missing"};
  if (!it->is_array() || it->size() != N) {
    return {ErrorCode::kInvalidArgument, std::string("'") + key + "' is not an array of " + std::to_string(N) + " numbers"};
  }
  for (std::size_t i = 0; i < N; ++i) {
    const json& v = (*it)[i];
    if (!v.is_number()) return {ErrorCode::kInvalidArgument, std::string("'") + key + "' holds a non-number"};
    out[i] = v.get<double>();
    if (!std::isfinite(out[i])) return {ErrorCode::kInvalidArgument, std::string("'") + key + "' holds a non-finite number"};
  }
  return Status::ok();
}

// Scales v (finite numbers) to unit length; false for the zero vector. It
// divides by the largest component first, so that every non-zero finite length
// works: the sum of squares of [1e200, 1e200, 0] would overflow, that of
// [1e-200, 0, 0] underflow to zero.
template <std::size_t N>
bool normalise(std::array<double, N>& v) {
  double largest = 0.0;
  for (double x : v) largest = std::max(largest, std::fabs(x));
  if (!(largest > 0.0)) return false;
  double n2 = 0.0;
  for (double& x : v) {
    x /= largest;
    n2 += x * x;
  }
  const double n = std::sqrt(n2);  // between 1 and sqrt(N)
  for (double& x : v) x /= n;
  return true;
}

json vec(const std::array<double, 3>& v) { return json::array({v[0], v[1], v[2]}); }
json orNull(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

}  // namespace

std::string_view gazeModeName(GazeMode mode) { return mode == GazeMode::kScript ? "script" : "cursor"; }

std::string_view linkStateName(LinkState state) {
  switch (state) {
    case LinkState::kConnecting: return "connecting";
    case LinkState::kRefused: return "refused";
    case LinkState::kStreaming: return "streaming";
    case LinkState::kRobotGone: return "robot-gone";
  }
  return "unknown";
}

Result<ViewerMessage> parseViewerMessage(std::string_view text) {
  if (text.size() > kMaxViewerMessageBytes) {
    return Result<ViewerMessage>(ErrorCode::kInvalidArgument,
                                 "message of " + std::to_string(text.size()) + " bytes (at most " +
                                     std::to_string(kMaxViewerMessageBytes) + ")");
  }
  const json message = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (message.is_discarded()) return Result<ViewerMessage>(ErrorCode::kParseError, "not JSON");
  if (!message.is_object()) return invalid("not a JSON object");
  const auto type = message.find("type");
  if (type == message.end() || !type->is_string()) return invalid("no 'type'");
  ViewerMessage out;
  if (*type == "gaze") {
    out.kind = ViewerMessage::Kind::kGaze;
    ViewerGaze& g = out.gaze;
    if (Status s = readNumbers(message, "origin", g.origin_m); !s.isOk()) return s;
    if (Status s = readNumbers(message, "direction", g.direction); !s.isOk()) return s;
    for (double x : g.origin_m) {
      if (std::fabs(x) > kMaxCoordinateM) return invalid("'origin' is more than 1e6 m from the world origin");
    }
    if (!normalise(g.direction)) return invalid("'direction' has no length");
    if (message.contains("orientation")) {
      if (Status s = readNumbers(message, "orientation", g.orientation); !s.isOk()) return s;
      if (!normalise(g.orientation)) return invalid("'orientation' has no length");
    }
    return out;
  }
  if (*type == "mode") {
    out.kind = ViewerMessage::Kind::kMode;
    const auto gaze = message.find("gaze");
    if (gaze == message.end() || !gaze->is_string()) return invalid("'gaze' is missing");
    if (*gaze == "cursor") {
      out.mode = GazeMode::kCursor;
    } else if (*gaze == "script") {
      out.mode = GazeMode::kScript;
    } else {
      return invalid("'gaze' is neither cursor nor script");
    }
    return out;
  }
  return invalid("unknown type '" + type->get<std::string>().substr(0, 32) + "'");
}

std::string helloJson(int tab, double gaze_hz, GazeMode mode, const std::string& script,
                      const std::optional<std::array<double, 6>>& initial_eye) {
  json j = {{"type", "hello"}, {"protocol", 1}, {"tab", tab}, {"gaze_hz", gaze_hz}, {"gaze_mode", gazeModeName(mode)}};
  j["script"] = script.empty() ? json(nullptr) : json(script);
  if (initial_eye) {
    const auto& e = *initial_eye;
    j["initial_eye"] = {{"origin", {e[0], e[1], e[2]}}, {"target", {e[3], e[4], e[5]}}};
  } else {
    j["initial_eye"] = nullptr;
  }
  return j.dump();
}

std::string stateJson(LinkState state, const std::string& detail, const std::string& robot) {
  // Text from the robot (a refusal's reason) may hold anything: replace what is not UTF-8.
  return json{{"type", "state"}, {"state", linkStateName(state)}, {"detail", detail}, {"robot", robot}}.dump(
      -1, ' ', false, json::error_handler_t::replace);
}

std::string statsJson(const ViewerFigures& f, uint64_t frames_dropped_for_tab) {
  json j = {{"type", "stats"},
            {"fps", orNull(f.fps)},
            {"wire_mb_per_s", orNull(f.wire_mb_per_s)},
            {"latency_ms", {{"p50", orNull(f.latency_p50_ms)}, {"p99", orNull(f.latency_p99_ms)}}},
            {"datagrams_lost", f.datagrams_lost},
            {"points_per_region", f.points_per_region},
            {"gaze_mode", gazeModeName(f.gaze_mode)},
            {"gaze_sent", f.gaze_sent}};
  j["gaze_last"] = f.gaze_last ? json{{"origin", vec(f.gaze_last->origin_m)}, {"direction", vec(f.gaze_last->direction)}}
                               : json(nullptr);
  json robot = {{"gaze_age_ms", f.robot_gaze_age_ms >= 0 ? json(f.robot_gaze_age_ms) : json(nullptr)},
                {"rtt_ms", f.robot_rtt_ms >= 0 ? json(f.robot_rtt_ms) : json(nullptr)}};
  robot["gaze_origin"] = f.robot_gaze_origin_m ? vec(*f.robot_gaze_origin_m) : json(nullptr);
  robot["gaze_direction"] = f.robot_gaze_direction ? vec(*f.robot_gaze_direction) : json(nullptr);
  j["robot"] = robot;
  j["view"] = {{"tabs", f.tabs}, {"frames_dropped_for_tab", frames_dropped_for_tab}, {"malformed", f.malformed}};
  return j.dump();
}

}  // namespace fovea::tools

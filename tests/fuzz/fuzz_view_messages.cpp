// Fuzz target for the viewer's WebSocket messages (tools/operator/view_messages.h):
// the bytes are one text message as a browser tab sends it, given to
// parseViewerMessage as ViewServer's data handler gives it. Oracles besides
// "no crash, no exception":
// - an error is kParseError (only for text that is not JSON) or
//   kInvalidArgument, with a message; text over kMaxViewerMessageBytes is
//   always an error;
// - the rules of view_messages.h, read here from the same JSON value on their
//   own, agree with the parser on every message: what they accept it accepts
//   (any non-zero finite direction and orientation, origins within 1e6 m), what
//   they refuse it refuses, and the values it gives are the ones sent (origin
//   exactly, direction and orientation scaled to unit length);
// - what parses, written back as the page writes it (JSON.stringify of the
//   same fields), parses to the same value; the gaze reads back exactly from
//   the stats message (statsJson) that carries it to the tabs;
// - the same bytes as a robot's text (a refusal's reason) in stateJson give
//   JSON whose detail is that text whenever it is UTF-8.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "tests/fuzz/fuzz_target.h"
#include "tools/operator/view_messages.h"

namespace {

using namespace fovea;
using namespace fovea::tools;
using nlohmann::json;

std::string_view current_input;  // for the report

[[noreturn]] void fail(const std::string& what) {
  std::fprintf(stderr, "fuzz_view_messages: %s\ninput: %.*s\n", what.c_str(), static_cast<int>(current_input.size()),
               current_input.data());
  std::abort();
}

// ---------------------------------------------------------------- the reference
// What view_messages.h promises a message gives, from the parsed JSON value.

struct Expected {
  bool accepted = false;
  ViewerMessage message;
};

// N finite numbers at key; false when absent or anything else.
template <std::size_t N>
bool numbersAt(const json& object, const char* key, std::array<double, N>& out) {
  const auto it = object.find(key);
  if (it == object.end() || !it->is_array() || it->size() != N) return false;
  for (std::size_t i = 0; i < N; ++i) {
    if (!(*it)[i].is_number()) return false;
    out[i] = (*it)[i].get<double>();
    if (!std::isfinite(out[i])) return false;
  }
  return true;
}

// v at unit length, scaled by its largest component first (so neither 1e300
// nor 1e-300 leaves double's range); false for the zero vector.
template <std::size_t N>
bool unitOf(std::array<double, N>& v) {
  double largest = 0.0;
  for (double x : v) largest = std::max(largest, std::fabs(x));
  if (!(largest > 0.0)) return false;
  double n2 = 0.0;
  for (double& x : v) {
    x /= largest;
    n2 += x * x;
  }
  const double n = std::sqrt(n2);
  for (double& x : v) x /= n;
  return true;
}

Expected reference(const json& message) {
  Expected e;
  if (!message.is_object()) return e;
  const auto type = message.find("type");
  if (type == message.end() || !type->is_string()) return e;
  if (*type == "mode") {
    const auto gaze = message.find("gaze");
    if (gaze == message.end() || !gaze->is_string()) return e;
    e.message.kind = ViewerMessage::Kind::kMode;
    if (*gaze == "cursor") {
      e.message.mode = GazeMode::kCursor;
    } else if (*gaze == "script") {
      e.message.mode = GazeMode::kScript;
    } else {
      return e;
    }
    e.accepted = true;
    return e;
  }
  if (*type != "gaze") return e;
  ViewerGaze& g = e.message.gaze;
  e.message.kind = ViewerMessage::Kind::kGaze;
  if (!numbersAt(message, "origin", g.origin_m) || !numbersAt(message, "direction", g.direction)) return e;
  for (double x : g.origin_m) {
    if (std::fabs(x) > 1e6) return e;
  }
  if (!unitOf(g.direction)) return e;
  if (message.contains("orientation") && (!numbersAt(message, "orientation", g.orientation) || !unitOf(g.orientation))) {
    return e;
  }
  e.accepted = true;
  return e;
}

// ---------------------------------------------------------------- comparisons

template <std::size_t N>
std::string show(const std::array<double, N>& v) {
  std::string s = "[";
  for (std::size_t i = 0; i < N; ++i) {
    char buf[40];
    std::snprintf(buf, sizeof buf, "%s%.17g", i == 0 ? "" : ",", v[i]);
    s += buf;
  }
  return s + "]";
}

template <std::size_t N>
bool near(const std::array<double, N>& a, const std::array<double, N>& b, double tolerance) {
  for (std::size_t i = 0; i < N; ++i) {
    if (!(std::fabs(a[i] - b[i]) <= tolerance)) return false;
  }
  return true;
}

template <std::size_t N>
void checkUnit(const std::array<double, N>& v, const char* what) {
  double n2 = 0.0;
  for (double x : v) {
    if (!std::isfinite(x)) fail(std::string(what) + " is not finite: " + show(v));
    n2 += x * x;
  }
  if (!(std::fabs(std::sqrt(n2) - 1.0) <= 1e-12)) fail(std::string(what) + " is not of unit length: " + show(v));
}

// The parser's value is the reference's: the origin exactly, unit vectors to
// within a few units in the last place.
void checkSame(const ViewerMessage& got, const ViewerMessage& want, double tolerance, const char* when) {
  const std::string where = std::string(" (") + when + ")";
  if (got.kind != want.kind) fail("the kind differs" + where);
  if (got.kind == ViewerMessage::Kind::kMode) {
    if (got.mode != want.mode) fail("the mode differs" + where);
    return;
  }
  const ViewerGaze& g = got.gaze;
  const ViewerGaze& w = want.gaze;
  if (g.origin_m != w.origin_m) fail("the origin differs" + where + ": " + show(g.origin_m) + " for " + show(w.origin_m));
  if (!near(g.direction, w.direction, tolerance)) {
    fail("the direction differs" + where + ": " + show(g.direction) + " for " + show(w.direction));
  }
  if (!near(g.orientation, w.orientation, tolerance)) {
    fail("the orientation differs" + where + ": " + show(g.orientation) + " for " + show(w.orientation));
  }
}

// ---------------------------------------------------------------- the oracles

// What parses, written as the page writes it (viewer_link.js sendGaze / setGazeMode),
// parses again to the same value.
void checkRoundTrip(const ViewerMessage& m) {
  json written;
  if (m.kind == ViewerMessage::Kind::kMode) {
    written = {{"type", "mode"}, {"gaze", gazeModeName(m.mode)}};
  } else {
    const ViewerGaze& g = m.gaze;
    written = {{"type", "gaze"},
               {"origin", {g.origin_m[0], g.origin_m[1], g.origin_m[2]}},
               {"direction", {g.direction[0], g.direction[1], g.direction[2]}},
               {"orientation", {g.orientation[0], g.orientation[1], g.orientation[2], g.orientation[3]}}};
  }
  const std::string text = written.dump();
  Result<ViewerMessage> again = parseViewerMessage(text);
  if (!again) fail("what parsed, written again, does not parse: " + again.status().message() + "\n" + text);
  checkSame(*again, m, 1e-15, "written and parsed again");

  if (m.kind != ViewerMessage::Kind::kGaze) return;
  // The operator shows the tabs the gaze it sent: statsJson's gaze_last.
  ViewerFigures figures;
  figures.gaze_last = m.gaze;
  figures.robot_gaze_origin_m = m.gaze.origin_m;
  figures.robot_gaze_direction = m.gaze.direction;
  // Not const: operator[] on a missing key then gives null, not an assertion.
  json stats = json::parse(statsJson(figures, 0), nullptr, /*allow_exceptions=*/false);
  if (stats.is_discarded()) fail("statsJson is not JSON");
  for (std::size_t i = 0; i < 3; ++i) {
    const json& o = stats["gaze_last"]["origin"][i];
    const json& d = stats["gaze_last"]["direction"][i];
    const json& ro = stats["robot"]["gaze_origin"][i];
    if (!o.is_number() || o.get<double>() != m.gaze.origin_m[i] || !ro.is_number() ||
        ro.get<double>() != m.gaze.origin_m[i]) {
      fail("statsJson does not carry the origin exactly: " + stats.dump());
    }
    if (!d.is_number() || d.get<double>() != m.gaze.direction[i]) {
      fail("statsJson does not carry the direction exactly: " + stats.dump());
    }
  }
}

// The bytes as text from the robot (a refusal's reason, its address): stateJson
// is JSON whatever they hold, and keeps them unchanged when they are UTF-8.
void checkState(std::string_view text) {
  const std::string bytes(text);
  const auto state = static_cast<LinkState>(text.size() % 4);
  json j = json::parse(stateJson(state, bytes, bytes), nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object()) fail("stateJson is not a JSON object");
  if (j["type"] != "state" || j["state"] != std::string(linkStateName(state))) fail("stateJson names the wrong state: " + j.dump());
  if (!j["detail"].is_string() || !j["robot"].is_string()) fail("stateJson's detail or robot is not a string");
  bool utf8 = true;
  try {
    (void)json(bytes).dump();
  } catch (const json::type_error&) {
    utf8 = false;
  }
  if (utf8 && (j["detail"] != bytes || j["robot"] != bytes)) fail("stateJson changed UTF-8 text");
  if (!utf8 && j["detail"].get<std::string>().empty()) fail("stateJson dropped text that is not UTF-8");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  // Exactly the message's bytes on the heap, as civetweb hands them over: ASan
  // sees any read past the end (std::string would add a terminator).
  const std::vector<char> bytes(data, data + size);
  const std::string_view text(bytes.data(), bytes.size());
  current_input = text;

  Result<ViewerMessage> got = parseViewerMessage(text);
  if (!got) {
    const ErrorCode code = got.status().code();
    if (code != ErrorCode::kParseError && code != ErrorCode::kInvalidArgument) fail("an error of another code");
    if (got.status().message().empty()) fail("an error without a message");
  }
  if (size > kMaxViewerMessageBytes) {
    if (got) fail("a message over kMaxViewerMessageBytes was accepted");
    return 0;
  }

  const json message = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (message.is_discarded()) {
    if (got || got.status().code() != ErrorCode::kParseError) fail("text that is not JSON is not a parse error");
  } else {
    if (!got && got.status().code() != ErrorCode::kInvalidArgument) fail("JSON that breaks a rule is a parse error");
    const Expected want = reference(message);
    if (got.isOk() != want.accepted) {
      fail(got ? "accepted a message the rules refuse"
               : "refused a message the rules accept: " + got.status().message());
    }
    if (got) {
      if (got->kind == ViewerMessage::Kind::kGaze) {
        checkUnit(got->gaze.direction, "the direction");
        checkUnit(got->gaze.orientation, "the orientation");
        for (double x : got->gaze.origin_m) {
          if (!(std::fabs(x) <= 1e6)) fail("the origin is out of range: " + show(got->gaze.origin_m));
        }
      }
      checkSame(*got, want.message, 1e-15, "against the rules");
      checkRoundTrip(*got);
    }
  }
  checkState(text);
  return 0;
}

// The corpus (tests/fuzz/corpus/fuzz_view_messages/) holds what the page sends.
std::vector<fuzz::Input> fuzz::seeds() { return {}; }

#include "tools/operator/gaze_script.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include <Eigen/Geometry>

namespace fovea::tools {

namespace {

Result<std::vector<double>> parseNumbers(std::string_view text, std::string_view what) {
  std::vector<double> values;
  std::string token;
  std::stringstream stream{std::string(text)};
  while (std::getline(stream, token, ',')) {
    char* end = nullptr;
    const double v = std::strtod(token.c_str(), &end);
    if (token.empty() || end == token.c_str() || *end != '\0' || !std::isfinite(v)) {
      return Result<std::vector<double>>(ErrorCode::kInvalidArgument,
                                         std::string(what) + ": '" + token + "' is not a finite number");
    }
    values.push_back(v);
  }
  return values;
}

Result<Eigen::Vector3d> parsePoint(std::string_view text, std::string_view what) {
  Result<std::vector<double>> v = parseNumbers(text, what);
  if (!v) return v.status();
  if (v->size() != 3) {
    return Result<Eigen::Vector3d>(ErrorCode::kInvalidArgument, std::string(what) + ": '" + std::string(text) +
                                                                    "' is not X,Y,Z");
  }
  return Eigen::Vector3d((*v)[0], (*v)[1], (*v)[2]);
}

Result<GazePoint> gazeTowards(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, std::string_view what) {
  const Eigen::Vector3d d = target - eye;
  if (!(d.norm() > 1e-9)) {
    return Result<GazePoint>(ErrorCode::kInvalidArgument, std::string(what) + ": target coincides with the eye");
  }
  return GazePoint{eye, d.normalized()};
}

// Unit-vector interpolation along the great circle (slerp); a and b unit.
Eigen::Vector3d slerp(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double s) {
  const double c = std::clamp(a.dot(b), -1.0, 1.0);
  const double angle = std::acos(c);
  if (angle < 1e-9) return a;
  if (std::abs(angle - M_PI) < 1e-9) {
    // Opposite directions: any great circle will do; turn through a perpendicular.
    Eigen::Vector3d p = a.unitOrthogonal();
    return s < 0.5 ? slerp(a, p, 2 * s) : slerp(p, b, 2 * s - 1);
  }
  const double sa = std::sin(angle);
  return ((std::sin((1 - s) * angle) / sa) * a + (std::sin(s * angle) / sa) * b).normalized();
}

}  // namespace

Result<GazeScript> GazeScript::parse(std::string_view text) {
  const auto colon = text.find(':');
  if (colon == std::string_view::npos) {
    return Result<GazeScript>(ErrorCode::kInvalidArgument,
                              "--gaze: '" + std::string(text) + "' is not fixed:EYE>TARGET, scan:EYE>T1;T2;... or csv:FILE");
  }
  const std::string_view kind = text.substr(0, colon);
  const std::string_view body = text.substr(colon + 1);
  if (kind == "fixed" || kind == "scan") return parseFixations(kind, body);
  if (kind == "csv") return parseTrace(std::string(body));
  return Result<GazeScript>(ErrorCode::kInvalidArgument,
                            "--gaze: unknown script kind '" + std::string(kind) + "' (fixed, scan, csv)");
}

Result<GazeScript> GazeScript::parseFixations(std::string_view kind, std::string_view body) {
  GazeScript script;
  script.kind_ = kind == "fixed" ? Kind::kFixed : Kind::kScan;
  if (kind == "scan") {
    if (const auto at = body.find('@'); at != std::string_view::npos) {
      if (Status s = script.takeScanTiming(body.substr(at + 1)); !s) return s;
      body = body.substr(0, at);
    }
  }
  const auto arrow = body.find('>');
  if (arrow == std::string_view::npos) {
    return Result<GazeScript>(ErrorCode::kInvalidArgument, "--gaze " + std::string(kind) + ": expected EYE>TARGET");
  }
  Result<Eigen::Vector3d> eye = parsePoint(body.substr(0, arrow), "--gaze eye");
  if (!eye) return eye.status();
  std::string targets(body.substr(arrow + 1));
  std::stringstream stream(targets);
  std::string target_text;
  while (std::getline(stream, target_text, ';')) {
    Result<Eigen::Vector3d> target = parsePoint(target_text, "--gaze target");
    if (!target) return target.status();
    Result<GazePoint> g = gazeTowards(eye.value(), target.value(), "--gaze");
    if (!g) return g.status();
    script.keys_.push_back({0, g.value()});
  }
  if (script.keys_.empty() || (kind == "fixed" && script.keys_.size() != 1)) {
    return Result<GazeScript>(ErrorCode::kInvalidArgument,
                              "--gaze " + std::string(kind) + (kind == "fixed" ? ": exactly one target" : ": at least one target"));
  }
  return script;
}

Status GazeScript::takeScanTiming(std::string_view text) {
  std::string timing(text);
  std::replace(timing.begin(), timing.end(), '/', ',');
  Result<std::vector<double>> times = parseNumbers(timing, "--gaze scan timing");
  if (!times) return times.status();
  // Up to an hour each, so the times stay far inside int64 nanoseconds.
  constexpr double kMaxMs = 3.6e6;
  if (times->empty() || times->size() > 2 || !((*times)[0] > 0 && (*times)[0] <= kMaxMs) ||
      (times->size() == 2 && !((*times)[1] >= 0 && (*times)[1] <= kMaxMs))) {
    return Status(ErrorCode::kInvalidArgument, "--gaze scan: timing is @DWELL_MS[/SACCADE_MS], positive, up to an hour");
  }
  dwell_ns_ = static_cast<int64_t>((*times)[0] * 1e6);
  if (times->size() == 2) saccade_ns_ = static_cast<int64_t>((*times)[1] * 1e6);
  return Status::ok();
}

Result<GazeScript> GazeScript::parseTrace(const std::string& path) {
  GazeScript script;
  script.kind_ = Kind::kTrace;
  std::ifstream file(path);
  if (!file) return Result<GazeScript>(ErrorCode::kNotFound, "--gaze csv: cannot open '" + path + "'");
  std::string line;
  int line_no = 0;
  while (std::getline(file, line)) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    if (line_no == 1 && !line.empty() && (std::isalpha(static_cast<unsigned char>(line[0])) != 0)) continue;  // header
    const std::string where = path + ":" + std::to_string(line_no);
    Result<std::vector<double>> v = parseNumbers(line, where);
    if (!v) return v.status();
    if (v->size() != 7) {
      return Result<GazeScript>(ErrorCode::kParseError, where + ": expected t_s,ox,oy,oz,dx,dy,dz");
    }
    const Eigen::Vector3d d((*v)[4], (*v)[5], (*v)[6]);
    if (!(d.norm() > 1e-9)) return Result<GazeScript>(ErrorCode::kParseError, where + ": zero gaze direction");
    // Up to a year: far inside int64 nanoseconds.
    if (!((*v)[0] >= 0 && (*v)[0] <= 3.2e7)) {
      return Result<GazeScript>(ErrorCode::kParseError, where + ": t_s must be within 0 .. 3.2e7 s");
    }
    const auto t_ns = static_cast<int64_t>((*v)[0] * 1e9);
    if (!script.keys_.empty() && t_ns < script.keys_.back().t_ns) {
      return Result<GazeScript>(ErrorCode::kParseError, where + ": time goes backwards");
    }
    script.keys_.push_back({t_ns, GazePoint{Eigen::Vector3d((*v)[1], (*v)[2], (*v)[3]), d.normalized()}});
  }
  if (script.keys_.empty()) return Result<GazeScript>(ErrorCode::kParseError, "--gaze csv: '" + path + "' has no samples");
  return script;
}

GazePoint GazeScript::at(int64_t t_ns) const {
  t_ns = std::max<int64_t>(t_ns, 0);
  switch (kind_) {
    case Kind::kFixed: return keys_.front().gaze;
    case Kind::kScan: {
      const int64_t period = dwell_ns_ + saccade_ns_;
      const int64_t step = t_ns / period;
      const int64_t in = t_ns % period;
      const std::size_t n = keys_.size();
      const GazePoint& from = keys_[static_cast<std::size_t>(step) % n].gaze;
      if (in < dwell_ns_ || n == 1) return from;
      const GazePoint& to = keys_[static_cast<std::size_t>(step + 1) % n].gaze;
      const double s = static_cast<double>(in - dwell_ns_) / static_cast<double>(saccade_ns_);
      return GazePoint{from.origin_m, slerp(from.direction, to.direction, s)};
    }
    case Kind::kTrace: {
      // The newest sample at or before t_ns (the first before the trace starts).
      auto it = std::upper_bound(keys_.begin(), keys_.end(), t_ns,
                                 [](int64_t t, const Key& k) { return t < k.t_ns; });
      if (it == keys_.begin()) return keys_.front().gaze;
      return std::prev(it)->gaze;
    }
  }
  return keys_.front().gaze;
}

}  // namespace fovea::tools

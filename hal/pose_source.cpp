#include "hal/pose_source.h"

#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>

namespace fovea::hal {

namespace {

bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }

// The next whitespace-separated field of text from pos; empty at the end.
std::string_view nextField(std::string_view text, std::size_t& pos) {
  while (pos < text.size() && isSpace(text[pos])) ++pos;
  const std::size_t start = pos;
  while (pos < text.size() && !isSpace(text[pos])) ++pos;
  return text.substr(start, pos - start);
}

bool parseNumber(std::string_view field, double& out) {
  if (!field.empty() && field.front() == '+') field.remove_prefix(1);
  const auto [end, ec] = std::from_chars(field.data(), field.data() + field.size(), out);
  return !field.empty() && ec == std::errc() && end == field.data() + field.size() && std::isfinite(out);
}

}  // namespace

bool parsePoseDatagram(std::string_view text, StampedPose& out) {
  std::size_t pos = 0;
  const std::string_view stamp = nextField(text, pos);
  int64_t stamp_ns = 0;
  const auto [end, ec] = std::from_chars(stamp.data(), stamp.data() + stamp.size(), stamp_ns);
  if (stamp.empty() || ec != std::errc() || end != stamp.data() + stamp.size()) return false;
  double v[7];
  for (double& x : v) {
    if (!parseNumber(nextField(text, pos), x)) return false;
  }
  if (!nextField(text, pos).empty()) return false;  // more than 8 fields
  Eigen::Quaterniond q;
  if (!normalisedQuaternion(v[3], v[4], v[5], v[6], q)) return false;
  out.stamp_ns = stamp_ns;
  out.t_world_cam = Eigen::Vector3d(v[0], v[1], v[2]);
  out.q_world_cam = q;
  return true;
}

PoseSource::PoseSource(const PoseSourceConfig& config) : config_(config) {}

Result<std::unique_ptr<PoseSource>> PoseSource::create(const PoseSourceConfig& config) {
  using R = Result<std::unique_ptr<PoseSource>>;
  if (Status s = checkRotation(config.pose.R_world_cam, "camera.pose rotation"); !s) return s;
  if (!config.pose.t_world_cam.allFinite()) return R(ErrorCode::kInvalidArgument, "camera.pose translation: not finite");
  std::unique_ptr<PoseSource> source(new PoseSource(config));
  if (config.kind != PoseSourceConfig::Kind::kSocket) return source;
  if (config.capacity < 2 || config.capacity > 1'000'000) {
    return R(ErrorCode::kInvalidArgument, "pose socket: the ring must hold 2 .. 1000000 poses (got " +
                                              std::to_string(config.capacity) + ")");
  }
  if (config.max_age_ns <= 0) return R(ErrorCode::kInvalidArgument, "pose socket: max age must be positive");
  const std::string& path = config.socket_path;
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  if (path.empty() || path.size() >= sizeof address.sun_path) {
    return R(ErrorCode::kInvalidArgument, "pose socket: path '" + path + "' must be 1 .. " +
                                              std::to_string(sizeof address.sun_path - 1) + " characters");
  }
  std::memcpy(address.sun_path, path.c_str(), path.size() + 1);
  std::error_code ec;
  const std::filesystem::path folder = std::filesystem::path(path).parent_path();
  if (!folder.empty() && !std::filesystem::is_directory(folder, ec)) {
    return R(ErrorCode::kNotFound, "pose socket " + path + ": folder " + folder.string() +
                                       " does not exist (create it; under systemd RuntimeDirectory=fovea makes /run/fovea)");
  }
  source->fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (source->fd_ < 0) return R(ErrorCode::kIoError, std::string("pose socket: socket(): ") + std::strerror(errno));
  struct stat st{};
  if (::lstat(path.c_str(), &st) == 0) {
    if (!S_ISSOCK(st.st_mode)) {
      return R(ErrorCode::kInvalidArgument, "pose socket " + path + ": a file that is not a socket is in the way");
    }
    // A socket file: someone's, or left by a process that died. Probe it.
    const int probe = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    const bool alive = probe >= 0 && ::connect(probe, reinterpret_cast<const sockaddr*>(&address), sizeof address) == 0;
    if (probe >= 0) ::close(probe);
    if (alive) {
      return R(ErrorCode::kUnavailable, "pose socket " + path + " is in use by another process (another fovead?)");
    }
    ::unlink(path.c_str());
  }
  if (::bind(source->fd_, reinterpret_cast<const sockaddr*>(&address), sizeof address) != 0) {
    const int e = errno;
    return R(ErrorCode::kIoError,
             "pose socket " + path + ": bind: " + std::strerror(e) +
                 (e == EACCES ? " (the folder must be writable by fovead's user)" : ""));
  }
  source->bound_ = true;
  source->ring_.resize(config.capacity);
  return source;
}

PoseSource::~PoseSource() {
  if (fd_ >= 0) ::close(fd_);
  if (bound_) ::unlink(config_.socket_path.c_str());
}

void PoseSource::push(const StampedPose& pose) {
  if (count_ > 0 && pose.stamp_ns <= at(count_ - 1).stamp_ns) {
    out_of_order_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  if (count_ == ring_.size()) {
    head_ = (head_ + 1) % ring_.size();
    --count_;
    overwritten_.fetch_add(1, std::memory_order_relaxed);
  }
  ring_[(head_ + count_) % ring_.size()] = pose;
  ++count_;
  received_.fetch_add(1, std::memory_order_relaxed);
}

void PoseSource::drain() {
  if (fd_ < 0) return;
  char buffer[kMaxPoseDatagramBytes + 1];
  // Bounded: a sender flooding faster than this reads must not hold the capture thread.
  const std::size_t max_reads = 4 * ring_.size() + 64;
  for (std::size_t i = 0; i < max_reads; ++i) {
    // MSG_TRUNC: the datagram's real length, to refuse what did not fit.
    const ssize_t n = ::recv(fd_, buffer, sizeof buffer, MSG_DONTWAIT | MSG_TRUNC);
    if (n < 0) {
      if (errno == EINTR) continue;
      return;  // EAGAIN: drained (other errors: nothing to read either)
    }
    StampedPose pose;
    if (static_cast<std::size_t>(n) > kMaxPoseDatagramBytes ||
        !parsePoseDatagram(std::string_view(buffer, static_cast<std::size_t>(n)), pose)) {
      malformed_.fetch_add(1, std::memory_order_relaxed);
      continue;
    }
    push(pose);
  }
}

bool PoseSource::poseAt(int64_t stamp_ns, Pose& out) {
  drain();
  if (count_ == 0) return false;
  const auto ring_at = [this](std::size_t i) -> const StampedPose& { return at(i); };
  Pose robot;
  bool fresh = interpolatePoseAt(count_, ring_at, stamp_ns, config_.max_age_ns, robot);
  if (!fresh) {
    // Outside the span by more than max_age: the nearest end pose, flagged stale.
    const StampedPose& nearest = stamp_ns < at(0).stamp_ns ? at(0) : at(count_ - 1);
    robot = poseFromQuaternion(nearest.t_world_cam, nearest.q_world_cam);
  }
  // T_world_cam = T_world_robot * T_robot_cam.
  out.R_world_cam = robot.R_world_cam * config_.pose.R_world_cam;
  out.t_world_cam = robot.R_world_cam * config_.pose.t_world_cam + robot.t_world_cam;
  return fresh;
}

bool PoseSource::apply(RgbdFrame& frame) {
  switch (config_.kind) {
    case PoseSourceConfig::Kind::kNone: return true;
    case PoseSourceConfig::Kind::kFixed:
      frame.T_world_cam = config_.pose;
      frames_fresh_.fetch_add(1, std::memory_order_relaxed);
      return true;
    case PoseSourceConfig::Kind::kSocket: break;
  }
  const bool fresh = poseAt(frame.stamp_ns, frame.T_world_cam);
  (fresh ? frames_fresh_ : frames_stale_).fetch_add(1, std::memory_order_relaxed);
  stale_.store(!fresh, std::memory_order_relaxed);
  return fresh;
}

PoseCounters PoseSource::counters() const {
  PoseCounters c;
  c.received = received_.load(std::memory_order_relaxed);
  c.malformed = malformed_.load(std::memory_order_relaxed);
  c.out_of_order = out_of_order_.load(std::memory_order_relaxed);
  c.overwritten = overwritten_.load(std::memory_order_relaxed);
  c.frames_fresh = frames_fresh_.load(std::memory_order_relaxed);
  c.frames_stale = frames_stale_.load(std::memory_order_relaxed);
  return c;
}

std::string PoseSource::describe() const {
  char text[512];
  const Pose& p = config_.pose;
  const Eigen::Quaterniond q(p.R_world_cam);
  switch (config_.kind) {
    case PoseSourceConfig::Kind::kNone:
      return "none: the world is the camera's frame (as the camera reports it; set camera.pose.source to fixed or "
             "socket on a robot)";
    case PoseSourceConfig::Kind::kFixed:
      std::snprintf(text, sizeof text, "fixed mount: t %.4f %.4f %.4f m, q xyzw %.4f %.4f %.4f %.4f", p.t_world_cam.x(),
                    p.t_world_cam.y(), p.t_world_cam.z(), q.x(), q.y(), q.z(), q.w());
      return text;
    case PoseSourceConfig::Kind::kSocket:
      std::snprintf(text, sizeof text,
                    "socket %s (ring %zu poses, max age %lld ms, mount t %.4f %.4f %.4f m q xyzw %.4f %.4f %.4f %.4f)",
                    config_.socket_path.c_str(), config_.capacity, static_cast<long long>(config_.max_age_ns / 1'000'000),
                    p.t_world_cam.x(), p.t_world_cam.y(), p.t_world_cam.z(), q.x(), q.y(), q.z(), q.w());
      return text;
  }
  return "?";
}

}  // namespace fovea::hal

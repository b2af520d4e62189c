#include "firmware/systemd_notify.h"

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cstddef>
#include <cstdlib>
#include <cstring>

#ifdef FOVEA_HAVE_SYSTEMD
#include <systemd/sd-daemon.h>
#endif

namespace fovea::firmware {

SystemdNotifier::SystemdNotifier() {
  const char* socket = std::getenv("NOTIFY_SOCKET");
  if (const char* usec = std::getenv("WATCHDOG_USEC")) {
    char* end = nullptr;
    const long long v = std::strtoll(usec, &end, 10);
    // WATCHDOG_PID, when set, must be ours (sd_watchdog_enabled's rule).
    const char* pid = std::getenv("WATCHDOG_PID");
    const bool ours = pid == nullptr || std::strtoll(pid, nullptr, 10) == static_cast<long long>(getpid());
    if (end != usec && *end == '\0' && v > 0 && ours) watchdog_ns_ = v * 1000;
  }
  if (socket == nullptr || socket[0] == '\0') return;
#ifdef FOVEA_HAVE_SYSTEMD
  active_ = true;
#else
  const std::size_t len = std::strlen(socket);
  if ((socket[0] != '/' && socket[0] != '@') || len >= sizeof path_) return;
  std::memcpy(path_, socket, len);
  if (path_[0] == '@') path_[0] = '\0';  // abstract namespace
  path_len_ = static_cast<unsigned>(len);
  fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  active_ = fd_ >= 0;
#endif
}

SystemdNotifier::~SystemdNotifier() {
#ifndef FOVEA_HAVE_SYSTEMD
  if (fd_ >= 0) close(fd_);
#endif
}

bool SystemdNotifier::notify(std::string_view message) {
  if (!active_) return false;
#ifdef FOVEA_HAVE_SYSTEMD
  // sd_notify wants a C string: copy into a fixed buffer (no allocation).
  char text[1024];
  const std::size_t n = std::min(message.size(), sizeof text - 1);
  std::memcpy(text, message.data(), n);
  text[n] = '\0';
  const bool ok = sd_notify(0, text) > 0;
#else
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, path_, path_len_);
  const auto addr_len = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + path_len_);
  const bool ok = sendto(fd_, message.data(), message.size(), MSG_NOSIGNAL, reinterpret_cast<const sockaddr*>(&addr),
                         addr_len) == static_cast<ssize_t>(message.size());
#endif
  if (ok) {
    ++sent_;
  } else {
    ++errors_;
  }
  return ok;
}

}  // namespace fovea::firmware

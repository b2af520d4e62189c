// systemd's service notification protocol (sd_notify(3)): READY=1, STATUS=...,
// WATCHDOG=1, STOPPING=1, as one datagram to the unix socket NOTIFY_SOCKET names.
// One implementation chosen at build time: libsystemd's sd_notify with
// FOVEA_HAVE_SYSTEMD, otherwise the datagram written here (the protocol is one
// sendto() of "KEY=VALUE\n..." to a path, or to an abstract socket when the
// name starts with '@'). Without NOTIFY_SOCKET every call is a no-op, so the
// service calls it unconditionally. No allocation after construction.
#pragma once

#include <cstdint>
#include <string_view>

namespace fovea::firmware {

class SystemdNotifier {
 public:
  // Reads NOTIFY_SOCKET and WATCHDOG_USEC from the environment once.
  SystemdNotifier();
  ~SystemdNotifier();
  SystemdNotifier(const SystemdNotifier&) = delete;
  SystemdNotifier& operator=(const SystemdNotifier&) = delete;

  bool active() const { return active_; }
  // WATCHDOG_USEC in nanoseconds; 0 when systemd watches nothing.
  int64_t watchdogNs() const { return watchdog_ns_; }

  // Sends one message ("READY=1", "STATUS=...", lines joined by '\n'). True
  // when it went out (false without NOTIFY_SOCKET or on an error, counted).
  bool notify(std::string_view message);
  uint64_t sent() const { return sent_; }
  uint64_t errors() const { return errors_; }

 private:
  bool active_ = false;
  int64_t watchdog_ns_ = 0;
  uint64_t sent_ = 0;
  uint64_t errors_ = 0;
#ifndef FOVEA_HAVE_SYSTEMD
  int fd_ = -1;
  char path_[108] = {};  // sockaddr_un's sun_path
  unsigned path_len_ = 0;
#endif
};

}  // namespace fovea::firmware

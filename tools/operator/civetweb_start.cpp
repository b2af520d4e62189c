#include "tools/operator/civetweb_start.h"

#include <civetweb.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>

#include "net/udp_socket.h"

namespace fovea::tools {

Result<CivetwebStarted> startCivetweb(const std::string& listen, std::size_t threads, void* user_data, const char* flag) {
  using R = Result<CivetwebStarted>;
  // civetweb's library set-up is process-wide; the first server does it, once.
  static const unsigned features = mg_init_library(0);
  (void)features;
  const std::string workers = std::to_string(threads);
  const char* options[] = {"listening_ports",    listen.c_str(),
                           "num_threads",        workers.c_str(),
                           "request_timeout_ms", "10000",
                           "websocket_timeout_ms", "5000",
                           "enable_websocket_ping_pong", "yes",
                           nullptr};
  mg_callbacks callbacks{};
  mg_init_data init{};
  init.callbacks = &callbacks;
  init.user_data = user_data;
  init.configuration_options = options;
  unsigned code = 0;
  char text[256] = {0};
  mg_error_data error{&code, text, sizeof text};
  CivetwebStarted started;
  started.ctx = mg_start2(&init, &error);
  if (started.ctx == nullptr) {
    return R(ErrorCode::kUnavailable, std::string(flag) + ": cannot serve on " + listen + ": " +
                                          (text[0] ? text : "civetweb failed to start"));
  }
  mg_server_port ports[4] = {};
  if (mg_get_server_ports(started.ctx, 4, ports) < 1) {
    mg_stop(started.ctx);
    return R(ErrorCode::kUnavailable, std::string(flag) + ": no listening port");
  }
  started.port = ports[0].port;
  const std::string host = listen.substr(0, listen.rfind(':'));
  started.url_host = host == "0.0.0.0" ? std::string("127.0.0.1") : host;
  return started;
}

void stopCivetweb(const CivetwebStarted& started) {
  if (started.ctx == nullptr) return;
  // Where to knock: the address it listens on (url_host, "[V6]" for IPv6).
  const Result<net::Endpoint> door = net::Endpoint::parse(started.url_host + ":" + std::to_string(started.port));
  std::atomic<bool> stopped{false};
  std::thread waker([&] {
    // A knock before mg_stop has set its flag only wakes the poll early; knock
    // again until it returns. An address that does not parse: no knocks, the 2 s.
    while (door && !stopped.load(std::memory_order_acquire)) {
      const int fd = ::socket(door->family(), SOCK_STREAM | SOCK_CLOEXEC, 0);
      if (fd < 0) return;
      (void)::connect(fd, door->addr(), door->size());
      ::close(fd);
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  });
  mg_stop(started.ctx);
  stopped.store(true, std::memory_order_release);
  waker.join();
}

void sayGoingAway(mg_connection* conn) {
  static constexpr char kGoingAway[] = "\x03\xe9the operator is stopping";  // close code 1001
  mg_websocket_write(conn, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE, kGoingAway, sizeof kGoingAway - 1);
}

}  // namespace fovea::tools

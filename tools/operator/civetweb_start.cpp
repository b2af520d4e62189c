#include "tools/operator/civetweb_start.h"

#include <arpa/inet.h>
#include <civetweb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <thread>

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

namespace {

// One connection to host:port, closed at once; false when host is no IPv4 or
// IPv6 address (a name: the waker gives up and the stop takes its 2 s).
bool knock(const std::string& host, int port) {
  sockaddr_storage address{};
  socklen_t size = 0;
  auto* v4 = reinterpret_cast<sockaddr_in*>(&address);
  auto* v6 = reinterpret_cast<sockaddr_in6*>(&address);
  std::string bare = host;
  if (bare.size() > 2 && bare.front() == '[' && bare.back() == ']') bare = bare.substr(1, bare.size() - 2);
  if (inet_pton(AF_INET, bare.c_str(), &v4->sin_addr) == 1) {
    v4->sin_family = AF_INET;
    v4->sin_port = htons(static_cast<uint16_t>(port));
    size = sizeof *v4;
  } else if (inet_pton(AF_INET6, bare.c_str(), &v6->sin6_addr) == 1) {
    v6->sin6_family = AF_INET6;
    v6->sin6_port = htons(static_cast<uint16_t>(port));
    size = sizeof *v6;
  } else {
    return false;
  }
  const int fd = ::socket(address.ss_family, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return false;
  (void)::connect(fd, reinterpret_cast<const sockaddr*>(&address), size);
  ::close(fd);
  return true;
}

}  // namespace

void stopCivetweb(const CivetwebStarted& started) {
  if (started.ctx == nullptr) return;
  std::atomic<bool> stopped{false};
  std::thread waker([&] {
    // A knock before mg_stop has set its flag only wakes the poll early; knock
    // again until it returns.
    while (!stopped.load(std::memory_order_acquire)) {
      if (!knock(started.url_host, started.port)) return;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  });
  mg_stop(started.ctx);
  stopped.store(true, std::memory_order_release);
  waker.join();
}

}  // namespace fovea::tools

#include "tools/operator/civetweb_start.h"

#include <civetweb.h>

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

}  // namespace fovea::tools

// Starting and stopping civetweb the one way fovea-operator's two servers (the
// browser viewer, view_server.h; the Foxglove WebSocket, foxglove_server.h) need
// it: the library's process-wide set-up once, a listening address, a worker per
// client and the same timeouts and WebSocket pings.
#pragma once

#include <cstddef>
#include <string>

#include "core/result.h"

struct mg_connection;
struct mg_context;

namespace fovea::tools {

struct CivetwebStarted {
  mg_context* ctx = nullptr;
  int port = 0;          // the port it listens on (the one chosen for port 0)
  std::string url_host;  // the address to put in a URL (127.0.0.1 for 0.0.0.0)
};

// `listen` in civetweb's listening_ports form (viewListenAddress); `flag` names
// the option in the errors ("--view"). Writes to a client that reads nothing
// for 10 s fail, and that client is closed.
Result<CivetwebStarted> startCivetweb(const std::string& listen, std::size_t threads, void* user_data, const char* flag);

// mg_stop, without waiting out civetweb's poll: its master thread looks at the
// stop flag only when its poll of the listening sockets returns, which it does
// every 2 s when nobody connects (civetweb 1.15), so each stop took 1.9 s (the
// operator's exit, each server a test starts). A thread beside it connects to
// the listening port until it returns: measured 14 ms with no client connected.
// A WebSocket client still connected keeps its worker in a poll of the same
// 2 s, which no knock wakes: such a stop still takes up to 2 s. Closes every
// connection, running their close handlers. Does nothing for a null ctx.
void stopCivetweb(const CivetwebStarted& started);

}  // namespace fovea::tools

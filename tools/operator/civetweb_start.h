// Starting and stopping civetweb the one way fovea-operator's two servers (the
// browser viewer, view_server.h; the Foxglove WebSocket, foxglove_server.h) need
// it: the library's process-wide set-up once, a listening address, a worker per
// client and the same timeouts and WebSocket pings.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <mutex>
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
// 2 s, which no knock wakes: each server's senders say goodbye first
// (endSending), and the client's answering close frame wakes that poll.
// Closes every connection, running their close handlers. Does nothing for a
// null ctx.
void stopCivetweb(const CivetwebStarted& started);

// Sends a WebSocket close frame, code 1001 ("going away"), to a client of a
// server that is stopping. A client answers with a close frame of its own
// (RFC 6455 5.5.1): its arrival ends the worker's read at once, where a silent
// client would keep it in its 2 s poll.
void sayGoingAway(mg_connection* conn);

// How long a stopping server waits for its senders' goodbyes before
// stopCivetweb: once civetweb's stop flag is set its writes send nothing.
inline constexpr std::chrono::milliseconds kGoodbyeWait{1000};

// A stopping server's destructor, `stopping` already set and `wake` notified:
// waits, at most kGoodbyeWait (a client that reads nothing holds its sender in
// a write), until no peer's sender runs any more. `lock` holds the server's mutex.
template <class Peers>
void waitForGoodbyes(std::unique_lock<std::mutex>& lock, std::condition_variable& wake, const Peers& peers) {
  wake.wait_for(lock, kGoodbyeWait, [&] {
    for (const auto& peer : peers) {
      if (peer.sending) return false;
    }
    return true;
  });
}

// The end of a client's sender thread (ViewServer's tabs, FoxgloveServer's
// clients: a `conn`, `closing` and `sending`): when the server stops, it says
// goodbye; then it is done, which the server's destructor waits for on `wake`.
// `lock` holds the server's mutex; `ok`: its last write went out.
template <class Peer>
void endSending(Peer& peer, bool ok, bool stopping, std::unique_lock<std::mutex>& lock, std::condition_variable& wake) {
  if (ok && stopping && !peer.closing) {
    lock.unlock();
    sayGoingAway(peer.conn);
    lock.lock();
  }
  peer.sending = false;
  wake.notify_all();
}

}  // namespace fovea::tools

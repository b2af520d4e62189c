// fovea-operator --foxglove: the Foxglove WebSocket protocol (foxglove.websocket.v1,
// github.com/foxglove/ws-protocol docs/spec.md), so that the Foxglove app or
// Lichtblick shows the stream live (docs/foxglove.md). civetweb serves it, as
// it serves the browser viewer (view_server.h), with the same design:
//
// Threads: the operator's thread publishes each channel's messages; each client
// has a sender thread that writes to it, and civetweb's worker threads read
// from it. A client is always sent a channel's newest message: messages
// published while it was still writing an older one are skipped and counted
// for it (newest wins: a client that never reads holds no more than its own
// send buffer, and never slows the operator or the other clients). A channel's
// newest message is held in a buffer allocated at start, and each client has a
// frame buffer allocated when it connects; publish() copies under the server's
// lock (as a sender copies into its frame: memory speed, never a network wait)
// and allocates nothing.
//
// Bad input from a client (text that is not JSON or not a known operation, a
// subscription to an unknown channel or with a used id, an unsubscription of
// an unknown id, a binary message (no client publishing is advertised), a
// message over kMaxClientMessageBytes) is counted and answered with an error
// status message; the connection stays up.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "core/result.h"
#include "io/foxglove/foxglove.h"
#include "tools/operator/civetweb_start.h"
#include "tools/operator/foxglove_messages.h"

namespace fovea::tools {

struct FoxgloveChannelSpec {
  uint32_t id = 0;          // unique, > 0
  std::string topic;        // "/fovea/cloud"
  foxglove::Schema schema;  // name, "protobuf", FileDescriptorSet
  std::size_t max_bytes = 0;  // the largest message; a larger one is dropped and counted
};

struct FoxgloveServerConfig {
  std::string listen = "8765";  // [ADDR:]PORT; ADDR defaults to 127.0.0.1; port 0 picks a free one
  std::size_t max_clients = 8;  // further clients are refused with a close frame that says so
  std::string name = "fovea-operator";
  std::vector<FoxgloveChannelSpec> channels;
};

struct FoxgloveServerCounters {
  uint64_t clients_open = 0;
  uint64_t clients_served = 0;    // ever connected
  uint64_t clients_refused = 0;   // over max_clients, or without the subprotocol
  uint64_t published = 0;         // all channels
  uint64_t too_large = 0;         // published messages over their channel's max_bytes
  uint64_t sent = 0;              // message frames written, all clients
  uint64_t dropped = 0;           // all clients: newer messages published while the client was busy
  uint64_t bad_requests = 0;      // the clients' messages refused (each answered with a status)
  uint64_t statuses_dropped = 0;  // status messages not queued: the client's queue was full
  uint64_t subscriptions = 0;     // accepted, ever
};

// The subprotocol clients must ask for.
inline constexpr const char* kFoxgloveSubprotocol = "foxglove.websocket.v1";

// The base64 of bytes (RFC 4648, with padding), for the advertised schemas.
std::string base64(std::span<const uint8_t> bytes);

class FoxgloveServer {
 public:
  static Result<std::unique_ptr<FoxgloveServer>> start(const FoxgloveServerConfig& config);
  ~FoxgloveServer();
  FoxgloveServer(const FoxgloveServer&) = delete;
  FoxgloveServer& operator=(const FoxgloveServer&) = delete;

  int port() const { return civetweb_.port; }
  const std::string& url() const { return url_; }  // ws://ADDR:PORT

  // The operator's thread: makes payload the channel's newest message, logged at
  // log_time_ns (ns since the Unix epoch). False when the channel is unknown or
  // the payload over its max_bytes (counted). Copies; allocates nothing.
  bool publish(uint32_t channel_id, std::span<const uint8_t> payload, uint64_t log_time_ns);
  // True when some client is subscribed to the channel (encoding can be skipped otherwise).
  bool subscribed(uint32_t channel_id) const;

  FoxgloveServerCounters counters() const;

 private:
  struct Buffer {
    std::vector<uint8_t> data;
    std::size_t bytes = 0;
    uint64_t log_time_ns = 0;
    uint64_t seq = 0;  // 0: nothing published yet
  };
  struct Channel {
    FoxgloveChannelSpec spec;
    Buffer newest;  // the newest message
    uint64_t seq = 0;
    int subscribers = 0;
  };
  struct Subscription {
    bool active = false;
    uint32_t id = 0;
    uint64_t sent_seq = 0;
  };
  struct Client {
    bool used = false;
    bool closing = false;
    bool sending = false;  // its sender runs; at a stop it says goodbye first
    int id = 0;
    mg_connection* conn = nullptr;
    std::thread sender;
    std::vector<Subscription> subs;  // per channel (index into channels_)
    std::deque<std::string> texts;   // serverInfo, advertise, statuses: to send, in order
    std::vector<uint8_t> frame;      // the message frame being written
    uint64_t dropped = 0;
    std::size_t next_channel = 0;    // round robin among channels with news
  };

  explicit FoxgloveServer(const FoxgloveServerConfig& config);
  void sendLoop(Client& client);
  void handleText(Client& client, std::string_view text);
  void queueStatus(Client& client, int level, const std::string& message);  // mu_ held
  int channelIndex(uint32_t id) const;
  static uint64_t realtimeSessionId();  // the realtime clock at start, as the session id
  static Client* clientOf(const mg_connection* conn);

  static int onWsConnect(const mg_connection* conn, void* self);
  static void onWsReady(mg_connection* conn, void* self);
  static int onWsData(mg_connection* conn, int bits, char* data, std::size_t len, void* self);
  static void onWsClose(const mg_connection* conn, void* self);
  static int onHttp(mg_connection* conn, void* self);

  FoxgloveServerConfig config_;
  CivetwebStarted civetweb_;  // its context, port and host (stopCivetweb)
  std::string url_;
  std::string server_info_;  // the serverInfo message
  std::string advertise_;    // the advertise message of every channel
  std::size_t max_frame_ = 0;

  mutable std::mutex mu_;
  std::condition_variable wake_;
  bool stopping_ = false;
  std::vector<Channel> channels_;
  std::vector<Client> clients_;
  int next_client_id_ = 1;
  FoxgloveServerCounters counters_;
};

}  // namespace fovea::tools

#include "tools/operator/foxglove_server.h"

#include <algorithm>
#include <cstring>
#include <ctime>

#include <civetweb.h>
#include <nlohmann/json.hpp>

#include "tools/operator/civetweb_start.h"
#include "tools/operator/view_server.h"

namespace fovea::tools {

namespace {

constexpr uint8_t kOpMessageData = 0x01;
constexpr std::size_t kFrameHeader = 1 + 4 + 8;  // opcode, subscription id, log time
constexpr std::size_t kMaxTextsQueued = 32;
// foxglove.websocket.v1 status levels.
constexpr int kStatusError = 2;  // 0 info, 1 warning, 2 error

void putU32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}
void putU64(uint8_t* p, uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}

}  // namespace

std::string base64(std::span<const uint8_t> bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 3 <= bytes.size(); i += 3) {
    const uint32_t v = (uint32_t{bytes[i]} << 16) | (uint32_t{bytes[i + 1]} << 8) | bytes[i + 2];
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += kAlphabet[v & 63];
  }
  if (const std::size_t rest = bytes.size() - i; rest > 0) {
    const uint32_t v = (uint32_t{bytes[i]} << 16) | (rest == 2 ? uint32_t{bytes[i + 1]} << 8 : 0u);
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += rest == 2 ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

FoxgloveServer::FoxgloveServer(const FoxgloveServerConfig& config) : config_(config) {}

Result<std::unique_ptr<FoxgloveServer>> FoxgloveServer::start(const FoxgloveServerConfig& config) {
  using R = Result<std::unique_ptr<FoxgloveServer>>;
  Result<std::string> listen = viewListenAddress(config.listen);
  if (!listen) {
    std::string why = listen.status().message();
    if (why.rfind("--view", 0) == 0) why.replace(0, 6, "--foxglove");
    return R(ErrorCode::kInvalidArgument, why);
  }
  if (config.max_clients < 1 || config.max_clients > 64) {
    return R(ErrorCode::kInvalidArgument, "--foxglove: max clients must be 1 .. 64");
  }
  std::unique_ptr<FoxgloveServer> s(new FoxgloveServer(config));
  nlohmann::json channels = nlohmann::json::array();
  for (const FoxgloveChannelSpec& spec : config.channels) {
    if (spec.id == 0 || s->channelIndex(spec.id) >= 0 || spec.max_bytes == 0 || spec.schema.data.empty()) {
      return R(ErrorCode::kInvalidArgument, "--foxglove: channel " + spec.topic + " has a bad id, size or schema");
    }
    Channel c;
    c.spec = spec;
    c.newest.data.resize(spec.max_bytes);
    s->channels_.push_back(std::move(c));
    s->max_frame_ = std::max(s->max_frame_, kFrameHeader + spec.max_bytes);
    channels.push_back({{"id", spec.id},
                        {"topic", spec.topic},
                        {"encoding", std::string(foxglove::kMessageEncoding)},
                        {"schemaName", std::string(spec.schema.name)},
                        {"schema", base64(spec.schema.data)},
                        {"schemaEncoding", std::string(spec.schema.encoding)}});
  }
  s->advertise_ = nlohmann::json{{"op", "advertise"}, {"channels", channels}}.dump();
  s->server_info_ = nlohmann::json{{"op", "serverInfo"},
                                   {"name", config.name},
                                   {"capabilities", nlohmann::json::array()},
                                   {"supportedEncodings", nlohmann::json::array()},
                                   {"metadata", nlohmann::json::object()},
                                   {"sessionId", std::to_string(realtimeSessionId())}}
                        .dump();
  s->clients_.resize(config.max_clients);

  Result<CivetwebStarted> started = startCivetweb(listen.value(), config.max_clients + 2, s.get(), "--foxglove");
  if (!started) return started.status();
  s->civetweb_ = *started;
  s->url_ = "ws://" + started->url_host + ":" + std::to_string(s->civetweb_.port);
  static const char* kProtocols[] = {kFoxgloveSubprotocol};
  static mg_websocket_subprotocols subprotocols{1, kProtocols};
  mg_set_request_handler(s->civetweb_.ctx, "/", &FoxgloveServer::onHttp, s.get());
  mg_set_websocket_handler_with_subprotocols(s->civetweb_.ctx, "/", &subprotocols, &FoxgloveServer::onWsConnect,
                                             &FoxgloveServer::onWsReady, &FoxgloveServer::onWsData,
                                             &FoxgloveServer::onWsClose, s.get());
  return s;
}

uint64_t FoxgloveServer::realtimeSessionId() {
  timespec t{};
  clock_gettime(CLOCK_REALTIME, &t);
  return static_cast<uint64_t>(t.tv_sec) * 1'000'000'000ull + static_cast<uint64_t>(t.tv_nsec);
}

FoxgloveServer::~FoxgloveServer() {
  std::unique_lock lock(mu_);
  stopping_ = true;
  wake_.notify_all();
  waitForGoodbyes(lock, wake_, clients_);  // before mg_stop, after which writes send nothing
  lock.unlock();
  stopCivetweb(civetweb_);
  for (Client& c : clients_) {
    if (c.sender.joinable()) c.sender.join();
  }
}

int FoxgloveServer::channelIndex(uint32_t id) const {
  for (std::size_t i = 0; i < channels_.size(); ++i) {
    if (channels_[i].spec.id == id) return static_cast<int>(i);
  }
  return -1;
}

bool FoxgloveServer::publish(uint32_t channel_id, std::span<const uint8_t> payload, uint64_t log_time_ns) {
  {
    std::lock_guard lock(mu_);
    const int index = channelIndex(channel_id);
    if (index < 0) return false;
    Channel& c = channels_[static_cast<std::size_t>(index)];
    if (payload.size() > c.spec.max_bytes) {
      ++counters_.too_large;
      return false;
    }
    // Copied under the lock, as each client's sender copies it into its own frame:
    // memory-speed copies of at most a cloud; no wait on any network write.
    Buffer& b = c.newest;
    std::memcpy(b.data.data(), payload.data(), payload.size());
    b.bytes = payload.size();
    b.log_time_ns = log_time_ns;
    b.seq = ++c.seq;
    ++counters_.published;
  }
  wake_.notify_all();
  return true;
}

bool FoxgloveServer::subscribed(uint32_t channel_id) const {
  std::lock_guard lock(mu_);
  const int index = channelIndex(channel_id);
  return index >= 0 && channels_[static_cast<std::size_t>(index)].subscribers > 0;
}

FoxgloveServerCounters FoxgloveServer::counters() const {
  std::lock_guard lock(mu_);
  return counters_;
}

FoxgloveServer::Client* FoxgloveServer::clientOf(const mg_connection* conn) {
  return static_cast<Client*>(mg_get_user_connection_data(conn));
}

void FoxgloveServer::queueStatus(Client& client, int level, const std::string& message) {
  if (client.texts.size() >= kMaxTextsQueued) {
    ++counters_.statuses_dropped;
    return;
  }
  client.texts.push_back(foxgloveStatusJson(level, message));
  wake_.notify_all();
}

void FoxgloveServer::sendLoop(Client& client) {
  std::unique_lock lock(mu_);
  bool ok = true;
  auto news = [&](std::size_t i) {
    const Channel& c = channels_[i];
    const Subscription& sub = client.subs[i];
    return sub.active && c.newest.seq != 0 && c.newest.seq != sub.sent_seq;
  };
  auto anyNews = [&] {
    for (std::size_t i = 0; i < channels_.size(); ++i) {
      if (news(i)) return true;
    }
    return false;
  };
  while (ok) {
    wake_.wait(lock, [&] { return stopping_ || client.closing || !client.texts.empty() || anyNews(); });
    if (stopping_ || client.closing) break;
    if (!client.texts.empty()) {
      const std::string text = std::move(client.texts.front());
      client.texts.pop_front();
      lock.unlock();
      ok = mg_websocket_write(client.conn, MG_WEBSOCKET_OPCODE_TEXT, text.data(), text.size()) > 0;
      lock.lock();
      continue;
    }
    // The next channel with a newer message than the client has, round robin.
    std::size_t i = client.next_channel;
    for (std::size_t k = 0; k < channels_.size() && !news(i); ++k) i = (i + 1) % channels_.size();
    client.next_channel = (i + 1) % channels_.size();
    Channel& c = channels_[i];
    Subscription& sub = client.subs[i];
    const Buffer& b = c.newest;
    if (sub.sent_seq != 0 && b.seq > sub.sent_seq + 1) {
      client.dropped += b.seq - sub.sent_seq - 1;
      counters_.dropped += b.seq - sub.sent_seq - 1;
    }
    sub.sent_seq = b.seq;
    uint8_t* f = client.frame.data();
    f[0] = kOpMessageData;
    putU32(f + 1, sub.id);
    putU64(f + 5, b.log_time_ns);
    std::memcpy(f + kFrameHeader, b.data.data(), b.bytes);
    const std::size_t bytes = kFrameHeader + b.bytes;
    lock.unlock();
    ok = mg_websocket_write(client.conn, MG_WEBSOCKET_OPCODE_BINARY, reinterpret_cast<const char*>(f), bytes) > 0;
    lock.lock();
    if (ok) ++counters_.sent;
  }
  endSending(client, ok, stopping_, lock, wake_);
}

void FoxgloveServer::handleText(Client& client, std::string_view text) {
  // mu_ held by the caller.
  auto refuse = [&](const std::string& why) {
    ++counters_.bad_requests;
    queueStatus(client, kStatusError, why);
  };
  Result<FoxgloveRequest> parsed = parseFoxgloveRequest(text);
  if (!parsed) {
    refuse(parsed.status().code() == ErrorCode::kParseError && text.size() <= kMaxClientMessageBytes
               ? "not a foxglove.websocket.v1 message (a JSON object with an \"op\")"
               : parsed.status().message());
    return;
  }
  const FoxgloveRequest& r = parsed.value();
  for (const std::string& why : r.refused) refuse(why);
  for (const FoxgloveSubscription& s : r.subscriptions) {
    const int index = channelIndex(s.channel_id);
    if (index < 0) {
      refuse("subscribe: no channel " + std::to_string(s.channel_id));
      continue;
    }
    const bool id_used = std::any_of(client.subs.begin(), client.subs.end(),
                                     [&](const Subscription& u) { return u.active && u.id == s.id; });
    Subscription& sub = client.subs[static_cast<std::size_t>(index)];
    if (id_used || sub.active) {
      refuse("subscribe: subscription id " + std::to_string(s.id) + " is in use, or channel " +
             std::to_string(s.channel_id) + " already subscribed");
      continue;
    }
    sub.active = true;
    sub.id = s.id;
    // Starts at the channel's newest message: what was published before is not its drop.
    sub.sent_seq = 0;
    ++channels_[static_cast<std::size_t>(index)].subscribers;
    ++counters_.subscriptions;
  }
  for (const uint32_t id : r.subscription_ids) {
    bool found = false;
    for (std::size_t i = 0; i < client.subs.size(); ++i) {
      Subscription& sub = client.subs[i];
      if (sub.active && sub.id == id) {
        sub.active = false;
        --channels_[i].subscribers;
        found = true;
      }
    }
    if (!found) refuse("unsubscribe: no subscription " + std::to_string(id));
  }
  wake_.notify_all();
}

int FoxgloveServer::onHttp(mg_connection* conn, void*) {
  mg_send_http_error(conn, 426, "%s", "a Foxglove WebSocket server (foxglove.websocket.v1): connect with Foxglove or Lichtblick");
  return 426;
}

// Refuses a client that does not speak foxglove.websocket.v1 (civetweb accepted no subprotocol).
int FoxgloveServer::onWsConnect(const mg_connection* conn, void* self_ptr) {
  const mg_request_info* req = mg_get_request_info(conn);
  if (req != nullptr && req->acceptedWebSocketSubprotocol != nullptr &&
      std::strcmp(req->acceptedWebSocketSubprotocol, kFoxgloveSubprotocol) == 0) {
    return 0;
  }
  auto* self = static_cast<FoxgloveServer*>(self_ptr);
  std::lock_guard lock(self->mu_);
  ++self->counters_.clients_refused;
  return 1;
}

void FoxgloveServer::onWsReady(mg_connection* conn, void* self_ptr) {
  auto* self = static_cast<FoxgloveServer*>(self_ptr);
  std::lock_guard lock(self->mu_);
  auto free_client = std::find_if(self->clients_.begin(), self->clients_.end(), [](const Client& c) { return !c.used; });
  if (self->stopping_ || free_client == self->clients_.end()) {
    ++self->counters_.clients_refused;
    mg_set_user_connection_data(conn, nullptr);
    static constexpr char kReason[] = "\x03\xf0too many Foxglove clients on this operator";  // close code 1008
    mg_websocket_write(conn, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE, kReason, sizeof kReason - 1);
    return;
  }
  Client& c = *free_client;
  c.used = true;
  c.closing = false;
  c.id = self->next_client_id_++;
  c.conn = conn;
  c.subs.assign(self->channels_.size(), Subscription{});
  c.texts.clear();
  c.texts.push_back(self->server_info_);
  c.texts.push_back(self->advertise_);
  c.frame.resize(self->max_frame_);  // a client's one allocation, at connection
  c.dropped = 0;
  c.next_channel = 0;
  ++self->counters_.clients_open;
  ++self->counters_.clients_served;
  mg_set_user_connection_data(conn, &c);
  c.sending = true;
  c.sender = std::thread([self, &c] { self->sendLoop(c); });
}

int FoxgloveServer::onWsData(mg_connection* conn, int bits, char* data, std::size_t len, void* self_ptr) {
  auto* self = static_cast<FoxgloveServer*>(self_ptr);
  const int opcode = bits & 0x0f;
  if (opcode == MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE) return 0;
  if (opcode == MG_WEBSOCKET_OPCODE_PING || opcode == MG_WEBSOCKET_OPCODE_PONG) return 1;
  Client* client = clientOf(conn);
  if (client == nullptr) return 0;  // refused: close
  std::lock_guard lock(self->mu_);
  if (opcode != MG_WEBSOCKET_OPCODE_TEXT) {
    ++self->counters_.bad_requests;
    self->queueStatus(*client, kStatusError,
                      opcode == MG_WEBSOCKET_OPCODE_BINARY
                          ? "binary messages refused: this server advertises no client publishing"
                          : "fragmented messages are not supported");
    return 1;
  }
  self->handleText(*client, std::string_view(data, len));
  return 1;
}

void FoxgloveServer::onWsClose(const mg_connection* conn, void* self_ptr) {
  auto* self = static_cast<FoxgloveServer*>(self_ptr);
  Client* client = clientOf(conn);
  if (client == nullptr) return;
  std::thread sender;
  {
    std::lock_guard lock(self->mu_);
    client->closing = true;
    sender = std::move(client->sender);
  }
  self->wake_.notify_all();
  if (sender.joinable()) sender.join();
  std::lock_guard lock(self->mu_);
  for (std::size_t i = 0; i < client->subs.size(); ++i) {
    if (client->subs[i].active) --self->channels_[i].subscribers;
    client->subs[i].active = false;
  }
  client->used = false;
  client->conn = nullptr;
  --self->counters_.clients_open;
}

}  // namespace fovea::tools

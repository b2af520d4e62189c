#include "tools/operator/view_server.h"

#include <algorithm>
#include <cstring>

#include <civetweb.h>

#include "core/clock.h"
#include "tools/operator/civetweb_start.h"
#include "net/udp_socket.h"
#include "tools/operator/view_assets.h"
#include "tools/operator/view_frame.h"

namespace fovea::tools {

Result<std::string> viewListenAddress(const std::string& text) {
  const std::size_t colon = text.rfind(':');
  const std::string address = colon == std::string::npos ? "127.0.0.1" : text.substr(0, colon);
  const std::string port = colon == std::string::npos ? text : text.substr(colon + 1);
  char* end = nullptr;
  const long p = std::strtol(port.c_str(), &end, 10);
  if (port.empty() || *end != '\0' || p < 0 || p > 65535) {
    return Result<std::string>(ErrorCode::kInvalidArgument, "--view: '" + port + "' is not a port (0 .. 65535)");
  }
  // IPv4 dotted quads only: civetweb takes them as they are (and "0.0.0.0" for every interface).
  int a = 0, b = 0, c = 0, d = 0;
  char tail = 0;
  if (std::sscanf(address.c_str(), "%d.%d.%d.%d%c", &a, &b, &c, &d, &tail) != 4 || a < 0 || a > 255 || b < 0 ||
      b > 255 || c < 0 || c > 255 || d < 0 || d > 255) {
    return Result<std::string>(ErrorCode::kInvalidArgument, "--view: '" + address + "' is not an IPv4 address");
  }
  return address + ":" + std::to_string(p);
}

ViewServer::ViewServer(const ViewServerConfig& config) : config_(config), mode_(config.initial_mode) {}

Result<std::unique_ptr<ViewServer>> ViewServer::start(const ViewServerConfig& config) {
  using R = Result<std::unique_ptr<ViewServer>>;
  Result<std::string> listen = viewListenAddress(config.listen);
  if (!listen) return listen.status();
  if (config.max_tabs < 1 || config.max_tabs > 64) return R(ErrorCode::kInvalidArgument, "--view: max tabs must be 1 .. 64");
  std::unique_ptr<ViewServer> s(new ViewServer(config));
  s->buffers_.resize(config.max_tabs + 2);
  for (Buffer& b : s->buffers_) b.data.resize(viewFrameBytes(config.max_points));
  s->tabs_.resize(config.max_tabs);

  // A worker per open tab, plus a few for page loads.
  Result<CivetwebStarted> started = startCivetweb(listen.value(), config.max_tabs + 4, s.get(), "--view");
  if (!started) return started.status();
  s->civetweb_ = *started;
  s->url_ = "http://" + started->url_host + ":" + std::to_string(s->civetweb_.port) + "/";
  mg_set_request_handler(s->civetweb_.ctx, "/", &ViewServer::onHttp, s.get());
  mg_set_websocket_handler(s->civetweb_.ctx, "/ws", &ViewServer::onWsConnect, &ViewServer::onWsReady, &ViewServer::onWsData,
                           &ViewServer::onWsClose, s.get());
  return s;
}

ViewServer::~ViewServer() {
  std::unique_lock lock(mu_);
  stopping_ = true;
  wake_.notify_all();
  waitForGoodbyes(lock, wake_, tabs_);  // before mg_stop, after which writes send nothing
  lock.unlock();
  // Closes every connection; each close handler joins its tab's sender.
  stopCivetweb(civetweb_);
  for (Tab& t : tabs_) {
    if (t.sender.joinable()) t.sender.join();
  }
}

std::span<uint8_t> ViewServer::frameBuffer() {
  std::lock_guard lock(mu_);
  if (writing_ < 0) {
    // One buffer per tab plus the newest plus this one: a free one always exists.
    for (std::size_t i = 0; i < buffers_.size(); ++i) {
      if (static_cast<int>(i) != latest_ && buffers_[i].readers == 0) {
        writing_ = static_cast<int>(i);
        break;
      }
    }
  }
  // Unreachable by the count above; an empty span makes the caller pack nothing.
  if (writing_ < 0) return {};
  return buffers_[static_cast<std::size_t>(writing_)].data;
}

void ViewServer::publishFrame(std::size_t bytes) {
  {
    std::lock_guard lock(mu_);
    if (writing_ < 0 || bytes == 0 || bytes > buffers_[static_cast<std::size_t>(writing_)].data.size()) return;
    Buffer& b = buffers_[static_cast<std::size_t>(writing_)];
    b.bytes = bytes;
    b.seq = ++frame_seq_;
    latest_ = writing_;
    writing_ = -1;
    ++counters_.frames_published;
  }
  wake_.notify_all();
}

void ViewServer::publishState(const std::string& json) {
  {
    std::lock_guard lock(mu_);
    state_json_ = json;
    ++state_seq_;
  }
  wake_.notify_all();
}

void ViewServer::publishFigures(ViewerFigures figures) {
  {
    std::lock_guard lock(mu_);
    figures.tabs = counters_.tabs_open;
    figures.malformed = counters_.malformed;
    figures_ = std::move(figures);
    for (Tab& t : tabs_) t.stats_pending = t.used;
  }
  wake_.notify_all();
}

std::optional<TabGaze> ViewServer::latestGaze() const {
  std::lock_guard lock(mu_);
  return gaze_;
}

GazeMode ViewServer::gazeMode() const {
  std::lock_guard lock(mu_);
  return mode_;
}

ViewServerCounters ViewServer::counters() const {
  std::lock_guard lock(mu_);
  return counters_;
}

ViewServer::Tab* ViewServer::tabOf(const mg_connection* conn) {
  return static_cast<Tab*>(mg_get_user_connection_data(conn));
}

void ViewServer::sendLoop(Tab& tab) {
  std::unique_lock lock(mu_);
  const std::string hello = helloJson(tab.id, config_.gaze_hz, mode_, config_.script, config_.initial_eye);
  lock.unlock();
  bool ok = mg_websocket_write(tab.conn, MG_WEBSOCKET_OPCODE_TEXT, hello.data(), hello.size()) > 0;
  lock.lock();
  while (ok) {
    wake_.wait(lock, [&] {
      return stopping_ || tab.closing || tab.state_seq != state_seq_ || tab.stats_pending ||
             (latest_ >= 0 && buffers_[static_cast<std::size_t>(latest_)].seq != tab.sent_seq);
    });
    if (stopping_ || tab.closing) break;
    if (tab.state_seq != state_seq_ || tab.stats_pending) {
      // State first: it says what the frames and figures mean.
      std::string text;
      if (tab.state_seq != state_seq_) {
        text = state_json_;
        tab.state_seq = state_seq_;
      } else {
        text = statsJson(figures_, tab.dropped);
        tab.stats_pending = false;
      }
      lock.unlock();
      ok = mg_websocket_write(tab.conn, MG_WEBSOCKET_OPCODE_TEXT, text.data(), text.size()) > 0;
      lock.lock();
      continue;
    }
    Buffer& b = buffers_[static_cast<std::size_t>(latest_)];
    // Frames published since the last one this tab got were skipped for it.
    if (tab.sent_seq != 0 && b.seq > tab.sent_seq + 1) {
      tab.dropped += b.seq - tab.sent_seq - 1;
      counters_.frames_dropped += b.seq - tab.sent_seq - 1;
    }
    tab.sent_seq = b.seq;
    ++b.readers;
    lock.unlock();
    ok = mg_websocket_write(tab.conn, MG_WEBSOCKET_OPCODE_BINARY, reinterpret_cast<const char*>(b.data.data()), b.bytes) > 0;
    lock.lock();
    --b.readers;
    if (ok) ++counters_.frames_sent;
  }
  endSending(tab, ok, stopping_, lock, wake_);
}

int ViewServer::onHttp(mg_connection* conn, void* self_ptr) {
  auto* self = static_cast<ViewServer*>(self_ptr);
  const mg_request_info* req = mg_get_request_info(conn);
  {
    std::lock_guard lock(self->mu_);
    ++self->counters_.http_requests;
  }
  const bool head = std::strcmp(req->request_method, "HEAD") == 0;
  if (!head && std::strcmp(req->request_method, "GET") != 0) {
    mg_send_http_error(conn, 405, "%s", "only GET and HEAD");
    return 405;
  }
  std::string_view path = req->local_uri != nullptr ? req->local_uri : "/";
  if (path == "/") path = "/index.html";
  for (const ViewAsset& a : viewAssets()) {
    if (a.path != path) continue;
    mg_printf(conn,
              "HTTP/1.1 200 OK\r\nContent-Type: %.*s\r\nContent-Length: %zu\r\nCache-Control: no-store\r\n"
              "X-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n",
              static_cast<int>(a.mime.size()), a.mime.data(), a.data.size());
    if (!head) mg_write(conn, a.data.data(), a.data.size());
    return 200;
  }
  {
    std::lock_guard lock(self->mu_);
    ++self->counters_.http_not_found;
  }
  mg_send_http_error(conn, 404, "%s", "not found");
  return 404;
}

int ViewServer::onWsConnect(const mg_connection*, void*) { return 0; }

void ViewServer::onWsReady(mg_connection* conn, void* self_ptr) {
  auto* self = static_cast<ViewServer*>(self_ptr);
  std::lock_guard lock(self->mu_);
  auto free_tab = std::find_if(self->tabs_.begin(), self->tabs_.end(), [](const Tab& t) { return !t.used; });
  if (self->stopping_ || free_tab == self->tabs_.end()) {
    ++self->counters_.tabs_refused;
    mg_set_user_connection_data(conn, nullptr);
    static constexpr char kReason[] = "\x03\xf0too many viewer tabs on this operator";  // close code 1008
    mg_websocket_write(conn, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE, kReason, sizeof kReason - 1);
    return;
  }
  Tab& t = *free_tab;
  t.used = true;
  t.closing = false;
  t.id = self->next_tab_id_++;
  t.conn = conn;
  // Frames published before it connected are not its drops; it starts at the newest.
  t.sent_seq = 0;
  t.state_seq = self->state_seq_ == 0 ? 0 : self->state_seq_ - 1;
  t.stats_pending = false;
  t.dropped = 0;
  ++self->counters_.tabs_open;
  ++self->counters_.tabs_served;
  mg_set_user_connection_data(conn, &t);
  t.sending = true;
  t.sender = std::thread([self, &t] { self->sendLoop(t); });
}

int ViewServer::onWsData(mg_connection* conn, int bits, char* data, std::size_t len, void* self_ptr) {
  auto* self = static_cast<ViewServer*>(self_ptr);
  const int opcode = bits & 0x0f;
  if (opcode == MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE) return 0;
  if (opcode == MG_WEBSOCKET_OPCODE_PING || opcode == MG_WEBSOCKET_OPCODE_PONG) return 1;
  Tab* tab = tabOf(conn);
  if (tab == nullptr) return 0;  // refused: close
  if (opcode != MG_WEBSOCKET_OPCODE_TEXT) {
    std::lock_guard lock(self->mu_);
    ++self->counters_.malformed;  // the page sends text only
    return 1;
  }
  Result<ViewerMessage> m = parseViewerMessage(std::string_view(data, len));
  std::lock_guard lock(self->mu_);
  if (!m) {
    ++self->counters_.malformed;
    return 1;
  }
  if (m->kind == ViewerMessage::Kind::kGaze) {
    self->gaze_ = TabGaze{m->gaze, tab->id, monotonicNs()};
    ++self->counters_.gaze_received;
  } else {
    self->mode_ = m->mode;
  }
  return 1;
}

void ViewServer::onWsClose(const mg_connection* conn, void* self_ptr) {
  auto* self = static_cast<ViewServer*>(self_ptr);
  Tab* tab = tabOf(conn);
  if (tab == nullptr) return;
  std::thread sender;
  {
    std::lock_guard lock(self->mu_);
    tab->closing = true;
    sender = std::move(tab->sender);
  }
  self->wake_.notify_all();
  if (sender.joinable()) sender.join();
  std::lock_guard lock(self->mu_);
  tab->used = false;
  tab->conn = nullptr;
  --self->counters_.tabs_open;
}

}  // namespace fovea::tools

// A viewer tab for the tests: civetweb's WebSocket client, recording what the
// operator's viewer sends it (tests/unit/tools/test_view_server.cpp,
// tests/integration/test_operator_view.cpp).
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <civetweb.h>
#include <gtest/gtest.h>

namespace fovea::test {

// A tab: a WebSocket client that records what it receives; delay_ms makes it
// slow (its reading thread sleeps after every binary message).
class Tab {
 public:
  // mg_init_library must have been called (a ViewServer in this process does,
  // or initTabs()).
  explicit Tab(int port, int delay_ms = 0) : delay_ms_(delay_ms) {
    char error[256] = {0};
    conn_ = mg_connect_websocket_client("127.0.0.1", port, 0, error, sizeof error, "/ws", nullptr, &Tab::onData,
                                        &Tab::onClose, this);
    error_ = error;
  }
  ~Tab() { close(); }
  // Closes as a browser's tab does, with a close frame: the server's answer
  // ends the client's read at once, where mg_close_connection alone waits out
  // its 2 s poll.
  void close() {
    if (conn_ == nullptr) return;
    hurry();  // a slow tab reads what is still in flight at once
    if (!closed_.load()) {
      static constexpr char kNormal[] = "\x03\xe8";  // close code 1000
      mg_websocket_client_write(conn_, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE, kNormal, sizeof kNormal - 1);
    }
    mg_close_connection(conn_);
    conn_ = nullptr;
  }
  bool connected() const { return conn_ != nullptr; }
  const std::string& error() const { return error_; }
  void send(const std::string& text, int opcode = MG_WEBSOCKET_OPCODE_TEXT) {
    ASSERT_GT(mg_websocket_client_write(conn_, opcode, text.data(), text.size()), 0);
  }
  std::vector<std::string> texts() {
    std::lock_guard lock(mu_);
    return texts_;
  }
  bool hasText(const std::string& part) {
    for (const std::string& t : texts()) {
      if (t.find(part) != std::string::npos) return true;
    }
    return false;
  }
  std::size_t frames() {
    std::lock_guard lock(mu_);
    return frames_;
  }
  std::vector<uint8_t> lastFrame() {
    std::lock_guard lock(mu_);
    return last_frame_;
  }
  bool closedByServer() const { return closed_.load(); }
  // The payload of the close frame the server sent (its code, two bytes big
  // endian, then its reason), empty if none came.
  std::string closeFrame() {
    std::lock_guard lock(mu_);
    return close_frame_;
  }
  // From now on it reads at full speed (what is in flight, then the newest).
  void hurry() { delay_ms_.store(0); }

 private:
  static int onData(mg_connection* conn, int bits, char* data, std::size_t len, void* self_ptr) {
    auto* self = static_cast<Tab*>(self_ptr);
    const int opcode = bits & 0x0f;
    {
      std::lock_guard lock(self->mu_);
      if (opcode == MG_WEBSOCKET_OPCODE_TEXT) self->texts_.emplace_back(data, len);
      if (opcode == MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE) self->close_frame_.assign(data, len);
      if (opcode == MG_WEBSOCKET_OPCODE_BINARY) {
        ++self->frames_;
        self->last_frame_.assign(data, data + len);
      }
    }
    if (opcode == MG_WEBSOCKET_OPCODE_BINARY && self->delay_ms_.load() > 0) {
      std::this_thread::sleep_for(std::chrono::milliseconds(self->delay_ms_.load()));
    }
    if (opcode != MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE) return 1;
    // A browser answers a close frame with its own (RFC 6455 5.5.1); civetweb's
    // client does not, so the tab does it as a browser would.
    mg_websocket_client_write(conn, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE, data, len);
    return 0;
  }
  static void onClose(const mg_connection*, void* self_ptr) { static_cast<Tab*>(self_ptr)->closed_.store(true); }

  std::atomic<int> delay_ms_;
  mg_connection* conn_ = nullptr;
  std::string error_;
  std::mutex mu_;
  std::vector<std::string> texts_;
  std::size_t frames_ = 0;
  std::vector<uint8_t> last_frame_;
  std::string close_frame_;
  std::atomic<bool> closed_{false};
};

// For a process without a ViewServer of its own.
inline void initTabs() {
  static const unsigned features = mg_init_library(0);
  (void)features;
}

}  // namespace fovea::test

// fovea-operator --view: serves the viewer page and streams decoded frames to
// its tabs over a WebSocket (docs/viewer.md). Built on civetweb (Debian's
// libcivetweb: HTTP and WebSocket in one small C library; each connection has
// a worker thread of its own).
//
// Threads: the operator's thread publishes frames, the connection state and the
// figures, and reads the tabs' gaze; each tab has a sender thread that writes
// to it, and civetweb's worker threads read from it. A tab is always sent the
// newest frame: frames published while it is still writing an older one are
// skipped and counted for it (a slow tab never queues frames, nor slows the
// others). Frame buffers are allocated at start: one per tab plus two.
#pragma once

#include <array>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "core/result.h"
#include "tools/operator/civetweb_start.h"
#include "tools/operator/view_messages.h"

namespace fovea::tools {

struct ViewServerConfig {
  std::string listen = "8080";  // [ADDR:]PORT; ADDR defaults to 127.0.0.1; port 0 picks a free one
  std::size_t max_tabs = 4;     // further tabs are refused with a close frame that says so
  std::size_t max_points = 640 * 480;
  // For the tabs' hello.
  double gaze_hz = 120.0;
  std::string script;                               // the operator's --gaze, if any
  std::optional<std::array<double, 6>> initial_eye;  // origin, target
  GazeMode initial_mode = GazeMode::kCursor;
};

// Parses --view's [ADDR:]PORT into civetweb's listening_ports form, loopback
// when ADDR is left out; the error names what is wrong.
Result<std::string> viewListenAddress(const std::string& text);

struct ViewServerCounters {
  uint64_t tabs_open = 0;
  uint64_t tabs_served = 0;     // ever connected
  uint64_t tabs_refused = 0;    // over max_tabs
  uint64_t frames_published = 0;
  uint64_t frames_sent = 0;     // all tabs
  uint64_t frames_dropped = 0;  // all tabs: published while the tab was busy
  uint64_t malformed = 0;       // tabs' messages that did not parse or validate
  uint64_t gaze_received = 0;
  uint64_t http_requests = 0;
  uint64_t http_not_found = 0;
};

struct TabGaze {
  ViewerGaze gaze;
  int tab = 0;
  int64_t received_ns = 0;  // CLOCK_MONOTONIC
};

class ViewServer {
 public:
  static Result<std::unique_ptr<ViewServer>> start(const ViewServerConfig& config);
  ~ViewServer();
  ViewServer(const ViewServer&) = delete;
  ViewServer& operator=(const ViewServer&) = delete;

  int port() const { return civetweb_.port; }
  const std::string& url() const { return url_; }

  // The operator's thread: frameBuffer() lends a buffer of viewFrameBytes(max_points)
  // bytes no tab is reading; publishFrame(bytes) makes its first bytes the newest frame.
  std::span<uint8_t> frameBuffer();
  void publishFrame(std::size_t bytes);
  // Sent to every tab now and to each new tab after its hello.
  void publishState(const std::string& json);
  // A stats message for every tab, with its own dropped-frame count.
  void publishFigures(ViewerFigures figures);

  std::optional<TabGaze> latestGaze() const;
  GazeMode gazeMode() const;
  ViewServerCounters counters() const;

 private:
  struct Buffer {
    std::vector<uint8_t> data;
    std::size_t bytes = 0;
    uint64_t seq = 0;
    int readers = 0;
  };
  struct Tab {
    bool used = false;
    bool closing = false;
    bool sending = false;  // its sender runs; at a stop it says goodbye first
    int id = 0;
    mg_connection* conn = nullptr;
    std::thread sender;
    uint64_t sent_seq = 0;     // the newest frame written to it
    uint64_t state_seq = 0;    // the newest state written to it
    bool stats_pending = false;
    uint64_t dropped = 0;
  };

  explicit ViewServer(const ViewServerConfig& config);
  void sendLoop(Tab& tab);
  static Tab* tabOf(const mg_connection* conn);

  static int onHttp(mg_connection* conn, void* self);
  static int onWsConnect(const mg_connection* conn, void* self);
  static void onWsReady(mg_connection* conn, void* self);
  static int onWsData(mg_connection* conn, int bits, char* data, std::size_t len, void* self);
  static void onWsClose(const mg_connection* conn, void* self);

  ViewServerConfig config_;
  CivetwebStarted civetweb_;  // its context, port and host (stopCivetweb)
  std::string url_;

  mutable std::mutex mu_;
  std::condition_variable wake_;
  bool stopping_ = false;
  std::vector<Buffer> buffers_;
  int latest_ = -1;   // the newest frame's buffer
  int writing_ = -1;  // lent to the operator's thread
  uint64_t frame_seq_ = 0;
  std::string state_json_;
  uint64_t state_seq_ = 0;
  ViewerFigures figures_;
  std::vector<Tab> tabs_;
  int next_tab_id_ = 1;
  std::optional<TabGaze> gaze_;
  GazeMode mode_;
  ViewServerCounters counters_;
};

}  // namespace fovea::tools

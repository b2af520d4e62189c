// fovea-operator --view's server with real WebSocket clients (civetweb's own
// client) over loopback: the page's files, frames to every tab, the newest
// frame for a slow tab (the others unaffected), malformed messages counted
// without closing anything, tabs over the limit refused, reconnection.
#include <chrono>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include <civetweb.h>
#include <gtest/gtest.h>

#include "tests/support/test_time.h"
#include "tests/support/websocket_tab.h"
#include "tools/operator/view_assets.h"
#include "tools/operator/view_server.h"

namespace fovea::tools {
namespace {

using namespace std::chrono_literals;
using test::waitUntil;
using test::Tab;

std::unique_ptr<ViewServer> startServer(std::size_t max_tabs = 4, std::size_t max_points = 1000) {
  ViewServerConfig config;
  config.listen = "127.0.0.1:0";
  config.max_tabs = max_tabs;
  config.max_points = max_points;
  config.script = "fixed:0,0,1>0,1,1";
  Result<std::unique_ptr<ViewServer>> s = ViewServer::start(config);
  EXPECT_TRUE(s.isOk()) << s.status().message();
  return s.isOk() ? std::move(s.value()) : nullptr;
}

// A frame of `bytes` bytes whose content names its sequence.
void publish(ViewServer& server, std::size_t bytes, uint8_t fill) {
  std::span<uint8_t> buf = server.frameBuffer();
  ASSERT_GE(buf.size(), bytes);
  std::memset(buf.data(), fill, bytes);
  server.publishFrame(bytes);
}

// An HTTP request; returns the status code and fills body (and the Content-Type, if asked).
int httpGet(int port, const std::string& request, std::string& body, std::string* content_type = nullptr) {
  char error[256] = {0};
  mg_connection* c = mg_download("127.0.0.1", port, 0, error, sizeof error, "%s", request.c_str());
  if (c == nullptr) return -1;
  const mg_response_info* info = mg_get_response_info(c);
  const int status = info->status_code;
  if (content_type != nullptr) {
    content_type->clear();
    for (int i = 0; i < info->num_headers; ++i) {
      if (mg_strcasecmp(info->http_headers[i].name, "Content-Type") == 0) *content_type = info->http_headers[i].value;
    }
  }
  body.clear();
  char buf[4096];
  for (int n; (n = mg_read(c, buf, sizeof buf)) > 0;) body.append(buf, static_cast<std::size_t>(n));
  mg_close_connection(c);
  return status;
}

TEST(ViewListenAddress, LoopbackByDefaultAndErrorsSayWhy) {
  EXPECT_EQ(viewListenAddress("8080").value(), "127.0.0.1:8080");
  EXPECT_EQ(viewListenAddress("0.0.0.0:80").value(), "0.0.0.0:80");
  EXPECT_EQ(viewListenAddress("192.168.1.20:0").value(), "192.168.1.20:0");
  EXPECT_NE(viewListenAddress("80a").status().message().find("not a port"), std::string::npos);
  EXPECT_NE(viewListenAddress("70000").status().message().find("not a port"), std::string::npos);
  EXPECT_NE(viewListenAddress("robot:80").status().message().find("not an IPv4 address"), std::string::npos);
  EXPECT_NE(viewListenAddress("1.2.3.256:80").status().message().find("not an IPv4 address"), std::string::npos);
}

TEST(ViewServer, ServesThePageItsFilesAndNothingElse) {
  auto server = startServer();
  ASSERT_TRUE(server);
  ASSERT_GT(server->port(), 0);
  EXPECT_EQ(server->url(), "http://127.0.0.1:" + std::to_string(server->port()) + "/");
  std::string body;
  ASSERT_EQ(httpGet(server->port(), "GET / HTTP/1.0\r\n\r\n", body), 200);
  EXPECT_NE(body.find("<html"), std::string::npos);
  for (const ViewAsset& a : viewAssets()) {
    ASSERT_EQ(httpGet(server->port(), "GET " + std::string(a.path) + " HTTP/1.0\r\n\r\n", body), 200) << a.path;
    EXPECT_EQ(body.size(), a.data.size()) << a.path;
  }
  EXPECT_EQ(httpGet(server->port(), "GET /../../etc/passwd HTTP/1.0\r\n\r\n", body), 404);
  EXPECT_EQ(httpGet(server->port(), "GET /missing.js HTTP/1.0\r\n\r\n", body), 404);
  EXPECT_EQ(httpGet(server->port(), "POST / HTTP/1.0\r\nContent-Length: 0\r\n\r\n", body), 405);
  EXPECT_GE(server->counters().http_not_found, 2u);
}

// The page is several plain scripts (index.html's <script src>): each must be in
// FOVEA_VIEWER_FILES and served as JavaScript, or the browser would not run it.
TEST(ViewServer, EveryScriptThePageLoadsIsServedAsJavaScript) {
  auto server = startServer();
  ASSERT_TRUE(server);
  std::string html;
  ASSERT_EQ(httpGet(server->port(), "GET /index.html HTTP/1.0\r\n\r\n", html), 200);
  int scripts = 0;
  for (std::size_t at = html.find("<script src=\""); at != std::string::npos; at = html.find("<script src=\"", at + 1)) {
    const std::size_t start = at + std::strlen("<script src=\"");
    const std::string name = html.substr(start, html.find('"', start) - start);
    std::string body;
    std::string type;
    ASSERT_EQ(httpGet(server->port(), "GET /" + name + " HTTP/1.0\r\n\r\n", body, &type), 200) << name;
    EXPECT_EQ(type, "text/javascript; charset=utf-8") << name;
    EXPECT_NE(body.find("'use strict';"), std::string::npos) << name;
    ++scripts;
  }
  EXPECT_GE(scripts, 1);
}

TEST(ViewServer, ATabGetsHelloStateFiguresAndTheNewestFrame) {
  auto server = startServer();
  ASSERT_TRUE(server);
  server->publishState(stateJson(LinkState::kConnecting, "saying hello", "127.0.0.1:7000"));
  Tab tab(server->port());
  ASSERT_TRUE(tab.connected()) << tab.error();
  ASSERT_TRUE(waitUntil([&] { return tab.hasText("\"type\":\"hello\""); }, 2000ms));
  EXPECT_TRUE(tab.hasText("\"script\":\"fixed:0,0,1>0,1,1\""));
  // The state published before it connected.
  ASSERT_TRUE(waitUntil([&] { return tab.hasText("\"state\":\"connecting\""); }, 2000ms));
  server->publishState(stateJson(LinkState::kStreaming, "", "127.0.0.1:7000"));
  ASSERT_TRUE(waitUntil([&] { return tab.hasText("\"state\":\"streaming\""); }, 2000ms));
  publish(*server, 500, 7);
  ASSERT_TRUE(waitUntil([&] { return tab.frames() == 1; }, 2000ms));
  EXPECT_EQ(tab.lastFrame(), std::vector<uint8_t>(500, 7));
  ViewerFigures figures;
  figures.fps = 29.5;
  server->publishFigures(figures);
  ASSERT_TRUE(waitUntil([&] { return tab.hasText("\"fps\":29.5"); }, 2000ms));
  EXPECT_TRUE(tab.hasText("\"tabs\":1"));
  EXPECT_EQ(server->counters().tabs_open, 1u);
}

TEST(ViewServer, GazeAndModeFromATabReachTheOperatorAndMalformedMessagesAreCounted) {
  auto server = startServer();
  ASSERT_TRUE(server);
  Tab tab(server->port());
  ASSERT_TRUE(tab.connected()) << tab.error();
  ASSERT_TRUE(waitUntil([&] { return tab.hasText("hello"); }, 2000ms));
  EXPECT_FALSE(server->latestGaze().has_value());
  tab.send("not json");
  tab.send(R"({"type":"gaze","origin":[0,0],"direction":[1,0,0]})");
  tab.send(std::string("\x00\x01\x02", 3), MG_WEBSOCKET_OPCODE_BINARY);
  tab.send(R"({"type":"gaze","origin":[3,0.35,1.55],"direction":[0,2,0]})");
  ASSERT_TRUE(waitUntil([&] { return server->latestGaze().has_value(); }, 2000ms));
  const TabGaze g = *server->latestGaze();
  EXPECT_EQ(g.gaze.origin_m[0], 3.0);
  EXPECT_EQ(g.gaze.direction[1], 1.0);
  EXPECT_EQ(g.tab, 1);
  EXPECT_EQ(server->counters().malformed, 3u);
  EXPECT_EQ(server->gazeMode(), GazeMode::kCursor);
  tab.send(R"({"type":"mode","gaze":"script"})");
  ASSERT_TRUE(waitUntil([&] { return server->gazeMode() == GazeMode::kScript; }, 2000ms));
  // The connection survived all of it.
  publish(*server, 100, 1);
  ASSERT_TRUE(waitUntil([&] { return tab.frames() == 1; }, 2000ms));
  EXPECT_FALSE(tab.closedByServer());
}

TEST(ViewServer, ASlowTabGetsTheNewestFramesWhileAFastOneGetsThemAll) {
  // 1 MB frames: a tab that takes 100 ms per frame cannot keep up with 200 a second.
  constexpr std::size_t kBytes = 1'000'000;
  auto server = startServer(4, kBytes / 16);
  ASSERT_TRUE(server);
  // Both paces scaled (test_time.h): under ThreadSanitizer the fast tab's
  // reading of 1 MB frames is itself 10 times slower, and on a loaded CI machine
  // it fell behind an unscaled slow tab (8 frames against 11).
  const auto slow_per_frame = test::scaled(100ms);
  const auto publish_every = test::scaled(5ms);
  Tab fast(server->port());
  Tab slow(server->port(), static_cast<int>(slow_per_frame.count()));
  ASSERT_TRUE(fast.connected() && slow.connected());
  ASSERT_TRUE(waitUntil([&] { return server->counters().tabs_open == 2; }, 2000ms));
  constexpr int kFrames = 60;
  for (int i = 1; i <= kFrames; ++i) {
    publish(*server, kBytes, static_cast<uint8_t>(i));
    std::this_thread::sleep_for(publish_every);
  }
  // Each tab ends on the newest frame. The slow one reads what is still in
  // flight at full speed (under TSan's scale its socket's 6 or so frames
  // would take 1 s each).
  slow.hurry();
  ASSERT_TRUE(waitUntil([&] { return !slow.lastFrame().empty() && slow.lastFrame()[0] == kFrames; }, 5000ms));
  ASSERT_TRUE(waitUntil([&] { return !fast.lastFrame().empty() && fast.lastFrame()[0] == kFrames; }, 5000ms));
  const ViewServerCounters c = server->counters();
  EXPECT_EQ(c.frames_published, static_cast<uint64_t>(kFrames));
  EXPECT_LT(slow.frames(), static_cast<std::size_t>(kFrames / 2)) << "the slow tab was not slow";
  EXPECT_GT(fast.frames(), slow.frames());
  // What a tab did not get is counted as dropped for it (a tab's count starts
  // at the first frame it was sent, which may be frame 2 if frame 1 was replaced
  // before its sender woke).
  ASSERT_TRUE(waitUntil([&] { return server->counters().frames_sent == fast.frames() + slow.frames(); }, 2000ms));
  const uint64_t accounted = server->counters().frames_sent + server->counters().frames_dropped;
  EXPECT_LE(accounted, 2u * kFrames);
  EXPECT_GE(accounted, 2u * kFrames - 4);
  EXPECT_GE(c.frames_dropped, static_cast<uint64_t>(kFrames / 2));
}

TEST(ViewServer, TabsOverTheLimitAreRefusedAndATabCanReconnect) {
  auto server = startServer(1);
  ASSERT_TRUE(server);
  auto first = std::make_unique<Tab>(server->port());
  ASSERT_TRUE(first->connected());
  ASSERT_TRUE(waitUntil([&] { return first->hasText("hello"); }, 2000ms));
  Tab second(server->port());
  ASSERT_TRUE(waitUntil([&] { return second.closedByServer(); }, 2000ms));
  EXPECT_EQ(server->counters().tabs_refused, 1u);
  EXPECT_FALSE(second.hasText("hello"));
  // The first tab is unaffected; then it goes, and a new tab takes its place.
  publish(*server, 64, 3);
  ASSERT_TRUE(waitUntil([&] { return first->frames() == 1; }, 2000ms));
  first.reset();
  ASSERT_TRUE(waitUntil([&] { return server->counters().tabs_open == 0; }, 2000ms));
  Tab third(server->port());
  ASSERT_TRUE(waitUntil([&] { return third.hasText("\"tab\":2"); }, 2000ms));
  publish(*server, 64, 4);
  ASSERT_TRUE(waitUntil([&] { return third.frames() >= 1 && third.lastFrame()[0] == 4; }, 2000ms));
  EXPECT_EQ(server->counters().tabs_served, 2u);
}

TEST(ViewServer, StopsWithTabsConnected) {
  auto server = startServer();
  ASSERT_TRUE(server);
  Tab a(server->port()), b(server->port(), 50);
  ASSERT_TRUE(waitUntil([&] { return server->counters().tabs_open == 2; }, 2000ms));
  publish(*server, 1000, 1);
  server.reset();  // must return, with both tabs still open
  EXPECT_TRUE(waitUntil([&] { return a.closedByServer() && b.closedByServer(); }, 2000ms));
  // Each was told why, with a close frame: 1001, going away (the frame's answer
  // lets the server stop without waiting out civetweb's poll).
  for (Tab* tab : {&a, &b}) EXPECT_EQ(tab->closeFrame(), "\x03\xe9the operator is stopping");
}

TEST(ViewServer, AnAddressInUseIsAClearError) {
  auto server = startServer();
  ASSERT_TRUE(server);
  ViewServerConfig config;
  config.listen = std::to_string(server->port());
  Result<std::unique_ptr<ViewServer>> second = ViewServer::start(config);
  ASSERT_FALSE(second.isOk());
  EXPECT_NE(second.status().message().find("cannot serve on 127.0.0.1:" + std::to_string(server->port())), std::string::npos)
      << second.status().message();
}

}  // namespace
}  // namespace fovea::tools

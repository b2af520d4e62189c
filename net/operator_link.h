// The operator's end of the link (docs/protocol.md): says Hello, waits for Accept
// (retrying with backoff), then sends gaze samples with receiver feedback and
// receives the robot's authenticated payloads. Single-threaded; no heap
// allocation per datagram.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "core/result.h"
#include "net/messages.h"
#include "net/secure_channel.h"
#include "net/udp_socket.h"

namespace fovea::net {

struct OperatorLinkConfig {
  std::optional<Key> key;  // the pre-shared key; without one, insecure must be set (all-zero key)
  bool insecure = false;
  std::string name = "operator";          // at most kMaxOperatorNameBytes
  uint64_t budget_bytes_per_s = 0;        // 0: whatever the robot allows
  uint32_t mtu_bytes = kDefaultMtu;       // kMinMtu..kMaxMtu
  int connect_timeout_ms = 3000;          // give up after this long
  int first_retry_ms = 100;               // Hello again after this, doubling up to 1 s
  // Room for the datagrams of a whole frame that arrive faster than they are
  // decoded (a 1.3 MB frame at a high budget): the default of about 200 KB holds
  // some 90 datagrams and overflows. The kernel may grant less (net.core.rmem_max).
  // 0: the kernel's default.
  int receive_buffer_bytes = 4 << 20;
};

struct OperatorLinkCounters {
  uint64_t datagrams_received = 0;  // all, valid or not
  uint64_t bytes_received = 0;      // authentic datagrams' bytes (reported back as feedback)
  DropCounters dropped;
  uint64_t datagrams_lost = 0;      // gaps in the robot's sequence numbers (reordered arrivals fill them)
  uint64_t hellos_sent = 0;
  uint64_t accepts_repeated = 0;    // Accepts after the first (answers to retransmitted Hellos)
  uint64_t gaze_sent = 0;
  uint64_t brick_acks_sent = 0;
  uint64_t send_failures = 0;
};

// One authentic datagram from the robot. payload stays valid until the next receive().
struct Received {
  MessageType type = MessageType::kChunk;
  std::span<const uint8_t> payload;
  uint64_t seq = 0;
  int64_t received_ns = 0;
};

class OperatorLink {
 public:
  // Says Hello to the robot at address ("HOST:PORT", "[V6]:PORT") and waits for
  // Accept. Errors: a refusal (with the robot's reason), a timeout, a bad address.
  static Result<std::unique_ptr<OperatorLink>> connect(std::string_view address, const OperatorLinkConfig& config);
  ~OperatorLink();  // says Bye while the session is up

  // Non-empty in insecure mode: the caller logs it loudly.
  const std::string& notice() const { return notice_; }

  // The session the robot granted.
  uint32_t mtuBytes() const { return mtu_bytes_; }
  uint64_t budgetBytesPerS() const { return budget_bytes_per_s_; }
  // False after a Bye (either way).
  bool sessionActive() const { return active_; }
  const Endpoint& robot() const { return robot_; }
  // The receive buffer the kernel granted (OperatorLinkConfig::receive_buffer_bytes).
  int receiveBufferBytes() const { return receive_buffer_bytes_; }

  // Sends a gaze sample. The link numbers it (sequence), stamps it if
  // operator_stamp_ns is 0, and fills the feedback except last_frame_id
  // (datagrams lost, bytes received, the robot-timestamp echo).
  [[nodiscard]] bool sendGaze(GazeSample sample);
  // Sends a brick acknowledgement (net/brick_cache.h's received() and evicted();
  // BrickAckMsg::partsThatFit says how many parts this session's MTU takes:
  // false when the message is larger).
  [[nodiscard]] bool sendBrickAck(const BrickAckMsg& ack);
  // The next authentic payload (chunk, frame summary, status, bye), waiting up to
  // timeout_ms; nullopt on timeout. Invalid datagrams are dropped and counted.
  std::optional<Received> receive(int timeout_ms);
  // A robot timestamp to echo in the next gaze (Accept and Status are noted already).
  void noteRobotStamp(int64_t robot_stamp_ns, int64_t received_ns);
  // Ends the session.
  void bye(std::string_view reason);

  // The newest Status received, if any.
  const std::optional<StatusReport>& lastStatus() const { return last_status_; }
  const OperatorLinkCounters& counters() const { return counters_; }
  int localPort() const { return socket_.localEndpoint().port(); }

  // Called with each gaze payload sent (plaintext, before sealing), on the
  // caller's thread: fovea-operator --record keeps them. A plain function and a
  // context, so a send allocates nothing.
  using SendTap = void (*)(void* context, MessageType type, std::span<const uint8_t> payload, int64_t now_ns);
  void setSendTap(SendTap tap, void* context) {
    send_tap_ = tap;
    send_tap_context_ = context;
  }

 private:
  OperatorLink() = default;
  // connect()'s steps, in order.
  Status configure(const OperatorLinkConfig& config);
  Status openSocket(std::string_view address, const OperatorLinkConfig& config);
  Status handshake(const HelloMsg& hello, const OperatorLinkConfig& config);
  std::optional<Status> awaitAnswer(const HelloMsg& hello, int64_t retry_at_ns);
  std::optional<Status> handleAnswer(std::span<const uint8_t> datagram, const HelloMsg& hello);
  std::optional<Received> handle(std::span<const uint8_t> datagram, int64_t now_ns);
  // The datagram's header, when it parses and comes from a robot; else the
  // drop is counted and false returned.
  bool readRobotHeader(std::span<const uint8_t> datagram, Header& header);
  void trackSequence(uint64_t seq);

  Key psk_;
  DirectionKeys handshake_;
  UdpSocket socket_;
  Endpoint robot_;
  int receive_buffer_bytes_ = -1;
  std::string notice_;
  SessionChannel channel_;
  bool active_ = false;
  uint32_t mtu_bytes_ = kDefaultMtu;
  uint64_t budget_bytes_per_s_ = 0;
  uint64_t gaze_seq_ = 0;
  uint64_t highest_robot_seq_ = 0;
  int64_t echo_robot_stamp_ns_ = 0;
  int64_t echo_received_ns_ = 0;
  std::optional<StatusReport> last_status_;
  MessageEncoder encoder_;
  OperatorLinkCounters counters_;
  std::array<uint8_t, kMaxMtu + 1> rx_buf_{};
  PlainBuffer plain_buf_;
  std::array<uint8_t, kMaxMtu> tx_buf_{};
  SendTap send_tap_ = nullptr;
  void* send_tap_context_ = nullptr;
};

}  // namespace fovea::net

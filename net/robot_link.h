// The robot's end of the link (docs/protocol.md, "Session", "Gaze", "Status"):
// binds the listen address, answers Hello with Accept or Refuse, serves one
// operator at a time, keeps the newest gaze sample, sends payloads to the
// operator. Single-threaded: call poll() from the loop that owns the link.
// No heap allocation per datagram.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include "core/result.h"
#include "net/messages.h"
#include "net/secure_channel.h"
#include "net/udp_socket.h"

namespace fovea::net {

struct RobotLinkConfig {
  std::string listen = "0.0.0.0:7000";  // port 0: any free port (tests)
  std::optional<Key> key;               // the pre-shared key (net/key.h)
  // Without a key the link refuses to start unless insecure is set; it then uses
  // the all-zero key and RobotLink::notice() says so: log it loudly.
  bool insecure = false;
  uint32_t max_mtu_bytes = kDefaultMtu;              // the Hello's MTU is clamped to this
  uint64_t max_budget_bytes_per_s = 12'500'000;      // 100 Mbit/s; the Hello's budget is clamped to this
  int64_t session_timeout_ns = 3'000'000'000;        // operator silent this long: session ends
};

struct RobotLinkCounters {
  uint64_t datagrams_received = 0;  // all, valid or not
  uint64_t bytes_received = 0;
  DropCounters dropped;
  uint64_t datagrams_sent = 0;
  uint64_t bytes_sent = 0;
  uint64_t send_failures = 0;       // kernel refused, or payload too large
  uint64_t hellos = 0;              // authentic Hello datagrams
  uint64_t sessions_accepted = 0;
  uint64_t refusals = 0;
  uint64_t sessions_ended_bye = 0;
  uint64_t sessions_timed_out = 0;
  uint64_t gaze_accepted = 0;       // became the newest sample
  uint64_t gaze_stale = 0;          // authentic but older than the newest sample
  uint64_t brick_acks = 0;          // BrickAck messages taken
  uint64_t brick_ack_overflow = 0;  // parts or evicted keys dropped: the caller did not take them in time
};

struct SessionInfo {
  ShortText operator_name;
  Endpoint peer;
  uint32_t mtu_bytes = kDefaultMtu;
  uint64_t budget_bytes_per_s = 0;
  int64_t started_ns = 0;
  // True once a datagram under the session key arrived: the peer holds the key
  // (a replayed Hello alone creates an unconfirmed session, see docs/protocol.md).
  bool confirmed = false;
};

struct ReceivedGaze {
  GazeSample sample;
  int64_t received_ns = 0;  // robot's CLOCK_MONOTONIC when it arrived
};

enum class SendResult : uint8_t { kSent, kNoSession, kTooLarge, kWrongType, kSocketError };

class RobotLink {
 public:
  static Result<std::unique_ptr<RobotLink>> create(const RobotLinkConfig& config);
  ~RobotLink();  // says Bye to the operator, if any

  // Non-empty in insecure mode: the caller logs it loudly.
  const std::string& notice() const { return notice_; }
  Endpoint localEndpoint() const { return socket_.localEndpoint(); }

  // Waits up to timeout_ms for datagrams, handles all that are waiting, and ends a
  // silent session. Returns the number of datagrams handled.
  int poll(int timeout_ms);

  bool hasSession() const { return session_.has_value(); }
  const SessionInfo* session() const { return session_ ? &session_->info : nullptr; }
  // Largest payload send() takes in this session (MTU - header - tag), 0 without one.
  std::size_t maxPayloadBytes() const;

  // The newest valid gaze of this session (by sequence number), if any.
  const std::optional<ReceivedGaze>& latestGaze() const { return latest_gaze_; }
  // Last round trip measured from a gaze's echo of a robot timestamp (-1: none).
  int64_t lastRttNs() const { return last_rtt_ns_; }

  // Brick parts the operator acknowledged and bricks it evicted (BrickAck),
  // since the last takeBrickAcks(): the caller takes them after each poll().
  // A new session starts empty. Fixed capacity (what overflows is counted).
  std::span<const BrickPartId> brickAcks() const { return {brick_acks_.data(), brick_ack_count_}; }
  std::span<const BrickKey> brickEvictions() const { return {brick_evictions_.data(), brick_eviction_count_}; }
  void takeBrickAcks() { brick_ack_count_ = brick_eviction_count_ = 0; }

  // Sends one datagram of a robot->operator type (chunk, frame summary, status).
  SendResult send(MessageType type, std::span<const uint8_t> payload);
  // Encodes and sends a Status (robot_stamp_ns is set to now; the operator echoes it).
  SendResult sendStatus(StatusReport report);
  // Ends the session with a Bye.
  void endSession(std::string_view reason);

  const RobotLinkCounters& counters() const { return counters_; }

  // Called with every gaze sample the session's operator sent that decoded
  // (stale ones included: as they came), its plaintext payload and when it
  // arrived; for recordings (firmware/session_recorder.h). In poll()'s thread;
  // must not block. Null: none.
  using ReceiveTap = void (*)(void* context, MessageType type, std::span<const uint8_t> payload, int64_t now_ns);
  void setReceiveTap(ReceiveTap tap, void* context) {
    receive_tap_ = tap;
    receive_tap_context_ = context;
  }

 private:
  struct Session {
    SessionInfo info;
    Nonce128 client_nonce;
    Nonce128 robot_nonce;
    SessionChannel channel;
    int64_t last_heard_ns = 0;
    int64_t robot_stamp_ns = 0;  // Accept's timestamp, sent again on retransmits
  };

  RobotLink(const RobotLinkConfig& config, const Key& psk, UdpSocket socket);
  void handleDatagram(std::span<const uint8_t> datagram, const Endpoint& from, int64_t now_ns);
  void handleHello(const Header& header, std::span<const uint8_t> datagram, const Endpoint& from, int64_t now_ns);
  // handleHello()'s steps.
  void handleRepeatedHello(const Header& header, std::span<const uint8_t> datagram, int64_t now_ns);
  bool openNewHello(const Header& header, std::span<const uint8_t> datagram, HelloMsg& hello);
  bool refuseUnservable(const HelloMsg& hello, const Endpoint& from);
  void startSession(const Header& header, const HelloMsg& hello, const Endpoint& from, int64_t now_ns);
  void handleSessionMessage(const Header& header, std::span<const uint8_t> datagram, const Endpoint& from,
                            int64_t now_ns);
  void sendAccept(int64_t now_ns);
  void refuse(const Endpoint& to, const Nonce128& client_nonce, RefuseReason reason, std::string_view text);
  bool sendDatagram(std::span<const uint8_t> datagram, const Endpoint& to);
  bool nonceSeenBefore(const Nonce128& nonce) const;
  void rememberNonce(const Nonce128& nonce);

  RobotLinkConfig config_;
  Key psk_;
  DirectionKeys handshake_;
  UdpSocket socket_;
  std::string notice_;
  std::optional<Session> session_;
  // Refusals go out in a robot epoch of their own (handshake key).
  SessionChannel refuse_channel_;
  std::optional<ReceivedGaze> latest_gaze_;
  int64_t last_rtt_ns_ = -1;
  // Client nonces of past sessions: a replayed Hello of one is dropped.
  static constexpr std::size_t kRememberedNonces = 64;
  std::array<Nonce128, kRememberedNonces> past_nonces_{};
  std::size_t past_nonce_count_ = 0;
  MessageEncoder encoder_;
  RobotLinkCounters counters_;
  ReceiveTap receive_tap_ = nullptr;
  void* receive_tap_context_ = nullptr;
  static constexpr std::size_t kBrickAckCapacity = 8192;
  static constexpr std::size_t kBrickEvictionCapacity = 1024;
  BrickAckMsg brick_ack_msg_;  // decode scratch
  std::array<BrickPartId, kBrickAckCapacity> brick_acks_{};
  std::size_t brick_ack_count_ = 0;
  std::array<BrickKey, kBrickEvictionCapacity> brick_evictions_{};
  std::size_t brick_eviction_count_ = 0;
  // One datagram in, its plaintext, one datagram out (preallocated).
  std::array<uint8_t, kMaxMtu + 1> rx_buf_{};
  PlainBuffer plain_buf_;
  std::array<uint8_t, kMaxMtu> tx_buf_{};
};

}  // namespace fovea::net

#include "net/robot_link.h"

#include <algorithm>
#include <cstdio>

#include "core/clock.h"

namespace fovea::net {

Result<std::unique_ptr<RobotLink>> RobotLink::create(const RobotLinkConfig& config) {
  using R = Result<std::unique_ptr<RobotLink>>;
  initCrypto();
  Key psk;
  std::string notice;
  if (config.key) {
    psk = *config.key;
  } else if (config.insecure) {
    psk = insecureKey();
    notice = kInsecureWarning;
  } else {
    return R(ErrorCode::kInvalidArgument,
             "robot link: no key configured: give a key file (--key-file FILE), or --insecure for a demo on a "
             "trusted host");
  }
  if (config.max_mtu_bytes < kMinMtu || config.max_mtu_bytes > kMaxMtu) {
    return R(ErrorCode::kInvalidArgument, "robot link: max MTU " + std::to_string(config.max_mtu_bytes) +
                                              " bytes is outside " + std::to_string(kMinMtu) + ".." +
                                              std::to_string(kMaxMtu));
  }
  if (config.session_timeout_ns <= 0 || config.max_budget_bytes_per_s == 0) {
    return R(ErrorCode::kInvalidArgument, "robot link: session timeout and budget must be positive");
  }
  Result<Endpoint> local = Endpoint::parse(config.listen);
  if (!local) return R(local.status().code(), "robot link: listen " + local.status().message());
  Result<UdpSocket> socket = UdpSocket::bind(local.value());
  if (!socket) return R(socket.status());
  std::unique_ptr<RobotLink> link(new RobotLink(config, psk, std::move(socket).value()));
  link->notice_ = std::move(notice);
  return link;
}

RobotLink::RobotLink(const RobotLinkConfig& config, const Key& psk, UdpSocket socket)
    : config_(config),
      psk_(psk),
      handshake_(handshakeKeys(psk, Role::kRobot)),
      socket_(std::move(socket)),
      refuse_channel_(handshake_, randomU64(), 0) {}

RobotLink::~RobotLink() {
  if (session_) endSession("robot shutting down");
}

std::size_t RobotLink::maxPayloadBytes() const {
  return session_ ? session_->info.mtu_bytes - kDatagramOverhead : 0;
}

int RobotLink::poll(int timeout_ms) {
  int handled = 0;
  if (socket_.waitReadable(timeout_ms)) {
    // Bounded so that a flood cannot keep the caller in here forever.
    constexpr int kMaxPerPoll = 1024;
    Endpoint from;
    while (handled < kMaxPerPoll) {
      const long n = socket_.receive(rx_buf_, from);
      if (n < 0) break;
      ++handled;
      ++counters_.datagrams_received;
      counters_.bytes_received += static_cast<uint64_t>(n);
      if (static_cast<std::size_t>(n) > kMaxMtu) {
        counters_.dropped.add(DropReason::kTooLong);
        continue;
      }
      handleDatagram({rx_buf_.data(), static_cast<std::size_t>(n)}, from, monotonicNs());
    }
  }
  if (session_ && monotonicNs() - session_->last_heard_ns > config_.session_timeout_ns) {
    ++counters_.sessions_timed_out;
    endSession("timeout");
  }
  return handled;
}

void RobotLink::handleDatagram(std::span<const uint8_t> datagram, const Endpoint& from, int64_t now_ns) {
  Header header;
  if (auto drop = parseHeader(datagram, header)) {
    counters_.dropped.add(*drop);
    return;
  }
  if (!isSentBy(header.type, Role::kOperator)) {
    counters_.dropped.add(DropReason::kWrongDirection);
    return;
  }
  if (header.type == MessageType::kHello) {
    handleHello(header, datagram, from, now_ns);
  } else {
    handleSessionMessage(header, datagram, from, now_ns);
  }
}

void RobotLink::handleHello(const Header& header, std::span<const uint8_t> datagram, const Endpoint& from,
                            int64_t now_ns) {
  if (session_ && from == session_->info.peer && header.epoch == session_->channel.rxEpoch()) {
    handleRepeatedHello(header, datagram, now_ns);
    return;
  }
  HelloMsg hello;
  if (!openNewHello(header, datagram, hello)) return;
  ++counters_.hellos;
  if (refuseUnservable(hello, from)) return;
  startSession(header, hello, from, now_ns);
  sendAccept(now_ns);
}

// The serving operator's Hello again (our Accept was lost): answer it again.
// A replay of the very same datagram fails the replay window.
void RobotLink::handleRepeatedHello(const Header& header, std::span<const uint8_t> datagram, int64_t now_ns) {
  std::span<const uint8_t> payload;
  HelloMsg hello;
  if (auto drop = session_->channel.open(header, datagram, plain_buf_, payload, &handshake_.rx)) {
    counters_.dropped.add(*drop);
    return;
  }
  if (auto drop = decode(payload, hello)) {
    counters_.dropped.add(*drop);
    return;
  }
  if (!(hello.client_nonce == session_->client_nonce)) {
    counters_.dropped.add(DropReason::kSemantic);
    return;
  }
  ++counters_.hellos;
  session_->last_heard_ns = now_ns;
  sendAccept(now_ns);
}

// A Hello for a new session, authenticated and decoded into hello; false when
// it was dropped (and counted).
bool RobotLink::openNewHello(const Header& header, std::span<const uint8_t> datagram, HelloMsg& hello) {
  if (header.seq == 0) {
    counters_.dropped.add(DropReason::kTooOld);
    return false;
  }
  auto opened = openSealed(handshake_.rx, datagram, plain_buf_);
  if (!opened) {
    counters_.dropped.add(DropReason::kAuth);
    return false;
  }
  if (auto drop = decode(*opened, hello)) {
    counters_.dropped.add(*drop);
    return false;
  }
  if (nonceSeenBefore(hello.client_nonce)) {
    // A recorded Hello of a session this robot already served (or is serving).
    counters_.dropped.add(DropReason::kReplay);
    return false;
  }
  return true;
}

// Refuses a Hello this robot cannot serve (another protocol version, an MTU
// below the minimum, a session already up); true when it did.
bool RobotLink::refuseUnservable(const HelloMsg& hello, const Endpoint& from) {
  char text[ShortText::kCapacity + 1];
  if (hello.protocol_version != kProtocolVersion) {
    std::snprintf(text, sizeof text, "version: robot speaks protocol %u, hello asks for %u",
                  static_cast<unsigned>(kProtocolVersion), static_cast<unsigned>(hello.protocol_version));
    refuse(from, hello.client_nonce, RefuseReason::kVersion, text);
    return true;
  }
  if (hello.mtu_bytes < kMinMtu) {
    std::snprintf(text, sizeof text, "bad request: MTU %u bytes is below the minimum %zu",
                  static_cast<unsigned>(hello.mtu_bytes), kMinMtu);
    refuse(from, hello.client_nonce, RefuseReason::kBadRequest, text);
    return true;
  }
  if (session_) {
    char peer[64];
    session_->info.peer.format(peer, sizeof peer);
    const std::string_view name = session_->info.operator_name.view();
    std::snprintf(text, sizeof text, "busy: serving %.*s at %s", static_cast<int>(name.size()), name.data(), peer);
    refuse(from, hello.client_nonce, RefuseReason::kBusy, text);
    return true;
  }
  return false;
}

// The session hello asked for, within this robot's limits (its Accept is sent next).
void RobotLink::startSession(const Header& header, const HelloMsg& hello, const Endpoint& from, int64_t now_ns) {
  Session s;
  s.client_nonce = hello.client_nonce;
  s.robot_nonce = randomNonce128();
  s.channel = SessionChannel(sessionKeys(psk_, Role::kRobot, s.client_nonce, s.robot_nonce), randomU64(),
                             header.epoch);
  s.channel.window().commit(header.seq);
  s.info.operator_name = hello.operator_name;
  s.info.peer = from;
  s.info.mtu_bytes = std::min<uint32_t>(hello.mtu_bytes, config_.max_mtu_bytes);
  s.info.budget_bytes_per_s = hello.budget_bytes_per_s == 0
                                  ? config_.max_budget_bytes_per_s
                                  : std::min(hello.budget_bytes_per_s, config_.max_budget_bytes_per_s);
  s.info.started_ns = now_ns;
  s.last_heard_ns = now_ns;
  session_ = s;
  rememberNonce(hello.client_nonce);
  latest_gaze_.reset();
  last_rtt_ns_ = -1;
  brick_ack_count_ = brick_eviction_count_ = 0;
  ++counters_.sessions_accepted;
}

void RobotLink::handleSessionMessage(const Header& header, std::span<const uint8_t> datagram, const Endpoint& from,
                                     int64_t now_ns) {
  if (!session_ || !(from == session_->info.peer)) {
    counters_.dropped.add(DropReason::kNoSession);
    return;
  }
  std::span<const uint8_t> payload;
  if (auto drop = session_->channel.open(header, datagram, plain_buf_, payload)) {
    counters_.dropped.add(*drop);
    return;
  }
  if (header.type == MessageType::kBye) {
    ByeMsg bye;
    if (auto drop = decode(payload, bye)) {
      counters_.dropped.add(*drop);
      return;
    }
    ++counters_.sessions_ended_bye;
    session_.reset();
    return;
  }
  if (header.type == MessageType::kBrickAck) {
    if (auto drop = decode(payload, brick_ack_msg_)) {
      counters_.dropped.add(*drop);
      return;
    }
    session_->last_heard_ns = now_ns;
    session_->info.confirmed = true;
    ++counters_.brick_acks;
    for (std::size_t i = 0; i < brick_ack_msg_.part_count; ++i) {
      if (brick_ack_count_ == brick_acks_.size()) {
        counters_.brick_ack_overflow += brick_ack_msg_.part_count - i;
        break;
      }
      brick_acks_[brick_ack_count_++] = brick_ack_msg_.parts[i];
    }
    for (std::size_t i = 0; i < brick_ack_msg_.evicted_count; ++i) {
      if (brick_eviction_count_ == brick_evictions_.size()) {
        counters_.brick_ack_overflow += brick_ack_msg_.evicted_count - i;
        break;
      }
      brick_evictions_[brick_eviction_count_++] = brick_ack_msg_.evicted[i];
    }
    return;
  }
  // Gaze (the only other operator type).
  GazeSample sample;
  if (auto drop = decode(payload, sample)) {
    counters_.dropped.add(*drop);
    return;
  }
  if (receive_tap_) receive_tap_(receive_tap_context_, header.type, payload, now_ns);
  session_->last_heard_ns = now_ns;
  session_->info.confirmed = true;
  if (latest_gaze_ && sample.sequence <= latest_gaze_->sample.sequence) {
    ++counters_.gaze_stale;
    return;
  }
  latest_gaze_ = ReceivedGaze{sample, now_ns};
  ++counters_.gaze_accepted;
  if (sample.feedback.echo_robot_stamp_ns > 0) {
    const int64_t rtt = now_ns - sample.feedback.echo_robot_stamp_ns - sample.feedback.echo_delay_ns;
    if (rtt >= 0) last_rtt_ns_ = rtt;
  }
}

void RobotLink::sendAccept(int64_t now_ns) {
  AcceptMsg accept;
  accept.client_nonce = session_->client_nonce;
  accept.robot_nonce = session_->robot_nonce;
  accept.mtu_bytes = session_->info.mtu_bytes;
  accept.budget_bytes_per_s = session_->info.budget_bytes_per_s;
  accept.robot_stamp_ns = now_ns;
  const auto d = session_->channel.seal(MessageType::kAccept, encoder_.encode(accept), tx_buf_, &handshake_.tx);
  if (!sendDatagram(d, session_->info.peer)) ++counters_.send_failures;
}

void RobotLink::refuse(const Endpoint& to, const Nonce128& client_nonce, RefuseReason reason, std::string_view text) {
  RefuseMsg msg;
  msg.client_nonce = client_nonce;
  msg.reason = reason;
  msg.text.assign(text);
  ++counters_.refusals;
  const auto d = refuse_channel_.seal(MessageType::kRefuse, encoder_.encode(msg), tx_buf_);
  if (!sendDatagram(d, to)) ++counters_.send_failures;
}

bool RobotLink::sendDatagram(std::span<const uint8_t> datagram, const Endpoint& to) {
  if (datagram.empty() || !socket_.sendTo(datagram, to)) return false;
  ++counters_.datagrams_sent;
  counters_.bytes_sent += datagram.size();
  return true;
}

SendResult RobotLink::send(MessageType type, std::span<const uint8_t> payload) {
  if (!isSentBy(type, Role::kRobot) || usesHandshakeKey(type) || type == MessageType::kBye) {
    return SendResult::kWrongType;
  }
  if (!session_) return SendResult::kNoSession;
  if (payload.size() > maxPayloadBytes()) {
    ++counters_.send_failures;
    return SendResult::kTooLarge;
  }
  const auto d = session_->channel.seal(type, payload, tx_buf_);
  if (!sendDatagram(d, session_->info.peer)) {
    ++counters_.send_failures;
    return SendResult::kSocketError;
  }
  return SendResult::kSent;
}

SendResult RobotLink::sendStatus(StatusReport report) {
  report.robot_stamp_ns = monotonicNs();
  return send(MessageType::kStatus, encoder_.encode(report));
}

void RobotLink::endSession(std::string_view reason) {
  if (!session_) return;
  ByeMsg bye;
  bye.reason.assign(reason);
  const auto d = session_->channel.seal(MessageType::kBye, encoder_.encode(bye), tx_buf_);
  if (!sendDatagram(d, session_->info.peer)) ++counters_.send_failures;
  session_.reset();
}

bool RobotLink::nonceSeenBefore(const Nonce128& nonce) const {
  const std::size_t n = std::min(past_nonce_count_, kRememberedNonces);
  for (std::size_t i = 0; i < n; ++i) {
    if (past_nonces_[i] == nonce) return true;
  }
  return false;
}

void RobotLink::rememberNonce(const Nonce128& nonce) {
  past_nonces_[past_nonce_count_ % kRememberedNonces] = nonce;
  ++past_nonce_count_;
}

}  // namespace fovea::net

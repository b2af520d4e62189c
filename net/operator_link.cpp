#include "net/operator_link.h"

#include <algorithm>

#include "core/clock.h"

namespace fovea::net {

Result<std::unique_ptr<OperatorLink>> OperatorLink::connect(std::string_view address,
                                                            const OperatorLinkConfig& config) {
  initCrypto();
  std::unique_ptr<OperatorLink> link(new OperatorLink());
  if (Status st = link->configure(config); !st) return st;
  if (Status st = link->openSocket(address, config); !st) return st;
  HelloMsg hello;
  hello.operator_name.assign(config.name);
  hello.budget_bytes_per_s = config.budget_bytes_per_s;
  hello.mtu_bytes = config.mtu_bytes;
  hello.client_nonce = randomNonce128();
  if (Status st = link->handshake(hello, config); !st) return st;
  return link;
}

// The key (or the insecure notice), after checking the configuration.
Status OperatorLink::configure(const OperatorLinkConfig& config) {
  if (config.key) {
    psk_ = *config.key;
  } else if (config.insecure) {
    psk_ = insecureKey();
    notice_ = kInsecureWarning;
  } else {
    return {ErrorCode::kInvalidArgument,
            "operator link: no key configured: give a key file (--key-file FILE), or --insecure for a demo on a "
            "trusted host"};
  }
  if (config.name.size() > kMaxOperatorNameBytes) {
    return {ErrorCode::kInvalidArgument, "operator link: name '" + config.name + "' is longer than " +
                                             std::to_string(kMaxOperatorNameBytes) + " bytes"};
  }
  if (config.mtu_bytes < kMinMtu || config.mtu_bytes > kMaxMtu) {
    return {ErrorCode::kInvalidArgument, "operator link: MTU " + std::to_string(config.mtu_bytes) +
                                             " bytes is outside " + std::to_string(kMinMtu) + ".." +
                                             std::to_string(kMaxMtu)};
  }
  return Status::ok();
}

// The socket towards the robot at address, and the handshake channel.
Status OperatorLink::openSocket(std::string_view address, const OperatorLinkConfig& config) {
  Result<Endpoint> robot = Endpoint::parse(address);
  if (!robot) return {robot.status().code(), "operator link: connect " + robot.status().message()};
  Result<UdpSocket> socket = UdpSocket::forPeer(robot.value());
  if (!socket) return socket.status();
  robot_ = robot.value();
  socket_ = std::move(socket).value();
  receive_buffer_bytes_ = socket_.setReceiveBuffer(config.receive_buffer_bytes);
  handshake_ = handshakeKeys(psk_, Role::kOperator);
  channel_ = SessionChannel(handshake_, randomU64(), 0);
  return Status::ok();
}

// Says Hello, again with backoff, until the robot accepts it (the session is up)
// or refuses it, or the connect timeout passes (kUnavailable both).
Status OperatorLink::handshake(const HelloMsg& hello, const OperatorLinkConfig& config) {
  const int64_t start_ns = monotonicNs();
  const int64_t deadline_ns = start_ns + int64_t{config.connect_timeout_ms} * 1'000'000;
  int64_t retry_ns = int64_t{std::max(config.first_retry_ms, 1)} * 1'000'000;
  for (;;) {
    const int64_t now_ns = monotonicNs();
    if (now_ns >= deadline_ns) break;
    const auto d = channel_.seal(MessageType::kHello, encoder_.encode(hello), tx_buf_);
    if (socket_.sendTo(d, robot_)) {
      ++counters_.hellos_sent;
    } else {
      ++counters_.send_failures;
    }
    const int64_t retry_at_ns = std::min(now_ns + retry_ns, deadline_ns);
    retry_ns = std::min<int64_t>(retry_ns * 2, 1'000'000'000);
    if (std::optional<Status> answer = awaitAnswer(hello, retry_at_ns)) return *answer;
  }
  return {ErrorCode::kUnavailable, "no answer from a robot at " + robot_.toString() + " within " +
                                       std::to_string(config.connect_timeout_ms) +
                                       " ms (is fovead listening there, with the same key?)"};
}

// Receives until retry_at_ns: the answer to hello (ok: accepted; an error: refused),
// or nullopt when none came. Every other datagram is dropped and counted.
std::optional<Status> OperatorLink::awaitAnswer(const HelloMsg& hello, int64_t retry_at_ns) {
  for (;;) {
    const int64_t wait_ns = retry_at_ns - monotonicNs();
    if (wait_ns <= 0 || !socket_.waitReadable(static_cast<int>((wait_ns + 999'999) / 1'000'000))) break;
    Endpoint from;
    long n = -1;
    while (monotonicNs() < retry_at_ns && (n = socket_.receive(rx_buf_, from)) >= 0) {
      ++counters_.datagrams_received;
      if (static_cast<std::size_t>(n) > kMaxMtu) {
        counters_.dropped.add(DropReason::kTooLong);
        continue;
      }
      if (std::optional<Status> answer = handleAnswer({rx_buf_.data(), static_cast<std::size_t>(n)}, hello)) {
        return answer;
      }
    }
  }
  return std::nullopt;
}

// One datagram while waiting for the robot's answer: an Accept of hello starts
// the session (ok), a Refuse of it is the error; nullopt for anything else
// (dropped and counted).
std::optional<Status> OperatorLink::handleAnswer(std::span<const uint8_t> datagram, const HelloMsg& hello) {
  Header header;
  if (!readRobotHeader(datagram, header)) return std::nullopt;
  if (header.type != MessageType::kAccept && header.type != MessageType::kRefuse) {
    counters_.dropped.add(DropReason::kNoSession);
    return std::nullopt;
  }
  auto payload = openSealed(handshake_.rx, datagram, plain_buf_);
  if (!payload) {
    counters_.dropped.add(DropReason::kAuth);
    return std::nullopt;
  }
  if (header.type == MessageType::kRefuse) {
    RefuseMsg refuse;
    if (auto drop = decode(*payload, refuse)) {
      counters_.dropped.add(*drop);
      return std::nullopt;
    }
    if (!(refuse.client_nonce == hello.client_nonce)) {
      counters_.dropped.add(DropReason::kSemantic);  // an old refusal, not ours
      return std::nullopt;
    }
    return Status(ErrorCode::kUnavailable, "robot at " + robot_.toString() + " refused (" +
                                               refuseReasonName(refuse.reason) + "): " +
                                               std::string(refuse.text.view()));
  }
  AcceptMsg accept;
  if (auto drop = decode(*payload, accept)) {
    counters_.dropped.add(*drop);
    return std::nullopt;
  }
  if (!(accept.client_nonce == hello.client_nonce)) {
    counters_.dropped.add(DropReason::kSemantic);  // an old Accept, not ours
    return std::nullopt;
  }
  counters_.bytes_received += datagram.size();
  channel_.rekey(sessionKeys(psk_, Role::kOperator, hello.client_nonce, accept.robot_nonce), header.epoch);
  channel_.window().commit(header.seq);
  highest_robot_seq_ = header.seq;
  mtu_bytes_ = accept.mtu_bytes;
  budget_bytes_per_s_ = accept.budget_bytes_per_s;
  noteRobotStamp(accept.robot_stamp_ns, monotonicNs());
  active_ = true;
  return Status::ok();
}

OperatorLink::~OperatorLink() {
  if (active_) bye("operator leaving");
}

bool OperatorLink::sendGaze(GazeSample sample) {
  if (!active_) return false;
  const int64_t now_ns = monotonicNs();
  sample.sequence = ++gaze_seq_;
  if (sample.operator_stamp_ns == 0) sample.operator_stamp_ns = now_ns;
  sample.feedback.datagrams_lost = counters_.datagrams_lost;
  sample.feedback.bytes_received = counters_.bytes_received;
  sample.feedback.echo_robot_stamp_ns = echo_robot_stamp_ns_;
  sample.feedback.echo_delay_ns = echo_robot_stamp_ns_ != 0 ? now_ns - echo_received_ns_ : 0;
  const std::span<const uint8_t> payload = encoder_.encode(sample);
  const auto d = channel_.seal(MessageType::kGaze, payload, tx_buf_);
  if (d.empty() || !socket_.sendTo(d, robot_)) {
    ++counters_.send_failures;
    return false;
  }
  ++counters_.gaze_sent;
  if (send_tap_) send_tap_(send_tap_context_, MessageType::kGaze, payload, now_ns);
  return true;
}

bool OperatorLink::sendBrickAck(const BrickAckMsg& ack) {
  if (!active_) return false;
  const std::span<const uint8_t> payload = encoder_.encode(ack);
  if (payload.size() + kDatagramOverhead > mtu_bytes_) {
    ++counters_.send_failures;
    return false;
  }
  const auto d = channel_.seal(MessageType::kBrickAck, payload, tx_buf_);
  if (d.empty() || !socket_.sendTo(d, robot_)) {
    ++counters_.send_failures;
    return false;
  }
  ++counters_.brick_acks_sent;
  return true;
}

void OperatorLink::noteRobotStamp(int64_t robot_stamp_ns, int64_t received_ns) {
  echo_robot_stamp_ns_ = robot_stamp_ns;
  echo_received_ns_ = received_ns;
}

void OperatorLink::bye(std::string_view reason) {
  if (!active_) return;
  ByeMsg msg;
  msg.reason.assign(reason);
  const auto d = channel_.seal(MessageType::kBye, encoder_.encode(msg), tx_buf_);
  if (d.empty() || !socket_.sendTo(d, robot_)) ++counters_.send_failures;
  active_ = false;
}

std::optional<Received> OperatorLink::receive(int timeout_ms) {
  const int64_t deadline_ns = monotonicNs() + int64_t{std::max(timeout_ms, 0)} * 1'000'000;
  for (;;) {
    Endpoint from;
    long n = -1;
    while ((n = socket_.receive(rx_buf_, from)) >= 0) {
      ++counters_.datagrams_received;
      if (static_cast<std::size_t>(n) > kMaxMtu) {
        counters_.dropped.add(DropReason::kTooLong);
        continue;
      }
      const int64_t now_ns = monotonicNs();
      if (auto r = handle({rx_buf_.data(), static_cast<std::size_t>(n)}, now_ns)) return r;
      if (now_ns >= deadline_ns) return std::nullopt;  // a flood does not hold the caller past its timeout
    }
    const int64_t wait_ns = deadline_ns - monotonicNs();
    if (wait_ns <= 0 || !socket_.waitReadable(static_cast<int>((wait_ns + 999'999) / 1'000'000))) return std::nullopt;
  }
}

bool OperatorLink::readRobotHeader(std::span<const uint8_t> datagram, Header& header) {
  if (auto drop = parseHeader(datagram, header)) {
    counters_.dropped.add(*drop);
    return false;
  }
  if (!isSentBy(header.type, Role::kRobot)) {
    counters_.dropped.add(DropReason::kWrongDirection);
    return false;
  }
  return true;
}

std::optional<Received> OperatorLink::handle(std::span<const uint8_t> datagram, int64_t now_ns) {
  Header header;
  if (!readRobotHeader(datagram, header)) return std::nullopt;
  if (!active_) {
    counters_.dropped.add(DropReason::kNoSession);
    return std::nullopt;
  }
  const bool handshake = usesHandshakeKey(header.type);
  std::span<const uint8_t> payload;
  if (auto drop = channel_.open(header, datagram, plain_buf_, payload, handshake ? &handshake_.rx : nullptr)) {
    counters_.dropped.add(*drop);
    return std::nullopt;
  }
  counters_.bytes_received += datagram.size();
  trackSequence(header.seq);
  if (handshake) {
    // A second Accept (the robot answered a retransmitted Hello): nothing new.
    ++counters_.accepts_repeated;
    return std::nullopt;
  }
  if (header.type == MessageType::kStatus) {
    StatusReport status;
    if (auto drop = decode(payload, status)) {
      counters_.dropped.add(*drop);
      return std::nullopt;
    }
    last_status_ = status;
    noteRobotStamp(status.robot_stamp_ns, now_ns);
  } else if (header.type == MessageType::kBye) {
    ByeMsg bye;
    if (auto drop = decode(payload, bye)) {
      counters_.dropped.add(*drop);
      return std::nullopt;
    }
    active_ = false;
  }
  return Received{header.type, payload, header.seq, now_ns};
}

void OperatorLink::trackSequence(uint64_t seq) {
  if (seq > highest_robot_seq_) {
    counters_.datagrams_lost += seq - highest_robot_seq_ - 1;
    highest_robot_seq_ = seq;
  } else if (counters_.datagrams_lost > 0) {
    --counters_.datagrams_lost;  // a reordered datagram fills a gap counted as lost
  }
}

}  // namespace fovea::net

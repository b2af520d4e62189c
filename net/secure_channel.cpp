#include "net/secure_channel.h"

#include <sodium.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>

namespace fovea::net {
namespace {

static_assert(crypto_aead_xchacha20poly1305_ietf_KEYBYTES == kKeyBytes);
static_assert(crypto_aead_xchacha20poly1305_ietf_ABYTES == kTagBytes);
static_assert(crypto_aead_xchacha20poly1305_ietf_NPUBBYTES == 24);

void putLe64(uint8_t* p, uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}
uint64_t getLe64(const uint8_t* p) {
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= uint64_t{p[i]} << (8 * i);
  return v;
}

void buildNonce(uint64_t epoch, uint64_t seq, uint8_t nonce[24]) {
  putLe64(nonce, epoch);
  putLe64(nonce + 8, seq);
  std::memset(nonce + 16, 0, 8);
}

// Keyed BLAKE2b of a label and a direction byte (and the session's nonces).
Key deriveKey(const Key& psk, const char* label, uint8_t direction, const Nonce128* client,
              const Nonce128* robot) {
  initCrypto();
  crypto_generichash_state state;
  crypto_generichash_init(&state, psk.bytes.data(), psk.bytes.size(), kKeyBytes);
  crypto_generichash_update(&state, reinterpret_cast<const uint8_t*>(label), std::strlen(label) + 1);
  crypto_generichash_update(&state, &direction, 1);
  uint8_t nonces[32];
  if (client != nullptr && robot != nullptr) {
    putLe64(nonces, client->lo);
    putLe64(nonces + 8, client->hi);
    putLe64(nonces + 16, robot->lo);
    putLe64(nonces + 24, robot->hi);
    crypto_generichash_update(&state, nonces, sizeof nonces);
  }
  Key key;
  crypto_generichash_final(&state, key.bytes.data(), key.bytes.size());
  sodium_memzero(&state, sizeof state);
  return key;
}

constexpr uint8_t kOperatorToRobot = 1;
constexpr uint8_t kRobotToOperator = 2;

}  // namespace

void initCrypto() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (sodium_init() < 0) {
      std::fprintf(stderr, "fovea: libsodium failed to initialise\n");
      std::abort();
    }
  });
}

bool isKnownType(uint8_t type) {
  return type >= static_cast<uint8_t>(MessageType::kHello) && type <= static_cast<uint8_t>(MessageType::kBrickAck);
}

bool isSentBy(MessageType type, Role role) {
  switch (type) {
    case MessageType::kHello:
    case MessageType::kGaze:
    case MessageType::kBrickAck: return role == Role::kOperator;
    case MessageType::kAccept:
    case MessageType::kRefuse:
    case MessageType::kChunk:
    case MessageType::kFrameSummary:
    case MessageType::kStatus:
    case MessageType::kBrickChunk: return role == Role::kRobot;
    case MessageType::kBye: return true;
  }
  return false;
}

bool usesHandshakeKey(MessageType type) {
  return type == MessageType::kHello || type == MessageType::kAccept || type == MessageType::kRefuse;
}

const char* messageTypeName(MessageType type) {
  switch (type) {
    case MessageType::kHello: return "hello";
    case MessageType::kAccept: return "accept";
    case MessageType::kRefuse: return "refuse";
    case MessageType::kBye: return "bye";
    case MessageType::kGaze: return "gaze";
    case MessageType::kChunk: return "chunk";
    case MessageType::kFrameSummary: return "frame-summary";
    case MessageType::kStatus: return "status";
    case MessageType::kBrickChunk: return "brick-chunk";
    case MessageType::kBrickAck: return "brick-ack";
  }
  return "unknown";
}

const char* dropReasonName(DropReason reason) {
  switch (reason) {
    case DropReason::kTooShort: return "too-short";
    case DropReason::kTooLong: return "too-long";
    case DropReason::kBadMagic: return "bad-magic";
    case DropReason::kBadVersion: return "bad-version";
    case DropReason::kBadType: return "bad-type";
    case DropReason::kWrongDirection: return "wrong-direction";
    case DropReason::kNoSession: return "no-session";
    case DropReason::kReplay: return "replay";
    case DropReason::kTooOld: return "too-old";
    case DropReason::kAuth: return "auth";
    case DropReason::kVerify: return "verify";
    case DropReason::kSemantic: return "semantic";
  }
  return "unknown";
}

uint64_t DropCounters::total() const {
  uint64_t sum = 0;
  for (uint64_t n : by_reason) sum += n;
  return sum;
}

std::optional<DropReason> parseHeader(std::span<const uint8_t> datagram, Header& header) {
  if (datagram.size() < kDatagramOverhead) return DropReason::kTooShort;
  if (datagram.size() > kMaxMtu) return DropReason::kTooLong;
  if (datagram[0] != 'F' || datagram[1] != 'V') return DropReason::kBadMagic;
  if (datagram[2] != kProtocolVersion) return DropReason::kBadVersion;
  if (!isKnownType(datagram[3])) return DropReason::kBadType;
  header.type = static_cast<MessageType>(datagram[3]);
  header.epoch = getLe64(datagram.data() + 4);
  header.seq = getLe64(datagram.data() + 12);
  return std::nullopt;
}

std::span<const uint8_t> seal(const Key& key, const Header& header, std::span<const uint8_t> payload,
                              std::span<uint8_t> out) {
  const std::size_t total = payload.size() + kDatagramOverhead;
  if (total > out.size() || total > kMaxMtu) return {};
  uint8_t* p = out.data();
  p[0] = 'F';
  p[1] = 'V';
  p[2] = kProtocolVersion;
  p[3] = static_cast<uint8_t>(header.type);
  putLe64(p + 4, header.epoch);
  putLe64(p + 12, header.seq);
  uint8_t nonce[24];
  buildNonce(header.epoch, header.seq, nonce);
  unsigned long long written = 0;
  crypto_aead_xchacha20poly1305_ietf_encrypt(p + kHeaderBytes, &written, payload.data(), payload.size(), p,
                                             kHeaderBytes, nullptr, nonce, key.bytes.data());
  return {out.data(), kHeaderBytes + static_cast<std::size_t>(written)};
}

std::optional<std::span<const uint8_t>> openSealed(const Key& key, std::span<const uint8_t> datagram,
                                                   PlainBuffer& plain_buffer) {
  if (datagram.size() < kDatagramOverhead) return std::nullopt;
  const std::size_t payload_bytes = datagram.size() - kDatagramOverhead;
  const std::span<uint8_t> plain(plain_buffer.bytes);
  if (plain.size() < payload_bytes) return std::nullopt;
  uint8_t nonce[24];
  buildNonce(getLe64(datagram.data() + 4), getLe64(datagram.data() + 12), nonce);
  unsigned long long n = 0;
  if (crypto_aead_xchacha20poly1305_ietf_decrypt(plain.data(), &n, nullptr, datagram.data() + kHeaderBytes,
                                                 datagram.size() - kHeaderBytes, datagram.data(), kHeaderBytes,
                                                 nonce, key.bytes.data()) != 0) {
    return std::nullopt;
  }
  return std::span<const uint8_t>(plain.data(), static_cast<std::size_t>(n));
}

Nonce128 randomNonce128() {
  initCrypto();
  Nonce128 n;
  randombytes_buf(&n.lo, sizeof n.lo);
  randombytes_buf(&n.hi, sizeof n.hi);
  return n;
}

uint64_t randomU64() {
  initCrypto();
  uint64_t v = 0;
  while (v == 0) randombytes_buf(&v, sizeof v);
  return v;
}

DirectionKeys handshakeKeys(const Key& psk, Role self) {
  const Key o2r = deriveKey(psk, "fovea handshake", kOperatorToRobot, nullptr, nullptr);
  const Key r2o = deriveKey(psk, "fovea handshake", kRobotToOperator, nullptr, nullptr);
  return self == Role::kOperator ? DirectionKeys{o2r, r2o} : DirectionKeys{r2o, o2r};
}

DirectionKeys sessionKeys(const Key& psk, Role self, const Nonce128& client_nonce, const Nonce128& robot_nonce) {
  const Key o2r = deriveKey(psk, "fovea session", kOperatorToRobot, &client_nonce, &robot_nonce);
  const Key r2o = deriveKey(psk, "fovea session", kRobotToOperator, &client_nonce, &robot_nonce);
  return self == Role::kOperator ? DirectionKeys{o2r, r2o} : DirectionKeys{r2o, o2r};
}

std::span<const uint8_t> SessionChannel::seal(MessageType type, std::span<const uint8_t> payload,
                                              std::span<uint8_t> out, const Key* key_override) {
  const Header header{type, tx_epoch_, tx_seq_ + 1};
  std::span<const uint8_t> d = net::seal(key_override ? *key_override : keys_.tx, header, payload, out);
  if (!d.empty()) ++tx_seq_;  // a sequence number (nonce) is never used twice
  return d;
}

std::optional<DropReason> SessionChannel::open(const Header& header, std::span<const uint8_t> datagram,
                                               PlainBuffer& plain, std::span<const uint8_t>& payload,
                                               const Key* key_override) {
  if (header.epoch != rx_epoch_) return DropReason::kNoSession;
  switch (window_.check(header.seq)) {
    case ReplayWindow::Verdict::kFresh: break;
    case ReplayWindow::Verdict::kDuplicate: return DropReason::kReplay;
    case ReplayWindow::Verdict::kTooOld: return DropReason::kTooOld;
  }
  auto opened = openSealed(key_override ? *key_override : keys_.rx, datagram, plain);
  if (!opened) return DropReason::kAuth;
  window_.commit(header.seq);
  payload = *opened;
  return std::nullopt;
}

}  // namespace fovea::net

// UDP endpoints and nonblocking sockets, IPv4 and IPv6.
//
// Addresses: "127.0.0.1:7000", "[::1]:7000", "localhost:7000", "0.0.0.0:7000",
// "[::]:7000" (port 0: any free port, see UdpSocket::localEndpoint()).
#pragma once

#include <sys/socket.h>

#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "core/result.h"

namespace fovea::net {

class Endpoint {
 public:
  Endpoint() = default;
  Endpoint(const sockaddr* addr, socklen_t len);
  // Resolves "HOST:PORT" or "[V6]:PORT" (numeric or a name such as localhost).
  static Result<Endpoint> parse(std::string_view text);

  int family() const { return storage_.ss_family; }
  uint16_t port() const;
  const sockaddr* addr() const { return reinterpret_cast<const sockaddr*>(&storage_); }
  socklen_t size() const { return len_; }
  bool valid() const { return len_ != 0; }
  // "127.0.0.1:7000", "[::1]:7000".
  std::string toString() const;
  // Writes toString() into buf without allocating; returns the characters written.
  std::size_t format(char* buf, std::size_t size) const;
  bool operator==(const Endpoint& other) const;

 private:
  sockaddr_storage storage_{};
  socklen_t len_ = 0;
};

class UdpSocket {
 public:
  UdpSocket() = default;
  ~UdpSocket();
  UdpSocket(UdpSocket&& other) noexcept;
  UdpSocket& operator=(UdpSocket&& other) noexcept;
  UdpSocket(const UdpSocket&) = delete;
  UdpSocket& operator=(const UdpSocket&) = delete;

  // A socket bound to the endpoint; the error names the address.
  static Result<UdpSocket> bind(const Endpoint& local);
  // A socket of the peer's family bound to an ephemeral port.
  static Result<UdpSocket> forPeer(const Endpoint& peer);

  // Waits up to timeout_ms (0: do not wait) for a datagram; false on timeout.
  bool waitReadable(int timeout_ms) const;
  // Receives one datagram into buf. Returns its full length (which may exceed
  // buf.size(): the datagram was truncated), or -1 when none is waiting.
  long receive(std::span<uint8_t> buf, Endpoint& from);
  // Sends one datagram; false when the kernel refused it (counted by the caller).
  [[nodiscard]] bool sendTo(std::span<const uint8_t> datagram, const Endpoint& to);

  Endpoint localEndpoint() const;
  int fd() const { return fd_; }
  // Asks the kernel for a receive buffer of `bytes` (SO_RCVBUF, which it caps at
  // net.core.rmem_max; then SO_RCVBUFFORCE, which only a privileged process may
  // use past that) and returns what it granted, in bytes of datagrams (the kernel
  // reports twice that, with its bookkeeping), or -1 on error. bytes <= 0 keeps the
  // kernel's default (and returns it).
  int setReceiveBuffer(int bytes);

 private:
  explicit UdpSocket(int fd) : fd_(fd) {}
  int fd_ = -1;
};

}  // namespace fovea::net

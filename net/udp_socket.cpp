#include "net/udp_socket.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>

namespace fovea::net {

Endpoint::Endpoint(const sockaddr* addr, socklen_t len) {
  if (len > sizeof storage_) len = sizeof storage_;
  std::memcpy(&storage_, addr, len);
  len_ = len;
}

Result<Endpoint> Endpoint::parse(std::string_view text) {
  std::string host;
  std::string_view port;
  if (!text.empty() && text.front() == '[') {
    const auto close = text.find(']');
    if (close == std::string_view::npos || close + 1 >= text.size() || text[close + 1] != ':') {
      return Result<Endpoint>(ErrorCode::kInvalidArgument,
                              "address '" + std::string(text) + "': expected [IPV6]:PORT");
    }
    host = std::string(text.substr(1, close - 1));
    port = text.substr(close + 2);
  } else {
    const auto colon = text.rfind(':');
    if (colon == std::string_view::npos || text.find(':') != colon) {
      return Result<Endpoint>(ErrorCode::kInvalidArgument,
                              "address '" + std::string(text) + "': expected HOST:PORT (IPv6 as [::1]:PORT)");
    }
    host = std::string(text.substr(0, colon));
    port = text.substr(colon + 1);
  }
  unsigned long port_value = 0;
  if (port.empty() || port.size() > 5) {
    return Result<Endpoint>(ErrorCode::kInvalidArgument, "address '" + std::string(text) + "': bad port");
  }
  for (char c : port) {
    if (c < '0' || c > '9') {
      return Result<Endpoint>(ErrorCode::kInvalidArgument, "address '" + std::string(text) + "': bad port");
    }
    port_value = port_value * 10 + static_cast<unsigned long>(c - '0');
  }
  if (port_value > 65535 || host.empty()) {
    return Result<Endpoint>(ErrorCode::kInvalidArgument,
                            "address '" + std::string(text) + "': bad host or port (0..65535)");
  }
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  hints.ai_flags = AI_NUMERICSERV;
  addrinfo* found = nullptr;
  const std::string port_text = std::to_string(port_value);
  const int rc = ::getaddrinfo(host.c_str(), port_text.c_str(), &hints, &found);
  if (rc != 0 || found == nullptr) {
    return Result<Endpoint>(ErrorCode::kNotFound,
                            "address '" + std::string(text) + "': cannot resolve '" + host + "': " + gai_strerror(rc));
  }
  // Prefer IPv4 for names with both (localhost), as the other side most often binds it.
  const addrinfo* pick = found;
  for (const addrinfo* a = found; a != nullptr; a = a->ai_next) {
    if (a->ai_family == AF_INET) {
      pick = a;
      break;
    }
  }
  Endpoint e(pick->ai_addr, pick->ai_addrlen);
  ::freeaddrinfo(found);
  return e;
}

uint16_t Endpoint::port() const {
  if (storage_.ss_family == AF_INET) return ntohs(reinterpret_cast<const sockaddr_in*>(&storage_)->sin_port);
  if (storage_.ss_family == AF_INET6) return ntohs(reinterpret_cast<const sockaddr_in6*>(&storage_)->sin6_port);
  return 0;
}

std::size_t Endpoint::format(char* buf, std::size_t size) const {
  char host[INET6_ADDRSTRLEN] = "?";
  int n = 0;
  if (storage_.ss_family == AF_INET) {
    ::inet_ntop(AF_INET, &reinterpret_cast<const sockaddr_in*>(&storage_)->sin_addr, host, sizeof host);
    n = std::snprintf(buf, size, "%s:%u", host, static_cast<unsigned>(port()));
  } else if (storage_.ss_family == AF_INET6) {
    ::inet_ntop(AF_INET6, &reinterpret_cast<const sockaddr_in6*>(&storage_)->sin6_addr, host, sizeof host);
    n = std::snprintf(buf, size, "[%s]:%u", host, static_cast<unsigned>(port()));
  } else {
    n = std::snprintf(buf, size, "(none)");
  }
  if (n < 0) return 0;
  return static_cast<std::size_t>(n) < size ? static_cast<std::size_t>(n) : size - 1;
}

std::string Endpoint::toString() const {
  char buf[INET6_ADDRSTRLEN + 16];
  return std::string(buf, format(buf, sizeof buf));
}

bool Endpoint::operator==(const Endpoint& other) const {
  if (family() != other.family()) return false;
  if (family() == AF_INET) {
    const auto* a = reinterpret_cast<const sockaddr_in*>(&storage_);
    const auto* b = reinterpret_cast<const sockaddr_in*>(&other.storage_);
    return a->sin_port == b->sin_port && a->sin_addr.s_addr == b->sin_addr.s_addr;
  }
  if (family() == AF_INET6) {
    const auto* a = reinterpret_cast<const sockaddr_in6*>(&storage_);
    const auto* b = reinterpret_cast<const sockaddr_in6*>(&other.storage_);
    return a->sin6_port == b->sin6_port && std::memcmp(&a->sin6_addr, &b->sin6_addr, sizeof a->sin6_addr) == 0;
  }
  return len_ == other.len_;
}

UdpSocket::~UdpSocket() {
  if (fd_ >= 0) ::close(fd_);
}

UdpSocket::UdpSocket(UdpSocket&& other) noexcept : fd_(other.fd_) { other.fd_ = -1; }

UdpSocket& UdpSocket::operator=(UdpSocket&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = other.fd_;
    other.fd_ = -1;
  }
  return *this;
}

Result<UdpSocket> UdpSocket::bind(const Endpoint& local) {
  const int fd = ::socket(local.family(), SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    return Result<UdpSocket>(ErrorCode::kUnavailable,
                             "udp socket for " + local.toString() + ": " + std::strerror(errno));
  }
  UdpSocket socket(fd);
  if (local.family() == AF_INET6) {
    const int only = 0;  // "[::]:PORT" also takes IPv4 where the host allows it
    (void)::setsockopt(fd, IPPROTO_IPV6, IPV6_V6ONLY, &only, sizeof only);
  }
  if (::bind(fd, local.addr(), local.size()) != 0) {
    return Result<UdpSocket>(ErrorCode::kUnavailable,
                             "cannot bind udp " + local.toString() + ": " + std::strerror(errno));
  }
  return socket;
}

int UdpSocket::setReceiveBuffer(int bytes) {
  const auto granted = [this] {
    int size = 0;
    socklen_t len = sizeof size;
    return ::getsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &size, &len) == 0 ? size / 2 : -1;
  };
  if (bytes <= 0) return granted();  // the kernel's default stays
  (void)::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &bytes, sizeof bytes);
  if (granted() < bytes) (void)::setsockopt(fd_, SOL_SOCKET, SO_RCVBUFFORCE, &bytes, sizeof bytes);
  return granted();
}

Result<UdpSocket> UdpSocket::forPeer(const Endpoint& peer) {
  if (peer.family() == AF_INET6) {
    sockaddr_in6 any{};
    any.sin6_family = AF_INET6;
    any.sin6_addr = in6addr_any;
    return bind(Endpoint(reinterpret_cast<const sockaddr*>(&any), sizeof any));
  }
  sockaddr_in any{};
  any.sin_family = AF_INET;
  any.sin_addr.s_addr = htonl(INADDR_ANY);
  return bind(Endpoint(reinterpret_cast<const sockaddr*>(&any), sizeof any));
}

bool UdpSocket::waitReadable(int timeout_ms) const {
  pollfd p{fd_, POLLIN, 0};
  for (;;) {
    const int rc = ::poll(&p, 1, timeout_ms < 0 ? 0 : timeout_ms);
    if (rc < 0 && errno == EINTR) continue;
    return rc > 0 && (p.revents & POLLIN) != 0;
  }
}

long UdpSocket::receive(std::span<uint8_t> buf, Endpoint& from) {
  sockaddr_storage addr{};
  socklen_t len = sizeof addr;
  for (;;) {
    const ssize_t n = ::recvfrom(fd_, buf.data(), buf.size(), MSG_TRUNC, reinterpret_cast<sockaddr*>(&addr), &len);
    if (n < 0) {
      if (errno == EINTR) continue;
      return -1;  // EAGAIN, or an ICMP error reported on the socket: nothing to read
    }
    from = Endpoint(reinterpret_cast<const sockaddr*>(&addr), len);
    return static_cast<long>(n);
  }
}

bool UdpSocket::sendTo(std::span<const uint8_t> datagram, const Endpoint& to) {
  for (;;) {
    const ssize_t n = ::sendto(fd_, datagram.data(), datagram.size(), 0, to.addr(), to.size());
    if (n < 0 && errno == EINTR) continue;
    return n == static_cast<ssize_t>(datagram.size());
  }
}

Endpoint UdpSocket::localEndpoint() const {
  sockaddr_storage addr{};
  socklen_t len = sizeof addr;
  if (::getsockname(fd_, reinterpret_cast<sockaddr*>(&addr), &len) != 0) return {};
  return Endpoint(reinterpret_cast<const sockaddr*>(&addr), len);
}

}  // namespace fovea::net

#include "net/key.h"

#include <fcntl.h>
#include <sodium.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "net/secure_channel.h"

namespace fovea::net {
namespace {

int hexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v'; }

}  // namespace

Result<Key> parseKeyHex(std::string_view text) {
  while (!text.empty() && isSpace(text.front())) text.remove_prefix(1);
  while (!text.empty() && isSpace(text.back())) text.remove_suffix(1);
  if (text.size() != 2 * kKeyBytes) {
    return Result<Key>(ErrorCode::kParseError,
                       "key: expected 64 hex characters (32 bytes), found " + std::to_string(text.size()) +
                           " characters (make one with generateKey/fovea-keygen)");
  }
  Key key;
  for (std::size_t i = 0; i < kKeyBytes; ++i) {
    const int hi = hexValue(text[2 * i]);
    const int lo = hexValue(text[2 * i + 1]);
    if (hi < 0 || lo < 0) {
      const std::size_t bad = hi < 0 ? 2 * i : 2 * i + 1;
      return Result<Key>(ErrorCode::kParseError,
                         "key: character " + std::to_string(bad + 1) + " is not a hex digit");
    }
    key.bytes[i] = static_cast<uint8_t>(hi * 16 + lo);
  }
  return key;
}

Result<LoadedKey> loadKeyFile(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    return Result<LoadedKey>(errno == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIoError,
                             "key file " + path + ": " + std::strerror(errno));
  }
  if (!S_ISREG(st.st_mode)) {
    return Result<LoadedKey>(ErrorCode::kInvalidArgument, "key file " + path + ": not a regular file");
  }
  if (st.st_size > 4096) {
    return Result<LoadedKey>(ErrorCode::kParseError,
                             "key file " + path + ": " + std::to_string(st.st_size) +
                                 " bytes, a key file holds 64 hex characters");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return Result<LoadedKey>(ErrorCode::kIoError, "key file " + path + ": cannot be read");
  }
  std::stringstream contents;
  contents << in.rdbuf();
  std::string text = contents.str();
  Result<Key> key = parseKeyHex(text);
  sodium_memzero(text.data(), text.size());
  if (!key) {
    return Result<LoadedKey>(key.status().code(), "key file " + path + ": " + key.status().message());
  }
  LoadedKey loaded{key.value(), {}};
  if ((st.st_mode & (S_IRGRP | S_IROTH)) != 0) {
    loaded.warning = "key file " + path + " is readable by other users (chmod 600 " + path + ")";
  }
  return loaded;
}

Key generateKey() {
  initCrypto();
  Key key;
  randombytes_buf(key.bytes.data(), key.bytes.size());
  return key;
}

std::string formatKeyHex(const Key& key) {
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string out;
  out.reserve(2 * kKeyBytes);
  for (uint8_t b : key.bytes) {
    out.push_back(kDigits[b >> 4]);
    out.push_back(kDigits[b & 15]);
  }
  return out;
}

Status writeKeyFile(const std::string& path, const Key& key) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0) return Status(ErrorCode::kIoError, "key file " + path + ": " + std::strerror(errno));
  const std::string text = formatKeyHex(key) + "\n";
  const ssize_t n = ::write(fd, text.data(), text.size());
  const bool ok = n == static_cast<ssize_t>(text.size());
  ::close(fd);
  if (!ok) return Status(ErrorCode::kIoError, "key file " + path + ": short write");
  return Status::ok();
}

}  // namespace fovea::net

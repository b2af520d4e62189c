// The pre-shared key (docs/protocol.md, "Keys and nonces").
//
// A key file holds 64 hexadecimal characters (32 bytes), optionally surrounded by
// whitespace. generateKey() makes one with libsodium's randombytes; formatKeyHex()
// writes it back. The file should be readable by its owner only: loadKeyFile()
// reports a group- or world-readable file as a warning the caller logs.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include "core/result.h"

namespace fovea::net {

inline constexpr std::size_t kKeyBytes = 32;

struct Key {
  std::array<uint8_t, kKeyBytes> bytes{};
  bool operator==(const Key&) const = default;
};

struct LoadedKey {
  Key key;
  std::string warning;  // non-empty: e.g. the file is readable by others
};

// Parses 64 hex characters with optional surrounding whitespace.
Result<Key> parseKeyHex(std::string_view text);
// Reads and parses a key file; the error names the file and what is wrong.
Result<LoadedKey> loadKeyFile(const std::string& path);
// 32 random bytes (libsodium randombytes_buf).
Key generateKey();
// 64 lowercase hex characters.
std::string formatKeyHex(const Key& key);
// Writes a new key file with mode 0600 (fails if the file exists).
Status writeKeyFile(const std::string& path, const Key& key);

// The all-zero key of insecure mode (--insecure): authenticates nothing against
// anyone who reads this source. Only for tests and demos on a trusted host.
inline Key insecureKey() { return Key{}; }
inline constexpr const char* kInsecureWarning =
    "INSECURE: no key configured, using the fixed all-zero key: anyone can read, "
    "forge and replay this link's datagrams (give a key file to secure it)";

}  // namespace fovea::net

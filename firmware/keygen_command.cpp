// fovead keygen FILE: a new pre-shared key for --key-file (robot and operator).
#include <cstdio>
#include <string>

#include "firmware/commands.h"
#include "net/key.h"

namespace fovea::firmware {

int keygenCommand(int argc, char** argv) {
  if (argc == 3 && (std::string(argv[2]) == "--help" || std::string(argv[2]) == "-h")) {
    std::printf(
        "usage: fovead keygen FILE\n"
        "\n"
        "Writes a new random 32-byte pre-shared key (64 hex characters) to FILE, readable\n"
        "by its owner only. Give the same file to fovead run --key-file and to\n"
        "fovea-operator --key-file. Refuses to overwrite an existing file.\n");
    return kExitOk;
  }
  if (argc != 3) {
    std::fprintf(stderr, "fovead keygen: expected one argument, the key file to write (see --help)\n");
    return kExitUsage;
  }
  if (Status s = net::writeKeyFile(argv[2], net::generateKey()); !s) {
    std::fprintf(stderr, "fovead keygen: %s\n", s.message().c_str());
    return kExitFailure;
  }
  std::printf("wrote a new key to %s\n", argv[2]);
  return kExitOk;
}

}  // namespace fovea::firmware

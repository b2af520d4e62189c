// fovead print-config (also `fovead --print-config`): the effective
// configuration, board profile, then config file, then --set, as TOML.
#include <cstdio>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "firmware/commands.h"
#include "firmware/config.h"

namespace fovea::firmware {

namespace {

const char* kPrintConfigHelp =
    "usage: fovead print-config [--board NAME] [--config FILE] [--set SECTION.KEY=VALUE ...]\n"
    "       fovead --print-config [same options]\n"
    "\n"
    "Prints the configuration fovead serve would run with, as TOML that --config reads\n"
    "back: the board profile (default host-mock; the file's `board` key when it has one),\n"
    "then FILE, then each --set in order, validated. Errors exit with status 2.\n"
    "\n"
    "  --board NAME             a profile of the board directory (NAME.toml; $FOVEA_BOARD_DIR overrides it)\n"
    "  --config FILE            a configuration file over the profile\n"
    "  --set SECTION.KEY=VALUE  one setting over both (repeatable), e.g. --set stream.budget_mbps=25\n";

}  // namespace

int printConfigCommand(int argc, char** argv) {
  auto usage = [](const std::string& message) {
    std::fprintf(stderr, "fovead print-config: %s\n", message.c_str());
    return kExitUsage;
  };
  std::vector<std::string> tokens(argv + 2, argv + argc);
  for (const std::string& t : tokens) {
    if (t == "--help" || t == "-h") {
      std::fputs(kPrintConfigHelp, stdout);
      std::printf("\nboards in %s\n", boardDirectory().c_str());
      return kExitOk;
    }
  }
  Result<ConfigSources> sources = takeConfigSources(tokens);
  if (!sources) return usage(sources.status().message());
  if (!tokens.empty()) return usage("unknown argument '" + tokens.front() + "' (see --help)");
  Result<ServiceConfig> config = resolveServiceConfig(sources.value());
  if (!config) return usage(config.status().message());
  std::fputs(formatServiceConfig(config.value()).c_str(), stdout);
  for (const std::string& note : missingBackends(config.value())) {
    std::fprintf(stderr, "fovead print-config: note: %s\n", note.c_str());
  }
  return kExitOk;
}

}  // namespace fovea::firmware

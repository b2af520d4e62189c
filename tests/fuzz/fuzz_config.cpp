// Fuzz target for the configuration (firmware/config.h): the bytes are a
// configuration file's text (TOML), parsed and validated by parseServiceConfig
// over the defaults as loadServiceConfig does after reading the file. Input
// that starts with "--set\n" is instead a list of --set assignments, one a
// line, applied by applyOverride and then validated. Oracle: a configuration
// that loads prints (formatServiceConfig) to text that loads back to the
// same configuration.
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

#include "firmware/config.h"
#include "tests/fuzz/fuzz_target.h"

namespace {

using namespace fovea;
using namespace fovea::firmware;

[[noreturn]] void fail(const char* what, const std::string& detail) {
  std::fprintf(stderr, "fuzz_config: %s\n%s\n", what, detail.c_str());
  std::abort();
}

void checkPrintsBack(const ServiceConfig& config) {
  const std::string printed = formatServiceConfig(config);
  Result<ServiceConfig> again = parseServiceConfig(printed, "printed.toml", ServiceConfig{});
  if (!again) fail("the printed configuration does not load", again.status().message() + "\n" + printed);
  if (formatServiceConfig(*again) != printed) fail("the printed configuration loads differently", printed);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  std::string_view text(reinterpret_cast<const char*>(data), size);
  constexpr std::string_view kSet = "--set\n";
  if (text.substr(0, kSet.size()) == kSet) {
    text.remove_prefix(kSet.size());
    ServiceConfig config;
    while (!text.empty()) {
      const std::size_t eol = std::min(text.find('\n'), text.size());
      if (!applyOverride(config, text.substr(0, eol))) return 0;
      text.remove_prefix(std::min(eol + 1, text.size()));
    }
    if (validate(config)) checkPrintsBack(config);
    return 0;
  }
  Result<ServiceConfig> config = parseServiceConfig(text, "fuzz.toml", ServiceConfig{});
  if (config) checkPrintsBack(*config);
  return 0;
}

// The default configuration as printed; the corpus adds hand-written files and
// the board profiles (board/*.toml).
std::vector<fuzz::Input> fuzz::seeds() {
  const std::string printed = formatServiceConfig(ServiceConfig{});
  return {Input(printed.begin(), printed.end())};
}

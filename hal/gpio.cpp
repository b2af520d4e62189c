#include "hal/gpio.h"

#include <string>

#include "hal/gpio/mock/mock_gpio.h"
#ifdef FOVEA_HAVE_GPIOD
#include "hal/gpio/gpiod/gpiod_gpio.h"
#endif

namespace fovea::hal {

namespace {

// The backends compiled in, one line each (no static self-registration).
struct Backend {
  std::string_view name;
  Result<std::unique_ptr<Gpio>> (*create)(std::string_view args);
  std::string (*help)();
};

const Backend kBackends[] = {
    {"mock", &mock::MockGpio::create, &mock::mockGpioHelp},
#ifdef FOVEA_HAVE_GPIOD
    {"gpiod", &gpiod::GpiodGpio::create, &gpiod::gpiodGpioHelp},
#endif
};

std::string backendNames() {
  std::string names;
  for (const Backend& backend : kBackends) {
    if (!names.empty()) names += '|';
    names += backend.name;
  }
  return names;
}

}  // namespace

Result<std::unique_ptr<Gpio>> createGpio(std::string_view spec) {
  const std::size_t colon = spec.find(':');
  const std::string_view name = spec.substr(0, colon);
  const std::string_view args =
      colon == std::string_view::npos ? std::string_view() : spec.substr(colon + 1);
  for (const Backend& backend : kBackends) {
    if (backend.name == name) return backend.create(args);
  }
  std::string hint;
  if (name == "gpiod") hint = " (this build has no libgpiod: apt-get install libgpiod-dev and reconfigure)";
  return Result<std::unique_ptr<Gpio>>(ErrorCode::kInvalidArgument,
                                       "gpio: unknown backend '" + std::string(name) + "' in '" +
                                           std::string(spec) + "'; accepted: " + backendNames() + hint);
}

std::string gpioSpecHelp() {
  std::string help;
  for (const Backend& backend : kBackends) {
    help += backend.help();
    help += '\n';
  }
  return help;
}

}  // namespace fovea::hal

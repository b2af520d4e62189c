#include "hal/gpio.h"

#include <string>

#include "hal/backend_table.h"
#include "hal/gpio/mock/mock_gpio.h"
#ifdef FOVEA_HAVE_GPIOD
#include "hal/gpio/gpiod/gpiod_gpio.h"
#endif

namespace fovea::hal {

namespace {

const Backend<Gpio> kBackends[] = {
    {"mock", &mock::MockGpio::create, &mock::mockGpioHelp, nullptr},
#ifdef FOVEA_HAVE_GPIOD
    {"gpiod", &gpiod::GpiodGpio::create, &gpiod::gpiodGpioHelp, nullptr},
#endif
};

}  // namespace

Result<std::unique_ptr<Gpio>> createGpio(std::string_view spec) {
  std::string_view hint;
#ifndef FOVEA_HAVE_GPIOD
  if (spec.substr(0, spec.find(':')) == "gpiod") hint = " (this build has no libgpiod: apt-get install libgpiod-dev and reconfigure)";
#endif
  return createFromSpec<Gpio>(kBackends, "gpio", spec, hint);
}

std::string gpioSpecHelp() { return backendsHelp<Gpio>(kBackends); }

std::vector<std::string_view> gpioBackendNames() { return backendNames<Gpio>(kBackends); }

}  // namespace fovea::hal

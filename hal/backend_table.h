// The explicit table of compiled-in backends that every HAL interface uses
// (cameras, GPIO): one line per backend, no static self-registration (a static
// library's linker would drop it), and one way to parse "backend:args" specs.
#pragma once

#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.h"

namespace fovea::hal {

// A device a backend can see now, for listings such as `fovead cameras`.
struct DeviceListing {
  std::string spec;                // what to pass as the spec ("v4l2:serial=123", "openni2:Dummy")
  std::string model;               // "Intel RealSense D435", "vivid"; "" when unknown
  std::string serial;              // "" when unknown
  std::string detail;              // bus path, driver, node...
  std::vector<std::string> modes;  // "depth Z16 640x480 @ 30 fps", "colour YUYV 1280x720 @ 30 fps"
};

template <typename Interface>
struct Backend {
  std::string_view name;
  // args: the spec after "name:" ("" when there is no ':').
  Result<std::unique_ptr<Interface>> (*create)(std::string_view args);
  std::string (*help)();
  // Lists the devices the backend sees now; nullptr when it cannot enumerate
  // (mock, recordings). An error says why enumeration failed and what to do.
  Result<std::vector<DeviceListing>> (*discover)();
};

// Creates the backend a "name[:args]" spec names. Errors name the spec, the
// accepted backends and `hint` (e.g. how to build a missing one).
template <typename Interface>
Result<std::unique_ptr<Interface>> createFromSpec(std::span<const Backend<Interface>> backends, std::string_view what,
                                                  std::string_view spec, std::string_view hint = {}) {
  const std::size_t colon = spec.find(':');
  const std::string_view name = spec.substr(0, colon);
  const std::string_view args = colon == std::string_view::npos ? std::string_view() : spec.substr(colon + 1);
  std::string names;
  for (const Backend<Interface>& backend : backends) {
    if (backend.name == name) return backend.create(args);
    if (!names.empty()) names += '|';
    names += backend.name;
  }
  return Result<std::unique_ptr<Interface>>(ErrorCode::kInvalidArgument,
                                            std::string(what) + ": unknown backend '" + std::string(name) + "' in '" +
                                                std::string(spec) + "'; accepted: " + names + std::string(hint));
}

// The names of the backends, in table order.
template <typename Interface>
std::vector<std::string_view> backendNames(std::span<const Backend<Interface>> backends) {
  std::vector<std::string_view> names;
  for (const Backend<Interface>& backend : backends) names.push_back(backend.name);
  return names;
}

// Every backend's help, a line each.
template <typename Interface>
std::string backendsHelp(std::span<const Backend<Interface>> backends) {
  std::string help;
  for (const Backend<Interface>& backend : backends) {
    help += backend.help();
    help += '\n';
  }
  return help;
}

}  // namespace fovea::hal

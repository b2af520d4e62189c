// The viewer page's files (tools/operator/viewer/), compiled into
// fovea-operator by tools/operator/embed_assets.cmake, so the page works
// offline and from any install without a path to look up.
#pragma once

#include <span>
#include <string_view>

namespace fovea::tools {

struct ViewAsset {
  std::string_view path;  // "/index.html"
  std::string_view mime;
  std::span<const unsigned char> data;
};

std::span<const ViewAsset> viewAssets();

}  // namespace fovea::tools

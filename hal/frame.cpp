#include "hal/frame.h"

namespace fovea::hal {

RgbdFrame::RgbdFrame(int max_width, int max_height)
    : width_(max_width),
      height_(max_height),
      depth_(static_cast<std::size_t>(max_width) * max_height, 0),
      rgb_(static_cast<std::size_t>(max_width) * max_height * 3, 0) {
  intrinsics.width = max_width;
  intrinsics.height = max_height;
}

bool RgbdFrame::setSize(int width, int height) {
  if (width <= 0 || height <= 0) return false;
  if (static_cast<std::size_t>(width) * static_cast<std::size_t>(height) > depth_.size()) return false;
  width_ = width;
  height_ = height;
  return true;
}

}  // namespace fovea::hal

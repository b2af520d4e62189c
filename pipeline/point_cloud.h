// Point buffers in structure-of-arrays form with a fixed capacity.
//
// Coordinates are float and relative to origin_m, a world position kept in
// double: floats hold a metre-scale neighbourhood to about a micrometre, while a
// robot's map may put it kilometres from the world origin (docs/precision.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace fovea::pipeline {

// 0x00RRGGBB
inline constexpr uint32_t packRgb(uint8_t r, uint8_t g, uint8_t b) {
  return (uint32_t{r} << 16) | (uint32_t{g} << 8) | uint32_t{b};
}
inline constexpr uint8_t rgbRed(uint32_t c) { return static_cast<uint8_t>(c >> 16); }
inline constexpr uint8_t rgbGreen(uint32_t c) { return static_cast<uint8_t>(c >> 8); }
inline constexpr uint8_t rgbBlue(uint32_t c) { return static_cast<uint8_t>(c); }

class PointCloud {
 public:
  PointCloud() = default;
  explicit PointCloud(std::size_t capacity)
      : x_(capacity), y_(capacity), z_(capacity), rgb_(capacity) {}

  std::size_t size() const { return size_; }
  std::size_t capacity() const { return x_.size(); }
  bool empty() const { return size_ == 0; }

  // Drops the points; keeps the memory.
  void clear() { size_ = 0; }
  // Sets the size directly (for kernels that write the arrays); false if over capacity.
  [[nodiscard]] bool resize(std::size_t n) {
    if (n > capacity()) return false;
    size_ = n;
    return true;
  }
  // Appends one point relative to origin(); false (nothing written) when full.
  [[nodiscard]] bool push(float x, float y, float z, uint32_t rgb) {
    if (size_ == capacity()) return false;
    x_[size_] = x;
    y_[size_] = y;
    z_[size_] = z;
    rgb_[size_] = rgb;
    ++size_;
    return true;
  }

  float* x() { return x_.data(); }
  float* y() { return y_.data(); }
  float* z() { return z_.data(); }
  uint32_t* rgb() { return rgb_.data(); }
  const float* x() const { return x_.data(); }
  const float* y() const { return y_.data(); }
  const float* z() const { return z_.data(); }
  const uint32_t* rgb() const { return rgb_.data(); }

  // World position of point i, in double.
  Eigen::Vector3d world(std::size_t i) const {
    return origin_m + Eigen::Vector3d(x_[i], y_[i], z_[i]);
  }

  Eigen::Vector3d origin_m = Eigen::Vector3d::Zero();  // world position of (0,0,0)
  bool has_color = true;

 private:
  std::size_t size_ = 0;
  std::vector<float> x_, y_, z_;
  std::vector<uint32_t> rgb_;
};

}  // namespace fovea::pipeline

namespace fovea::pipeline {

// The output of foveation: points plus, per point, its region and how many input
// points it stands for (1 in the fovea, the voxel's population elsewhere). A
// cloud made without weights has none (the service's slots: nothing on the robot
// reads them, 4 bytes a point); every sampler and copy skips them then.
struct FoveatedCloud {
  enum class Weights { kKept, kNone };
  FoveatedCloud() = default;
  explicit FoveatedCloud(std::size_t capacity, Weights weights = Weights::kKept)
      : points(capacity), region(capacity), weight(weights == Weights::kKept ? capacity : 0) {}

  std::size_t size() const { return points.size(); }
  void clear() { points.clear(); }
  bool hasWeights() const { return !weight.empty(); }

  PointCloud points;
  std::vector<uint8_t> region;
  std::vector<uint32_t> weight;
};

}  // namespace fovea::pipeline

#include "bench/pcl_method.h"

#include <pcl/filters/voxel_grid.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "pipeline/fixation.h"

namespace fovea::bench {

struct PclFoveation::Impl {
  pipeline::FoveationConfig config;
  pipeline::RegionModel model;
  pipeline::ConeBounds bounds;
  std::vector<uint8_t> region;
  std::vector<double> t_scratch;
  // Per region: the points handed to PCL (world float coordinates), and PCL's output.
  std::array<pcl::PointCloud<pcl::PointXYZRGB>::Ptr, pipeline::kMaxRegions> in, out;
  pcl::VoxelGrid<pcl::PointXYZRGB> grid;
};

PclFoveation::PclFoveation(std::size_t max_points, const pipeline::FoveationConfig& config)
    : impl_(new Impl{config, pipeline::RegionModel::create(config.acuity).value(), {}, {}, {}, {}, {}, {}}) {
  impl_->bounds = pipeline::ConeBounds::fromModel(impl_->model);
  impl_->region.resize(max_points);
  impl_->t_scratch.resize(max_points);
  for (int r = 0; r < pipeline::kMaxRegions; ++r) {
    impl_->in[r].reset(new pcl::PointCloud<pcl::PointXYZRGB>);
    impl_->out[r].reset(new pcl::PointCloud<pcl::PointXYZRGB>);
    impl_->in[r]->reserve(max_points);
  }
}

PclFoveation::~PclFoveation() = default;

int PclFoveation::regionCount() const { return impl_->model.regionCount(); }

Status PclFoveation::run(const pipeline::PointCloud& cloud, const pipeline::Gaze& input_gaze) {
  Impl& m = *impl_;
  if (cloud.size() > m.region.size()) return {ErrorCode::kCapacityExceeded, "pcl: cloud larger than capacity"};
  // Normalised once more, as Foveator::foveate does: renormalising a unit vector
  // can change its last bits, and with them d0 and every voxel size.
  Result<pipeline::Gaze> unit = pipeline::normalizeGaze(input_gaze);
  if (!unit) return unit.status();
  const pipeline::Gaze& gaze = unit.value();
  pipeline::PartitionCounts counts;
  pipeline::partitionRef(cloud, gaze, m.bounds, m.region.data(), counts);
  const pipeline::Fixation fixation =
      pipeline::computeFixation(cloud, m.region.data(), gaze, m.config.fixation, m.t_scratch.data());
  d0_m_ = fixation.d0_m;
  const int regions = m.model.regionCount();
  for (int r = 0; r < regions; ++r) {
    voxel_size_m_[r] = r == 0 ? 0.0 : m.model.voxelSizeM(r, d0_m_);
    m.in[r]->clear();
  }
  const Eigen::Vector3d& o = cloud.origin_m;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const uint8_t r = m.region[i];
    if (r >= regions) continue;
    pcl::PointXYZRGB p;
    p.x = static_cast<float>(o.x() + static_cast<double>(cloud.x()[i]));
    p.y = static_cast<float>(o.y() + static_cast<double>(cloud.y()[i]));
    p.z = static_cast<float>(o.z() + static_cast<double>(cloud.z()[i]));
    const uint32_t c = cloud.rgb()[i];
    p.r = pipeline::rgbRed(c);
    p.g = pipeline::rgbGreen(c);
    p.b = pipeline::rgbBlue(c);
    m.in[r]->push_back(p);
  }
  for (int r = 1; r < regions; ++r) {
    if (m.in[r]->empty()) {
      m.out[r]->clear();
      continue;
    }
    const auto leaf = static_cast<float>(voxel_size_m_[r]);
    m.grid.setInputCloud(m.in[r]);
    m.grid.setLeafSize(leaf, leaf, leaf);
    m.grid.filter(*m.out[r]);
  }
  return Status::ok();
}

std::size_t PclFoveation::outputSize() const {
  std::size_t n = impl_->in[0]->size();
  for (int r = 1; r < impl_->model.regionCount(); ++r) n += impl_->out[r]->size();
  return n;
}

void PclFoveation::output(std::vector<std::array<double, 3>>& world, std::vector<uint8_t>& region) const {
  world.clear();
  region.clear();
  for (int r = 0; r < impl_->model.regionCount(); ++r) {
    const auto& cloud = r == 0 ? *impl_->in[0] : *impl_->out[r];
    for (const pcl::PointXYZRGB& p : cloud) {
      world.push_back({static_cast<double>(p.x), static_cast<double>(p.y), static_cast<double>(p.z)});
      region.push_back(static_cast<uint8_t>(r));
    }
  }
}

}  // namespace fovea::bench

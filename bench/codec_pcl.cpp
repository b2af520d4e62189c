#include "bench/codec_baselines.h"

#include <chrono>
#include <sstream>

#ifdef FOVEA_HAVE_PCL_OCTREE
#include <pcl/compression/octree_pointcloud_compression.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#endif

namespace fovea::bench {

#ifdef FOVEA_HAVE_PCL_OCTREE
bool havePclOctree() { return true; }

CodecRun runPclOctree(const pipeline::FoveatedCloud& cloud, double point_resolution_m, double octree_resolution_m,
                      int runs) {
  using Clock = ThreadCpuClock;
  using Codec = pcl::io::OctreePointCloudCompression<pcl::PointXYZRGB>;
  CodecRun run;
  run.max_error_m = point_resolution_m;
  pcl::PointCloud<pcl::PointXYZRGB>::Ptr in(new pcl::PointCloud<pcl::PointXYZRGB>);
  in->resize(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3d w = cloud.points.world(i);
    pcl::PointXYZRGB& p = (*in)[i];
    p.x = static_cast<float>(w.x()), p.y = static_cast<float>(w.y()), p.z = static_cast<float>(w.z());
    const uint32_t c = cloud.points.rgb()[i];
    p.r = pipeline::rgbRed(c), p.g = pipeline::rgbGreen(c), p.b = pipeline::rgbBlue(c);
  }
  std::vector<double> enc_ms, dec_ms;
  for (int r = 0; r <= runs; ++r) {  // run 0 warms up
    Codec encoder(pcl::io::MANUAL_CONFIGURATION, false, point_resolution_m, octree_resolution_m, false, 30, true, 8);
    Codec decoder;
    std::stringstream stream;
    const auto t0 = Clock::now();
    encoder.encodePointCloud(in, stream);
    const auto t1 = Clock::now();
    run.bytes = stream.str().size();
    pcl::PointCloud<pcl::PointXYZRGB>::Ptr out(new pcl::PointCloud<pcl::PointXYZRGB>);
    const auto t2 = Clock::now();
    decoder.decodePointCloud(stream, out);
    const auto t3 = Clock::now();
    run.points_out = out->size();
    if (r > 0) {
      enc_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
      dec_ms.push_back(std::chrono::duration<double, std::milli>(t3 - t2).count());
    }
  }
  run.encode_ms = median(enc_ms);
  run.decode_ms = median(dec_ms);
  return run;
}
#else
bool havePclOctree() { return false; }
CodecRun runPclOctree(const pipeline::FoveatedCloud&, double, double, int) {
  CodecRun run;
  run.error = "not built (PCL's io/octree components not found)";
  return run;
}
#endif

}  // namespace fovea::bench

#include "bench/codec_baselines.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#ifdef FOVEA_HAVE_DRACO
#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/point_cloud/point_cloud_builder.h>
#endif

namespace fovea::bench {

double median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

double dracoStep(const pipeline::FoveatedCloud& cloud, int position_bits) {
  double lo[3] = {std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
                  std::numeric_limits<double>::max()};
  double hi[3] = {-lo[0], -lo[1], -lo[2]};
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    // Draco sees float world coordinates.
    const float w[3] = {static_cast<float>(cloud.points.world(i).x()), static_cast<float>(cloud.points.world(i).y()),
                        static_cast<float>(cloud.points.world(i).z())};
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], double{w[a]}), hi[a] = std::max(hi[a], double{w[a]});
  }
  const double range = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  return range / static_cast<double>((1 << position_bits) - 1);
}

#ifdef FOVEA_HAVE_DRACO
bool haveDraco() { return true; }

CodecRun runDraco(const pipeline::FoveatedCloud& cloud, int position_bits, int runs) {
  using Clock = ThreadCpuClock;
  CodecRun run;
  run.max_error_m = dracoStep(cloud, position_bits) / 2;
  const std::size_t n = cloud.size();
  std::vector<float> xyz(3 * n);
  std::vector<uint8_t> rgb(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d w = cloud.points.world(i);
    xyz[3 * i] = static_cast<float>(w.x()), xyz[3 * i + 1] = static_cast<float>(w.y());
    xyz[3 * i + 2] = static_cast<float>(w.z());
    const uint32_t c = cloud.points.rgb()[i];
    rgb[3 * i] = pipeline::rgbRed(c), rgb[3 * i + 1] = pipeline::rgbGreen(c), rgb[3 * i + 2] = pipeline::rgbBlue(c);
  }
  draco::PointCloudBuilder builder;
  builder.Start(static_cast<draco::PointIndex::ValueType>(n));
  const int pos = builder.AddAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32);
  const int col = builder.AddAttribute(draco::GeometryAttribute::COLOR, 3, draco::DT_UINT8);
  builder.SetAttributeValuesForAllPoints(pos, xyz.data(), 0);
  builder.SetAttributeValuesForAllPoints(col, rgb.data(), 0);
  std::unique_ptr<draco::PointCloud> pc = builder.Finalize(false);
  if (!pc) {
    run.error = "draco: PointCloudBuilder failed";
    return run;
  }
  draco::Encoder encoder;
  encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, position_bits);
  encoder.SetSpeedOptions(10, 10);
  encoder.SetEncodingMethod(draco::POINT_CLOUD_KD_TREE_ENCODING);

  std::vector<double> enc_ms, dec_ms;
  std::vector<float> out_xyz(3 * n);
  std::vector<uint8_t> out_rgb(3 * n);
  for (int r = 0; r <= runs; ++r) {  // run 0 warms up
    draco::EncoderBuffer buffer;
    const auto t0 = Clock::now();
    const draco::Status st = encoder.EncodePointCloudToBuffer(*pc, &buffer);
    const auto t1 = Clock::now();
    if (!st.ok()) {
      run.error = std::string("draco encode: ") + st.error_msg();
      return run;
    }
    run.bytes = buffer.size();
    draco::DecoderBuffer in;
    in.Init(buffer.data(), buffer.size());
    draco::Decoder decoder;
    const auto t2 = Clock::now();
    auto decoded = decoder.DecodePointCloudFromBuffer(&in);
    if (!decoded.ok()) {
      run.error = std::string("draco decode: ") + decoded.status().error_msg();
      return run;
    }
    const draco::PointCloud& out = *decoded.value();
    // Into flat arrays, as fovea's decoder writes its cloud.
    const draco::PointAttribute* p = out.GetNamedAttribute(draco::GeometryAttribute::POSITION);
    const draco::PointAttribute* c = out.GetNamedAttribute(draco::GeometryAttribute::COLOR);
    const std::size_t m = std::min<std::size_t>(out.num_points(), n);
    for (std::size_t i = 0; i < m; ++i) {
      const draco::PointIndex pi(static_cast<uint32_t>(i));
      p->GetMappedValue(pi, &out_xyz[3 * i]);
      c->GetMappedValue(pi, &out_rgb[3 * i]);
    }
    const auto t3 = Clock::now();
    run.points_out = out.num_points();
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
bool haveDraco() { return false; }
CodecRun runDraco(const pipeline::FoveatedCloud&, int, int) {
  CodecRun run;
  run.error = "not built (libdraco-dev not found)";
  return run;
}
#endif

}  // namespace fovea::bench

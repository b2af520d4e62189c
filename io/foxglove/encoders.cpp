#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "io/foxglove/foxglove.h"

#include "foxglove/FrameTransform.pb.h"
#include "foxglove/Log.pb.h"
#include "foxglove/PointCloud.pb.h"
#include "foxglove/SceneUpdate.pb.h"

namespace fovea::foxglove {

Schema pointCloudSchema() { return {"foxglove.PointCloud", "protobuf", schemaData("foxglove.PointCloud")}; }
Schema frameTransformSchema() { return {"foxglove.FrameTransform", "protobuf", schemaData("foxglove.FrameTransform")}; }
Schema logSchema() { return {"foxglove.Log", "protobuf", schemaData("foxglove.Log")}; }
Schema sceneUpdateSchema() { return {"foxglove.SceneUpdate", "protobuf", schemaData("foxglove.SceneUpdate")}; }

namespace {

void setStamp(google::protobuf::Timestamp* t, int64_t ns) {
  int64_t sec = ns / 1'000'000'000;
  int64_t nsec = ns % 1'000'000'000;
  if (nsec < 0) {
    nsec += 1'000'000'000;
    --sec;
  }
  t->set_seconds(sec);
  t->set_nanos(static_cast<int32_t>(nsec));
}

void assign(std::string* s, std::string_view v) { s->assign(v.data(), v.size()); }

// Serialises into out (grown only when a message is larger than any before).
template <typename Message>
std::span<const uint8_t> serialize(const Message& m, std::vector<uint8_t>& out) {
  const std::size_t bytes = m.ByteSizeLong();
  if (out.size() < bytes) out.resize(bytes);
  m.SerializeWithCachedSizesToArray(out.data());
  return {out.data(), bytes};
}

}  // namespace

// ---- PointCloud
struct PointCloudEncoder::Impl {
  ::foxglove::PointCloud msg;
  std::vector<uint8_t> out;
};

PointCloudEncoder::PointCloudEncoder() : impl_(std::make_unique<Impl>()) {
  ::foxglove::PointCloud& m = impl_->msg;
  m.set_point_stride(kPointStride);
  const char* names[] = {"x", "y", "z"};
  for (uint32_t i = 0; i < 3; ++i) {
    ::foxglove::PackedElementField* f = m.add_fields();
    f->set_name(names[i]);
    f->set_offset(4 * i);
    f->set_type(::foxglove::PackedElementField::FLOAT32);
  }
  ::foxglove::PackedElementField* rgba = m.add_fields();
  rgba->set_name("rgba");
  rgba->set_offset(12);
  rgba->set_type(::foxglove::PackedElementField::UINT32);
  m.mutable_pose()->mutable_orientation()->set_w(1.0);
  m.mutable_pose()->mutable_position();
  m.mutable_timestamp();
}
PointCloudEncoder::~PointCloudEncoder() = default;
PointCloudEncoder::PointCloudEncoder(PointCloudEncoder&&) noexcept = default;
PointCloudEncoder& PointCloudEncoder::operator=(PointCloudEncoder&&) noexcept = default;

std::span<const uint8_t> PointCloudEncoder::encode(const pipeline::PointCloud& cloud, std::string_view frame_id,
                                                   int64_t stamp_ns) {
  ::foxglove::PointCloud& m = impl_->msg;
  setStamp(m.mutable_timestamp(), stamp_ns);
  assign(m.mutable_frame_id(), frame_id);
  ::foxglove::Vector3* p = m.mutable_pose()->mutable_position();
  p->set_x(cloud.origin_m.x());
  p->set_y(cloud.origin_m.y());
  p->set_z(cloud.origin_m.z());
  std::string* data = m.mutable_data();
  const std::size_t n = cloud.size();
  data->resize(n * kPointStride);
  auto* d = reinterpret_cast<uint8_t*>(data->data());
  const float* x = cloud.x();
  const float* y = cloud.y();
  const float* z = cloud.z();
  const uint32_t* rgb = cloud.rgb();
  for (std::size_t i = 0; i < n; ++i) {
    uint8_t* q = d + i * kPointStride;
    std::memcpy(q, &x[i], 4);
    std::memcpy(q + 4, &y[i], 4);
    std::memcpy(q + 8, &z[i], 4);
    // 0xAARRGGBB as a little-endian uint32 (bytes B, G, R, A): how Foxglove's 3D
    // panel reads a packed "rgba" field (its "BGRA (packed)" colour mode, as rviz).
    const uint32_t c = cloud.has_color ? rgb[i] : 0x808080u;
    q[12] = pipeline::rgbBlue(c);
    q[13] = pipeline::rgbGreen(c);
    q[14] = pipeline::rgbRed(c);
    q[15] = 0xff;
  }
  return serialize(m, impl_->out);
}

void PointCloudEncoder::reserve(std::size_t points) {
  impl_->msg.mutable_data()->reserve(points * kPointStride);
  // The message is its points and a header of a few hundred bytes (frame id, pose, fields).
  if (impl_->out.size() < points * kPointStride + 1024) impl_->out.resize(points * kPointStride + 1024);
}

// ---- FrameTransform
struct FrameTransformEncoder::Impl {
  ::foxglove::FrameTransform msg;
  std::vector<uint8_t> out;
};

FrameTransformEncoder::FrameTransformEncoder() : impl_(std::make_unique<Impl>()) {
  impl_->msg.mutable_timestamp();
  impl_->msg.mutable_translation();
  impl_->msg.mutable_rotation();
}
FrameTransformEncoder::~FrameTransformEncoder() = default;
FrameTransformEncoder::FrameTransformEncoder(FrameTransformEncoder&&) noexcept = default;
FrameTransformEncoder& FrameTransformEncoder::operator=(FrameTransformEncoder&&) noexcept = default;

std::span<const uint8_t> FrameTransformEncoder::encode(std::string_view parent, std::string_view child,
                                                       const std::array<double, 3>& translation,
                                                       const std::array<double, 4>& rotation_wxyz, int64_t stamp_ns) {
  ::foxglove::FrameTransform& m = impl_->msg;
  setStamp(m.mutable_timestamp(), stamp_ns);
  assign(m.mutable_parent_frame_id(), parent);
  assign(m.mutable_child_frame_id(), child);
  m.mutable_translation()->set_x(translation[0]);
  m.mutable_translation()->set_y(translation[1]);
  m.mutable_translation()->set_z(translation[2]);
  m.mutable_rotation()->set_w(rotation_wxyz[0]);
  m.mutable_rotation()->set_x(rotation_wxyz[1]);
  m.mutable_rotation()->set_y(rotation_wxyz[2]);
  m.mutable_rotation()->set_z(rotation_wxyz[3]);
  return serialize(m, impl_->out);
}

// ---- Log
struct LogEncoder::Impl {
  ::foxglove::Log msg;
  std::vector<uint8_t> out;
};

// Room for lines of up to 4 KiB (status lines are a few hundred bytes) and
// names of 64, so that a longer line than the last allocates nothing.
LogEncoder::LogEncoder() : impl_(std::make_unique<Impl>()) {
  impl_->msg.mutable_timestamp();
  impl_->msg.mutable_message()->reserve(4096);
  impl_->msg.mutable_name()->reserve(64);
  impl_->out.resize(4096 + 256);
}
LogEncoder::~LogEncoder() = default;
LogEncoder::LogEncoder(LogEncoder&&) noexcept = default;
LogEncoder& LogEncoder::operator=(LogEncoder&&) noexcept = default;

std::span<const uint8_t> LogEncoder::encode(LogLevel level, std::string_view message, std::string_view name,
                                            int64_t stamp_ns) {
  ::foxglove::Log& m = impl_->msg;
  setStamp(m.mutable_timestamp(), stamp_ns);
  m.set_level(static_cast<::foxglove::Log::Level>(static_cast<int>(level)));
  assign(m.mutable_message(), message);
  assign(m.mutable_name(), name);
  return serialize(m, impl_->out);
}

// ---- the gaze ray
struct GazeRayEncoder::Impl {
  ::foxglove::SceneUpdate msg;
  std::vector<uint8_t> out;
};

GazeRayEncoder::GazeRayEncoder() : impl_(std::make_unique<Impl>()) {
  ::foxglove::SceneEntity* e = impl_->msg.add_entities();
  e->set_id("gaze");
  e->mutable_timestamp();
  ::foxglove::ArrowPrimitive* a = e->add_arrows();
  a->mutable_pose()->mutable_position();
  a->mutable_pose()->mutable_orientation();
  a->set_shaft_diameter(0.01);
  a->set_head_diameter(0.04);
  a->set_head_length(0.08);
  ::foxglove::Color* c = a->mutable_color();
  c->set_r(1.0);
  c->set_g(0.2);
  c->set_b(0.1);
  c->set_a(1.0);
}
GazeRayEncoder::~GazeRayEncoder() = default;
GazeRayEncoder::GazeRayEncoder(GazeRayEncoder&&) noexcept = default;
GazeRayEncoder& GazeRayEncoder::operator=(GazeRayEncoder&&) noexcept = default;

std::span<const uint8_t> GazeRayEncoder::encode(std::string_view frame_id, const std::array<double, 3>& origin_m,
                                                const std::array<double, 3>& direction, double length_m,
                                                int64_t stamp_ns) {
  ::foxglove::SceneEntity* e = impl_->msg.mutable_entities(0);
  setStamp(e->mutable_timestamp(), stamp_ns);
  assign(e->mutable_frame_id(), frame_id);
  ::foxglove::ArrowPrimitive* a = e->mutable_arrows(0);
  ::foxglove::Pose* pose = a->mutable_pose();
  pose->mutable_position()->set_x(origin_m[0]);
  pose->mutable_position()->set_y(origin_m[1]);
  pose->mutable_position()->set_z(origin_m[2]);
  // The arrow points along its pose's +x: the rotation taking +x to the direction.
  double dx = direction[0], dy = direction[1], dz = direction[2];
  const double norm = std::sqrt(dx * dx + dy * dy + dz * dz);
  double qw = 1.0, qx = 0.0, qy = 0.0, qz = 0.0;
  if (norm > 0.0 && std::isfinite(norm)) {
    dx /= norm;
    dy /= norm;
    dz /= norm;
    // q = (1 + x.d, x × d) normalised; x × d = (0, -dz, dy).
    const double w = 1.0 + dx;
    if (w < 1e-9) {
      qw = 0.0;  // d = -x: half a turn about z
      qz = 1.0;
    } else {
      const double s = std::sqrt(w * w + dz * dz + dy * dy);
      qw = w / s;
      qy = -dz / s;
      qz = dy / s;
    }
  }
  pose->mutable_orientation()->set_w(qw);
  pose->mutable_orientation()->set_x(qx);
  pose->mutable_orientation()->set_y(qy);
  pose->mutable_orientation()->set_z(qz);
  a->set_shaft_length(std::max(0.0, length_m - a->head_length()));
  return serialize(impl_->msg, impl_->out);
}

}  // namespace fovea::foxglove

// One frame's way through the pipeline, shared by `fovead run` (one thread) and
// the service's foveation stage. Two sources (foveation.source, docs/map.md):
//  - frame: back-projection into the stage's own cloud, foveated as it is;
//  - map: the frame is fused into the surfel map; the cloud is then the frame's
//    points the map does not explain yet (a moving object, new surface) and,
//    once the gaze is known, the map's stable surfels the operator's eye can
//    see (pipeline/map/eye_view.h), all foveated together.
// The foveation configuration the gaze policy chose is applied only when it
// changes. Everything is allocated by create(); a frame allocates nothing.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string_view>

#include "core/clock.h"
#include "core/result.h"
#include "hal/frame.h"
#include "pipeline/backproject.h"
#include "pipeline/foveator.h"
#include "pipeline/kernels/backprojector.h"
#include "pipeline/map/eye_view.h"
#include "pipeline/map/surfel_map.h"
#include "pipeline/point_cloud.h"

namespace fovea::firmware {

enum class FoveationSource : uint8_t { kFrame, kMap };
std::string_view foveationSourceName(FoveationSource source);
std::optional<FoveationSource> parseFoveationSource(std::string_view name);

// The map's settings ([map] in the configuration file, foveation.source).
// The map's depth range and largest frame are the camera's (create() sets them).
struct MapSettings {
  FoveationSource source = FoveationSource::kFrame;
  pipeline::map::SurfelMapConfig map;
  pipeline::map::EyeViewConfig eye;
};

// What the map did with the last frame (map source only).
struct MapFrameFigures {
  pipeline::map::FuseStats fuse;
  pipeline::map::EyeViewStats eye;
  uint32_t frame_points = 0;  // the frame's points in the cloud: unexplained (fused) or all (refused)
};

class FrameFoveator {
 public:
  // capacity.max_points: the frame's pixels; the map source adds the map's
  // max_surfels to the cloud's capacity itself (cloudCapacity()).
  static Result<FrameFoveator> create(const pipeline::PipelineCapacity& capacity,
                                      const pipeline::FoveationConfig& config, const pipeline::DepthRange& range,
                                      const MapSettings& map = {}, int width = 640, int height = 480);
  // The points a cloud may hold for this source: the pixels, plus the map's
  // surfels for the map source (what the foveated output must hold too).
  static std::size_t cloudCapacity(std::size_t pixels, const MapSettings& map) {
    return map.source == FoveationSource::kMap ? pixels + map.map.max_surfels : pixels;
  }

  // Takes a frame in. frame source: back-projects it into cloud()
  // (kCapacityExceeded for a frame larger than the capacity). map source: fuses
  // it (a refused frame is counted in the map's counters; pose_valid false is
  // the pose source's "no pose for this stamp") and puts the points the map does
  // not explain into cloud(); a frame the map refused is back-projected whole.
  Status backproject(const hal::RgbdFrame& frame, pipeline::BackprojectCounts& counts, bool pose_valid = true);
  // Makes `config` the foveation in use. The gaze policy hands out pointers to
  // its own configurations, so a pointer equal to the one in use means no change
  // (invalidate() forces the next call to apply, e.g. after the policy's
  // configuration was replaced in place). On error the previous one stays.
  Status use(const pipeline::FoveationConfig* config) {
    if (config == in_use_) return Status::ok();
    if (Status s = foveator_.setConfig(*config); !s) return s;
    in_use_ = config;
    return Status::ok();
  }
  void invalidate() { in_use_ = nullptr; }
  // Foveates the cloud of the last backproject() (map source: with the map's
  // surfels the eye at gaze.origin_m sees appended first, afresh at each call).
  Status foveate(const pipeline::Gaze& gaze, pipeline::FoveatedCloud& out, pipeline::FoveationStats& stats);

  FoveationSource source() const { return source_; }
  const pipeline::PointCloud& cloud() const { return cloud_; }
  pipeline::Foveator& foveator() { return foveator_; }
  const pipeline::DepthRange& range() const { return range_; }
  // The map source's map and its figures for the last frame (null / zero otherwise).
  const pipeline::map::SurfelMap* map() const { return map_.get(); }
  const MapFrameFigures& mapFigures() const { return map_figures_; }
  // Bytes the map source allocated (the map and the eye's depth buffer).
  std::size_t mapMemoryBytes() const { return map_ ? map_->memoryBytes() + eye_->memoryBytes() : 0; }

 private:
  FrameFoveator(pipeline::Foveator foveator, const pipeline::PipelineCapacity& capacity,
                const pipeline::DepthRange& range)
      : foveator_(std::move(foveator)),
        backprojector_(capacity.threads, capacity.kernels),
        cloud_(capacity.max_points),
        range_(range) {}

  pipeline::Foveator foveator_;
  pipeline::Backprojector backprojector_;
  pipeline::PointCloud cloud_;
  pipeline::DepthRange range_;
  const pipeline::FoveationConfig* in_use_ = nullptr;
  FoveationSource source_ = FoveationSource::kFrame;
  std::unique_ptr<pipeline::map::SurfelMap> map_;
  std::unique_ptr<pipeline::map::EyeView> eye_;
  MapFrameFigures map_figures_;
};

}  // namespace fovea::firmware

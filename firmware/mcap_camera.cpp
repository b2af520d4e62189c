#include "firmware/mcap_camera.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <thread>
#include <vector>

#include "firmware/frame_record.h"
#include "hal/spec_options.h"

namespace fovea::firmware {
namespace {

Status invalid(const std::string& why) { return {ErrorCode::kInvalidArgument, "mcap: " + why}; }

}  // namespace

Result<McapCameraOptions> parseMcapCameraOptions(std::string_view args) {
  McapCameraOptions options;
  const hal::SpecTokens tokens = hal::tokenizeSpec(args);
  const std::string_view path = tokens.head.value_or("");
  if (path.empty()) return invalid("expected mcap:FILE.mcap[,loop=on|off,realtime=on|off]");
  options.path = std::string(path);
  for (const auto& [key, value, has_value] : tokens.items) {
    if (!has_value) return invalid("option '" + std::string(key) + "' is not key=value (keys: loop, realtime)");
    if (key == "loop") {
      if (Status s = hal::parseSpecOnOff("mcap", key, value, options.loop); !s) return s;
    } else if (key == "realtime") {
      if (Status s = hal::parseSpecOnOff("mcap", key, value, options.realtime); !s) return s;
    } else {
      return invalid("unknown option '" + std::string(key) + "' (keys: loop, realtime)");
    }
  }
  return options;
}

std::string mcapCameraHelp() {
  return "mcap:FILE[,loop=on|off,realtime=on|off]  the frames of a session recorded with fovead serve --record FILE "
         "--record-frames (docs/recording.md), bit for bit; loop=on (default) restarts at the end, realtime=on paces "
         "frames to their timestamps";
}

McapCamera::McapCamera(McapCameraOptions options) : options_(std::move(options)) {
  info_.name = "mcap:" + options_.path;
}

McapCamera::~McapCamera() { unmap(); }

Result<std::unique_ptr<hal::Camera>> McapCamera::create(std::string_view args) {
  Result<McapCameraOptions> options = parseMcapCameraOptions(args);
  if (!options) return options.status();
  return std::unique_ptr<hal::Camera>(new McapCamera(std::move(options.value())));
}

void McapCamera::unmap() {
  reader_.reset();
  file_ = mcap::MappedFile();
}

// What open()'s pass through the file found, beside what it sets on the camera
// (the frames channel, the frame count, the first frame's intrinsics).
struct McapCamera::Scan {
  hal::RgbdFrame scratch;  // sized for the largest frame
  std::size_t scratch_pixels = 0;
  std::vector<int64_t> stamps;
  bool have_channel = false;
  std::size_t bad = 0;
  std::string first_bad;
  int max_width = 0, max_height = 0;
};

Status McapCamera::open() {
  unmap();
  opened_ = started_ = finished_ = false;
  frame_count_ = 0;
  Result<mcap::MappedFile> mapped = mcap::MappedFile::open(options_.path);
  if (!mapped) return Status(mapped.status().code(), "mcap: " + mapped.status().message());
  file_ = std::move(mapped.value());

  // Once through the file: the frames channel, every frame checked, the size,
  // the stamps and where the file stops being readable.
  // The reader stays for the replay: it keeps the schemas, channels and its
  // chunk buffer from this pass, so acquire() allocates nothing.
  reader_ = std::make_unique<mcap::Reader>(file_.bytes());
  Scan scan;
  if (Status s = scanFrames(scan); !s) {
    unmap();
    return s;
  }
  stop_reason_ = reader_->complete() ? std::string() : reader_->stopReason();
  if (!scan.have_channel || frame_count_ == 0) {
    unmap();
    return noFramesError(scan);
  }
  describeRecording(scan);
  for (std::size_t i = 0; i < scan.bad; ++i) counters_.badFrame();
  reader_->rewind();
  opened_ = true;
  loops_ = 0;
  start_stamp_known_ = false;
  return Status::ok();
}

Status McapCamera::scanFrames(Scan& scan) {
  mcap::Reader& reader = *reader_;
  for (mcap::Reader::Item item = reader.next(); item != mcap::Reader::Item::kEnd; item = reader.next()) {
    if (item == mcap::Reader::Item::kChannel && reader.channel().topic == kFramesTopic) {
      const mcap::SchemaRecord* schema = reader.findSchema(reader.channel().schema_id);
      if (schema == nullptr || schema->name != kFrameRecordSchemaName) {
        return {ErrorCode::kInvalidInput, "mcap: '" + options_.path + "': channel " + std::string(kFramesTopic) +
                                              " is not of schema " + kFrameRecordSchemaName};
      }
      frames_channel_ = reader.channel().id;
      scan.have_channel = true;
      continue;
    }
    if (item != mcap::Reader::Item::kMessage || !scan.have_channel || reader.message().channel_id != frames_channel_) continue;
    scanFrame(reader.message().data, scan);
  }
  return Status::ok();
}

void McapCamera::scanFrame(std::span<const uint8_t> data, Scan& scan) {
  // A slot for the frame's size (open() may allocate; the record's own checks follow).
  if (data.size() >= kFrameRecordHeaderBytes) {
    uint32_t w = 0, h = 0;
    std::memcpy(&w, data.data() + 8, 4);
    std::memcpy(&h, data.data() + 12, 4);
    if (w > 0 && h > 0 && w <= 16384 && h <= 16384 && std::size_t{w} * h > scan.scratch_pixels) {
      scan.scratch = hal::RgbdFrame(static_cast<int>(w), static_cast<int>(h));
      scan.scratch_pixels = std::size_t{w} * h;
    }
  }
  hal::RgbdFrame& scratch = scan.scratch;
  if (Status s = decodeFrameRecord(data, scratch); !s) {
    if (scan.bad++ == 0) scan.first_bad = s.message();
    return;
  }
  if (scratch.width() * scratch.height() > scan.max_width * scan.max_height) {
    scan.max_width = scratch.width();
    scan.max_height = scratch.height();
  }
  if (frame_count_ == 0) {
    info_.intrinsics = scratch.intrinsics;
    info_.depth_scale_m = scratch.depth_scale_m;
  }
  scan.stamps.push_back(scratch.stamp_ns);
  ++frame_count_;
}

Status McapCamera::noFramesError(const Scan& scan) const {
  const std::string why = !scan.have_channel
                              ? "has no " + std::string(kFramesTopic) + " channel"
                              : "has no readable frame" + (scan.bad > 0 ? " (" + scan.first_bad + ")" : std::string());
  return {ErrorCode::kNotFound, "mcap: '" + options_.path + "' " + why + (stop_reason_.empty() ? "" : "; " + stop_reason_) +
                                    ": record the camera with fovead serve --record FILE --record-frames"};
}

void McapCamera::describeRecording(const Scan& scan) {
  const std::vector<int64_t>& stamps = scan.stamps;
  const int64_t span_ns = stamps.back() - stamps.front();
  const int64_t period_ns =
      stamps.size() > 1 && span_ns > 0 ? span_ns / static_cast<int64_t>(stamps.size() - 1) : 33'333'333;
  loop_period_ns_ = span_ns + period_ns;
  info_.fps = 1e9 / static_cast<double>(period_ns);
  info_.model = "fovea recording, " + std::to_string(frame_count_) + " frames" +
                (scan.bad > 0 ? ", " + std::to_string(scan.bad) + " unreadable (" + scan.first_bad + ")" : std::string()) +
                (stop_reason_.empty() ? std::string() : "; cut short: " + stop_reason_);
}

Status McapCamera::start() {
  if (!opened_) return Status(ErrorCode::kUnavailable, "mcap camera: call open() before start()");
  started_ = true;
  start_time_ = std::chrono::steady_clock::now();
  start_stamp_known_ = false;
  return Status::ok();
}

void McapCamera::stop() { started_ = false; }

bool McapCamera::nextFrameMessage(std::span<const uint8_t>& data) {
  for (mcap::Reader::Item item = reader_->next(); item != mcap::Reader::Item::kEnd; item = reader_->next()) {
    if (item == mcap::Reader::Item::kMessage && reader_->message().channel_id == frames_channel_) {
      data = reader_->message().data;
      return true;
    }
  }
  return false;
}

// Error messages stay within std::string's small-buffer capacity (15
// characters in libstdc++), so even the error paths do not allocate.
Status McapCamera::acquire(hal::RgbdFrame& slot, std::chrono::nanoseconds timeout) {
  if (!started_) {
    counters_.error();
    return Status(ErrorCode::kUnavailable, "not started");
  }
  if (finished_) return Status(ErrorCode::kUnavailable, "end of record");
  std::span<const uint8_t> data = pending_;
  pending_ = {};
  if (data.empty() && !nextFrameMessage(data)) {
    // The end of the file (or of what of it is readable): the next pass.
    ++loops_;
    if (!options_.loop) {
      finished_ = true;
      return Status(ErrorCode::kUnavailable, "end of record");
    }
    reader_->rewind();
    if (!nextFrameMessage(data)) {
      finished_ = true;
      return Status(ErrorCode::kUnavailable, "end of record");
    }
  }
  const int64_t loop_offset_ns = static_cast<int64_t>(loops_) * loop_period_ns_;
  int64_t recorded_stamp_ns = 0;
  if (data.size() >= kFrameRecordHeaderBytes) std::memcpy(&recorded_stamp_ns, data.data() + 24, 8);
  const int64_t stamp_ns = recorded_stamp_ns + loop_offset_ns;
  if (options_.realtime) {
    using Clock = std::chrono::steady_clock;
    if (!start_stamp_known_) {
      start_stamp_ns_ = stamp_ns;
      start_stamp_known_ = true;
    }
    const Clock::time_point due = start_time_ + std::chrono::nanoseconds(stamp_ns - start_stamp_ns_);
    const Clock::time_point now = Clock::now();
    if (due > now && due - now > timeout) {
      // Not yet: this frame is read again at the next call.
      std::this_thread::sleep_for(timeout);
      counters_.timeout();
      pending_ = data;
      return Status(ErrorCode::kUnavailable, "timeout");
    }
    if (due > now) std::this_thread::sleep_until(due);
  }
  if (Status s = decodeFrameRecord(data, slot); !s) {
    // A slot smaller than the frame keeps the frame for the next call; a frame
    // that does not read (checked at open(): cannot happen unless the file changed) is skipped.
    if (s.message().find("larger than the frame slot") != std::string::npos) {
      pending_ = data;
      counters_.error();
      return Status(ErrorCode::kCapacityExceeded, "slot too small");
    }
    counters_.badFrame();
    return Status(ErrorCode::kInvalidInput, "bad frame");
  }
  slot.stamp_ns = stamp_ns;
  slot.sequence += static_cast<uint64_t>(loops_) * frame_count_;
  counters_.frameDelivered();
  return Status::ok();
}

Result<std::unique_ptr<hal::Camera>> createCamera(std::string_view spec) {
  if (spec.rfind("mcap:", 0) == 0 || spec == "mcap") {
    return McapCamera::create(spec.size() > 5 ? spec.substr(5) : std::string_view());
  }
  Result<std::unique_ptr<hal::Camera>> created = hal::createCamera(spec);
  if (!created && created.status().message().find("unknown backend") != std::string::npos) {
    return Status(created.status().code(), created.status().message() + "; or mcap:FILE, a fovea recording");
  }
  return created;
}

std::string cameraSpecHelp() { return hal::cameraSpecHelp() + mcapCameraHelp() + "\n"; }

}  // namespace fovea::firmware

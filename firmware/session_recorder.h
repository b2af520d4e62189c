// `fovead serve --record FILE.mcap`: one MCAP file per session (docs/recording.md),
// written by io/mcap's Recorder. The service's threads hand it bytes; each
// thread has its own producer ring, so every call here only copies bytes into a
// preallocated slot (never blocks, never allocates; a full ring or disk drops
// and counts).
//
// Channels (topic: message encoding, schema):
//   /fovea/chunks         fovea.chunk: every point chunk payload as the streamer
//                         sent it (plaintext, before sealing); schema: protocol
//                         version and docs/protocol-chunks.md
//   /fovea/frame_summary  fovea.flatbuffer: each frame's summary as sent;
//                         schema: net/schema/chunk.fbs
//   /fovea/brick_chunks   fovea.chunk: the map's brick parts as sent (map.delta)
//   /fovea/gaze           fovea.flatbuffer: each gaze sample (with the HMD pose)
//                         as it came, decrypted; schema: net/schema/control.fbs
//   /fovea/camera_pose    json: the camera pose of each frame foveated, and with
//                         tracking its outcome and moving share
//   /fovea/status         json: the status lines
//
// Threads: onSent and onReceived are the send stage's (fovea-send), onFrame the
// foveation stage's (fovea-foveate), onStatusLine the supervisor's.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "core/result.h"
#include "firmware/log.h"
#include "hal/frame.h"
#include "io/foxglove/recording.h"
#include "io/mcap/recorder.h"
#include "net/stream_channels.h"
#include "net/wire.h"
#include "pipeline/map/tracker.h"
#include "pipeline/point_cloud.h"

namespace fovea::firmware {

struct RecordSettings {
  std::string path;                 // "": no recording
  std::size_t send_slots = 4096;    // datagrams queued from the send stage at most
  std::size_t frame_slots = 64;     // poses queued from the foveation stage
  std::size_t status_slots = 64;    // status lines queued
  std::size_t max_datagram_bytes = net::kMaxMtu;
  // --record-frames: every captured frame, raw (firmware/frame_record.h), on
  // /fovea/frames; the slots hold frames of up to frame_width x frame_height.
  bool frames = false;
  std::size_t frame_record_slots = 8;
  int frame_width = 0;
  int frame_height = 0;
  // The Foxglove channels (docs/recording.md): the foveated cloud of up to this
  // many points a frame (0: no foxglove.PointCloud channel).
  std::size_t max_cloud_points = 0;
  bool foxglove_cloud = true;  // --record-cloud off: no /fovea/cloud (16 bytes a point a frame)
  std::size_t cloud_slots = 4;
};

class SessionRecorder {
 public:
  // Creates the file and its channels and schemas (an error when the file
  // cannot be created). `log` gets the recorder's one line when the disk fails.
  static Result<std::unique_ptr<SessionRecorder>> create(const RecordSettings& settings, Logger& log);
  ~SessionRecorder();

  Status start();
  // Drains, writes the summary and the footer. Idempotent.
  Status close();

  // fovea-send: a datagram payload the streamer sent (Streamer::SendTap).
  void onSent(net::MessageType type, std::span<const uint8_t> payload, uint32_t frame_id, int64_t capture_ns);
  // fovea-send: an operator message the link decoded (RobotLink::ReceiveTap).
  void onReceived(net::MessageType type, std::span<const uint8_t> payload, int64_t received_ns);
  // fovea-foveate: one frame foveated: its pose, and its foveated points.
  // This is where channels built from the frame go (the Foxglove ones:
  // foxglove.PointCloud from `cloud`, foxglove.FrameTransform from the pose):
  // give them their own producer slots sized for the cloud, as frame_slots are.
  // track: the tracker's figures for the frame (nullptr: no tracking).
  void onFrame(uint32_t frame_id, int64_t captured_ns, const hal::RgbdFrame& frame, bool pose_fresh,
               const pipeline::FoveatedCloud& cloud, const pipeline::map::TrackStats* track);
  // fovea-capture: a frame as the camera gave it (with --record-frames; the
  // pose source's pose applied). A frame larger than the slots is dropped and counted.
  void onCapture(const hal::RgbdFrame& frame);
  // The supervisor: one status line.
  void onStatusLine(std::string_view line);

  mcap::RecorderCounters counters() const { return recorder_->counters(); }
  // "recording FILE: N messages, B MB (R MB/min); dropped: ring full A, too big B, disk C"
  std::string summary() const;
  std::size_t ringBytes() const { return recorder_->ringBytes(); }
  const std::string& path() const { return recorder_->path(); }

 private:
  SessionRecorder() = default;
  std::unique_ptr<mcap::Recorder> recorder_;
  mcap::RecorderProducer* send_ = nullptr;
  mcap::RecorderProducer* frames_ = nullptr;
  mcap::RecorderProducer* status_ = nullptr;
  mcap::RecorderProducer* raw_ = nullptr;  // --record-frames
  uint16_t frames_channel_ = 0;
  // The Foxglove channels (io/foxglove/recording.h), whose transcoders the
  // writer thread calls: ~SessionRecorder's close() joins it before they go.
  std::unique_ptr<foxglove::RecordingChannels> foxglove_;
  mcap::RecorderProducer* cloud_ = nullptr;  // fovea-foveate: the cloud's arrays
  net::StreamChannels stream_;
  uint16_t pose_ = 0, status_channel_ = 0;
};

}  // namespace fovea::firmware

// What fovea-operator sets up before its first hello (the gaze script, the link's
// configuration, the frame assembler, the map, the viewer, the Foxglove server,
// the recording and the frame log), and the recording's close at the end.
#pragma once

#include <cstdint>
#include <fstream>
#include <memory>
#include <optional>
#include <string_view>

#include "io/foxglove/foxglove.h"
#include "io/foxglove/recording.h"
#include "io/mcap/recorder.h"
#include "net/codec.h"
#include "net/operator_link.h"
#include "net/stream_channels.h"
#include "tools/operator/foxglove_server.h"
#include "tools/operator/gaze_script.h"
#include "tools/operator/map_holder.h"
#include "tools/operator/operator_exit.h"
#include "tools/operator/operator_options.h"
#include "tools/operator/view_server.h"

namespace fovea::tools {

// What the operator sets up before its first hello. In this order, so that
// they are torn down in the reverse one.
struct Station {
  std::optional<tools::GazeScript> script;
  net::OperatorLinkConfig link_config;
  std::optional<net::FrameAssembler> assembler;
  std::optional<tools::MapHolder> map;
  std::unique_ptr<tools::ViewServer> view;
  std::unique_ptr<tools::FoxgloveServer> foxglove;
  std::ofstream frame_log;
  // --record: the file, its producers (all the receive loop's) and channels. The
  // Foxglove channels' transcoders outlive the recorder's writer thread (declared first).
  std::unique_ptr<foxglove::RecordingChannels> record_foxglove;
  std::unique_ptr<mcap::Recorder> recorder;
  mcap::RecorderProducer* record_producer = nullptr;
  mcap::RecorderProducer* record_clouds = nullptr;
  net::StreamChannels record_channels;
};

// The Foxglove channels (--foxglove).
inline constexpr uint32_t kFoxCloud = 1, kFoxHead = 2, kFoxGaze = 3, kFoxLog = 4;
inline constexpr std::string_view kFoxWorld = foxglove::kWorldFrame;

// Everything the station sets up, in the order it always has (the first failure is the one reported).
Exit setUp(const OperatorOptions& opt, Station& station);

// --record: closes the file and prints its line of the summary; nothing without one.
void closeRecording(Station& station);

}  // namespace fovea::tools

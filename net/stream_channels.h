// The MCAP channels of what travels the link, in the one layout both ends
// record: `fovead serve --record` (what the streamer sent, what the link
// received) and `fovea-operator --record` (what the operator received). Either
// file replays through `fovea-operator --replay` (docs/recording.md).
//
//   /fovea/chunks         fovea.chunk: point chunk payloads (plaintext); schema:
//                         the protocol version and docs/protocol-chunks.md
//   /fovea/frame_summary  fovea.flatbuffer: frame summaries; schema: net/schema/chunk.fbs
//   /fovea/brick_chunks   fovea.chunk: the map's brick parts (map.delta)
//   /fovea/gaze           fovea.flatbuffer: gaze samples with the HMD pose;
//                         schema: net/schema/control.fbs and geometry.fbs
#pragma once

#include <cstdint>
#include <optional>
#include <string_view>

#include "core/result.h"
#include "io/mcap/recorder.h"
#include "net/wire.h"

namespace fovea::net {

inline constexpr std::string_view kChunksTopic = "/fovea/chunks";
inline constexpr std::string_view kFrameSummaryTopic = "/fovea/frame_summary";
inline constexpr std::string_view kBrickChunksTopic = "/fovea/brick_chunks";
inline constexpr std::string_view kGazeTopic = "/fovea/gaze";

struct StreamChannels {
  uint16_t chunks = 0;
  uint16_t summaries = 0;
  uint16_t bricks = 0;
  uint16_t gaze = 0;
  // The channel of a message type; 0 for a type no recording keeps.
  uint16_t channelOf(MessageType type) const;
};

// Adds the schemas and channels above to a recorder before its start().
Result<StreamChannels> addStreamChannels(mcap::Recorder& recorder);

// The message type a recorded topic carries (nullopt: not one of the link's).
std::optional<MessageType> streamMessageType(std::string_view topic);

}  // namespace fovea::net

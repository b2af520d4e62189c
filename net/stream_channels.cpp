#include "net/stream_channels.h"

#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "net/recording_schemas.h"

namespace fovea::net {
namespace {

std::span<const uint8_t> bytesOf(std::string_view s) { return {reinterpret_cast<const uint8_t*>(s.data()), s.size()}; }

std::vector<uint8_t> concat(std::initializer_list<std::span<const uint8_t>> parts) {
  std::vector<uint8_t> out;
  for (std::span<const uint8_t> p : parts) out.insert(out.end(), p.begin(), p.end());
  return out;
}

}  // namespace

uint16_t StreamChannels::channelOf(MessageType type) const {
  switch (type) {
    case MessageType::kChunk: return chunks;
    case MessageType::kFrameSummary: return summaries;
    case MessageType::kBrickChunk: return bricks;
    case MessageType::kGaze: return gaze;
    default: return 0;
  }
}

Result<StreamChannels> addStreamChannels(mcap::Recorder& m) {
  char version[160];
  std::snprintf(version, sizeof version,
                "fovea stream protocol version %u: point chunk payloads as sent (plaintext), "
                "laid out as the document below says\n\n",
                static_cast<unsigned>(kProtocolVersion));
  const std::vector<uint8_t> chunk_schema = concat({bytesOf(version), protocolChunksText()});
  const std::vector<uint8_t> control_schema = concat({controlFbsText(), bytesOf("\n// geometry.fbs\n"), geometryFbsText()});
  Result<uint16_t> chunk_id = m.addSchema("fovea.Chunk", "fovea.chunk", chunk_schema);
  Result<uint16_t> summary_id = m.addSchema("fovea.net.wire.FrameSummary", "fovea.flatbuffer.fbs", chunkFbsText());
  Result<uint16_t> gaze_id = m.addSchema("fovea.net.wire.Gaze", "fovea.flatbuffer.fbs", control_schema);
  for (const Result<uint16_t>* id : {&chunk_id, &summary_id, &gaze_id}) {
    if (!*id) return id->status();
  }
  char protocol[8];
  std::snprintf(protocol, sizeof protocol, "%u", static_cast<unsigned>(kProtocolVersion));
  const std::pair<std::string, std::string> meta[] = {{"protocol_version", protocol}};
  Result<uint16_t> chunks = m.addChannel(kChunksTopic, "fovea.chunk", *chunk_id, meta);
  Result<uint16_t> summaries = m.addChannel(kFrameSummaryTopic, "fovea.flatbuffer", *summary_id, meta);
  Result<uint16_t> bricks = m.addChannel(kBrickChunksTopic, "fovea.chunk", *chunk_id, meta);
  Result<uint16_t> gaze = m.addChannel(kGazeTopic, "fovea.flatbuffer", *gaze_id, meta);
  for (const Result<uint16_t>* id : {&chunks, &summaries, &bricks, &gaze}) {
    if (!*id) return id->status();
  }
  return StreamChannels{*chunks, *summaries, *bricks, *gaze};
}

std::optional<MessageType> streamMessageType(std::string_view topic) {
  if (topic == kChunksTopic) return MessageType::kChunk;
  if (topic == kFrameSummaryTopic) return MessageType::kFrameSummary;
  if (topic == kBrickChunksTopic) return MessageType::kBrickChunk;
  if (topic == kGazeTopic) return MessageType::kGaze;
  return std::nullopt;
}

}  // namespace fovea::net

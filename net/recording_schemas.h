// The texts a recording embeds as its channels' schemas, compiled in from the
// source tree (net/CMakeLists.txt generates recording_schemas.cpp), so a
// recording describes its own bytes whatever version of fovea reads it.
#pragma once

#include <cstdint>
#include <span>

namespace fovea::net {

std::span<const uint8_t> protocolChunksText();  // docs/protocol-chunks.md: the v2 point chunk format
std::span<const uint8_t> chunkFbsText();        // net/schema/chunk.fbs: the frame summary
std::span<const uint8_t> controlFbsText();      // net/schema/control.fbs: gaze and the control messages
std::span<const uint8_t> geometryFbsText();     // net/schema/geometry.fbs: Vec3d, Quatd

}  // namespace fovea::net

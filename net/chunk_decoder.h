// What the rest of the codec uses of net/chunk_decoder.cpp beyond net/codec.h
// (internal: net/frame_assembler.cpp warms the decoder's per-thread state).
#pragma once

namespace fovea::net::codec_detail {

// Allocates the calling thread's decompression context and buffer now, so that
// no later decodeChunk() on this thread allocates.
void warmThreadDecoder();

}  // namespace fovea::net::codec_detail

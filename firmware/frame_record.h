// A camera frame as a recording keeps it: `fovead serve --record-frames` writes
// one per captured frame into the session's MCAP file (channel /fovea/frames,
// docs/recording.md), and the `mcap:` camera reads them back, so a recorded
// session replays through the pipeline bit for bit.
//
// Little-endian, a fixed header and then the images exactly as the camera gave
// them (the MCAP chunk's zstd compresses them):
//
//   offset  size      field
//   0       4         magic "FVFR"
//   4       2         version (kFrameRecordVersion)
//   6       2         flags: bit 0 has colour
//   8       4         width (pixels)
//   12      4         height
//   16      8         camera sequence
//   24      8         capture stamp (ns, the camera's clock)
//   32      4 x 8     fx, fy, cx, cy (double)
//   64      8         depth scale (metres per depth unit, double)
//   72      9 x 8     R_world_cam, row-major (double)
//   144     3 x 8     t_world_cam (metres, double)
//   168     w*h*2     depth, row-major uint16 (0: no measurement)
//   ...     w*h*3     colour RGB8, registered to the depth (only with flag bit 0)
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

#include "core/result.h"
#include "hal/frame.h"

namespace fovea::firmware {

inline constexpr std::string_view kFramesTopic = "/fovea/frames";
inline constexpr uint16_t kFrameRecordVersion = 1;
inline constexpr std::size_t kFrameRecordHeaderBytes = 168;
// The MCAP schema of the channel: its name, and the layout above as its text.
inline constexpr const char* kFrameRecordSchemaName = "fovea.FrameRecord";
std::span<const uint8_t> frameRecordSchemaText();

// The bytes a record of a width x height frame takes.
std::size_t frameRecordBytes(int width, int height, bool has_rgb);

// The header alone: a record is it, then frame.depth() (pixels x 2 bytes), then
// frame.rgb() (pixels x 3) when frame.has_rgb; for writers that gather the
// parts instead of copying the images twice (the recorder's slot is the copy).
void encodeFrameRecordHeader(const hal::RgbdFrame& frame, std::span<uint8_t, kFrameRecordHeaderBytes> out);

// Writes `frame` into `out`; the bytes written, or 0 when `out` is too small.
// Never allocates (the recorder calls it on the capture path).
std::size_t encodeFrameRecord(const hal::RgbdFrame& frame, std::span<uint8_t> out);

// Reads a record into `frame` (sized for it: a larger frame than the slot is an
// error, not a resize). Every field is checked: a record that is short, long, of
// another version, or with a size, intrinsics, scale or pose that no camera gives
// is an error that says which, and `frame` is then unspecified.
Status decodeFrameRecord(std::span<const uint8_t> record, hal::RgbdFrame& frame);

}  // namespace fovea::firmware

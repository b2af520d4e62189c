// One V4L2 capture node: open and capability check, format enumeration and
// negotiation, mmap streaming buffers (allocated at open, counted), and the
// per-frame dequeue/requeue that allocates nothing. Depth nodes use raw
// open/ioctl (libv4l2 does not convert depth formats and would only add a
// copy); colour nodes go through libv4l2 (v4l2_open, v4l2_ioctl, v4l2_mmap) so
// it can convert a format fovea does not decode into RGB3. Every ioctl is
// retried on EINTR.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "core/result.h"

namespace fovea::hal::v4l2 {

struct NodeCaps {
  std::string driver;    // "uvcvideo", "vivid"
  std::string card;      // "Intel(R) RealSense(TM) Depth Ca"
  std::string bus_info;  // "usb-0000:01:00.0-1", "platform:vivid-000"
  bool capture = false;    // V4L2_CAP_VIDEO_CAPTURE
  bool streaming = false;  // V4L2_CAP_STREAMING
};

struct FrameSize {
  int width = 0;
  int height = 0;
  // Stepwise or continuous sizes (vivid's non-webcam inputs): a range.
  bool range = false;
  int max_width = 0;
  int max_height = 0;
};

class V4l2Node {
 public:
  enum class Io : uint8_t { kRaw, kLibv4l2 };

  explicit V4l2Node(Io io) : io_(io) {}
  ~V4l2Node() { close(); }
  V4l2Node(const V4l2Node&) = delete;
  V4l2Node& operator=(const V4l2Node&) = delete;

  // Opens the node non-blocking and checks it can capture by streaming.
  // kNotFound (absent), kUnavailable (permission: the video group and the
  // udev rule; busy), kInvalidArgument (not a capture node).
  Status open(const std::string& path);
  // Every negotiation call below needs an open node.
  bool isOpen() const { return fd_ >= 0; }
  const std::string& path() const { return path_; }
  const NodeCaps& caps() const { return caps_; }

  std::vector<uint32_t> formats() const;
  std::vector<FrameSize> frameSizes(uint32_t fourcc) const;
  // Discrete frame rates the node offers for this format and size (fps), highest first.
  std::vector<double> frameRates(uint32_t fourcc, int width, int height) const;

  // S_FMT, then checks the driver kept the format and size (it may adjust them).
  Status setFormat(uint32_t fourcc, int width, int height);
  // S_PARM 1/fps; the rate the driver took is fps() (0 when it does not say).
  Status setFps(int fps);
  double fps() const { return fps_; }
  uint32_t pixelFormat() const { return pixel_format_; }
  int width() const { return width_; }
  int height() const { return height_; }
  std::size_t bytesPerLine() const { return bytes_per_line_; }
  std::size_t sizeImage() const { return size_image_; }

  // REQBUFS (MMAP), QUERYBUF and mmap of each; the bytes mapped are mappedBytes().
  Status allocateBuffers(int count);
  std::size_t mappedBytes() const { return mapped_bytes_; }
  int bufferCount() const { return static_cast<int>(buffers_.size()); }

  // QBUF every buffer, STREAMON.
  Status startStreaming();
  // STREAMOFF (errors ignored: the device may be gone).
  void stopStreaming();
  bool streaming() const { return streaming_; }
  // stopStreaming, munmap, REQBUFS 0 and close; safe to call twice.
  void close();

  int fd() const { return fd_; }
  // The errno of the last failed open() (0 after a success or another failure).
  int lastOpenErrno() const { return last_open_errno_; }
  // Whether the node is still registered (VIDIOC_QUERYCAP does not fail with
  // ENODEV); no allocation.
  bool present() const;

  struct Frame {
    int index = -1;
    const uint8_t* data = nullptr;
    std::size_t bytesused = 0;
    int64_t stamp_ns = 0;       // CLOCK_MONOTONIC
    bool error_flag = false;    // V4L2_BUF_FLAG_ERROR: the driver says the data is corrupt
    bool stamp_from_driver = false;  // false: the driver's stamps are not monotonic, taken at dequeue
    uint32_t sequence = 0;
  };
  // DQBUF (non-blocking; poll fd() first): 0 and `frame` filled, else the
  // errno (EAGAIN nothing ready, ENODEV the device went away). No allocation.
  int dequeue(Frame& frame);
  // QBUF of a buffer dequeue() gave: 0 or the errno.
  int requeue(int index);

 private:
  int ioctl(unsigned long request, void* arg) const;

  Io io_;
  int fd_ = -1;
  std::string path_;
  NodeCaps caps_;
  uint32_t pixel_format_ = 0;
  int width_ = 0;
  int height_ = 0;
  std::size_t bytes_per_line_ = 0;
  std::size_t size_image_ = 0;
  double fps_ = 0.0;
  struct Buffer {
    void* start = nullptr;
    std::size_t length = 0;
  };
  std::vector<Buffer> buffers_;
  std::size_t mapped_bytes_ = 0;
  bool streaming_ = false;
  int last_open_errno_ = 0;
};

// The message for a failed open() of `path` (errno `err`): what it means and
// what to do (plugged in? video group / udev rule? who holds it?).
Status nodeOpenError(const std::string& path, int err);

}  // namespace fovea::hal::v4l2

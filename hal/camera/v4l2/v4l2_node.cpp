#include "hal/camera/v4l2/v4l2_node.h"

#include <fcntl.h>
#include <libv4l2.h>
#include <linux/videodev2.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <ctime>

#include "core/clock.h"
#include "hal/camera/v4l2/v4l2_options.h"

namespace fovea::hal::v4l2 {

namespace {

std::string cString(const uint8_t* text, std::size_t size) {
  std::size_t n = 0;
  while (n < size && text[n] != 0) ++n;
  return std::string(reinterpret_cast<const char*>(text), n);
}

}  // namespace

Status nodeOpenError(const std::string& path, int err) {
  switch (err) {
    case ENOENT:
    case ENODEV:
    case ENXIO:
      return {ErrorCode::kNotFound, "v4l2: " + path +
                                        " does not exist: is the camera plugged in? `v4l2-ctl --list-devices` lists "
                                        "the video nodes, `fovead cameras` the depth cameras fovea can use"};
    case EACCES:
    case EPERM:
      return {ErrorCode::kUnavailable,
              "v4l2: permission denied opening " + path +
                  ": add the service's user to the video group (sudo usermod -aG video $USER, then log in again) or "
                  "install fovea's udev rule 60-fovea-rgbd-cameras.rules (docs/cameras-usb.md)"};
    case EBUSY:
      return {ErrorCode::kUnavailable, "v4l2: " + path +
                                           " is busy: another program is streaming from it (`fuser -v " + path +
                                           "` names it); stop it or pick another node"};
    default:
      return {ErrorCode::kIoError, "v4l2: cannot open " + path + ": " + std::strerror(err)};
  }
}

int V4l2Node::ioctl(unsigned long request, void* arg) const {
  int r = 0;
  do {
    r = io_ == Io::kLibv4l2 ? v4l2_ioctl(fd_, request, arg) : ::ioctl(fd_, request, arg);
  } while (r == -1 && errno == EINTR);
  return r == -1 ? errno : 0;
}

Status V4l2Node::open(const std::string& path) {
  close();
  path_ = path;
  last_open_errno_ = 0;
  int fd = -1;
  do {
    fd = io_ == Io::kLibv4l2 ? v4l2_open(path.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC)
                             : ::open(path.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
  } while (fd == -1 && errno == EINTR);
  if (fd == -1) {
    last_open_errno_ = errno;
    return nodeOpenError(path, last_open_errno_);
  }
  fd_ = fd;
  v4l2_capability cap{};
  if (const int err = ioctl(VIDIOC_QUERYCAP, &cap); err != 0) {
    close();
    return {ErrorCode::kInvalidArgument,
            "v4l2: " + path + " is not a V4L2 device (VIDIOC_QUERYCAP: " + std::strerror(err) + ")"};
  }
  caps_.driver = cString(cap.driver, sizeof(cap.driver));
  caps_.card = cString(cap.card, sizeof(cap.card));
  caps_.bus_info = cString(cap.bus_info, sizeof(cap.bus_info));
  const uint32_t node_caps = (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
  caps_.capture = (node_caps & V4L2_CAP_VIDEO_CAPTURE) != 0;
  caps_.streaming = (node_caps & V4L2_CAP_STREAMING) != 0;
  if (!caps_.capture || !caps_.streaming) {
    const std::string what = caps_.capture ? "cannot stream (no V4L2_CAP_STREAMING)"
                                           : "is not a video capture node (a metadata or output node?)";
    close();
    return {ErrorCode::kInvalidArgument, "v4l2: " + path + " (" + caps_.card + ") " + what +
                                             "; `fovead cameras` lists the nodes that give depth"};
  }
  return Status::ok();
}

std::vector<uint32_t> V4l2Node::formats() const {
  std::vector<uint32_t> out;
  for (uint32_t i = 0; i < 256; ++i) {
    v4l2_fmtdesc desc{};
    desc.index = i;
    desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (ioctl(VIDIOC_ENUM_FMT, &desc) != 0) break;
    out.push_back(desc.pixelformat);
  }
  return out;
}

std::vector<FrameSize> V4l2Node::frameSizes(uint32_t fourcc) const {
  std::vector<FrameSize> out;
  for (uint32_t i = 0; i < 256; ++i) {
    v4l2_frmsizeenum size{};
    size.index = i;
    size.pixel_format = fourcc;
    if (ioctl(VIDIOC_ENUM_FRAMESIZES, &size) != 0) break;
    if (size.type == V4L2_FRMSIZE_TYPE_DISCRETE) {
      out.push_back({static_cast<int>(size.discrete.width), static_cast<int>(size.discrete.height), false, 0, 0});
    } else {
      out.push_back({static_cast<int>(size.stepwise.min_width), static_cast<int>(size.stepwise.min_height), true,
                     static_cast<int>(size.stepwise.max_width), static_cast<int>(size.stepwise.max_height)});
      break;  // stepwise and continuous have only index 0
    }
  }
  return out;
}

std::vector<double> V4l2Node::frameRates(uint32_t fourcc, int width, int height) const {
  std::vector<double> out;
  for (uint32_t i = 0; i < 64; ++i) {
    v4l2_frmivalenum ival{};
    ival.index = i;
    ival.pixel_format = fourcc;
    ival.width = static_cast<uint32_t>(width);
    ival.height = static_cast<uint32_t>(height);
    if (ioctl(VIDIOC_ENUM_FRAMEINTERVALS, &ival) != 0) break;
    if (ival.type != V4L2_FRMIVAL_TYPE_DISCRETE) break;
    if (ival.discrete.numerator != 0) {
      out.push_back(static_cast<double>(ival.discrete.denominator) / ival.discrete.numerator);
    }
  }
  std::sort(out.rbegin(), out.rend());
  return out;
}

Status V4l2Node::setFormat(uint32_t fourcc, int width, int height) {
  v4l2_format fmt{};
  fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  fmt.fmt.pix.pixelformat = fourcc;
  fmt.fmt.pix.width = static_cast<uint32_t>(width);
  fmt.fmt.pix.height = static_cast<uint32_t>(height);
  fmt.fmt.pix.field = V4L2_FIELD_NONE;
  if (const int err = ioctl(VIDIOC_S_FMT, &fmt); err != 0) {
    if (err == EBUSY) return nodeOpenError(path_, EBUSY);
    if (err == ENODEV) return nodeOpenError(path_, ENODEV);
    return {ErrorCode::kInvalidArgument, "v4l2: " + path_ + " refuses format " + fourccText(fourcc) + " " +
                                             std::to_string(width) + "x" + std::to_string(height) + ": " +
                                             std::strerror(err)};
  }
  if (fmt.fmt.pix.pixelformat != fourcc || static_cast<int>(fmt.fmt.pix.width) != width ||
      static_cast<int>(fmt.fmt.pix.height) != height) {
    return {ErrorCode::kInvalidArgument,
            "v4l2: " + path_ + " gives " + fourccText(fmt.fmt.pix.pixelformat) + " " +
                std::to_string(fmt.fmt.pix.width) + "x" + std::to_string(fmt.fmt.pix.height) + " when asked for " +
                fourccText(fourcc) + " " + std::to_string(width) + "x" + std::to_string(height) +
                "; `fovead cameras` lists the modes it offers"};
  }
  pixel_format_ = fourcc;
  width_ = width;
  height_ = height;
  bytes_per_line_ = fmt.fmt.pix.bytesperline;
  size_image_ = fmt.fmt.pix.sizeimage;
  if (bytes_per_line_ == 0) {
    // Compressed formats and some drivers leave it 0; packed formats are tight then.
    const std::size_t bpp = fourcc == V4L2_PIX_FMT_RGB24 || fourcc == V4L2_PIX_FMT_BGR24 ? 3 : 2;
    bytes_per_line_ = static_cast<std::size_t>(width) * bpp;
  }
  v4l2_streamparm parm{};
  parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  fps_ = 0.0;
  if (ioctl(VIDIOC_G_PARM, &parm) == 0 && parm.parm.capture.timeperframe.numerator != 0) {
    fps_ = static_cast<double>(parm.parm.capture.timeperframe.denominator) / parm.parm.capture.timeperframe.numerator;
  }
  return Status::ok();
}

Status V4l2Node::setFps(int fps) {
  v4l2_streamparm parm{};
  parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  parm.parm.capture.timeperframe.numerator = 1;
  parm.parm.capture.timeperframe.denominator = static_cast<uint32_t>(fps);
  if (const int err = ioctl(VIDIOC_S_PARM, &parm); err != 0) {
    return {ErrorCode::kInvalidArgument,
            "v4l2: " + path_ + " refuses " + std::to_string(fps) + " fps: " + std::strerror(err)};
  }
  if (parm.parm.capture.timeperframe.numerator != 0) {
    fps_ = static_cast<double>(parm.parm.capture.timeperframe.denominator) / parm.parm.capture.timeperframe.numerator;
  }
  return Status::ok();
}

Status V4l2Node::allocateBuffers(int count) {
  v4l2_requestbuffers req{};
  req.count = static_cast<uint32_t>(count);
  req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  req.memory = V4L2_MEMORY_MMAP;
  if (const int err = ioctl(VIDIOC_REQBUFS, &req); err != 0) {
    if (err == EBUSY) return nodeOpenError(path_, EBUSY);
    return {ErrorCode::kUnavailable, "v4l2: " + path_ + " gives no mmap streaming buffers (VIDIOC_REQBUFS: " +
                                         std::strerror(err) + ")"};
  }
  if (req.count < 2) {
    return {ErrorCode::kUnavailable, "v4l2: " + path_ + " gave " + std::to_string(req.count) +
                                         " streaming buffers, at least 2 are needed (out of memory?)"};
  }
  buffers_.reserve(req.count);
  for (uint32_t i = 0; i < req.count; ++i) {
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = i;
    if (const int err = ioctl(VIDIOC_QUERYBUF, &buf); err != 0) {
      return {ErrorCode::kIoError, "v4l2: " + path_ + ": VIDIOC_QUERYBUF: " + std::strerror(err)};
    }
    void* start = io_ == Io::kLibv4l2
                      ? v4l2_mmap(nullptr, buf.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, buf.m.offset)
                      : ::mmap(nullptr, buf.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, buf.m.offset);
    if (start == MAP_FAILED) {
      return {ErrorCode::kIoError, "v4l2: " + path_ + ": mmap of a streaming buffer (" +
                                       std::to_string(buf.length) + " bytes): " + std::strerror(errno)};
    }
    buffers_.push_back({start, buf.length});
    mapped_bytes_ += buf.length;
  }
  return Status::ok();
}

Status V4l2Node::startStreaming() {
  for (int i = 0; i < bufferCount(); ++i) {
    if (const int err = requeue(i); err != 0) {
      if (err == ENODEV) return nodeOpenError(path_, ENODEV);
      return {ErrorCode::kIoError, "v4l2: " + path_ + ": VIDIOC_QBUF: " + std::strerror(err)};
    }
  }
  int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (const int err = ioctl(VIDIOC_STREAMON, &type); err != 0) {
    if (err == EBUSY || err == ENODEV) return nodeOpenError(path_, err);
    return {ErrorCode::kIoError, "v4l2: " + path_ + ": VIDIOC_STREAMON: " + std::strerror(err)};
  }
  streaming_ = true;
  return Status::ok();
}

void V4l2Node::stopStreaming() {
  if (fd_ < 0) return;
  int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  (void)ioctl(VIDIOC_STREAMOFF, &type);  // also dequeues every buffer
  streaming_ = false;
}

void V4l2Node::close() {
  if (fd_ < 0) return;
  stopStreaming();
  for (const Buffer& b : buffers_) {
    if (io_ == Io::kLibv4l2) {
      v4l2_munmap(b.start, b.length);
    } else {
      ::munmap(b.start, b.length);
    }
  }
  buffers_.clear();
  mapped_bytes_ = 0;
  v4l2_requestbuffers req{};
  req.count = 0;
  req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  req.memory = V4L2_MEMORY_MMAP;
  (void)ioctl(VIDIOC_REQBUFS, &req);
  if (io_ == Io::kLibv4l2) {
    v4l2_close(fd_);
  } else {
    ::close(fd_);
  }
  fd_ = -1;
}

bool V4l2Node::present() const {
  if (fd_ < 0) return false;
  v4l2_capability cap{};
  return ioctl(VIDIOC_QUERYCAP, &cap) != ENODEV;
}

int V4l2Node::dequeue(Frame& frame) {
  v4l2_buffer buf{};
  buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  buf.memory = V4L2_MEMORY_MMAP;
  if (const int err = ioctl(VIDIOC_DQBUF, &buf); err != 0) return err;
  if (buf.index >= buffers_.size()) return EINVAL;
  const Buffer& b = buffers_[buf.index];
  frame.index = static_cast<int>(buf.index);
  frame.data = static_cast<const uint8_t*>(b.start);
  frame.bytesused = std::min<std::size_t>(buf.bytesused, b.length);
  frame.error_flag = (buf.flags & V4L2_BUF_FLAG_ERROR) != 0;
  frame.sequence = buf.sequence;
  frame.stamp_from_driver = (buf.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
  frame.stamp_ns = frame.stamp_from_driver
                       ? static_cast<int64_t>(buf.timestamp.tv_sec) * 1'000'000'000 + buf.timestamp.tv_usec * 1000
                       : monotonicNs();
  return 0;
}

int V4l2Node::requeue(int index) {
  v4l2_buffer buf{};
  buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  buf.memory = V4L2_MEMORY_MMAP;
  buf.index = static_cast<uint32_t>(index);
  return ioctl(VIDIOC_QBUF, &buf);
}

}  // namespace fovea::hal::v4l2

#include "agv/v4l2/v4l2_camera.hpp"

#include <errno.h>
#include <fcntl.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <mutex>
#include <sstream>
#include <vector>

namespace agv::v4l2 {

using hal::CameraStatus;

TimestampKind timestamp_kind(std::uint32_t flags) {
  TimestampKind k;
  k.monotonic = (flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
  k.ref = (flags & V4L2_BUF_FLAG_TSTAMP_SRC_MASK) == V4L2_BUF_FLAG_TSTAMP_SRC_SOE
              ? camera::TimestampRef::kStartOfExposure
              : camera::TimestampRef::kEndOfFrame;
  return k;
}

std::int64_t frame_time_ns(std::uint32_t flags, std::int64_t buffer_ts_ns,
                           std::int64_t dequeue_mono_ns, std::int64_t exposure_ns,
                           std::int64_t readout_ns) {
  const TimestampKind k = timestamp_kind(flags);
  if (!k.monotonic) {
    return camera::exposure_mid_ns(dequeue_mono_ns, camera::TimestampRef::kEndOfFrame, exposure_ns,
                                   readout_ns);
  }
  return camera::exposure_mid_ns(buffer_ts_ns, k.ref, exposure_ns, readout_ns);
}

namespace {

int xioctl(int fd, unsigned long request, void* arg) {
  int r;
  do {
    r = ioctl(fd, request, arg);
  } while (r == -1 && errno == EINTR);
  return r;
}

bool is_gone(int err) { return err == ENODEV || err == ENXIO || err == ENOENT; }

}  // namespace

struct V4l2Camera::Impl {
  struct Buffer {
    void* map = MAP_FAILED;
    std::size_t length = 0;
    bool outstanding = false;        // held by the consumer
    std::vector<std::uint8_t> gray;  // YUYV only: converted copy
  };

  hal::CameraConfig cfg;
  int fd = -1;
  bool started = false;
  bool disconnected = false;
  std::uint32_t fourcc = 0;
  std::uint32_t forced_fourcc = 0;
  int stride = 0;
  camera::GrayLayout layout;
  bool exposure_applied = false;
  std::int64_t exposure_ns = 0;
  std::int64_t frame_period_ns = 0;
  std::vector<Buffer> buffers;
  std::int64_t last_sequence = -1;

  mutable std::mutex stat_mutex;  // stats_/error read from other threads
  hal::CameraStats stats;
  std::string error;

  void set_error(const std::string& e) {
    std::lock_guard<std::mutex> lock(stat_mutex);
    error = e;
  }
  void count_error() {
    std::lock_guard<std::mutex> lock(stat_mutex);
    ++stats.errors;
  }
  CameraStatus fail(CameraStatus s, const std::string& what, int err) {
    std::ostringstream e;
    e << "v4l2 " << cfg.id << ": " << what;
    if (err != 0) e << ": " << std::strerror(err);
    set_error(e.str());
    return s;
  }
  CameraStatus fail_errno(const std::string& what, int err) {
    if (is_gone(err)) {
      disconnected = true;
      return fail(CameraStatus::kDisconnected, what, err);
    }
    return fail(CameraStatus::kDeviceError, what, err);
  }

  bool queue(std::size_t index) {
    v4l2_buffer b{};
    b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    b.memory = V4L2_MEMORY_MMAP;
    b.index = static_cast<std::uint32_t>(index);
    if (xioctl(fd, VIDIOC_QBUF, &b) != 0) {
      const int err = errno;
      fail_errno("VIDIOC_QBUF", err);
      count_error();
      return false;
    }
    return true;
  }

  void set_control(std::uint32_t id, std::int32_t value, bool* ok) {
    v4l2_control c{};
    c.id = id;
    c.value = value;
    *ok = xioctl(fd, VIDIOC_S_CTRL, &c) == 0;
  }

  void close_all() {
    if (fd >= 0) {
      if (started) {
        int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        xioctl(fd, VIDIOC_STREAMOFF, &type);
      }
      for (Buffer& b : buffers) {
        if (b.map != MAP_FAILED) munmap(b.map, b.length);
      }
      buffers.clear();
      v4l2_requestbuffers req{};
      req.count = 0;
      req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      req.memory = V4L2_MEMORY_MMAP;
      xioctl(fd, VIDIOC_REQBUFS, &req);  // may fail on a vanished device; nothing to do then
      close(fd);
    }
    for (Buffer& b : buffers) {
      if (b.map != MAP_FAILED) munmap(b.map, b.length);
    }
    buffers.clear();
    fd = -1;
    started = false;
    last_sequence = -1;
  }

  CameraStatus open_and_stream();
  CameraStatus configure_format();
  void configure_controls();
};

CameraStatus V4l2Camera::Impl::configure_format() {
  std::vector<std::uint32_t> offered;
  for (std::uint32_t i = 0;; ++i) {
    v4l2_fmtdesc d{};
    d.index = i;
    d.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (xioctl(fd, VIDIOC_ENUM_FMT, &d) != 0) break;
    offered.push_back(d.pixelformat);
  }
  fourcc = camera::choose_format(cfg.pixel_format, offered, forced_fourcc);
  if (fourcc == 0) {
    std::string list;
    for (std::uint32_t f : offered) list += " " + camera::fourcc_to_string(f);
    const std::string need =
        forced_fourcc != 0 ? "forced format " + camera::fourcc_to_string(forced_fourcc)
                           : std::string("a usable pixel format (GREY, NV12, YU12, YUYV or RGB24)");
    return fail(CameraStatus::kInvalidArgument, "need " + need + "; device offers:" + list, 0);
  }
  v4l2_format fmt{};
  fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  fmt.fmt.pix.width = static_cast<std::uint32_t>(cfg.width_px);
  fmt.fmt.pix.height = static_cast<std::uint32_t>(cfg.height_px);
  fmt.fmt.pix.pixelformat = fourcc;
  fmt.fmt.pix.field = V4L2_FIELD_NONE;
  if (xioctl(fd, VIDIOC_S_FMT, &fmt) != 0) return fail_errno("VIDIOC_S_FMT", errno);
  if (fmt.fmt.pix.pixelformat != fourcc ||
      fmt.fmt.pix.width != static_cast<std::uint32_t>(cfg.width_px) ||
      fmt.fmt.pix.height != static_cast<std::uint32_t>(cfg.height_px)) {
    std::ostringstream e;
    e << "device cannot capture " << camera::fourcc_to_string(fourcc) << " " << cfg.width_px << "x"
      << cfg.height_px << "; nearest is " << camera::fourcc_to_string(fmt.fmt.pix.pixelformat)
      << " " << fmt.fmt.pix.width << "x" << fmt.fmt.pix.height;
    return fail(CameraStatus::kInvalidArgument, e.str(), 0);
  }
  if (fmt.fmt.pix.field != V4L2_FIELD_NONE && fmt.fmt.pix.field != V4L2_FIELD_ANY) {
    return fail(CameraStatus::kInvalidArgument, "device delivers interlaced fields only", 0);
  }
  stride = static_cast<int>(fmt.fmt.pix.bytesperline);
  if (stride == 0) stride = fourcc == camera::kFourccYuyv ? 2 * cfg.width_px : cfg.width_px;
  std::string err;
  if (!camera::gray_layout(fourcc, cfg.width_px, cfg.height_px, stride, &layout, &err)) {
    return fail(CameraStatus::kDeviceError, err, 0);
  }
  // Frame rate: best effort; many UVC cameras only offer discrete intervals.
  v4l2_streamparm parm{};
  parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (xioctl(fd, VIDIOC_G_PARM, &parm) == 0 &&
      (parm.parm.capture.capability & V4L2_CAP_TIMEPERFRAME) != 0) {
    parm.parm.capture.timeperframe.numerator = 1000;
    parm.parm.capture.timeperframe.denominator =
        static_cast<std::uint32_t>(std::lround(cfg.fps * 1000.0));
    xioctl(fd, VIDIOC_S_PARM, &parm);
  }
  frame_period_ns = 0;
  if (xioctl(fd, VIDIOC_G_PARM, &parm) == 0 && parm.parm.capture.timeperframe.denominator != 0) {
    frame_period_ns = static_cast<std::int64_t>(parm.parm.capture.timeperframe.numerator) *
                      1'000'000'000 / parm.parm.capture.timeperframe.denominator;
  }
  return CameraStatus::kOk;
}

void V4l2Camera::Impl::configure_controls() {
  // Manual exposure in units of 100 us (V4L2_CID_EXPOSURE_ABSOLUTE). Gain units are
  // sensor-specific in V4L2, so gain stays as the device default (docs/guide/camera.md).
  bool ok_mode = false, ok_exp = false;
  set_control(V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL, &ok_mode);
  const std::int32_t units = std::max(1, static_cast<int>(std::lround(cfg.exposure_us / 100.0)));
  set_control(V4L2_CID_EXPOSURE_ABSOLUTE, units, &ok_exp);
  exposure_applied = ok_exp;
  exposure_ns = static_cast<std::int64_t>(cfg.exposure_us) * 1000;
  if (ok_exp) {
    v4l2_control c{};
    c.id = V4L2_CID_EXPOSURE_ABSOLUTE;
    if (xioctl(fd, VIDIOC_G_CTRL, &c) == 0 && c.value > 0) {
      exposure_ns = static_cast<std::int64_t>(c.value) * 100'000;  // what the device took
    }
  }
}

CameraStatus V4l2Camera::Impl::open_and_stream() {
  fd = open(cfg.id.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return fail_errno("open", errno);
  v4l2_capability cap{};
  if (xioctl(fd, VIDIOC_QUERYCAP, &cap) != 0) return fail_errno("VIDIOC_QUERYCAP", errno);
  const std::uint32_t caps =
      (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
  if ((caps & V4L2_CAP_VIDEO_CAPTURE) == 0 || (caps & V4L2_CAP_STREAMING) == 0) {
    return fail(CameraStatus::kInvalidArgument,
                "not a single-planar streaming capture device (multi-planar devices: use the "
                "libcamera driver)",
                0);
  }
  CameraStatus s = configure_format();
  if (s != CameraStatus::kOk) return s;
  configure_controls();

  v4l2_requestbuffers req{};
  req.count = static_cast<std::uint32_t>(cfg.buffer_count);
  req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  req.memory = V4L2_MEMORY_MMAP;
  if (xioctl(fd, VIDIOC_REQBUFS, &req) != 0) return fail_errno("VIDIOC_REQBUFS", errno);
  if (req.count < 2) return fail(CameraStatus::kDeviceError, "driver granted < 2 buffers", 0);
  buffers.resize(req.count);
  for (std::uint32_t i = 0; i < req.count; ++i) {
    v4l2_buffer b{};
    b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    b.memory = V4L2_MEMORY_MMAP;
    b.index = i;
    if (xioctl(fd, VIDIOC_QUERYBUF, &b) != 0) return fail_errno("VIDIOC_QUERYBUF", errno);
    if (b.length < layout.min_bytes) {
      return fail(CameraStatus::kDeviceError, "buffer smaller than one frame", 0);
    }
    buffers[i].length = b.length;
    buffers[i].map = mmap(nullptr, b.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd, b.m.offset);
    if (buffers[i].map == MAP_FAILED) return fail_errno("mmap", errno);
    if (!layout.in_place) {
      buffers[i].gray.resize(static_cast<std::size_t>(cfg.width_px) *
                             static_cast<std::size_t>(cfg.height_px));
    }
  }
  for (std::size_t i = 0; i < buffers.size(); ++i) {
    if (!queue(i)) return disconnected ? CameraStatus::kDisconnected : CameraStatus::kDeviceError;
  }
  int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (xioctl(fd, VIDIOC_STREAMON, &type) != 0) return fail_errno("VIDIOC_STREAMON", errno);
  started = true;
  return CameraStatus::kOk;
}

V4l2Camera::V4l2Camera(hal::CameraConfig config) : impl_(std::make_unique<Impl>()) {
  impl_->cfg = std::move(config);
}

V4l2Camera::~V4l2Camera() { stop(); }

CameraStatus V4l2Camera::start() {
  Impl& m = *impl_;
  if (m.started) return CameraStatus::kOk;
  const std::string invalid = camera::validate_config(m.cfg);
  if (!invalid.empty()) return m.fail(CameraStatus::kInvalidArgument, invalid, 0);
  if (m.cfg.id.empty()) {
    return m.fail(CameraStatus::kInvalidArgument, "camera id (device node) is empty", 0);
  }
  m.disconnected = false;
  const CameraStatus s = m.open_and_stream();
  if (s != CameraStatus::kOk) {
    m.close_all();
    m.count_error();
    return s;
  }
  m.set_error("");
  return CameraStatus::kOk;
}

void V4l2Camera::stop() { impl_->close_all(); }

CameraStatus V4l2Camera::next_frame(std::int64_t timeout_ns, hal::FrameView* frame) {
  Impl& m = *impl_;
  if (frame == nullptr) return CameraStatus::kInvalidArgument;
  if (!m.started) return CameraStatus::kNotStarted;
  if (m.disconnected) return CameraStatus::kDisconnected;
  const std::int64_t deadline = camera::monotonic_now_ns() + std::max<std::int64_t>(0, timeout_ns);
  v4l2_buffer got{};
  bool have = false;
  for (;;) {
    v4l2_buffer b{};
    b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    b.memory = V4L2_MEMORY_MMAP;
    if (xioctl(m.fd, VIDIOC_DQBUF, &b) == 0) {
      if ((b.flags & V4L2_BUF_FLAG_ERROR) != 0 || b.index >= m.buffers.size() ||
          b.bytesused < m.layout.min_bytes) {
        m.count_error();
        if (b.index < m.buffers.size() && !m.queue(b.index) && m.disconnected) {
          return CameraStatus::kDisconnected;
        }
        continue;
      }
      if (have) {  // a newer frame is ready: hand out the newest, recycle the older one
        // (counted as dropped through the sequence gap below)
        if (!m.queue(got.index) && m.disconnected) return CameraStatus::kDisconnected;
      }
      got = b;
      have = true;
      continue;  // drain whatever else is ready without waiting
    }
    const int err = errno;
    if (err != EAGAIN) {
      m.count_error();
      return m.fail_errno("VIDIOC_DQBUF", err);
    }
    if (have) break;
    const std::int64_t left = deadline - camera::monotonic_now_ns();
    if (left <= 0) return CameraStatus::kTimeout;
    pollfd p{};
    p.fd = m.fd;
    p.events = POLLIN;
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(left / 1'000'000'000);
    ts.tv_nsec = static_cast<long>(left % 1'000'000'000);
    const int r = ppoll(&p, 1, &ts, nullptr);
    if (r < 0 && errno != EINTR) {
      m.count_error();
      return m.fail_errno("poll", errno);
    }
    if (r > 0 && (p.revents & (POLLHUP | POLLNVAL)) != 0) {
      m.disconnected = true;
      m.count_error();
      return m.fail(CameraStatus::kDisconnected, "device hung up", 0);
    }
    // POLLERR without POLLHUP: vb2 reports it when no buffer is queued (the consumer holds
    // them all: nothing can arrive, so report a timeout at once) or after a queue error (DQBUF
    // then says which).
    if (r > 0 && (p.revents & POLLERR) != 0 && (p.revents & POLLIN) == 0) {
      const bool all_held = std::all_of(m.buffers.begin(), m.buffers.end(),
                                        [](const Impl::Buffer& x) { return x.outstanding; });
      if (all_held) {
        m.fail(CameraStatus::kTimeout, "all buffers held by the consumer; release frames", 0);
        return CameraStatus::kTimeout;
      }
      v4l2_buffer probe{};
      probe.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      probe.memory = V4L2_MEMORY_MMAP;
      if (xioctl(m.fd, VIDIOC_DQBUF, &probe) == 0) {
        m.queue(probe.index);  // a buffer after all; recycle it and keep waiting
      } else if (errno != EAGAIN) {
        m.count_error();
        return m.fail_errno("VIDIOC_DQBUF after POLLERR", errno);
      } else {
        timespec pause{0, 1'000'000};  // avoid spinning on a persistent POLLERR
        nanosleep(&pause, nullptr);
      }
    }
  }
  const std::int64_t now = camera::monotonic_now_ns();
  const std::int64_t ts_ns = static_cast<std::int64_t>(got.timestamp.tv_sec) * 1'000'000'000 +
                             static_cast<std::int64_t>(got.timestamp.tv_usec) * 1000;
  Impl::Buffer& buf = m.buffers[got.index];
  buf.outstanding = true;
  const auto* base = static_cast<const std::uint8_t*>(buf.map);
  if (m.layout.in_place) {
    frame->data = base;
    frame->stride_bytes = m.stride;
  } else {
    camera::convert_to_gray(m.fourcc, base, m.stride, m.cfg.width_px, m.cfg.height_px,
                            buf.gray.data(), m.cfg.width_px);
    frame->data = buf.gray.data();
    frame->stride_bytes = m.cfg.width_px;
  }
  frame->width_px = m.cfg.width_px;
  frame->height_px = m.cfg.height_px;
  frame->t_exposure_ns = frame_time_ns(got.flags, ts_ns, now, m.exposure_ns,
                                       static_cast<std::int64_t>(m.cfg.readout_us) * 1000);
  frame->sequence = got.sequence;
  frame->slot = static_cast<int>(got.index);
  {
    std::lock_guard<std::mutex> lock(m.stat_mutex);
    m.stats.frames_dropped += camera::frames_skipped(m.last_sequence, got.sequence);
    ++m.stats.frames_delivered;
  }
  m.last_sequence = got.sequence;
  return CameraStatus::kOk;
}

void V4l2Camera::release(const hal::FrameView& frame) {
  Impl& m = *impl_;
  if (!m.started || frame.slot < 0 || frame.slot >= static_cast<int>(m.buffers.size())) return;
  Impl::Buffer& b = m.buffers[static_cast<std::size_t>(frame.slot)];
  const std::uint8_t* expected =
      m.layout.in_place ? static_cast<const std::uint8_t*>(b.map) : b.gray.data();
  if (!b.outstanding || frame.data != expected) return;
  b.outstanding = false;
  m.queue(static_cast<std::size_t>(frame.slot));
}

hal::CameraStats V4l2Camera::stats() const {
  std::lock_guard<std::mutex> lock(impl_->stat_mutex);
  return impl_->stats;
}

const char* V4l2Camera::last_error() const {
  std::lock_guard<std::mutex> lock(impl_->stat_mutex);
  return impl_->error.c_str();
}

void V4l2Camera::force_fourcc(std::uint32_t fourcc) { impl_->forced_fourcc = fourcc; }
std::uint32_t V4l2Camera::fourcc() const { return impl_->fourcc; }
int V4l2Camera::stride_bytes() const { return impl_->stride; }
bool V4l2Camera::exposure_applied() const { return impl_->exposure_applied; }
std::int64_t V4l2Camera::frame_period_ns() const { return impl_->frame_period_ns; }
int V4l2Camera::buffers() const { return static_cast<int>(impl_->buffers.size()); }
int V4l2Camera::frames_outstanding() const {
  return static_cast<int>(std::count_if(impl_->buffers.begin(), impl_->buffers.end(),
                                        [](const Impl::Buffer& b) { return b.outstanding; }));
}

}  // namespace agv::v4l2

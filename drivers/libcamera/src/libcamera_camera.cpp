#include "agv/libcamera/libcamera_camera.hpp"

#include <libcamera/libcamera.h>
#include <libcamera/version.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <map>
#include <mutex>
#include <sstream>

#include "agv/camera/common.hpp"
#include "agv/libcamera/completion_queue.hpp"

// libcamera 0.5 replaced AeEnable by per-parameter manual modes.
#if LIBCAMERA_VERSION_MAJOR > 0 || LIBCAMERA_VERSION_MINOR >= 5
#define AGV_LIBCAMERA_MANUAL_MODES 1
#else
#define AGV_LIBCAMERA_MANUAL_MODES 0
#endif

namespace agv::libcam {

using hal::CameraStatus;
namespace lc = libcamera;

int select_camera(const std::vector<CameraInfo>& cameras, const std::string& id,
                  const std::string& model) {
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    const bool id_ok = id.empty() || cameras[i].id == id;
    const bool model_ok = model.empty() || cameras[i].model == model;
    if (id_ok && model_ok) return static_cast<int>(i);
  }
  return -1;
}

namespace {

// libcamera 0.0.3 aborts (assertion in PipelineHandler::stop) when a camera whose device has
// vanished is stopped, because the failed STREAMOFF leaves requests queued. A removed camera is
// therefore abandoned, never stopped: its objects are leaked on purpose and its CameraManager
// (libcamera allows one per process, and it cannot be stopped with that camera inside) lives on
// as the process's shared manager, reused by later start() calls (it still sees hotplug).
std::mutex g_orphan_mutex;
lc::CameraManager* g_orphan_cm = nullptr;

struct Abandoned {  // never deleted
  std::shared_ptr<lc::Camera> camera;
  std::unique_ptr<lc::CameraConfiguration> config;
  std::unique_ptr<lc::FrameBufferAllocator> allocator;
  std::vector<std::unique_ptr<lc::Request>> requests;
};

std::string model_of(const lc::Camera& cam) {
  const auto m = cam.properties().get(lc::properties::Model);
  return m ? std::string(*m) : std::string();
}

std::vector<CameraInfo> infos(const std::vector<std::shared_ptr<lc::Camera>>& cams) {
  std::vector<CameraInfo> out;
  for (const auto& c : cams) out.push_back({std::string(c->id()), model_of(*c)});
  return out;
}

std::string describe(const std::vector<CameraInfo>& cams) {
  if (cams.empty()) return "no cameras found";
  std::string s = "available:";
  for (const auto& c : cams) s += " '" + c.id + "' (" + c.model + ")";
  return s;
}

}  // namespace

std::vector<CameraInfo> list_cameras(std::string* error) {
  {
    std::lock_guard<std::mutex> lock(g_orphan_mutex);
    if (g_orphan_cm != nullptr) return infos(g_orphan_cm->cameras());
  }
  lc::CameraManager cm;
  if (const int r = cm.start(); r != 0) {
    if (error) *error = "libcamera CameraManager::start failed: " + std::to_string(r);
    return {};
  }
  std::vector<CameraInfo> out = infos(cm.cameras());
  cm.stop();
  return out;
}

struct LibcameraCamera::Impl {
  struct Slot {
    std::unique_ptr<lc::Request> request;
    const std::uint8_t* y_plane = nullptr;
    bool outstanding = false;        // held by the consumer
    std::vector<std::uint8_t> gray;  // YUYV only
  };
  struct Mapping {
    void* base = MAP_FAILED;
    std::size_t length = 0;
  };

  hal::CameraConfig cfg;
  lc::CameraManager* cm = nullptr;  // own_cm or the shared orphan
  std::unique_ptr<lc::CameraManager> own_cm;
  std::atomic<bool> removed{false};  // cameraRemoved / Camera::disconnected seen
  std::shared_ptr<lc::Camera> camera;
  bool acquired = false;
  bool running = false;
  bool started = false;
  std::unique_ptr<lc::CameraConfiguration> config;
  lc::Stream* stream = nullptr;
  std::unique_ptr<lc::FrameBufferAllocator> allocator;
  std::vector<Slot> slots;
  std::vector<Mapping> mappings;
  // Capacity 1: the consumer always gets the newest completed frame (latency matters more than
  // completeness for localization); older ones are recycled and counted as dropped.
  CompletionQueue<lc::Request*> queue{1};
  std::uint32_t fourcc = 0;
  int stride = 0;
  camera::GrayLayout layout;
  bool exposure_applied = false;
  std::int64_t last_activity_ns = 0;
  std::int64_t last_sequence = -1;
  bool disconnected = false;
  std::string camera_id;

  mutable std::mutex stat_mutex;
  hal::CameraStats stats;
  std::string error;

  // --- runs on libcamera's thread: hand over only ---
  void on_request_completed(lc::Request* request) { queue.push(request); }
  void on_camera_removed(std::shared_ptr<lc::Camera> cam) {
    if (cam == camera) on_camera_disconnected();
  }
  void on_camera_disconnected() {
    removed = true;
    queue.set_disconnected();
  }

  CameraStatus fail(CameraStatus s, const std::string& what) {
    std::lock_guard<std::mutex> lock(stat_mutex);
    error = "libcamera " + (camera_id.empty() ? cfg.id + cfg.model : camera_id) + ": " + what;
    ++stats.errors;
    return s;
  }

  std::int64_t stall_timeout_ns() const {
    const double period_ns = 1e9 / std::max(cfg.fps, camera::kMinFps);
    return std::max<std::int64_t>(2'000'000'000, static_cast<std::int64_t>(20 * period_ns));
  }

  void apply_controls(lc::ControlList& ctrls) {
    const lc::ControlInfoMap& info = camera->controls();
    const auto has = [&](const lc::ControlId& id) { return info.find(&id) != info.end(); };
#if AGV_LIBCAMERA_MANUAL_MODES
    if (has(lc::controls::ExposureTimeMode)) {
      ctrls.set(lc::controls::ExposureTimeMode, lc::controls::ExposureTimeModeManual);
    }
    if (has(lc::controls::AnalogueGainMode)) {
      ctrls.set(lc::controls::AnalogueGainMode, lc::controls::AnalogueGainModeManual);
    }
#else
    if (has(lc::controls::AeEnable)) ctrls.set(lc::controls::AeEnable, false);
#endif
    exposure_applied = has(lc::controls::ExposureTime);
    if (exposure_applied) ctrls.set(lc::controls::ExposureTime, std::int32_t{cfg.exposure_us});
    if (has(lc::controls::AnalogueGain)) {
      ctrls.set(lc::controls::AnalogueGain, static_cast<float>(cfg.analogue_gain));
    }
    if (has(lc::controls::FrameDurationLimits)) {
      const std::int64_t d_us = std::llround(1e6 / cfg.fps);
      const std::array<std::int64_t, 2> limits{d_us, d_us};
      ctrls.set(lc::controls::FrameDurationLimits, lc::Span<const std::int64_t, 2>(limits));
    }
  }

  bool requeue(Slot& s) {
    s.request->reuse(lc::Request::ReuseBuffers);
    if (camera->queueRequest(s.request.get()) != 0) {
      fail(CameraStatus::kDeviceError, "queueRequest failed");
      return false;
    }
    return true;
  }

  Slot* slot_of(lc::Request* r) {
    const std::uint64_t i = r->cookie();
    return i < slots.size() && slots[i].request.get() == r ? &slots[i] : nullptr;
  }

  CameraStatus open_and_start();
  CameraStatus configure_stream();
  CameraStatus map_buffers();
  void teardown();
};

CameraStatus LibcameraCamera::Impl::configure_stream() {
  config = camera->generateConfiguration(std::vector<lc::StreamRole>{lc::StreamRole::Viewfinder});
  if (!config || config->size() != 1) {
    return fail(CameraStatus::kDeviceError, "camera offers no single-stream configuration");
  }
  lc::StreamConfiguration& sc = config->at(0);
  std::vector<std::uint32_t> offered;
  for (const lc::PixelFormat& f : sc.formats().pixelformats()) offered.push_back(f.fourcc());
  fourcc = camera::choose_format(cfg.pixel_format, offered);
  if (fourcc == 0) {
    std::string list;
    for (std::uint32_t f : offered) list += " " + camera::fourcc_to_string(f);
    return fail(
        CameraStatus::kInvalidArgument,
        "no usable pixel format (need R8, NV12, YUV420, YUYV or RGB888); camera offers:" + list);
  }
  sc.pixelFormat = lc::PixelFormat(fourcc);
  sc.size = lc::Size(static_cast<unsigned>(cfg.width_px), static_cast<unsigned>(cfg.height_px));
  sc.bufferCount = static_cast<unsigned>(cfg.buffer_count);
  const lc::CameraConfiguration::Status st = config->validate();
  if (st == lc::CameraConfiguration::Invalid) {
    return fail(CameraStatus::kInvalidArgument, "configuration rejected: " + sc.toString());
  }
  if (sc.pixelFormat.fourcc() != fourcc ||
      sc.size !=
          lc::Size(static_cast<unsigned>(cfg.width_px), static_cast<unsigned>(cfg.height_px))) {
    return fail(CameraStatus::kInvalidArgument,
                "camera cannot deliver " + camera::fourcc_to_string(fourcc) + " " +
                    std::to_string(cfg.width_px) + "x" + std::to_string(cfg.height_px) +
                    "; nearest is " + sc.toString());
  }
  if (camera->configure(config.get()) != 0) {
    return fail(CameraStatus::kDeviceError, "Camera::configure failed for " + sc.toString());
  }
  stream = sc.stream();
  stride = static_cast<int>(sc.stride);
  std::string err;
  if (!camera::gray_layout(fourcc, cfg.width_px, cfg.height_px, stride, &layout, &err)) {
    return fail(CameraStatus::kDeviceError, err);
  }
  return CameraStatus::kOk;
}

CameraStatus LibcameraCamera::Impl::map_buffers() {
  allocator = std::make_unique<lc::FrameBufferAllocator>(camera);
  if (allocator->allocate(stream) < 2) {
    return fail(CameraStatus::kDeviceError, "could not allocate at least 2 buffers");
  }
  std::map<int, std::size_t> mapping_of_fd;  // planes often share one dmabuf
  const auto& bufs = allocator->buffers(stream);
  slots.resize(bufs.size());
  for (std::size_t i = 0; i < bufs.size(); ++i) {
    const lc::FrameBuffer::Plane& p0 = bufs[i]->planes()[0];
    const int fd = p0.fd.get();
    auto it = mapping_of_fd.find(fd);
    if (it == mapping_of_fd.end()) {
      const off_t len = lseek(fd, 0, SEEK_END);
      Mapping m;
      m.length =
          len > 0 ? static_cast<std::size_t>(len) : static_cast<std::size_t>(p0.offset) + p0.length;
      m.base = mmap(nullptr, m.length, PROT_READ, MAP_SHARED, fd, 0);
      if (m.base == MAP_FAILED) return fail(CameraStatus::kDeviceError, "mmap of a buffer failed");
      mappings.push_back(m);
      it = mapping_of_fd.emplace(fd, mappings.size() - 1).first;
    }
    const Mapping& m = mappings[it->second];
    std::size_t frame_bytes = 0;
    for (const auto& p : bufs[i]->planes()) frame_bytes += p.length;
    if (static_cast<std::size_t>(p0.offset) + p0.length > m.length ||
        frame_bytes < layout.min_bytes) {
      return fail(CameraStatus::kDeviceError, "buffer smaller than one frame");
    }
    slots[i].y_plane = static_cast<const std::uint8_t*>(m.base) + p0.offset;
    slots[i].request = camera->createRequest(i);
    if (!slots[i].request || slots[i].request->addBuffer(stream, bufs[i].get()) != 0) {
      return fail(CameraStatus::kDeviceError, "could not create a request");
    }
    if (!layout.in_place) {
      slots[i].gray.resize(static_cast<std::size_t>(cfg.width_px) *
                           static_cast<std::size_t>(cfg.height_px));
    }
  }
  return CameraStatus::kOk;
}

CameraStatus LibcameraCamera::Impl::open_and_start() {
  removed = false;
  {
    std::lock_guard<std::mutex> lock(g_orphan_mutex);
    cm = g_orphan_cm;
  }
  if (cm == nullptr) {
    own_cm = std::make_unique<lc::CameraManager>();
    if (const int r = own_cm->start(); r != 0) {
      own_cm.reset();
      return fail(CameraStatus::kDeviceError, "CameraManager::start failed: " + std::to_string(r));
    }
    cm = own_cm.get();
  }
  const auto cams = cm->cameras();
  const std::vector<CameraInfo> list = infos(cams);
  const int idx = select_camera(list, cfg.id, cfg.model);
  if (idx < 0) {
    return fail(CameraStatus::kDisconnected, "no camera matches id '" + cfg.id + "' model '" +
                                                 cfg.model + "'; " + describe(list));
  }
  camera = cams[static_cast<std::size_t>(idx)];
  camera_id = list[static_cast<std::size_t>(idx)].id;
  if (camera->acquire() != 0) return fail(CameraStatus::kDeviceError, "camera is in use");
  acquired = true;
  CameraStatus s = configure_stream();
  if (s != CameraStatus::kOk) return s;
  s = map_buffers();
  if (s != CameraStatus::kOk) return s;

  queue.reset();
  camera->requestCompleted.connect(this, &Impl::on_request_completed);
  camera->disconnected.connect(this, &Impl::on_camera_disconnected);
  cm->cameraRemoved.connect(this, &Impl::on_camera_removed);
  lc::ControlList start_controls(camera->controls());
  apply_controls(start_controls);
  if (camera->start(&start_controls) != 0) {
    return fail(CameraStatus::kDeviceError, "Camera::start failed");
  }
  running = true;
  for (Slot& sl : slots) {
    apply_controls(sl.request->controls());  // also per request: some pipelines ignore start()
    if (camera->queueRequest(sl.request.get()) != 0) {
      return fail(CameraStatus::kDeviceError, "queueRequest failed");
    }
  }
  last_activity_ns = camera::monotonic_now_ns();
  return CameraStatus::kOk;
}

void LibcameraCamera::Impl::teardown() {
  // A camera that stopped delivering is never stopped: if its device is gone, libcamera 0.0.3's
  // Camera::stop() aborts the process (see g_orphan_cm), and hotplug removal is not reported
  // reliably enough to tell a dead device from a silent one (not seen within 3 s under vimc in
  // the VM although udev delivered the events). Recovery therefore needs a new process.
  const bool abandon = running && disconnected;
  if (camera) {
    camera->requestCompleted.disconnect(this, &Impl::on_request_completed);
    camera->disconnected.disconnect(this, &Impl::on_camera_disconnected);
  }
  if (cm) cm->cameraRemoved.disconnect(this, &Impl::on_camera_removed);
  if (abandon) {
    auto* grave = new Abandoned;  // intentionally leaked, see g_orphan_cm
    grave->camera = std::move(camera);
    grave->config = std::move(config);
    grave->allocator = std::move(allocator);
    for (Slot& sl : slots) grave->requests.push_back(std::move(sl.request));
    slots.clear();
    mappings.clear();  // the mapped memory stays mapped with the abandoned buffers
    queue.drain();
    if (own_cm) {
      std::lock_guard<std::mutex> lock(g_orphan_mutex);
      g_orphan_cm = own_cm.release();
    }
    cm = nullptr;
    running = false;
    acquired = false;
    stream = nullptr;
    started = false;
    last_sequence = -1;
    fail(CameraStatus::kDisconnected,
         std::string("camera lost (") + (removed ? "removed" : "no frames") +
             "); abandoned without stop, restart the process to use it again");
    return;
  }
  if (camera && running) camera->stop();  // completes pending requests as cancelled
  running = false;
  queue.drain();
  slots.clear();  // requests before the buffers they reference
  for (Mapping& m : mappings) munmap(m.base, m.length);
  mappings.clear();
  if (allocator && stream) allocator->free(stream);
  allocator.reset();
  config.reset();
  stream = nullptr;
  if (camera && acquired) camera->release();
  acquired = false;
  camera.reset();
  if (own_cm) own_cm->stop();
  own_cm.reset();
  cm = nullptr;
  started = false;
  last_sequence = -1;
}

LibcameraCamera::LibcameraCamera(hal::CameraConfig config) : impl_(std::make_unique<Impl>()) {
  impl_->cfg = std::move(config);
}

LibcameraCamera::~LibcameraCamera() { stop(); }

CameraStatus LibcameraCamera::start() {
  Impl& m = *impl_;
  if (m.started) return CameraStatus::kOk;
  const std::string invalid = camera::validate_config(m.cfg);
  if (!invalid.empty()) return m.fail(CameraStatus::kInvalidArgument, invalid);
  m.disconnected = false;
  m.camera_id.clear();
  const CameraStatus s = m.open_and_start();
  if (s != CameraStatus::kOk) {
    m.teardown();
    return s;
  }
  m.started = true;
  std::lock_guard<std::mutex> lock(m.stat_mutex);
  m.error.clear();
  return CameraStatus::kOk;
}

void LibcameraCamera::stop() { impl_->teardown(); }

CameraStatus LibcameraCamera::next_frame(std::int64_t timeout_ns, hal::FrameView* frame) {
  Impl& m = *impl_;
  if (frame == nullptr) return CameraStatus::kInvalidArgument;
  if (!m.started) return CameraStatus::kNotStarted;
  if (m.disconnected) return CameraStatus::kDisconnected;
  const std::int64_t deadline = camera::monotonic_now_ns() + std::max<std::int64_t>(0, timeout_ns);
  std::vector<lc::Request*> recycle;
  for (;;) {
    lc::Request* req = nullptr;
    const auto r = m.queue.pop(deadline - camera::monotonic_now_ns(), &req, &recycle);
    for (lc::Request* old : recycle) {  // evicted by newer frames: back to the camera
      if (Impl::Slot* s = m.slot_of(old)) m.requeue(*s);
    }
    recycle.clear();
    const std::int64_t now = camera::monotonic_now_ns();
    if (r == CompletionQueue<lc::Request*>::Result::kDisconnected) {
      m.disconnected = true;
      return m.fail(CameraStatus::kDisconnected, "camera removed");
    }
    if (r == CompletionQueue<lc::Request*>::Result::kTimeout) {
      const bool all_held = std::all_of(m.slots.begin(), m.slots.end(),
                                        [](const Impl::Slot& s) { return s.outstanding; });
      if (all_held) m.last_activity_ns = now;  // starvation by the consumer is not a fault
      if (now - m.last_activity_ns > m.stall_timeout_ns()) {
        m.disconnected = true;
        return m.fail(
            CameraStatus::kDisconnected,
            "no frame for " + std::to_string((now - m.last_activity_ns) / 1'000'000) + " ms");
      }
      return CameraStatus::kTimeout;
    }
    m.last_activity_ns = now;
    Impl::Slot* slot = m.slot_of(req);
    if (slot == nullptr) continue;  // not ours (cannot happen); ignore
    if (req->status() == lc::Request::RequestCancelled) {
      m.disconnected = true;  // only stop() cancels on purpose, and stop() drains the queue
      return m.fail(CameraStatus::kDisconnected, "request cancelled by the pipeline");
    }
    lc::FrameBuffer* buf = req->findBuffer(m.stream);
    if (buf == nullptr || buf->metadata().status != lc::FrameMetadata::FrameSuccess) {
      m.fail(CameraStatus::kDeviceError, "frame completed with an error");
      m.requeue(*slot);
      continue;
    }
    const lc::FrameMetadata& md = buf->metadata();
    // Timestamp: SensorTimestamp (start of exposure, documented on CLOCK_BOOTTIME); fall back
    // to the buffer timestamp. The clock domain is checked, not assumed (see common.hpp).
    const auto sensor_ts = req->metadata().get(lc::controls::SensorTimestamp);
    const std::int64_t ts = sensor_ts ? *sensor_ts : static_cast<std::int64_t>(md.timestamp);
    const std::int64_t now_mono = camera::monotonic_now_ns();
    const std::int64_t now_boot = camera::boottime_now_ns();
    const camera::ClockDomain dom = camera::guess_clock_domain(ts, now_mono, now_boot);
    const auto exp_md = req->metadata().get(lc::controls::ExposureTime);
    const std::int64_t exposure_ns =
        static_cast<std::int64_t>(exp_md ? *exp_md : m.cfg.exposure_us) * 1000;
    frame->t_exposure_ns =
        camera::exposure_mid_ns(camera::to_monotonic_ns(ts, dom, now_mono, now_boot),
                                camera::TimestampRef::kStartOfExposure, exposure_ns,
                                static_cast<std::int64_t>(m.cfg.readout_us) * 1000);
    slot->outstanding = true;
    if (m.layout.in_place) {
      frame->data = slot->y_plane;
      frame->stride_bytes = m.stride;
    } else {
      camera::convert_to_gray(m.fourcc, slot->y_plane, m.stride, m.cfg.width_px, m.cfg.height_px,
                              slot->gray.data(), m.cfg.width_px);
      frame->data = slot->gray.data();
      frame->stride_bytes = m.cfg.width_px;
    }
    frame->width_px = m.cfg.width_px;
    frame->height_px = m.cfg.height_px;
    frame->sequence = md.sequence;
    frame->slot = static_cast<int>(req->cookie());
    {
      std::lock_guard<std::mutex> lock(m.stat_mutex);
      m.stats.frames_dropped += camera::frames_skipped(m.last_sequence, md.sequence);
      ++m.stats.frames_delivered;
    }
    m.last_sequence = md.sequence;
    return CameraStatus::kOk;
  }
}

void LibcameraCamera::release(const hal::FrameView& frame) {
  Impl& m = *impl_;
  if (!m.started || frame.slot < 0 || frame.slot >= static_cast<int>(m.slots.size())) return;
  Impl::Slot& s = m.slots[static_cast<std::size_t>(frame.slot)];
  const std::uint8_t* expected = m.layout.in_place ? s.y_plane : s.gray.data();
  if (!s.outstanding || frame.data != expected) return;
  s.outstanding = false;
  if (!m.disconnected) m.requeue(s);
}

hal::CameraStats LibcameraCamera::stats() const {
  std::lock_guard<std::mutex> lock(impl_->stat_mutex);
  return impl_->stats;  // frames evicted by newest-wins show up as sequence gaps
}

const char* LibcameraCamera::last_error() const {
  std::lock_guard<std::mutex> lock(impl_->stat_mutex);
  return impl_->error.c_str();
}

std::string LibcameraCamera::camera_id() const { return impl_->camera_id; }
std::uint32_t LibcameraCamera::fourcc() const { return impl_->fourcc; }
int LibcameraCamera::stride_bytes() const { return impl_->stride; }
bool LibcameraCamera::exposure_applied() const { return impl_->exposure_applied; }
int LibcameraCamera::buffers() const { return static_cast<int>(impl_->slots.size()); }
int LibcameraCamera::frames_outstanding() const {
  return static_cast<int>(std::count_if(impl_->slots.begin(), impl_->slots.end(),
                                        [](const Impl::Slot& s) { return s.outstanding; }));
}
std::int64_t LibcameraCamera::stall_timeout_ns() const { return impl_->stall_timeout_ns(); }

}  // namespace agv::libcam

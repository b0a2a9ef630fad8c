#include "agv/aravis/aravis_camera.hpp"

#include <arv.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>
#include <sstream>
#include <thread>
#include <vector>

#include "agv/camera/common.hpp"
#include "gvcp_probe.hpp"

namespace agv::aravis {

using hal::CameraStatus;

std::uint64_t frame_id_gap(std::uint64_t previous_id, std::uint64_t id) {
  if (id > previous_id) return id - previous_id - 1;
  constexpr std::uint64_t kMax16 = 0xffff;
  if (previous_id <= kMax16 && id >= 1 && previous_id - id > kMax16 / 2) {
    return (kMax16 - previous_id) + (id - 1);  // wrapped 65535 -> 1
  }
  return 0;
}

double gain_to_db(double gain) { return 20.0 * std::log10(gain); }

namespace {

constexpr std::int64_t kNsPerUs = 1000;
// Longest single wait inside next_frame: the lost-control flag and the probe are looked at
// between waits.
constexpr std::int64_t kWaitSliceNs = 20'000'000;
constexpr std::int64_t kProbeIntervalNs = 200'000'000;

std::int64_t realtime_now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// Takes a GError's message and frees it; empty when there was none.
std::string take_error(GError** e) {
  if (e == nullptr || *e == nullptr) return {};
  std::string m = (*e)->message != nullptr ? (*e)->message : "unknown error";
  g_clear_error(e);
  return m;
}

void on_control_lost(ArvDevice* /*device*/, gpointer flag) {
  static_cast<std::atomic<bool>*>(flag)->store(true);
}

}  // namespace

struct AravisCamera::Impl {
  struct Buffer {
    ArvBuffer* buffer = nullptr;
    bool outstanding = false;
  };

  hal::CameraConfig cfg;
  AravisOptions opt;
  ArvCamera* camera = nullptr;
  ArvStream* stream = nullptr;
  gulong lost_handler = 0;
  std::atomic<bool> control_lost{false};
  GvcpProbe probe;
  bool started = false;
  bool disconnected = false;
  std::vector<Buffer> buffers;
  ClockMap clock;
  std::string serial, model;
  double frame_rate = 0, exposure_us = 0, gain_db = std::numeric_limits<double>::quiet_NaN();
  std::int64_t exposure_ns = 0;
  bool have_id = false;
  std::uint64_t last_id = 0;
  std::uint64_t sequence = 0;
  std::int64_t last_alive_ns = 0;  // last frame or answered probe
  std::int64_t last_probe_ns = 0;
  FrameStamps stamps;

  mutable std::mutex stat_mutex;
  hal::CameraStats stats;
  std::string error;

  explicit Impl(AravisOptions o) : opt(o), clock(o.clock) {}

  CameraStatus fail(CameraStatus s, const std::string& what) {
    std::lock_guard<std::mutex> lock(stat_mutex);
    error = "aravis " + (cfg.id.empty() ? std::string("(first camera)") : cfg.id) + ": " + what;
    return s;
  }
  void count_error() {
    std::lock_guard<std::mutex> lock(stat_mutex);
    ++stats.errors;
  }
  CameraStatus lost(const std::string& why) {
    disconnected = true;
    count_error();
    return fail(CameraStatus::kDisconnected, why);
  }

  void close_all();
  CameraStatus open_camera();
  CameraStatus configure_format();
  CameraStatus configure_timing();
  CameraStatus start_stream();
  void open_probe();
  CameraStatus check_alive(std::int64_t now_ns);
  Buffer* find(ArvBuffer* b);
  bool usable(ArvBuffer* b);
  void deliver(ArvBuffer* b, hal::FrameView* frame);
};

void AravisCamera::Impl::close_all() {
  const bool gone = disconnected || control_lost.load();
  if (camera != nullptr) {
    GError* e = nullptr;
    if (started && !gone) arv_camera_stop_acquisition(camera, &e);
    g_clear_error(&e);
    ArvDevice* dev = arv_camera_get_device(camera);
    if (lost_handler != 0 && dev != nullptr) g_signal_handler_disconnect(dev, lost_handler);
  }
  lost_handler = 0;
  // The stream owns the buffers pushed to it; the ones the consumer held are ours to free.
  for (Buffer& b : buffers) {
    if (b.outstanding && b.buffer != nullptr) g_object_unref(b.buffer);
  }
  buffers.clear();
  if (gone && camera != nullptr) {
    // Freeing a vanished GigE camera waits for its heartbeat thread's retries and for the
    // release of control to time out (12 s with Aravis 0.8's defaults): done aside, so that
    // stop() returns at once and the caller can reopen or carry on with its other cameras.
    std::thread([stream = stream, cam = camera] {
      if (stream != nullptr) g_object_unref(stream);
      g_object_unref(cam);
    }).detach();
  } else {
    if (stream != nullptr) g_object_unref(stream);
    if (camera != nullptr) g_object_unref(camera);
  }
  stream = nullptr;
  camera = nullptr;
  probe.close();
  started = false;
  have_id = false;
  control_lost = false;
}

CameraStatus AravisCamera::Impl::open_camera() {
  GError* e = nullptr;
  camera = arv_camera_new(cfg.id.empty() ? nullptr : cfg.id.c_str(), &e);
  if (camera == nullptr) {
    std::string msg =
        cfg.id.empty() ? std::string("no camera found") : "no camera with id '" + cfg.id + "'";
    const std::string why = take_error(&e);
    if (!why.empty()) msg += " (" + why + ")";
    std::string seen;
    for (unsigned i = 0; i < arv_get_n_devices(); ++i) {
      const char* id = arv_get_device_id(i);
      if (id != nullptr) seen += std::string(seen.empty() ? "" : ", ") + id;
    }
    msg += "; cameras seen: " + (seen.empty() ? std::string("none") : seen);
    return fail(CameraStatus::kDisconnected, msg);
  }
  // DeviceSerialNumber where the camera has it, else the older DeviceID (also the serial).
  const char* serial_number = arv_camera_get_device_serial_number(camera, &e);
  if (serial_number == nullptr) {
    g_clear_error(&e);
    serial_number = arv_camera_get_device_id(camera, &e);
  }
  serial = serial_number != nullptr ? serial_number : "";
  g_clear_error(&e);
  const char* m = arv_camera_get_model_name(camera, &e);
  model = m != nullptr ? m : "";
  g_clear_error(&e);
  if (ArvDevice* dev = arv_camera_get_device(camera); dev != nullptr) {
    lost_handler =
        g_signal_connect(dev, "control-lost", G_CALLBACK(on_control_lost), &control_lost);
  }
  return CameraStatus::kOk;
}

CameraStatus AravisCamera::Impl::configure_format() {
  GError* e = nullptr;
  guint n = 0;
  gint64* formats = arv_camera_dup_available_pixel_formats(camera, &n, &e);
  if (formats == nullptr) {
    return fail(CameraStatus::kDeviceError, "cannot list pixel formats: " + take_error(&e));
  }
  const bool has_mono8 =
      std::find(formats, formats + n, static_cast<gint64>(ARV_PIXEL_FORMAT_MONO_8)) != formats + n;
  g_free(formats);
  if (!has_mono8) {
    const char** names = arv_camera_dup_available_pixel_formats_as_strings(camera, &n, &e);
    std::string list;
    for (guint i = 0; names != nullptr && i < n; ++i) list += std::string(" ") + names[i];
    g_free(names);
    g_clear_error(&e);
    return fail(CameraStatus::kInvalidArgument, "camera has no Mono8; it offers:" + list);
  }
  arv_camera_set_pixel_format(camera, ARV_PIXEL_FORMAT_MONO_8, &e);
  if (e != nullptr) return fail(CameraStatus::kDeviceError, "set Mono8: " + take_error(&e));

  gint wmin = 0, wmax = 0, hmin = 0, hmax = 0;
  arv_camera_get_width_bounds(camera, &wmin, &wmax, &e);
  if (e == nullptr) arv_camera_get_height_bounds(camera, &hmin, &hmax, &e);
  if (e != nullptr) return fail(CameraStatus::kDeviceError, "size bounds: " + take_error(&e));
  if (cfg.width_px < wmin || cfg.width_px > wmax || cfg.height_px < hmin || cfg.height_px > hmax) {
    std::ostringstream s;
    s << "size " << cfg.width_px << "x" << cfg.height_px << " outside the camera's " << wmin << ".."
      << wmax << " x " << hmin << ".." << hmax;
    return fail(CameraStatus::kInvalidArgument, s.str());
  }
  arv_camera_set_region(camera, 0, 0, cfg.width_px, cfg.height_px, &e);
  gint x = 0, y = 0, w = 0, h = 0;
  if (e == nullptr) arv_camera_get_region(camera, &x, &y, &w, &h, &e);
  if (e != nullptr) return fail(CameraStatus::kDeviceError, "set region: " + take_error(&e));
  if (w != cfg.width_px || h != cfg.height_px) {
    std::ostringstream s;
    s << "camera cannot capture " << cfg.width_px << "x" << cfg.height_px << "; nearest is " << w
      << "x" << h;
    return fail(CameraStatus::kInvalidArgument, s.str());
  }
  return CameraStatus::kOk;
}

// Rate, exposure and gain where the camera has them, each checked against its range first so
// that a setting the camera would clamp silently is named instead.
CameraStatus AravisCamera::Impl::configure_timing() {
  GError* e = nullptr;
  double lo = 0, hi = 0;
  auto range_error = [&](const char* what, double v, const char* unit) {
    std::ostringstream s;
    s << what << " " << v << " " << unit << " outside the camera's " << lo << ".." << hi;
    return fail(CameraStatus::kInvalidArgument, s.str());
  };
  if (arv_camera_is_frame_rate_available(camera, &e)) {
    arv_camera_get_frame_rate_bounds(camera, &lo, &hi, &e);
    if (e == nullptr && (cfg.fps < lo || cfg.fps > hi)) return range_error("fps", cfg.fps, "Hz");
    arv_camera_set_frame_rate(camera, cfg.fps, &e);
    if (e == nullptr) frame_rate = arv_camera_get_frame_rate(camera, &e);
  }
  if (e != nullptr) return fail(CameraStatus::kDeviceError, "frame rate: " + take_error(&e));

  exposure_ns = static_cast<std::int64_t>(cfg.exposure_us) * kNsPerUs;
  if (arv_camera_is_exposure_time_available(camera, &e)) {
    if (arv_camera_is_exposure_auto_available(camera, &e)) {
      arv_camera_set_exposure_time_auto(camera, ARV_AUTO_OFF, &e);
    }
    if (e == nullptr) arv_camera_get_exposure_time_bounds(camera, &lo, &hi, &e);
    const double us = cfg.exposure_us;
    if (e == nullptr && (us < lo || us > hi)) return range_error("exposure", us, "us");
    if (e == nullptr) arv_camera_set_exposure_time(camera, us, &e);
    if (e == nullptr) exposure_us = arv_camera_get_exposure_time(camera, &e);
    if (e == nullptr) exposure_ns = std::llround(exposure_us * kNsPerUs);
  }
  if (e != nullptr) return fail(CameraStatus::kDeviceError, "exposure: " + take_error(&e));

  if (arv_camera_is_gain_available(camera, &e)) {
    if (arv_camera_is_gain_auto_available(camera, &e)) {
      arv_camera_set_gain_auto(camera, ARV_AUTO_OFF, &e);
    }
    if (e == nullptr) arv_camera_get_gain_bounds(camera, &lo, &hi, &e);
    const double db = gain_to_db(cfg.analogue_gain);
    if (e == nullptr && (db < lo || db > hi)) return range_error("gain", db, "dB");
    if (e == nullptr) arv_camera_set_gain(camera, db, &e);
    if (e == nullptr) gain_db = arv_camera_get_gain(camera, &e);
  }
  if (e != nullptr) return fail(CameraStatus::kDeviceError, "gain: " + take_error(&e));
  return CameraStatus::kOk;
}

CameraStatus AravisCamera::Impl::start_stream() {
  GError* e = nullptr;
  const guint payload = arv_camera_get_payload(camera, &e);
  if (e != nullptr) return fail(CameraStatus::kDeviceError, "payload size: " + take_error(&e));
  const std::size_t frame_bytes =
      static_cast<std::size_t>(cfg.width_px) * static_cast<std::size_t>(cfg.height_px);
  if (payload < frame_bytes) {
    return fail(CameraStatus::kDeviceError, "camera payload smaller than one Mono8 frame");
  }
  stream = arv_camera_create_stream(camera, nullptr, nullptr, &e);
  if (stream == nullptr) {
    return fail(CameraStatus::kDeviceError, "cannot create the stream: " + take_error(&e));
  }
  buffers.resize(static_cast<std::size_t>(cfg.buffer_count));
  for (Buffer& b : buffers) {
    b.buffer = arv_buffer_new_allocate(payload);
    arv_stream_push_buffer(stream, b.buffer);
  }
  arv_camera_set_acquisition_mode(camera, ARV_ACQUISITION_MODE_CONTINUOUS, &e);
  if (e == nullptr) arv_camera_start_acquisition(camera, &e);
  if (e != nullptr) return fail(CameraStatus::kDeviceError, "start acquisition: " + take_error(&e));
  return CameraStatus::kOk;
}

void AravisCamera::Impl::open_probe() {
  ArvDevice* dev = arv_camera_get_device(camera);
  if (dev == nullptr || !ARV_IS_GV_DEVICE(dev)) return;  // USB3: unplugs come as control-lost
  GSocketAddress* sa = arv_gv_device_get_device_address(ARV_GV_DEVICE(dev));
  if (sa == nullptr || !G_IS_INET_SOCKET_ADDRESS(sa)) return;
  auto* isa = G_INET_SOCKET_ADDRESS(sa);
  gchar* ip = g_inet_address_to_string(g_inet_socket_address_get_address(isa));
  std::string err;
  if (ip != nullptr && !probe.open(ip, g_inet_socket_address_get_port(isa), &err)) {
    count_error();  // the heartbeat still notices a lost camera, only later
  }
  g_free(ip);
}

CameraStatus AravisCamera::Impl::check_alive(std::int64_t now_ns) {
  if (control_lost.load()) return lost("camera lost (no answer to the heartbeat, or unplugged)");
  if (!probe.is_open() || now_ns - last_alive_ns < opt.probe_after_ns) return CameraStatus::kOk;
  GvcpProbe::Result r = probe.poll_answers();
  if (r == GvcpProbe::Result::kNothing && now_ns - last_probe_ns >= kProbeIntervalNs) {
    r = probe.send_request();
    last_probe_ns = now_ns;
  }
  if (r == GvcpProbe::Result::kRefused) {
    return lost("camera gone: its control port refuses (the camera or its process stopped)");
  }
  if (r == GvcpProbe::Result::kAnswered) last_alive_ns = now_ns;
  if (now_ns - last_alive_ns >= opt.disconnect_after_ns) {
    std::ostringstream s;
    s << "camera gone: no frame and no answer for " << (now_ns - last_alive_ns) / 1'000'000
      << " ms";
    return lost(s.str());
  }
  return CameraStatus::kOk;
}

AravisCamera::Impl::Buffer* AravisCamera::Impl::find(ArvBuffer* b) {
  for (Buffer& x : buffers) {
    if (x.buffer == b) return &x;
  }
  return nullptr;
}

bool AravisCamera::Impl::usable(ArvBuffer* b) {
  if (arv_buffer_get_status(b) != ARV_BUFFER_STATUS_SUCCESS) return false;
  if (arv_buffer_get_image_width(b) != cfg.width_px ||
      arv_buffer_get_image_height(b) != cfg.height_px ||
      arv_buffer_get_image_pixel_format(b) != ARV_PIXEL_FORMAT_MONO_8) {
    return false;
  }
  gint pad_x = 0, pad_y = 0;
  arv_buffer_get_image_padding(b, &pad_x, &pad_y);
  std::size_t size = 0;
  const void* data = arv_buffer_get_image_data(b, &size);
  const std::size_t stride = static_cast<std::size_t>(cfg.width_px + std::max(0, pad_x));
  return data != nullptr && pad_x >= 0 &&
         size >= stride * static_cast<std::size_t>(cfg.height_px - 1) +
                     static_cast<std::size_t>(cfg.width_px);
}

void AravisCamera::Impl::deliver(ArvBuffer* b, hal::FrameView* frame) {
  const std::int64_t mono_now = camera::monotonic_now_ns();
  const std::int64_t real_now = realtime_now_ns();
  // Aravis stamps the first packet's arrival on the wall clock; moved onto CLOCK_MONOTONIC with
  // the two clocks read together now.
  const auto system_ns = static_cast<std::int64_t>(arv_buffer_get_system_timestamp(b));
  FrameStamps st;
  st.frame_id = arv_buffer_get_frame_id(b);
  st.camera_ns = arv_buffer_get_timestamp(b);
  st.receive_ns = system_ns > 0 ? mono_now - (real_now - system_ns) : mono_now;
  st.receive_ns = std::min(st.receive_ns, mono_now);
  st.mapped_ns = st.receive_ns;
  camera::TimestampRef ref = camera::TimestampRef::kEndOfFrame;
  if (st.camera_ns != 0 &&
      st.camera_ns <= static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max())) {
    const auto cam_ns = static_cast<std::int64_t>(st.camera_ns);
    st.clock_sample = clock.add(cam_ns, st.receive_ns);
    std::int64_t mapped = 0;
    // A held-back stamp is either late (its mapping is still right) or belongs to a clock that
    // may be jumping; until the map knows, the receive time is the safer stamp.
    if ((st.clock_sample == ClockSample::kAccepted || st.clock_sample == ClockSample::kJump) &&
        clock.map(cam_ns, &mapped)) {
      st.mapped_ns = mapped;
      ref = camera::TimestampRef::kStartOfExposure;
    }
  }
  {
    std::lock_guard<std::mutex> lock(stat_mutex);
    if (have_id) stats.frames_dropped += frame_id_gap(last_id, st.frame_id);
    ++stats.frames_delivered;
    stamps = st;
  }
  sequence += have_id ? 1 + frame_id_gap(last_id, st.frame_id) : 0;
  have_id = true;
  last_id = st.frame_id;
  last_alive_ns = mono_now;

  gint pad_x = 0, pad_y = 0;
  arv_buffer_get_image_padding(b, &pad_x, &pad_y);
  std::size_t size = 0;
  frame->data = static_cast<const std::uint8_t*>(arv_buffer_get_image_data(b, &size));
  frame->width_px = cfg.width_px;
  frame->height_px = cfg.height_px;
  frame->stride_bytes = cfg.width_px + pad_x;
  frame->t_exposure_ns = camera::exposure_mid_ns(
      st.mapped_ns, ref, exposure_ns, static_cast<std::int64_t>(cfg.readout_us) * kNsPerUs);
  frame->sequence = sequence;
  Buffer* slot = find(b);
  slot->outstanding = true;
  frame->slot = static_cast<int>(slot - buffers.data());
}

AravisCamera::AravisCamera(hal::CameraConfig config, AravisOptions options)
    : impl_(std::make_unique<Impl>(options)) {
  impl_->cfg = std::move(config);
}

AravisCamera::~AravisCamera() { stop(); }

CameraStatus AravisCamera::start() {
  Impl& m = *impl_;
  if (m.started) return CameraStatus::kOk;
  std::string invalid = camera::validate_config(m.cfg);
  if (invalid.empty()) invalid = validate_clock_map_config(m.opt.clock);
  if (invalid.empty() && m.cfg.pixel_format == hal::PixelFormatPreference::kYuv) {
    invalid = "pixel_format yuv: this driver delivers Mono8 only";
  }
  if (invalid.empty() && (m.opt.probe_after_ns <= 0 || m.opt.disconnect_after_ns <= 0)) {
    invalid = "probe_after_ns and disconnect_after_ns must be > 0";
  }
  if (!invalid.empty()) return m.fail(CameraStatus::kInvalidArgument, invalid);
  m.disconnected = false;
  m.clock.reset();
  m.sequence = 0;
  CameraStatus s = m.open_camera();
  if (s == CameraStatus::kOk) s = m.configure_format();
  if (s == CameraStatus::kOk) s = m.configure_timing();
  if (s == CameraStatus::kOk) s = m.start_stream();
  if (s != CameraStatus::kOk) {
    m.close_all();
    m.count_error();
    return s;
  }
  m.open_probe();
  m.started = true;
  m.last_alive_ns = camera::monotonic_now_ns();
  m.last_probe_ns = 0;
  std::lock_guard<std::mutex> lock(m.stat_mutex);
  m.error.clear();
  return CameraStatus::kOk;
}

void AravisCamera::stop() { impl_->close_all(); }

CameraStatus AravisCamera::next_frame(std::int64_t timeout_ns, hal::FrameView* frame) {
  Impl& m = *impl_;
  if (frame == nullptr) return CameraStatus::kInvalidArgument;
  if (!m.started) return CameraStatus::kNotStarted;
  if (m.disconnected) return CameraStatus::kDisconnected;
  const std::int64_t deadline = camera::monotonic_now_ns() + std::max<std::int64_t>(0, timeout_ns);
  ArvBuffer* got = nullptr;
  for (;;) {
    const std::int64_t now = camera::monotonic_now_ns();
    const std::int64_t wait_ns = std::clamp<std::int64_t>(deadline - now, 0, kWaitSliceNs);
    ArvBuffer* b = got == nullptr ? arv_stream_timeout_pop_buffer(
                                        m.stream, static_cast<guint64>(wait_ns / 1000))
                                  : arv_stream_try_pop_buffer(m.stream);
    if (b != nullptr) {
      if (m.find(b) == nullptr) {  // not one of ours (never pushed here): give it back
        m.count_error();
        arv_stream_push_buffer(m.stream, b);
        continue;
      }
      if (!m.usable(b)) {
        m.count_error();
        arv_stream_push_buffer(m.stream, b);
        continue;
      }
      // Hand out the newest frame; an older one still queued is recycled (its frame id
      // shows up as a gap, counted as dropped).
      if (got != nullptr) arv_stream_push_buffer(m.stream, got);
      got = b;
      continue;
    }
    if (got != nullptr) break;
    const CameraStatus alive = m.check_alive(camera::monotonic_now_ns());
    if (alive != CameraStatus::kOk) return alive;
    if (camera::monotonic_now_ns() >= deadline) {
      const bool all_held = std::all_of(m.buffers.begin(), m.buffers.end(),
                                        [](const Impl::Buffer& x) { return x.outstanding; });
      if (all_held)
        m.fail(CameraStatus::kTimeout, "all buffers held by the consumer; release frames");
      return CameraStatus::kTimeout;
    }
  }
  m.deliver(got, frame);
  return CameraStatus::kOk;
}

void AravisCamera::release(const hal::FrameView& frame) {
  Impl& m = *impl_;
  if (!m.started || frame.slot < 0 || frame.slot >= static_cast<int>(m.buffers.size())) return;
  Impl::Buffer& b = m.buffers[static_cast<std::size_t>(frame.slot)];
  std::size_t size = 0;
  if (!b.outstanding || frame.data != arv_buffer_get_image_data(b.buffer, &size)) return;
  b.outstanding = false;
  arv_stream_push_buffer(m.stream, b.buffer);
}

hal::CameraStats AravisCamera::stats() const {
  std::lock_guard<std::mutex> lock(impl_->stat_mutex);
  return impl_->stats;
}

const char* AravisCamera::last_error() const {
  std::lock_guard<std::mutex> lock(impl_->stat_mutex);
  return impl_->error.c_str();
}

std::string AravisCamera::serial() const { return impl_->serial; }
std::string AravisCamera::model() const { return impl_->model; }
double AravisCamera::frame_rate_hz() const { return impl_->frame_rate; }
double AravisCamera::exposure_us() const { return impl_->exposure_us; }
double AravisCamera::gain_db() const { return impl_->gain_db; }
int AravisCamera::buffers() const { return static_cast<int>(impl_->buffers.size()); }
int AravisCamera::frames_outstanding() const {
  return static_cast<int>(std::count_if(impl_->buffers.begin(), impl_->buffers.end(),
                                        [](const Impl::Buffer& b) { return b.outstanding; }));
}
FrameStamps AravisCamera::last_stamps() const {
  std::lock_guard<std::mutex> lock(impl_->stat_mutex);
  return impl_->stamps;
}
const ClockMap& AravisCamera::clock() const { return impl_->clock; }

}  // namespace agv::aravis

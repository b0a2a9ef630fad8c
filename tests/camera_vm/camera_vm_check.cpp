// Live-camera check for the VM (and for a real camera on the vehicle):
//   camera_vm_check --driver libcamera|v4l2 [--id ID] [--model M] [--width W] [--height H]
//                   [--fps F] [--exposure-us E] [--format auto|gray|yuv] [--frames N]
//                   [--restart-frames N] [--timeout-ms T] [--max-age-ms A]
//                   [--unbind PATH=DEVICE] [--v4l2-ctrl "NAME=VALUE"] [--v4l2-fourcc YUYV]
// Opens the camera, captures N frames at the configured size and checks: every frame has the
// configured size and a plausible stride, the image is not blank, exposure timestamps strictly
// increase and lie close to CLOCK_MONOTONIC "now", sequence numbers increase, buffers are
// recycled (more frames than buffers, every slot returns), a held frame stays valid while
// others arrive; then stop() and start() again and capture --restart-frames more. With --unbind
// the device is removed through sysfs during capture and next_frame must report kDisconnected.
// --v4l2-ctrl sets a device control by name before starting (e.g. vivid's "Timestamp Source=1":
// vivid's end-of-frame stamps are synthetic, 0.9 frame periods after frame start, i.e. in the
// future when the buffer is delivered; start-of-exposure stamps are real).
// Prints measured numbers; exits 0 when every check passed, 1 otherwise, 2 on bad usage.
#include <fcntl.h>
#include <linux/videodev2.h>
#include <sys/ioctl.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "agv/camera/common.hpp"
#include "agv/hal/camera.hpp"
#include "agv/v4l2/v4l2_camera.hpp"
#ifdef AGV_HAVE_LIBCAMERA_DRIVER
#include "agv/libcamera/libcamera_camera.hpp"
#endif

namespace {

using agv::hal::CameraStatus;

int g_failures = 0;

void fail(const std::string& msg) {
  std::printf("FAIL: %s\n", msg.c_str());
  std::fflush(stdout);
  ++g_failures;
}

struct Args {
  std::string driver;
  agv::hal::CameraConfig cfg;
  int frames = 300;
  int restart_frames = 30;
  std::int64_t timeout_ns = 3'000'000'000;  // TCG emulation is slow
  std::int64_t max_age_ns = 1'000'000'000;  // frame exposure mid-time vs now
  std::string unbind_path, unbind_device;
  std::vector<std::pair<std::string, int>> v4l2_ctrls;
  std::string v4l2_fourcc;  // V4L2 only: force this format (e.g. YUYV)
};

bool parse(int argc, char** argv, Args* a) {
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    if (i + 1 >= argc) return false;
    const std::string v = argv[++i];
    if (k == "--driver")
      a->driver = v;
    else if (k == "--id")
      a->cfg.id = v;
    else if (k == "--model")
      a->cfg.model = v;
    else if (k == "--width")
      a->cfg.width_px = std::atoi(v.c_str());
    else if (k == "--height")
      a->cfg.height_px = std::atoi(v.c_str());
    else if (k == "--fps")
      a->cfg.fps = std::atof(v.c_str());
    else if (k == "--exposure-us")
      a->cfg.exposure_us = std::atoi(v.c_str());
    else if (k == "--frames")
      a->frames = std::atoi(v.c_str());
    else if (k == "--restart-frames")
      a->restart_frames = std::atoi(v.c_str());
    else if (k == "--timeout-ms")
      a->timeout_ns = std::atoll(v.c_str()) * 1'000'000;
    else if (k == "--max-age-ms")
      a->max_age_ns = std::atoll(v.c_str()) * 1'000'000;
    else if (k == "--format") {
      if (v == "auto")
        a->cfg.pixel_format = agv::hal::PixelFormatPreference::kAuto;
      else if (v == "gray")
        a->cfg.pixel_format = agv::hal::PixelFormatPreference::kGray;
      else if (v == "yuv")
        a->cfg.pixel_format = agv::hal::PixelFormatPreference::kYuv;
      else
        return false;
    } else if (k == "--unbind") {
      const auto eq = v.find('=');
      if (eq == std::string::npos) return false;
      a->unbind_path = v.substr(0, eq);
      a->unbind_device = v.substr(eq + 1);
    } else if (k == "--v4l2-fourcc") {
      if (v.size() < 2 || v.size() > 4) return false;
      a->v4l2_fourcc = v;
    } else if (k == "--v4l2-ctrl") {
      const auto eq = v.rfind('=');
      if (eq == std::string::npos) return false;
      a->v4l2_ctrls.emplace_back(v.substr(0, eq), std::atoi(v.c_str() + eq + 1));
    } else {
      return false;
    }
  }
  return a->driver == "v4l2" || a->driver == "libcamera";
}

struct Extra {  // driver-specific introspection
  std::function<int()> buffers;
  std::function<int()> outstanding;
  std::function<std::string()> format;
};

std::int64_t median(std::vector<std::int64_t> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// Captures n frames with all checks. Returns the last exposure time (or prev_t on failure).
std::int64_t capture(agv::hal::Camera& cam, const Args& a, const Extra& x, int n,
                     std::int64_t prev_t, const char* phase) {
  std::vector<std::int64_t> periods, ages;
  std::set<int> slots;
  std::int64_t last_t = prev_t;
  std::int64_t last_seq = -1;
  int timeouts = 0;
  bool checked_content = false;
  const std::int64_t tolerance_future =
      (static_cast<std::int64_t>(a.cfg.exposure_us) + a.cfg.readout_us) * 1000 + 1'000'000;
  const std::int64_t t0 = agv::camera::monotonic_now_ns();
  int got = 0;
  while (got < n) {
    agv::hal::FrameView f;
    const CameraStatus s = cam.next_frame(a.timeout_ns, &f);
    const std::int64_t now = agv::camera::monotonic_now_ns();
    if (s == CameraStatus::kTimeout && ++timeouts <= 3) continue;
    if (s != CameraStatus::kOk) {
      fail(std::string(phase) + ": next_frame after " + std::to_string(got) +
           " frames: " + agv::hal::to_string(s) + " (" + cam.last_error() + ")");
      return last_t;
    }
    ++got;
    if (f.width_px != a.cfg.width_px || f.height_px != a.cfg.height_px) {
      fail(std::string(phase) + ": frame size " + std::to_string(f.width_px) + "x" +
           std::to_string(f.height_px) + " != configured");
    }
    if (f.data == nullptr || f.stride_bytes < f.width_px)
      fail(std::string(phase) + ": bad data/stride");
    if (f.t_exposure_ns <= last_t) {
      fail(std::string(phase) + ": timestamp not increasing at frame " + std::to_string(got) +
           ": " + std::to_string(f.t_exposure_ns) + " <= " + std::to_string(last_t));
    }
    const std::int64_t age = now - f.t_exposure_ns;
    if (age > a.max_age_ns || age < -tolerance_future) {
      fail(std::string(phase) + ": exposure time " + std::to_string(age / 1000) +
           " us before now (allowed " + std::to_string(-tolerance_future / 1000) + " .. " +
           std::to_string(a.max_age_ns / 1000) + ")");
    }
    if (last_seq >= 0 && static_cast<std::int64_t>(f.sequence) <= last_seq) {
      fail(std::string(phase) + ": sequence not increasing");
    }
    if (!checked_content) {  // a test pattern, not a blank buffer
      checked_content = true;
      int lo = 255, hi = 0;
      for (int r = 0; r < f.height_px; r += 7) {
        for (int c = 0; c < f.width_px; c += 5) {
          const int v = f.data[static_cast<std::ptrdiff_t>(r) * f.stride_bytes + c];
          lo = std::min(lo, v);
          hi = std::max(hi, v);
        }
      }
      std::printf("%s: first frame gray range %d..%d\n", phase, lo, hi);
      if (hi - lo < 16) fail(std::string(phase) + ": image looks blank");
    }
    if (last_t != prev_t) periods.push_back(f.t_exposure_ns - last_t);
    ages.push_back(age);
    last_t = f.t_exposure_ns;
    last_seq = static_cast<std::int64_t>(f.sequence);
    slots.insert(f.slot);
    cam.release(f);
  }
  const double secs = static_cast<double>(agv::camera::monotonic_now_ns() - t0) * 1e-9;
  const auto st = cam.stats();
  std::printf(
      "%s: %d frames in %.2f s (%.1f fps delivered), median period %.2f ms, median age %.2f ms, "
      "%zu slots used of %d buffers, stats delivered=%llu dropped=%llu errors=%llu, timeouts=%d, "
      "format %s\n",
      phase, got, secs, got / secs, static_cast<double>(median(periods)) * 1e-6,
      static_cast<double>(median(ages)) * 1e-6, slots.size(), x.buffers(),
      static_cast<unsigned long long>(st.frames_delivered),
      static_cast<unsigned long long>(st.frames_dropped),
      static_cast<unsigned long long>(st.errors), timeouts, x.format().c_str());
  if (x.outstanding() != 0) fail(std::string(phase) + ": frames still outstanding after release");
  if (n >= 4 * x.buffers()) {
    if (static_cast<int>(slots.size()) < 2)
      fail(std::string(phase) + ": only one buffer slot used");
    if (static_cast<int>(slots.size()) > x.buffers())
      fail(std::string(phase) + ": slot outside buffers");
  }
  return last_t;
}

void check_hold(agv::hal::Camera& cam, const Args& a, const Extra& x) {
  agv::hal::FrameView held, other;
  if (cam.next_frame(a.timeout_ns, &held) != CameraStatus::kOk) {
    fail(std::string("hold: no frame: ") + cam.last_error());
    return;
  }
  const std::vector<std::uint8_t> copy(held.data, held.data + held.stride_bytes);
  for (int i = 0; i < 2 * x.buffers(); ++i) {
    const CameraStatus s = cam.next_frame(a.timeout_ns, &other);
    if (s != CameraStatus::kOk) {
      fail(std::string("hold: next_frame while holding one: ") + agv::hal::to_string(s));
      break;
    }
    if (other.slot == held.slot) fail("hold: held buffer handed out again");
    cam.release(other);
  }
  if (!std::equal(copy.begin(), copy.end(), held.data)) fail("hold: held frame was overwritten");
  cam.release(held);
  cam.release(held);  // double release must be harmless
  std::printf("hold: one frame held across %d others: ok\n", 2 * x.buffers());
}

void check_unbind(agv::hal::Camera& cam, const Args& a) {
  std::thread remover([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    std::ofstream f(a.unbind_path);
    f << a.unbind_device << std::flush;
    if (!f)
      std::printf("unbind: writing %s to %s failed\n", a.unbind_device.c_str(),
                  a.unbind_path.c_str());
  });
  const std::int64_t t0 = agv::camera::monotonic_now_ns();
  CameraStatus s = CameraStatus::kOk;
  int frames = 0;
  while (agv::camera::monotonic_now_ns() - t0 < 30'000'000'000) {
    agv::hal::FrameView f;
    s = cam.next_frame(a.timeout_ns, &f);
    if (s == CameraStatus::kOk) {
      ++frames;
      cam.release(f);
      continue;
    }
    if (s != CameraStatus::kTimeout) break;
  }
  remover.join();
  const double secs = static_cast<double>(agv::camera::monotonic_now_ns() - t0) * 1e-9;
  std::printf("unbind: %d frames, then '%s' after %.2f s (%s)\n", frames, agv::hal::to_string(s),
              secs, cam.last_error());
  if (s != CameraStatus::kDisconnected)
    fail("unbind: expected disconnected, got " + std::string(agv::hal::to_string(s)));
  agv::hal::FrameView f;
  if (cam.next_frame(0, &f) != CameraStatus::kDisconnected)
    fail("unbind: disconnected is not sticky");
  cam.stop();
  if (cam.start() == CameraStatus::kOk) fail("unbind: start() succeeded on a removed device");
  std::printf("unbind: restart on the removed device fails with: %s\n", cam.last_error());
  cam.stop();
}

}  // namespace

// Sets a control by its name on the device node (controls persist across opens).
bool set_v4l2_ctrl(const std::string& dev, const std::string& name, int value) {
  const int fd = open(dev.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) return false;
  bool ok = false;
  v4l2_queryctrl q{};
  q.id = V4L2_CTRL_FLAG_NEXT_CTRL;
  while (ioctl(fd, VIDIOC_QUERYCTRL, &q) == 0) {
    if (name == reinterpret_cast<const char*>(q.name)) {
      v4l2_control c{};
      c.id = q.id;
      c.value = value;
      ok = ioctl(fd, VIDIOC_S_CTRL, &c) == 0;
      break;
    }
    q.id |= V4L2_CTRL_FLAG_NEXT_CTRL;
  }
  close(fd);
  return ok;
}

int main(int argc, char** argv) {
  Args a;
  if (!parse(argc, argv, &a)) {
    std::fprintf(
        stderr,
        "usage: camera_vm_check --driver libcamera|v4l2 [--id ID] [--model M] "
        "[--width W] [--height H] [--fps F] [--exposure-us E] [--format auto|gray|yuv] "
        "[--frames N] [--restart-frames N] [--timeout-ms T] [--max-age-ms A] "
        "[--unbind SYSFS_UNBIND=DEVICE] [--v4l2-ctrl NAME=VALUE] [--v4l2-fourcc FOURCC]\n");
    return 2;
  }
  std::unique_ptr<agv::hal::Camera> cam;
  Extra x;
  if (a.driver == "v4l2") {
    auto c = std::make_unique<agv::v4l2::V4l2Camera>(a.cfg);
    auto* p = c.get();
    if (!a.v4l2_fourcc.empty()) {
      std::string f = a.v4l2_fourcc;
      f.resize(4, ' ');
      p->force_fourcc(agv::camera::make_fourcc(f[0], f[1], f[2], f[3]));
    }
    x.buffers = [p] { return p->buffers(); };
    x.outstanding = [p] { return p->frames_outstanding(); };
    x.format = [p] {
      return agv::camera::fourcc_to_string(p->fourcc()) + " period " +
             std::to_string(p->frame_period_ns() / 1000) + " us stride " +
             std::to_string(p->stride_bytes()) +
             (p->exposure_applied() ? "" : " (no manual exposure)");
    };
    cam = std::move(c);
  } else {
#ifdef AGV_HAVE_LIBCAMERA_DRIVER
    std::string list_error;
    const auto cams = agv::libcam::list_cameras(&list_error);
    for (const auto& c : cams)
      std::printf("libcamera camera: '%s' model '%s'\n", c.id.c_str(), c.model.c_str());
    if (cams.empty()) fail("list_cameras: no camera " + list_error);
    auto c = std::make_unique<agv::libcam::LibcameraCamera>(a.cfg);
    auto* p = c.get();
    x.buffers = [p] { return p->buffers(); };
    x.outstanding = [p] { return p->frames_outstanding(); };
    x.format = [p] {
      return "'" + p->camera_id() + "' " + agv::camera::fourcc_to_string(p->fourcc()) + " stride " +
             std::to_string(p->stride_bytes()) +
             (p->exposure_applied() ? "" : " (no ExposureTime control)");
    };
    cam = std::move(c);
#else
    std::fprintf(stderr, "camera_vm_check: built without libcamera\n");
    return 2;
#endif
  }
  const std::string invalid = agv::camera::validate_config(a.cfg);
  if (!invalid.empty()) {
    std::fprintf(stderr, "camera_vm_check: %s\n", invalid.c_str());
    return 2;
  }
  for (const auto& [name, value] : a.v4l2_ctrls) {
    if (!set_v4l2_ctrl(a.cfg.id, name, value)) {
      fail("cannot set control '" + name + "' on " + a.cfg.id);
      return 1;
    }
    std::printf("camera_vm_check: set control '%s' = %d\n", name.c_str(), value);
  }
  std::printf("camera_vm_check: driver %s, %dx%d @ %.1f fps, exposure %d us, %d frames\n",
              a.driver.c_str(), a.cfg.width_px, a.cfg.height_px, a.cfg.fps, a.cfg.exposure_us,
              a.frames);
  CameraStatus s = cam->start();
  if (s != CameraStatus::kOk) {
    fail(std::string("start: ") + agv::hal::to_string(s) + " (" + cam->last_error() + ")");
    return 1;
  }
  std::int64_t t = capture(*cam, a, x, a.frames, 0, "capture");
  check_hold(*cam, a, x);
  cam->stop();
  cam->stop();  // idempotent
  agv::hal::FrameView f;
  if (cam->next_frame(0, &f) != CameraStatus::kNotStarted)
    fail("after stop: next_frame should be kNotStarted");
  if (a.restart_frames > 0) {
    s = cam->start();
    if (s != CameraStatus::kOk) {
      fail(std::string("restart: ") + agv::hal::to_string(s) + " (" + cam->last_error() + ")");
    } else {
      t = capture(*cam, a, x, a.restart_frames, t, "restart");
    }
  }
  if (!a.unbind_path.empty() && g_failures == 0) check_unbind(*cam, a);
  cam->stop();
  if (g_failures == 0) {
    std::printf("PASS: camera_vm_check %s\n", a.driver.c_str());
    return 0;
  }
  std::printf("camera_vm_check: %d check(s) failed\n", g_failures);
  return 1;
}

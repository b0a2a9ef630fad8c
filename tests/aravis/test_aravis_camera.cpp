// The Aravis driver against Aravis's own simulated GigE Vision camera (arv-fake-gv-camera-0.8,
// Debian aravis-tools) on the loopback interface: real GVCP control and GVSP streaming, real
// camera timestamps, a camera that dies mid-stream.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "agv/aravis/aravis_camera.hpp"

extern char** environ;

namespace {

using agv::aravis::AravisCamera;
using agv::hal::CameraStatus;

constexpr char kFakeCamera[] = "arv-fake-gv-camera-0.8";

std::string find_in_path(const std::string& name) {
  const char* path = std::getenv("PATH");
  std::string rest = path != nullptr ? path : "/usr/bin:/bin";
  std::size_t start = 0;
  while (start <= rest.size()) {
    const std::size_t end = std::min(rest.find(':', start), rest.size());
    const std::filesystem::path p = std::filesystem::path(rest.substr(start, end - start)) / name;
    if (!p.parent_path().empty() && access(p.c_str(), X_OK) == 0) return p.string();
    start = end + 1;
  }
  return "";
}

std::int64_t clock_ns(clockid_t id) {
  timespec ts{};
  clock_gettime(id, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// One fake camera process on 127.0.0.1 with a serial of its own. Only one can listen on the
// GVCP port at a time: the tests that start one hold /tmp/agv-fake-gv.lock while it may run,
// and a start that loses the port to another camera anyway is retried.
// It is opened by address: the fake camera answers discovery on every interface, and Aravis
// may keep eth0's answer and have the frames sent where its packet socket never sees them.
class FakeCamera {
 public:
  bool start(const std::string& binary, std::string* error) {
    if (lock_fd_ < 0) {
      lock_fd_ = open("/tmp/agv-fake-gv.lock", O_RDWR | O_CREAT | O_CLOEXEC, 0666);
      if (lock_fd_ < 0 || flock(lock_fd_, LOCK_EX) != 0) {
        *error = "cannot lock /tmp/agv-fake-gv.lock";
        return false;
      }
    }
    serial_ = "AGV" + std::to_string(getpid());
    for (int attempt = 0; attempt < 30; ++attempt) {
      std::vector<std::string> args = {binary, "-i", "127.0.0.1", "-s", serial_};
      std::vector<char*> argv;
      for (std::string& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      if (posix_spawn(&pid_, binary.c_str(), nullptr, nullptr, argv.data(), environ) != 0) {
        *error = "cannot run " + binary;
        return false;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(300));
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == 0) return true;  // still running: it has the port
      pid_ = -1;
      std::this_thread::sleep_for(std::chrono::milliseconds(500));
    }
    *error = std::string(kFakeCamera) + " kept exiting (GVCP port 3956 on 127.0.0.1 taken?)";
    return false;
  }
  void pause() {
    if (pid_ > 0) kill(pid_, SIGSTOP);
  }
  void stop() {
    if (pid_ <= 0) return;
    kill(pid_, SIGKILL);  // also ends a paused one
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = -1;
  }
  ~FakeCamera() {
    stop();
    if (lock_fd_ >= 0) close(lock_fd_);
  }
  std::string serial() const { return serial_; }

 private:
  pid_t pid_ = -1;
  int lock_fd_ = -1;
  std::string serial_;
};

agv::hal::CameraConfig small_config(const std::string& id) {
  return {.id = id,
          .width_px = 320,
          .height_px = 240,
          .fps = 50.0,
          .exposure_us = 2000,
          .analogue_gain = 2.0,
          .buffer_count = 6};
}

// Opens the camera, retrying while the fresh fake camera is not yet discoverable.
CameraStatus start_with_retry(AravisCamera* cam) {
  CameraStatus s = CameraStatus::kDisconnected;
  for (int i = 0; i < 3 && s == CameraStatus::kDisconnected; ++i) s = cam->start();
  return s;
}

// Reads frames (releasing them) until next_frame says something other than kOk or kTimeout;
// returns the seconds that took, *last the status that ended it.
double seconds_until_not_timeout(AravisCamera* cam, CameraStatus* last) {
  const auto t0 = std::chrono::steady_clock::now();
  *last = CameraStatus::kOk;
  while (std::chrono::steady_clock::now() - t0 < std::chrono::seconds(10)) {
    agv::hal::FrameView f;
    *last = cam->next_frame(100'000'000, &f);
    if (*last == CameraStatus::kOk) cam->release(f);
    if (*last != CameraStatus::kOk && *last != CameraStatus::kTimeout) break;
  }
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

TEST(AravisHelpers, FrameIdGaps) {
  EXPECT_EQ(agv::aravis::frame_id_gap(10, 11), 0u);
  EXPECT_EQ(agv::aravis::frame_id_gap(10, 14), 3u);
  EXPECT_EQ(agv::aravis::frame_id_gap(65535, 1), 0u);  // 16-bit ids skip 0 when they wrap
  EXPECT_EQ(agv::aravis::frame_id_gap(65534, 2), 2u);  // 65535 and 1 missing
  EXPECT_EQ(agv::aravis::frame_id_gap(11, 11), 0u);    // repeated
  EXPECT_EQ(agv::aravis::frame_id_gap(11, 5), 0u);     // older
  EXPECT_EQ(agv::aravis::frame_id_gap(70000, 3), 0u);  // 64-bit ids do not wrap
  EXPECT_NEAR(agv::aravis::gain_to_db(2.0), 6.0206, 1e-3);
  EXPECT_EQ(agv::aravis::gain_to_db(1.0), 0.0);
}

TEST(AravisCamera, UnknownCameraIdIsNamed) {
  AravisCamera cam(small_config("agv-no-such-camera"));
  EXPECT_EQ(cam.start(), CameraStatus::kDisconnected);
  EXPECT_NE(std::string(cam.last_error()).find("no camera with id 'agv-no-such-camera'"),
            std::string::npos)
      << cam.last_error();
  agv::hal::FrameView f;
  EXPECT_EQ(cam.next_frame(1'000'000, &f), CameraStatus::kNotStarted);
}

TEST(AravisCamera, RefusesAYuvRequestWithoutTouchingACamera) {
  agv::hal::CameraConfig c = small_config("agv-no-such-camera");
  c.pixel_format = agv::hal::PixelFormatPreference::kYuv;
  AravisCamera cam(c);
  EXPECT_EQ(cam.start(), CameraStatus::kInvalidArgument);
  EXPECT_NE(std::string(cam.last_error()).find("Mono8"), std::string::npos) << cam.last_error();
}

// Everything that needs the fake camera, in one test: only one fake camera can run at a time.
TEST(AravisCamera, StreamsFromTheFakeGigECameraAndReportsItsDeath) {
  const std::string binary = find_in_path(kFakeCamera);
  if (binary.empty()) {
    GTEST_SKIP() << kFakeCamera << " not installed (Debian aravis-tools; tools/install-deps.sh)";
  }
  FakeCamera fake;
  std::string error;
  ASSERT_TRUE(fake.start(binary, &error)) << error;

  {  // A size beyond the sensor is refused by name.
    agv::hal::CameraConfig big = small_config("127.0.0.1");
    big.width_px = 8192;
    AravisCamera cam(big);
    EXPECT_EQ(start_with_retry(&cam), CameraStatus::kInvalidArgument);
    EXPECT_NE(std::string(cam.last_error()).find("size 8192x240"), std::string::npos)
        << cam.last_error();
  }

  AravisCamera cam(small_config("127.0.0.1"));
  ASSERT_EQ(start_with_retry(&cam), CameraStatus::kOk) << cam.last_error();
  EXPECT_EQ(cam.serial(), fake.serial());  // ours, not another test's camera
  EXPECT_NEAR(cam.frame_rate_hz(), 50.0, 0.5);
  EXPECT_NEAR(cam.exposure_us(), 2000.0, 1.0);
  EXPECT_NEAR(cam.gain_db(), 6.0206, 0.5);  // the fake camera's gain is in whole dB

  constexpr int kFrames = 25;
  CameraStatus s = CameraStatus::kOk;
  std::vector<std::int64_t> t_ns;
  std::vector<std::uint64_t> seq;
  // The fake camera is another process: on a loaded host it can miss a second now and then (seen
  // with a build beside the test), which is its stall, not the driver's. Timeouts are allowed
  // within an overall limit; any other status fails at once.
  int timeouts = 0;
  while (static_cast<int>(t_ns.size()) < kFrames) {
    agv::hal::FrameView f;
    s = cam.next_frame(1'000'000'000, &f);
    if (s == CameraStatus::kTimeout && ++timeouts <= 15) continue;
    ASSERT_EQ(s, CameraStatus::kOk) << agv::hal::to_string(s) << ": " << cam.last_error();
    ASSERT_NE(f.data, nullptr);
    EXPECT_EQ(f.width_px, 320);
    EXPECT_EQ(f.height_px, 240);
    EXPECT_GE(f.stride_bytes, 320);
    // Borrowed: the pixels are readable until release. The fake camera draws a pattern, so a
    // buffer handed out unfilled (all one value) shows.
    std::uint8_t lo = 255, hi = 0;
    for (int y = 0; y < f.height_px; ++y) {
      const std::uint8_t v = f.data[y * f.stride_bytes + f.width_px - 1];
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
    EXPECT_LT(lo, hi);
    const agv::aravis::FrameStamps st = cam.last_stamps();
    EXPECT_NE(st.camera_ns, 0u);  // the fake camera stamps its frames
    EXPECT_LE(st.mapped_ns, st.receive_ns + 1'000'000);
    EXPECT_LT(st.receive_ns - st.mapped_ns, 200'000'000);
    t_ns.push_back(f.t_exposure_ns);
    seq.push_back(f.sequence);
    cam.release(f);
  }
  const std::int64_t mono = clock_ns(CLOCK_MONOTONIC);
  const std::int64_t real = clock_ns(CLOCK_REALTIME);
  for (std::size_t i = 1; i < t_ns.size(); ++i) {
    EXPECT_GT(t_ns[i], t_ns[i - 1]) << i;
    EXPECT_GT(seq[i], seq[i - 1]) << i;
  }
  // Mapped onto the monotonic clock: recent, not in the future. (The fake camera stamps a frame
  // when it sends it, so its mid-exposure time, half an exposure later, may lie after `mono`.)
  EXPECT_LT(cam.last_stamps().mapped_ns, mono);
  EXPECT_LT(t_ns.back(), mono + 1'000'000);
  EXPECT_GT(t_ns.back(), mono - 1'000'000'000);
  // The fake camera's clock is this host's wall clock, so the mapped offset is the wall clock's
  // distance to the monotonic one plus a small receive latency.
  EXPECT_TRUE(cam.clock().has_offset());
  EXPECT_NEAR(static_cast<double>(cam.clock().offset_ns() + (real - mono)), 0.0, 50e6);
  // Rate from the camera stamps over the frame ids (frames skipped on a busy host drop out).
  const double period_ms = static_cast<double>(t_ns.back() - t_ns.front()) /
                           static_cast<double>(seq.back() - seq.front()) / 1e6;
  EXPECT_NEAR(period_ms, 20.0, 4.0);
  const agv::hal::CameraStats stats = cam.stats();
  EXPECT_EQ(stats.frames_delivered, static_cast<std::uint64_t>(kFrames));
  EXPECT_EQ(stats.frames_dropped, seq.back() - seq.front() - (kFrames - 1));
  EXPECT_EQ(cam.frames_outstanding(), 0);
  std::printf(
      "fake GigE camera: %d frames, period %.2f ms, %llu dropped, mapped offset %+.1f us "
      "from wall - monotonic, receive - mapped %.1f us\n",
      kFrames, period_ms, static_cast<unsigned long long>(stats.frames_dropped),
      static_cast<double>(cam.clock().offset_ns() + (real - mono)) / 1e3,
      static_cast<double>(cam.last_stamps().receive_ns - cam.last_stamps().mapped_ns) / 1e3);

  // Kill the camera mid-stream: queued frames, then timeouts, then kDisconnected; no crash.
  fake.stop();
  const double detect_s = seconds_until_not_timeout(&cam, &s);
  EXPECT_EQ(s, CameraStatus::kDisconnected) << agv::hal::to_string(s);
  EXPECT_NE(std::string(cam.last_error()).find("refuses"), std::string::npos) << cam.last_error();
  EXPECT_LT(detect_s, 3.0);
  std::printf("killed camera reported disconnected after %.2f s\n", detect_s);
  agv::hal::FrameView f;
  EXPECT_EQ(cam.next_frame(1'000'000, &f), CameraStatus::kDisconnected);
  cam.stop();
  EXPECT_EQ(cam.next_frame(1'000'000, &f), CameraStatus::kNotStarted);

  // A camera that hangs (stopped process: the port stays open, nothing answers) is reported
  // after disconnect_after_ns of silence.
  ASSERT_TRUE(fake.start(binary, &error)) << error;
  agv::aravis::AravisOptions opt;
  opt.disconnect_after_ns = 1'000'000'000;
  AravisCamera hung(small_config("127.0.0.1"), opt);
  ASSERT_EQ(start_with_retry(&hung), CameraStatus::kOk) << hung.last_error();
  ASSERT_EQ(hung.next_frame(1'000'000'000, &f), CameraStatus::kOk) << hung.last_error();
  hung.release(f);
  fake.pause();
  const double hung_s = seconds_until_not_timeout(&hung, &s);
  EXPECT_EQ(s, CameraStatus::kDisconnected) << agv::hal::to_string(s);
  EXPECT_NE(std::string(hung.last_error()).find("no frame and no answer"), std::string::npos)
      << hung.last_error();
  EXPECT_GT(hung_s, 0.9);
  EXPECT_LT(hung_s, 2.5);
  std::printf("hung camera reported disconnected after %.2f s\n", hung_s);
}

}  // namespace

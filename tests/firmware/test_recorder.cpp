// `agvloc record` (app::Recorder) with fake devices: rows reach the files while it records, the
// IIO gyro gives imu.csv, a recording killed mid-way replays, and write errors are counted and
// fail the recording.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <opencv2/core.hpp>
#include <sstream>
#include <thread>

#include "agv/can/fake_can.hpp"
#include "agv/fakecamera/fake_camera.hpp"
#include "agv/posix/posix_clock.hpp"
#include "agv/protocol/codec.hpp"
#include "agv/recording/recording.hpp"
#include "ranging_stream.hpp"
#include "recorder.hpp"

// The two tests that record in a forked child cannot run under TSan: its runtime refuses to start
// threads after a fork of a process with threads ("starting new threads after multi-threaded fork
// is not supported"), and the recorder starts threads. They check file contents, not races, and
// run in the default and ASan builds.
#if defined(__SANITIZE_THREAD__)
#define AGV_TEST_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define AGV_TEST_TSAN 1
#endif
#endif
#ifdef AGV_TEST_TSAN
#define AGV_SKIP_FORK_UNDER_TSAN() GTEST_SKIP() << "fork + threads: not supported by TSan"
#else
#define AGV_SKIP_FORK_UNDER_TSAN() (void)0
#endif

namespace {

namespace fs = std::filesystem;
namespace p = agv::protocol;
using agv::fakecamera::FakeCamera;
using agv::hal::ImuStatus;

constexpr std::int64_t kMs = 1'000'000;

std::string fresh_dir(const std::string& name) {
  const fs::path d =
      fs::temp_directory_path() / ("agv_test_recorder_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d.string();
}

std::string slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// Calls `step` until `done` holds or 5 s pass; true when it held.
bool step_until(agv::app::Recorder& rec, const std::function<bool()>& done) {
  const auto t_end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (std::chrono::steady_clock::now() < t_end) {
    rec.step(kMs);
    if (done()) return true;
  }
  return false;
}

std::size_t rows_in(const std::string& path) {
  const std::string t = slurp(path);
  const auto n = static_cast<std::size_t>(std::count(t.begin(), t.end(), '\n'));
  return n > 0 ? n - 1 : 0;  // the header
}

void write_meta(const std::string& dir) {
  agv::recording::Meta meta;
  auto& k = meta.camera.intrinsics;
  k.fx = k.fy = 770.0;
  k.cx = 319.5;
  k.cy = 239.5;
  std::string err;
  ASSERT_TRUE(agv::recording::write_meta(dir, meta, &err)) << err;
}

FakeCamera::Options waiting_camera() {
  FakeCamera::Options o;
  o.wait_for_events = true;  // next_frame blocks for a push, as a live camera does
  return o;
}

// An IIO-style gyro: 1 ms samples on its own stamps, 0.25 rad/s.
class FakeImu final : public agv::hal::Imu {
 public:
  ImuStatus start() override { return ImuStatus::kOk; }
  void stop() override {}
  ImuStatus read(agv::hal::GyroSample* out, std::size_t max, std::size_t* n,
                 std::int64_t) override {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
    *n = 0;
    if (max == 0) return ImuStatus::kTimeout;
    ++sent_;
    out[0].t_ns = 5'000 * kMs + sent_ * kMs;
    out[0].gyro_z_radps = 0.25;
    *n = 1;
    return ImuStatus::kOk;
  }
  agv::hal::ImuStats stats() const override { return {}; }
  const char* last_error() const override { return ""; }

 private:
  std::int64_t sent_ = 0;
};

// The vehicle side of the bus: odometry (and AGV_Gyro) frames with advancing counters.
struct Vehicle {
  explicit Vehicle(const p::ProtocolConfig& config) : pc(config), ep(net.create_endpoint(4096)) {}
  void odom(std::int64_t t_ns, double v_mps) {
    net.set_time_ns(t_ns);
    agv::hal::CanFrame f;
    p::encode_odometry(pc, v_mps, 0.01, static_cast<std::uint8_t>(odom_counter++ % 15), &f);
    ep->send(f);
  }
  void gyro(std::int64_t t_ns, double rate_radps, bool saturated) {
    net.set_time_ns(t_ns);
    agv::hal::CanFrame f;
    p::GyroSample g;
    g.gyro_z_radps = rate_radps;
    g.saturated = saturated;
    p::encode_gyro(pc, g, static_cast<std::uint8_t>(gyro_counter++ % 15), &f);
    ep->send(f);
  }
  p::ProtocolConfig pc;
  agv::can::FakeCanNetwork net;
  std::unique_ptr<agv::can::FakeCanEndpoint> ep;
  int odom_counter = 0, gyro_counter = 0;
};

// The vehicle on a fake bus, a camera that waits for pushes, and the recorder writing what both
// send into `dir`.
struct VehicleRecording {
  VehicleRecording(const std::string& dir, const p::ProtocolConfig& pc,
                   const agv::app::RecorderOptions& opt = {})
      : vehicle(pc),
        bus(vehicle.net.create_endpoint(4096)),
        camera(waiting_camera()),
        rec(dir, pc, camera, *bus, nullptr, clock, opt) {}
  Vehicle vehicle;
  std::unique_ptr<agv::can::FakeCanEndpoint> bus;
  FakeCamera camera;
  agv::posix::PosixClock clock;
  agv::app::Recorder rec;
};

// Runs `child` in a forked process (it ends with _exit); returns its pid, or -1.
template <class F>
pid_t in_child(F child) {
  const pid_t pid = ::fork();
  if (pid == 0) child();
  return pid;
}

p::ProtocolConfig can_gyro_config() {
  p::ProtocolConfig pc;
  pc.gyro.enabled = true;
  return pc;
}

// Before: every row stayed in memory until exit. Now each row is in its file within a flush
// period while recording goes on.
TEST(Recorder, RowsReachTheFilesWhileRecording) {
  const std::string dir = fresh_dir("stream");
  const p::ProtocolConfig pc = can_gyro_config();
  agv::app::RecorderOptions opt;
  opt.flush_period_ns = 20 * kMs;
  VehicleRecording v(dir, pc, opt);
  Vehicle& vehicle = v.vehicle;
  FakeCamera& camera = v.camera;
  agv::app::Recorder& rec = v.rec;
  std::string err;
  ASSERT_TRUE(rec.start(&err)) << err;
  // Headers are on disk at once: a recording killed before its first row is still valid.
  EXPECT_EQ(slurp(dir + "/odom.csv"), "t_ns,v_mps,omega_radps\n");
  EXPECT_EQ(slurp(dir + "/frames.csv"), "t_ns,file\n");

  for (int i = 0; i < 10; ++i) vehicle.odom((1000 + 10 * i) * kMs, 0.1 * i);
  for (int i = 0; i < 5; ++i) vehicle.gyro((1001 + 10 * i) * kMs, 0.5, i == 2);
  // One at a time: the newest frame replaces one still waiting for the PNG writer.
  for (std::uint64_t i = 0; i < 3; ++i) {
    camera.push_frame(FakeCamera::solid(640, 480, 100), (1000 + 33 * static_cast<int>(i)) * kMs);
    ASSERT_TRUE(step_until(rec, [&] { return rec.counters().frames == i + 1; }));
  }
  ASSERT_TRUE(step_until(rec,
                         [&] {
                           return rows_in(dir + "/odom.csv") == 10 &&
                                  rows_in(dir + "/imu.csv") == 4 &&
                                  rows_in(dir + "/frames.csv") == 3;
                         }))
      << "rows not in the files while recording: odom " << rows_in(dir + "/odom.csv") << ", imu "
      << rows_in(dir + "/imu.csv") << ", frames " << rows_in(dir + "/frames.csv");
  // In exactly the format the reader reads.
  std::vector<agv::recording::OdomRow> odom;
  ASSERT_TRUE(agv::recording::parse_odom_csv(slurp(dir + "/odom.csv"), &odom, &err)) << err;
  ASSERT_EQ(odom.size(), 10u);
  EXPECT_EQ(odom[3].t_ns, 1030 * kMs);
  EXPECT_NEAR(odom[3].v_mps, (0.3 + 0.01) / 2, 1e-3);  // wheels mode: the mean wheel speed
  std::vector<agv::recording::ImuRow> imu;
  ASSERT_TRUE(agv::recording::parse_imu_csv(slurp(dir + "/imu.csv"), &imu, &err)) << err;
  ASSERT_EQ(imu.size(), 4u);
  EXPECT_EQ(imu[2].t_ns, 1031 * kMs);  // the saturated sample at 1021 ms is left out
  std::vector<agv::recording::FrameRow> frames;
  ASSERT_TRUE(agv::recording::parse_frames_csv(slurp(dir + "/frames.csv"), &frames, &err)) << err;
  ASSERT_EQ(frames.size(), 3u);
  EXPECT_EQ(frames[2].t_ns, 1066 * kMs);
  EXPECT_TRUE(fs::is_regular_file(fs::path(dir) / frames[2].file));

  EXPECT_TRUE(rec.stop());
  const auto c = rec.counters();
  EXPECT_EQ(c.gyro_saturated, 1u);
  EXPECT_EQ(c.odom, 10u);
  EXPECT_EQ(c.gyro, 4u);
  EXPECT_EQ(c.frames, 3u);
  EXPECT_EQ(c.csv_write_errors + c.png_write_errors, 0u);
  write_meta(dir);
  agv::recording::Recording r;
  EXPECT_TRUE(agv::recording::read_recording(dir, &r, &err)) << err;
  fs::remove_all(dir);
}

// imu.source iio: before, `agvloc record` wrote no imu.csv for it at all.
TEST(Recorder, IioGyroGivesImuCsv) {
  const std::string dir = fresh_dir("iio");
  p::ProtocolConfig pc;  // no CAN gyro
  agv::can::FakeCanNetwork net;
  auto bus = net.create_endpoint(16);
  FakeCamera camera(waiting_camera());
  agv::posix::PosixClock clock;
  agv::app::Recorder rec(dir, pc, camera, *bus, std::make_unique<FakeImu>(), clock);
  std::string err;
  ASSERT_TRUE(rec.start(&err)) << err;
  ASSERT_TRUE(step_until(rec, [&] { return rows_in(dir + "/imu.csv") >= 20; }))
      << "no IIO samples in imu.csv while recording";
  EXPECT_TRUE(rec.stop());
  write_meta(dir);
  agv::recording::Recording r;
  ASSERT_TRUE(agv::recording::read_recording(dir, &r, &err)) << err;
  ASSERT_TRUE(r.has_imu);
  ASSERT_GE(r.imu.size(), 20u);
  EXPECT_EQ(r.imu.size(), rec.counters().gyro);
  for (std::size_t i = 0; i < r.imu.size(); ++i) {
    EXPECT_EQ(r.imu[i].t_ns, 5'000 * kMs + static_cast<std::int64_t>(i + 1) * kMs);  // its stamps
    EXPECT_EQ(r.imu[i].gyro_z_radps, 0.25);
  }
  fs::remove_all(dir);
}

// A child process records until it is SIGKILLed: what reached the files replays as it is. A
// line cut by a power loss is an error naming the file and line, never a crash.
TEST(Recorder, RecordingKilledMidwayReplays) {
  AGV_SKIP_FORK_UNDER_TSAN();
  const std::string dir = fresh_dir("killed");
  write_meta(dir);
  const pid_t pid = in_child([&] {
    VehicleRecording v(dir, can_gyro_config());
    std::string err;
    if (!v.rec.start(&err)) ::_exit(3);
    for (std::int64_t i = 0;; ++i) {  // until killed
      v.vehicle.odom((1000 + 10 * i) * kMs, 0.2);
      v.vehicle.gyro((1001 + 10 * i) * kMs, 0.1, false);
      if (i % 3 == 0) v.camera.push_frame(FakeCamera::solid(640, 480, 50), (1000 + 10 * i) * kMs);
      v.rec.step(0);
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  });
  ASSERT_GE(pid, 0);
  const auto t_end = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while ((rows_in(dir + "/odom.csv") < 100 || rows_in(dir + "/frames.csv") < 5) &&
         std::chrono::steady_clock::now() < t_end) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ::kill(pid, SIGKILL);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status)) << "child exited with " << WEXITSTATUS(status);

  agv::recording::Recording r;
  std::string err;
  ASSERT_TRUE(agv::recording::read_recording(dir, &r, &err)) << err;
  EXPECT_GE(r.odom.size(), 100u);
  EXPECT_GE(r.frames.size(), 5u);
  EXPECT_TRUE(r.has_imu);
  for (std::size_t i = 0; i < r.frames.size(); ++i) {
    cv::Mat img;
    EXPECT_TRUE(agv::recording::load_frame(r, i, &img, &err)) << err;
  }

  // A power loss can cut the last line: the rows before it replay, the cut row is dropped and
  // named, never parsed as a shortened value.
  const fs::path odom = fs::path(dir) / "odom.csv";
  fs::resize_file(odom, fs::file_size(odom) - 3);
  agv::recording::Recording cut;
  ASSERT_TRUE(agv::recording::read_recording(dir, &cut, &err)) << err;
  EXPECT_EQ(cut.odom.size(), r.odom.size() - 1);
  ASSERT_EQ(cut.warnings.size(), 1u);
  EXPECT_NE(
      cut.warnings[0].find("odom.csv:" + std::to_string(r.odom.size() + 1) + ": last line cut"),
      std::string::npos)
      << cut.warnings[0];
  fs::remove_all(dir);
}

// PNG write errors are counted and fail the recording (exit code 1), as before.
TEST(Recorder, PngWriteErrorsAreCounted) {
  const std::string dir = fresh_dir("png_errors");
  { std::ofstream(fs::path(dir) / "frames") << "a file where the frames directory goes\n"; }
  p::ProtocolConfig pc;
  agv::can::FakeCanNetwork net;
  auto bus = net.create_endpoint(16);
  FakeCamera camera(waiting_camera());
  agv::posix::PosixClock clock;
  agv::app::Recorder rec(dir, pc, camera, *bus, nullptr, clock);
  std::string err;
  ASSERT_TRUE(rec.start(&err)) << err;
  for (std::uint64_t i = 0; i < 2; ++i) {
    camera.push_frame(FakeCamera::solid(640, 480, 100), (1000 + 33 * static_cast<int>(i)) * kMs);
    ASSERT_TRUE(step_until(rec, [&] { return rec.counters().png_write_errors == i + 1; }));
  }
  EXPECT_FALSE(rec.stop());
  EXPECT_EQ(rec.counters().frames, 0u);
  EXPECT_EQ(rows_in(dir + "/frames.csv"), 0u);  // no row names a PNG that is not there
  fs::remove_all(dir);
}

// A file that stops growing (here the file-size limit; on the vehicle a full disk) is counted
// and fails the recording; what was written before stays whole rows and replays.
TEST(Recorder, CsvWriteErrorsAreCountedAndLeaveWholeRows) {
  AGV_SKIP_FORK_UNDER_TSAN();
  const std::string dir = fresh_dir("csv_errors");
  write_meta(dir);
  const pid_t pid = in_child([&] {  // the limit applies to the whole process: only the child's
    ::signal(SIGXFSZ, SIG_IGN);
    const rlimit lim{4096, 4096};
    ::setrlimit(RLIMIT_FSIZE, &lim);
    VehicleRecording v(dir, p::ProtocolConfig{});
    std::string err;
    if (!v.rec.start(&err)) ::_exit(3);
    for (int i = 0; i < 400; ++i) {
      v.vehicle.odom((1000 + 10 * i) * kMs, 0.123456);
      v.rec.step(0);
    }
    const bool ok = v.rec.stop();
    const auto c = v.rec.counters();
    ::_exit(!ok && c.csv_write_errors > 0 && c.rows_lost > 0 && c.odom + c.rows_lost == 400 ? 0
                                                                                            : 4);
  });
  ASSERT_GE(pid, 0);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "write errors not counted, or stop() did not fail";
  EXPECT_LE(fs::file_size(fs::path(dir) / "odom.csv"), 4096u);
  agv::recording::Recording r;
  std::string err;
  ASSERT_TRUE(agv::recording::read_recording(dir, &r, &err)) << err;  // no half row at the end
  EXPECT_GT(r.odom.size(), 50u);
  EXPECT_LT(r.odom.size(), 400u);
  fs::remove_all(dir);
}

}  // namespace

// The floor camera and the second one (ranging_camera.enabled), both waiting for pushes.
struct TwoCameras {
  explicit TwoCameras(const std::string& dir)
      : vehicle(pc),
        bus(vehicle.net.create_endpoint(4096)),
        camera(waiting_camera()),
        ranging(waiting_camera()),
        rec(dir, pc, camera, *bus, nullptr, clock, {}, &ranging) {}
  const p::ProtocolConfig pc;
  Vehicle vehicle;
  std::unique_ptr<agv::can::FakeCanEndpoint> bus;
  FakeCamera camera, ranging;
  agv::posix::PosixClock clock;
  agv::app::Recorder rec;
};

// ranging_camera.enabled: before, `agvloc record` left the second camera out; its frames now go
// to ranging/ in the stream format replay reads.
TEST(Recorder, SecondCameraGoesToRangingInTheStreamFormat) {
  const std::string dir = fresh_dir("ranging");
  TwoCameras v(dir);
  FakeCamera &camera = v.camera, &ranging = v.ranging;
  agv::app::Recorder& rec = v.rec;
  std::string err;
  ASSERT_TRUE(rec.start(&err)) << err;
  camera.push_frame(FakeCamera::solid(640, 480, 100), 1000 * kMs);
  for (std::uint64_t i = 0; i < 3; ++i) {
    ranging.push_frame(FakeCamera::solid(64, 48, 80), (1005 + 66 * static_cast<int>(i)) * kMs);
    ASSERT_TRUE(step_until(rec, [&] { return rec.counters().ranging_frames.frames == i + 1; }));
  }
  ASSERT_TRUE(step_until(rec, [&] { return rec.counters().frames == 1; }));
  EXPECT_TRUE(rec.stop());
  EXPECT_NE(rec.summary().find("ranging camera: 3 frames"), std::string::npos) << rec.summary();
  agv::config::RangingCameraSection section;
  section.camera.width_px = 64;
  section.camera.height_px = 48;
  section.intrinsics.width_px = 64;
  section.intrinsics.height_px = 48;
  agv::recording::Recording stream;
  std::vector<std::string> warnings;
  ASSERT_TRUE(agv::app::read_ranging_stream(dir, section, &stream, &warnings, &err)) << err;
  ASSERT_EQ(stream.frames.size(), 3u);
  EXPECT_EQ(stream.frames[2].t_ns, 1137 * kMs);
  cv::Mat img;
  EXPECT_TRUE(agv::recording::load_frame(stream, 2, &img, &err)) << err;
  EXPECT_EQ(img.cols, 64);
  fs::remove_all(dir);
}

TEST(Recorder, ASecondCameraThatDoesNotStartLeavesNothingRunning) {
  const std::string dir = fresh_dir("ranging_down");
  TwoCameras v(dir);
  FakeCamera& camera = v.camera;
  v.ranging.set_start_status(agv::hal::CameraStatus::kDisconnected);
  std::string err;
  EXPECT_FALSE(v.rec.start(&err));
  EXPECT_NE(err.find("ranging camera did not start"), std::string::npos) << err;
  EXPECT_EQ(camera.start_calls(), 1);
  EXPECT_EQ(camera.stop_calls(), 1);
  EXPECT_FALSE(fs::exists(fs::path(dir) / "odom.csv"));
  EXPECT_FALSE(fs::exists(fs::path(dir) / "frames.csv"));
  fs::remove_all(dir);
}

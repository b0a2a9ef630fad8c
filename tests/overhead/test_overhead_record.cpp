// agvloc-overhead record (overhead/src/record.cpp) on scripted cameras: what it records replays
// frame for frame, a writer that falls behind drops frames and counts them, a folder is never
// overwritten, and a recorder killed (SIGKILL) at any moment leaves folders that replay either
// reads whole or refuses with a named error. Also what run and record log of a camera's clock
// (live_feed.hpp): the first mapping, the first drift, every jump, once each.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "agv/fakecamera/fake_camera.hpp"
#include "agv/posix/posix_clock.hpp"
#include "agv/recording/recording.hpp"
#include "agv/sim/site_render.hpp"
#include "inputs.hpp"
#include "live_feed.hpp"
#include "record.hpp"
#include "replay.hpp"
#include "two_camera_frames.hpp"

namespace agv::overhead_app {
namespace {

namespace fs = std::filesystem;

fakecamera::FakeImage render(const site::Site& s, std::size_t cam) {
  return test::render_fake_frame(s, cam, test::two_vehicles());
}

fakecamera::FakeImage noise(int w, int h, unsigned seed) {
  fakecamera::FakeImage img;
  img.width_px = w;
  img.height_px = h;
  img.gray.resize(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
  std::mt19937 rng(seed);
  for (std::uint8_t& v : img.gray) v = static_cast<std::uint8_t>(rng());
  return img;
}

class OverheadRecord : public ::testing::Test {
 protected:
  void SetUp() override {
    out_ = fs::temp_directory_path() /
           ("overhead_record_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(out_);
    fs::create_directories(out_);
  }
  void TearDown() override { fs::remove_all(out_); }

  // One scripted camera per site camera: `frames` frames `period_ns` apart (each after a stall
  // of that length when paced), then the end of the stream unless `endless`.
  std::vector<LiveCamera> cameras(const std::vector<fakecamera::FakeImage>& imgs, int frames,
                                  std::int64_t period_ns, bool paced) {
    fakecamera::FakeCamera::Options opt;
    opt.clock = &clock_;
    opt.end_of_stream_when_empty = true;
    std::vector<LiveCamera> cams;
    const std::int64_t t0 = clock_.now_ns();
    for (std::size_t c = 0; c < imgs.size(); ++c) {
      auto fake = std::make_unique<fakecamera::FakeCamera>(opt);
      for (int k = 0; k < frames; ++k) {
        if (paced) fake->push_stall(period_ns);
        fake->push_frame(imgs[c], t0 + (k + 1) * period_ns);
      }
      cams.push_back({site_.cameras[c].id, c, std::move(fake)});
    }
    return cams;
  }

  // What record_cameras of `cams` into `out` found, for at most `duration_ns` (0: until the
  // cameras' end of stream).
  struct Recorded {
    bool ok = false;
    std::vector<CameraRecordCounters> counters;
    std::vector<CameraHealth> health;
    std::string err;
  };
  Recorded record(std::vector<LiveCamera>* cams, const fs::path& out, std::int64_t duration_ns) {
    const std::atomic<bool> stop{false};
    Recorded r;
    r.ok = record_cameras(cams, site_, out.string(), "test", stop, duration_ns, &r.counters,
                          &r.health, &r.err);
    return r;
  }

  posix::PosixClock clock_;
  site::Site site_ = test::two_camera_site();
  fs::path out_;
};

TEST_F(OverheadRecord, RecordedFramesReplayFrameForFrame) {
  constexpr int kFrames = 8;
  constexpr std::int64_t kPeriodNs = 100'000'000;
  const std::vector<fakecamera::FakeImage> imgs = {render(site_, 0), render(site_, 1)};
  std::vector<LiveCamera> cams = cameras(imgs, kFrames, kPeriodNs, true);
  const std::int64_t t0 = clock_.now_ns();
  Recorded run = record(&cams, out_, 20'000'000'000);
  ASSERT_TRUE(run.ok) << run.err;
  const std::vector<CameraRecordCounters>& counters = run.counters;
  const std::vector<CameraHealth>& health = run.health;
  std::string& err = run.err;
  ASSERT_EQ(counters.size(), 2u);
  std::vector<std::string> dirs;
  for (std::size_t c = 0; c < 2; ++c) {
    EXPECT_EQ(counters[c].frames_written, static_cast<std::uint64_t>(kFrames));
    EXPECT_EQ(counters[c].frames_dropped + counters[c].write_errors, 0u);
    EXPECT_EQ(health[c].frames, static_cast<std::uint64_t>(kFrames));
    dirs.push_back((out_ / site_.cameras[c].id).string());
    recording::Recording rec;
    ASSERT_TRUE(recording::read_recording(dirs.back(), &rec, &err)) << err;
    EXPECT_TRUE(rec.warnings.empty());
    ASSERT_EQ(rec.frames.size(), static_cast<std::size_t>(kFrames));
    EXPECT_EQ(rec.meta.camera.intrinsics.width_px, site_.cameras[c].intrinsics.width_px);
    EXPECT_EQ(rec.meta.camera.intrinsics.fx, site_.cameras[c].intrinsics.fx);
    EXPECT_EQ(rec.meta.landmark_family, "tag36h11");
    std::string id;
    ASSERT_TRUE(read_camera_id(dirs.back(), &id, &err)) << err;
    EXPECT_EQ(id, site_.cameras[c].id);
    for (int k = 0; k < kFrames; ++k) {
      EXPECT_GT(rec.frames[k].t_ns, t0);  // the scripted stamps, in order
      if (k > 0) {
        EXPECT_EQ(rec.frames[k].t_ns - rec.frames[k - 1].t_ns, kPeriodNs);
      }
      cv::Mat img;
      ASSERT_TRUE(recording::load_frame(rec, static_cast<std::size_t>(k), &img, &err)) << err;
      EXPECT_TRUE(std::equal(img.datastart, img.dataend, imgs[c].gray.begin())) << k;
    }
    for (const auto& e : fs::directory_iterator(fs::path(dirs.back()) / "frames"))
      EXPECT_EQ(e.path().extension(), ".png") << e.path();  // no temporary left
  }
  // The replay of what was recorded tracks both vehicles.
  ReplayArgs ra;
  ra.site_path = test::kTwoCameraSitePath;
  ra.recordings = dirs;
  ra.out_dir = (out_ / "replay").string();
  ra.fast = true;
  ASSERT_EQ(run_replay(ra), 0);
  std::ifstream tracks(out_ / "replay" / "tracks.csv");
  std::string line, text;
  while (std::getline(tracks, line)) text += line + "\n";
  for (const site::FleetAgv& a : site_.fleet) {
    EXPECT_NE(text.find("," + a.id + ","), std::string::npos) << a.id;
  }
  EXPECT_NE(text.find("confirmed"), std::string::npos);
}

TEST_F(OverheadRecord, AWriterBehindDropsFramesAndCountsThemAndStampsMustIncrease) {
  // 1280x720 noise: PNG encoding takes far longer than a burst of frames takes to arrive.
  constexpr int kFrames = 30;
  const std::vector<fakecamera::FakeImage> imgs = {noise(1280, 720, 1)};
  site_.cameras.resize(1);
  site_.cameras[0].intrinsics.width_px = 1280;
  site_.cameras[0].intrinsics.height_px = 720;
  std::vector<LiveCamera> cams = cameras(imgs, kFrames, 1'000'000, false);
  auto* fake = static_cast<fakecamera::FakeCamera*>(cams[0].camera.get());
  // Once the writer has caught up, a frame older than every other: the reader's order rule
  // refuses it, so the recorder counts it and leaves it out.
  fake->push_stall(1'000'000'000);
  fake->push_frame(imgs[0], 1);
  Recorded run = record(&cams, out_, 20'000'000'000);
  ASSERT_TRUE(run.ok) << run.err;
  const std::vector<CameraRecordCounters>& counters = run.counters;
  const std::vector<CameraHealth>& health = run.health;
  std::string& err = run.err;
  const CameraRecordCounters& c = counters[0];
  EXPECT_GT(c.frames_dropped, 0u);
  EXPECT_EQ(health[0].stamps_backwards, 1u);
  EXPECT_EQ(c.frames_out_of_order, 1u);
  EXPECT_EQ(c.frames_written + c.frames_dropped + c.frames_out_of_order,
            static_cast<std::uint64_t>(kFrames + 1));
  recording::Recording rec;
  ASSERT_TRUE(recording::read_recording(c.dir, &rec, &err)) << err;
  EXPECT_EQ(rec.frames.size(), c.frames_written);
  std::printf("burst of %d frames of 1280x720: %llu written, %llu dropped, %llu out of order\n",
              kFrames, static_cast<unsigned long long>(c.frames_written),
              static_cast<unsigned long long>(c.frames_dropped),
              static_cast<unsigned long long>(c.frames_out_of_order));
}

TEST_F(OverheadRecord, ARecordingIsNeverOverwritten) {
  const fs::path dir = out_ / "cam-west";
  fs::create_directories(dir);
  std::ofstream(dir / "frames.csv") << "t_ns,file\n";
  std::string err;
  EXPECT_FALSE(start_recording_folder(dir.string(), site_.cameras[0], site_, "test", &err));
  EXPECT_NE(err.find("never overwritten"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(dir / "meta.yaml"));
  // record_cameras checks every camera's folder before it writes any.
  std::vector<LiveCamera> cams = cameras({render(site_, 0), render(site_, 1)}, 1, 1'000'000, false);
  std::swap(cams[0], cams[1]);  // cam-east first: its folder is free, cam-west's is not
  const Recorded run = record(&cams, out_, 0);
  EXPECT_FALSE(run.ok);
  EXPECT_NE(run.err.find("cam-west: exists and is not an empty folder"), std::string::npos)
      << run.err;
  EXPECT_FALSE(fs::exists(out_ / "cam-east"));
  // An empty folder is taken.
  fs::create_directories(out_ / "empty");
  EXPECT_TRUE(start_recording_folder((out_ / "empty").string(), site_.cameras[0], site_, "t", &err))
      << err;
}

// The command: no camera configured is bad input; a camera that never starts leaves a folder with
// no frame, which replay refuses by name.
TEST_F(OverheadRecord, CommandRefusesNoCameraAndAnEmptyRecordingIsRefusedByReplay) {
  const fs::path cfg = out_ / "config.yaml";
  std::ofstream(cfg) << "output.rate_hz: 30\n";
  RecordArgs a;
  a.config_path = cfg.string();
  a.site_path = test::kTwoCameraSitePath;
  a.out_dir = (out_ / "rec").string();
  a.duration_s = 0.3;
  EXPECT_EQ(run_record_command(a), 2);
  EXPECT_FALSE(fs::exists(a.out_dir));
  std::ofstream(cfg) << "cameras:\n  cam-west: {device: /dev/agvloc-no-such-video}\n";
  EXPECT_EQ(run_record_command(a), 0);
  const std::string dir = (fs::path(a.out_dir) / "cam-west").string();
  std::vector<CameraRecording> recs;
  std::vector<std::string> warnings;
  std::string err;
  EXPECT_FALSE(open_recordings({dir}, site_, OverheadConfig{}, &recs, &warnings, &err));
  EXPECT_EQ(err, dir + ": frames.csv has no frame");
}

// Polls a frames.csv until it holds a frame row (a header and one line), for up to 60 s.
void wait_for_first_frame_row(const fs::path& csv) {
  for (int i = 0; i < 6000; ++i) {
    std::ifstream in(csv);
    std::string line;
    int lines = 0;
    while (std::getline(in, line)) ++lines;
    if (lines >= 2) return;
    usleep(10'000);
  }
}

// A recorder killed with SIGKILL at several moments (before, during and after its first
// frames): every folder replays whole or is refused with an error naming it, never a crash.
TEST_F(OverheadRecord, KilledMidWriteLeavesFoldersReplayReadsOrRefuses) {
#ifdef AGV_FORK_THREADS_UNSUPPORTED
  GTEST_SKIP() << "fork, then threads in the child: aborts qemu-user 7.2 (runs natively)";
#endif
  const std::vector<fakecamera::FakeImage> imgs = {noise(640, 400, 2), noise(640, 400, 3)};
  int replayed = 0;
  // -1: killed as soon as the first camera's frames.csv holds a frame (however slow the machine:
  // under qemu the fixed moments can all fall before the first frame).
  for (const int kill_after_ms : {0, 5, 40, 150, 400, 700, -1}) {
    const fs::path out = out_ / ("kill_" + std::to_string(kill_after_ms));
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      std::vector<LiveCamera> cams = cameras(imgs, 1000, 10'000'000, true);
      record(&cams, out, 0);
      _exit(3);
    }
    if (kill_after_ms >= 0) {
      usleep(static_cast<useconds_t>(kill_after_ms) * 1000);
    } else {
      wait_for_first_frame_row(out / site_.cameras.front().id / "frames.csv");
    }
    kill(pid, SIGKILL);
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    ASSERT_TRUE(WIFSIGNALED(status)) << "the recorder ended before it was killed";
    for (const site::CeilingCamera& cam : site_.cameras) {
      const std::string dir = (out / cam.id).string();
      std::vector<CameraRecording> recs;
      std::vector<std::string> warnings;
      std::string err;
      if (!open_recordings({dir}, site_, OverheadConfig{}, &recs, &warnings, &err)) {
        EXPECT_EQ(err.rfind(dir, 0), 0u) << err;  // refused, naming the folder
        continue;
      }
      ++replayed;
      for (std::size_t i = 0; i < recs[0].rec.frames.size(); ++i) {
        cv::Mat img;
        EXPECT_TRUE(recording::load_frame(recs[0].rec, i, &img, &err)) << dir << ": " << err;
      }
    }
  }
  EXPECT_GT(replayed, 0);  // the later kills leave frames behind
}

// A camera clock 100 ms behind the host's with 40 ppm drift, 30 fps, 1 ms receive latency; then
// its counter restarts from zero (a reboot); then a new stream.
TEST(CameraClockLog, FirstMappingFirstDriftAndEveryJumpAreLoggedOnce) {
  ClockMap m;
  ClockWatch w;
  std::vector<std::string> lines;
  auto feed = [&](std::int64_t device_ns, std::int64_t host_ns) {
    m.add(device_ns, host_ns);
    for (const std::string& l : clock_news(m, &w)) lines.push_back(l);
  };
  EXPECT_TRUE(clock_news(m, &w).empty());  // nothing mapped yet
  std::int64_t host = 5'000'000'000;
  for (int k = 0; k < 60; ++k, host += 33'333'333) {
    feed(static_cast<std::int64_t>(static_cast<double>(host - 100'000'000) / (1 + 40e-6)) -
             1'000'000,
         host);
  }
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[0].rfind("camera clock mapped onto the host's: offset ", 0), 0u) << lines[0];
  EXPECT_NE(lines[0].find("drift not yet estimated"), std::string::npos) << lines[0];
  EXPECT_EQ(lines[1].rfind("camera clock drift estimated: offset ", 0), 0u) << lines[1];
  EXPECT_NE(lines[1].find("ppm"), std::string::npos) << lines[1];
  for (int k = 0; k < 10; ++k, host += 33'333'333) feed(k * 33'333'333, host);
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_EQ(lines[2].rfind("camera clock jumped; mapping restarted: offset ", 0), 0u) << lines[2];
  EXPECT_EQ(w.jumps_total, 1u);
  // A new stream: the mapping is logged again, the jumps already counted stay counted.
  m.reset();
  w.restart();
  feed(1'000'000, host);
  ASSERT_EQ(lines.size(), 4u);
  EXPECT_EQ(lines[3].rfind("camera clock mapped onto the host's", 0), 0u) << lines[3];
  EXPECT_EQ(w.jumps_total, 1u);
}

}  // namespace
}  // namespace agv::overhead_app

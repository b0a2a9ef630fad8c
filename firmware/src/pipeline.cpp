#include "pipeline.hpp"

#include <unistd.h>

#include <algorithm>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <thread>

#include "affinity.hpp"
#include "agv/adapters/hybrid_wait_clock.hpp"
#include "agv/hal/clock.hpp"
#include "agv/posix/futex_wakeup.hpp"
#include "agv/posix/posix_clock.hpp"
#include "agv/posix/realtime.hpp"
#include "handoff.hpp"
#include "ranging_worker.hpp"
#include "snapshot_slot.hpp"

namespace agv::app {

namespace {

// Fix-triggered poses are not waited for in the last part of a period (see the output thread).
constexpr std::int64_t kFixWaitGuardNs = 200'000;

vision::VisionConfig vision_config_with_clock(const config::Config& cfg, const hal::Clock* clock) {
  vision::VisionConfig v = cfg.vision;
  if (clock) {
    v.now_ns = [clock] { return clock->now_ns(); };
  } else {
    v.now_ns = [] { return posix::monotonic_now_ns(); };
  }
  return v;
}

// SCHED_FIFO for the calling thread when priority > 0; a refusal is reported, not fatal.
void apply_fifo_priority(int priority, const char* which) {
  if (priority <= 0) return;
  const int err = posix::set_fifo_priority(priority);
  if (err) {
    const std::string what = std::string("SCHED_FIFO (") + which + ")";
    std::fprintf(stderr, "agvloc: %s\n", posix::explain_realtime_error(what.c_str(), err).c_str());
  }
}

// The three threads of the live loop and what they share. Each *_main runs on its own thread.
class ThreadedRun {
 public:
  ThreadedRun(const config::Config& cfg, const LandmarkMap* map, PipelineIo& io)
      : cfg_(cfg),
        map_(map),
        io_(io),
        clock_(*io.clock),
        core_(localizer_config(cfg)),
        loop_(core_, io.bus, clock_, io.odometry, fix_queue_,
              io.quiet ? 0 : static_cast<std::int64_t>(cfg.loop.log_period_s * 1e9), io.imu,
              sinks(io, &fault_log_)),
        wakeup_(clock_),
        pose_on_fix_(cfg.loop.pose_on_fix),
        last_frame_ns_(clock_.now_ns()),
        snapshot_(core_.time_base()) {
    loop_.keep_received_odometry(io.odometry_received);
    loop_.set_live_gyro(io.live_gyro);
    if (io.ranging_camera && io.rack_observer && io.ranging_counts) {
      ranging_ring_ = std::make_unique<RangingRing>();
      loop_.set_ranging(ranging_ring_.get());
      ranging_ = std::make_unique<RangingWorker>(
          io.ranging_camera, io.rack_observer, io.ranging_counts, ranging_ring_.get(), &snapshot_,
          &clock_, core_.config().ranging.camera_offset_ns, [this] {
            pin_this_thread(cfg_.loop.vision_cpus, "ranging, loop.vision_cpus");
            apply_fifo_priority(cfg_.loop.vision_priority, "ranging, loop.vision_priority");
          });
    }
  }

  void start_camera() {
    if (io_.camera->start() != hal::CameraStatus::kOk) {
      std::fprintf(stderr, "agvloc: camera did not start: %s (continuing: dead reckoning only)\n",
                   io_.camera->last_error());
      camera_error_ = true;
    }
    if (ranging_) ranging_->start();
  }
  void capture_main();
  void vision_main();
  void output_main();
  // After the output thread has ended: stops the others and the camera, hands the final state
  // to the sinks.
  void stop(std::thread* capture, std::thread* worker) {
    done_ = true;
    mailbox_.close();
    capture->join();
    worker->join();
    if (ranging_) ranging_->stop();
    io_.camera->stop();
    loop_.finish(mailbox_.dropped());
  }
  void collect(RunResult* result) const;

 private:
  static std::vector<OutputSink*> sinks(const PipelineIo& io, FaultLogSink* fault_log) {
    std::vector<OutputSink*> s = io.sinks;
    if (!io.quiet) s.push_back(fault_log);
    return s;
  }
  // One camera read; false at the end of the stream.
  bool capture_once(std::int64_t* retry_at_ns);
  // One output period at now (woken at next_ns); sets done_ at the end of the run.
  void output_period(std::int64_t now);

  const config::Config& cfg_;
  const LandmarkMap* map_;
  PipelineIo& io_;
  hal::Clock& clock_;
  localizer::Localizer core_;
  FixRing fix_queue_;
  FaultLogSink fault_log_;
  OutputLoop loop_;
  // loop.pose_on_fix: the vision worker wakes the output thread, which fuses the fix and sends
  // the pose pair at once; it stays the only CAN writer and shares no lock with vision.
  posix::FutexWakeup wakeup_;
  const bool pose_on_fix_;
  FrameMailbox mailbox_;
  std::atomic<bool> done_{false};
  std::atomic<bool> camera_eos_{false};
  std::atomic<bool> camera_error_{false};
  std::atomic<std::int64_t> last_frame_ns_;
  std::atomic<std::uint64_t> vision_busy_{0};
  VisionStats vstats_;
  SnapshotSlot snapshot_;
  // ranging_camera.enabled: the second camera's worker and its ring (null: none).
  std::unique_ptr<RangingRing> ranging_ring_;
  std::unique_ptr<RangingWorker> ranging_;
  // Written by one thread each (worker, output), read after both are joined.
  std::uint64_t fixes_not_recorded_ = 0, ticks_not_recorded_ = 0;
};

bool ThreadedRun::capture_once(std::int64_t* retry_at_ns) {
  if (camera_error_.load()) {
    // Reopen a vanished camera once a second; fusion dead-reckons meanwhile.
    if (clock_.now_ns() < *retry_at_ns) {
      clock_.sleep_until_ns(std::min(*retry_at_ns, clock_.now_ns() + 50 * hal::kNsPerMs));
      return true;
    }
    io_.camera->stop();
    if (io_.camera->start() == hal::CameraStatus::kOk) {
      camera_error_ = false;
    } else {
      *retry_at_ns = clock_.now_ns() + 1000 * hal::kNsPerMs;
      return true;
    }
  }
  hal::FrameView f;
  const hal::CameraStatus s = io_.camera->next_frame(50 * hal::kNsPerMs, &f);
  if (s == hal::CameraStatus::kOk) {
    last_frame_ns_ = clock_.now_ns();
    hal::FrameView old;
    if (mailbox_.put(f, &old)) io_.camera->release(old);
  } else if (s == hal::CameraStatus::kEndOfStream) {
    camera_eos_ = true;
    return false;
  } else if (s == hal::CameraStatus::kDisconnected || s == hal::CameraStatus::kDeviceError ||
             s == hal::CameraStatus::kNotStarted) {
    camera_error_ = true;
    *retry_at_ns = clock_.now_ns() + 1000 * hal::kNsPerMs;
  }
  return true;
}

// Capture: never blocks on processing; the mailbox keeps only the newest frame.
void ThreadedRun::capture_main() {
  posix::set_thread_name("agv-capture");
  pin_this_thread(cfg_.loop.vision_cpus, "capture, loop.vision_cpus");
  apply_fifo_priority(cfg_.loop.vision_priority, "capture, loop.vision_priority");
  std::int64_t retry_at_ns = 0;
  while (!done_.load() && capture_once(&retry_at_ns)) {
  }
  mailbox_.close();
}

// Vision worker: always the newest frame; results go to the output thread through a fixed ring.
void ThreadedRun::vision_main() {
  posix::set_thread_name("agv-vision");
  pin_this_thread(cfg_.loop.vision_cpus, "vision, loop.vision_cpus");
  apply_fifo_priority(cfg_.loop.vision_priority, "vision, loop.vision_priority");
  vision::LandmarkLocalizer loc(vision_config_with_clock(cfg_, &clock_), cfg_.camera_model,
                                config::landmark_geometry(cfg_), map_);
  FrameRecord rec;
  while (true) {
    hal::FrameView f;
    if (!mailbox_.take(100 * hal::kNsPerMs, &f)) {
      if (mailbox_.closed() || done_.load()) break;
      continue;
    }
    vision_busy_ = 1;
    const std::int64_t t0 = clock_.now_ns();
    const cv::Mat img(f.height_px, f.width_px, CV_8UC1, const_cast<std::uint8_t*>(f.data),
                      static_cast<size_t>(f.stride_bytes));
    const vision::Prediction pred = snapshot_.predict_exposure(f.t_exposure_ns);
    loc.process(img, pred, &rec.fix);
    const std::int64_t t1 = clock_.now_ns();
    if (io_.diag_frames) io_.diag_frames->offer(img, f.t_exposure_ns);
    rec.t_exposure_ns = f.t_exposure_ns;
    rec.t_done_ns = t1;
    io_.camera->release(f);
    localizer::record_vision(rec.fix, t0 - f.t_exposure_ns, t1 - t0, &vstats_);
    if (io_.fixes && io_.fixes->size() < io_.fixes->capacity()) {
      io_.fixes->push_back(rec);
    } else if (io_.fixes) {
      ++fixes_not_recorded_;
    }
    if (rec.fix.status != vision::FixStatus::kNoLandmark && fix_queue_.push(rec.for_fusion()) &&
        pose_on_fix_ && rec.fix.status == vision::FixStatus::kOk) {
      wakeup_.wake();
    }
    vision_busy_ = 0;
  }
  hal::FrameView f;
  if (mailbox_.drain(&f)) io_.camera->release(f);
}

void ThreadedRun::output_period(std::int64_t now) {
  CameraState cam;
  cam.last_frame_ns = last_frame_ns_.load();
  cam.end_of_stream = camera_eos_.load();
  cam.error = camera_error_.load();
  cam.frames_dropped = mailbox_.dropped();
  TickRecord* tr = nullptr;
  if (io_.ticks && io_.ticks->size() < io_.ticks->capacity()) {
    tr = &io_.ticks->emplace_back();
  } else if (io_.ticks) {
    ++ticks_not_recorded_;
  }
  loop_.tick(now, cam, tr);
  snapshot_.publish(core_.snapshot_at(now));
  if (io_.stop && io_.stop->load()) done_ = true;
  const bool can_odometry_done =
      io_.can_odometry_end_ns == INT64_MIN ||
      now >= io_.can_odometry_end_ns + cfg_.fusion.health.odom_timeout_ns;
  const bool ranging_done = !ranging_ || (ranging_->ended() && !ranging_->busy());
  if (io_.stop_at_end_of_stream && camera_eos_.load() && vision_busy_.load() == 0 &&
      mailbox_.closed() && loop_.odometry_done() && can_odometry_done && ranging_done) {
    // Hand over what the worker produced, then stop.
    loop_.take_inputs(INT64_MAX);
    done_ = true;
  }
}

// Output: absolute-time periodic timer; between two periods, fix-triggered poses when woken.
void ThreadedRun::output_main() {
  const std::int64_t period_ns = static_cast<std::int64_t>(1e9 / cfg_.loop.output_rate_hz);
  const std::int64_t spin_ns = std::int64_t{cfg_.loop.spin_before_deadline_us} * 1000;
  posix::set_thread_name("agv-output");
  pin_this_thread(cfg_.loop.realtime_cpus, "output, loop.realtime_cpus");
  apply_fifo_priority(cfg_.loop.realtime_priority, "output, loop.realtime_priority");
  adapters::HybridWaitClock wait(clock_, spin_ns);
  std::int64_t next_ns = clock_.now_ns() + period_ns;
  while (!done_.load()) {
    // A futex timeout carries the thread's timer slack (50 us by default, real-time threads
    // included: +27 us of median jitter measured), the periodic wait none for a SCHED_FIFO
    // thread. So wait for fixes only up to a guard before the deadline and end the period with
    // the same wait as without pose_on_fix; a fix in the guard window goes out with the tick.
    if (pose_on_fix_ && wakeup_.wait_until_ns(next_ns - std::max(spin_ns, kFixWaitGuardNs)) ==
                            hal::WaitResult::kWoken) {
      loop_.on_wake(clock_.now_ns());
      continue;
    }
    wait.sleep_until_ns(next_ns);
    const std::int64_t now = clock_.now_ns();
    core_.mutable_stats().period_jitter_ns.record_ns(now - next_ns);
    if (now - next_ns > period_ns) {
      core_.note_missed_period();
      // Skip the missed periods instead of bursting to catch up.
      next_ns += ((now - next_ns) / period_ns) * period_ns;
    }
    output_period(now);
    next_ns += period_ns;
  }
}

void ThreadedRun::collect(RunResult* result) const {
  result->output = core_.stats();
  result->vision = vstats_;
  result->camera = io_.camera->stats();
  result->frames_dropped_mailbox = mailbox_.dropped();
  result->fixes_dropped_queue = fix_queue_.dropped();
  result->odometry_rejected_can = core_.odometry_decoder().counters().rejected();
  result->odometry_can = core_.odometry_decoder().counters();
  result->ticks_not_recorded = ticks_not_recorded_;
  result->fixes_not_recorded = fixes_not_recorded_;
  result->odometry_not_recorded = loop_.odometry_not_recorded();
  if (io_.bus) {
    result->can = io_.bus->stats();
    result->can_present = true;
  }
  result->camera_error = io_.camera->last_error();
}

}  // namespace

int run_threads(const config::Config& cfg, const LandmarkMap* map, PipelineIo& io,
                RunResult* result) {
  ThreadedRun run(cfg, map, io);
  run.start_camera();
  std::thread capture([&] { run.capture_main(); });
  std::thread worker([&] { run.vision_main(); });
  std::thread output([&] { run.output_main(); });
  output.join();
  run.stop(&capture, &worker);
  run.collect(result);
  return 0;
}

namespace {

// The replay's span in recording time: the first and last frame or odometry row (false: empty).
bool replay_span(const recording::Recording& rec, std::int64_t* t_begin, std::int64_t* t_end) {
  *t_begin = INT64_MAX;
  *t_end = INT64_MIN;
  if (!rec.frames.empty()) {
    *t_begin = std::min(*t_begin, rec.frames.front().t_ns);
    *t_end = std::max(*t_end, rec.frames.back().t_ns);
  }
  if (!rec.odom.empty()) {
    *t_begin = std::min(*t_begin, rec.odom.front().t_ns);
    *t_end = std::max(*t_end, rec.odom.back().t_ns);
  }
  return *t_begin <= *t_end;
}

// The fast replay's state: one thread, the loop clock stepped in recording time.
class FastRun {
 public:
  FastRun(const config::Config& cfg, const LandmarkMap* map, const recording::Recording& rec,
          PipelineIo& io, RunResult* result)
      : rec_(rec),
        io_(io),
        clock_(*io.clock),
        result_(result),
        core_(localizer_config(cfg)),
        loop_(core_, io.bus, clock_, io.odometry, pending_, 0, io.imu, io.sinks),
        loc_(vision_config_with_clock(cfg, nullptr), cfg.camera_model,
             config::landmark_geometry(cfg), map),
        pose_on_fix_(cfg.loop.pose_on_fix),
        delay_ns_(static_cast<std::int64_t>(cfg.replay_fix_delay_ms * 1e6)),
        ranging_offset_ns_(core_.config().ranging.camera_offset_ns) {
    wakes_.reserve(64);
    if (io.ranging_frames && io.rack_observer && io.ranging_counts) {
      ranging_ring_ = std::make_unique<RangingRing>();
      loop_.set_ranging(ranging_ring_.get());
    }
  }

  // Frames exposed up to now are processed; their fixes arrive after the vision delay.
  void process_frames(std::int64_t now);
  // Fix arrivals up to now wake the output step as the vision worker does live.
  void wake_for_fixes(std::int64_t now) {
    while (pose_on_fix_ && wake_head_ < wakes_.size() && wakes_[wake_head_] <= now) {
      const std::int64_t t_wake = wakes_[wake_head_++];
      clock_.sleep_until_ns(t_wake);
      loop_.on_wake(clock_.now_ns());
    }
  }
  void tick(std::int64_t now) {
    clock_.sleep_until_ns(now);
    TickRecord tr;
    loop_.tick(now, cam_, &tr);
    if (io_.ticks) io_.ticks->push_back(tr);
  }
  void start(std::int64_t t_begin) {
    cam_.last_frame_ns = t_begin;
    clock_.sleep_until_ns(t_begin);
  }
  void finish(std::int64_t wall_ns);
  std::size_t frames_done() const { return frame_i_; }
  std::uint64_t fixes_fused() const { return core_.stats().fixes_fused; }
  std::int64_t delay_ns() const { return delay_ns_; }

 private:
  void process_frame(std::size_t i);
  void process_ranging_frame(std::size_t i);

  const recording::Recording& rec_;
  PipelineIo& io_;
  hal::Clock& clock_;
  RunResult* result_;
  localizer::Localizer core_;
  FixRing pending_;  // fixes wait here for their simulated arrival
  OutputLoop loop_;
  vision::LandmarkLocalizer loc_;
  VisionStats vstats_;
  const bool pose_on_fix_;
  const std::int64_t delay_ns_;
  // Arrival times of the good fixes in pending_, where the output step is woken (pose_on_fix);
  // arrival = exposure + fixed delay, so FIFO is time order.
  std::vector<std::int64_t> wakes_;
  std::size_t wake_head_ = 0;
  std::size_t frame_i_ = 0;
  CameraState cam_;
  cv::Mat img_;
  std::string err_;
  // The second camera's stream (null: not configured), in data time with the floor frames.
  const std::int64_t ranging_offset_ns_;
  std::unique_ptr<RangingRing> ranging_ring_;
  std::size_t ranging_i_ = 0;
  RangingRecord ranging_rec_;
};

void FastRun::process_ranging_frame(std::size_t i) {
  const recording::Recording& rr = *io_.ranging_frames;
  RangingCounts& counts = *io_.ranging_counts;
  if (!recording::load_frame(rr, i, &img_, &err_)) {
    ++counts.frame_errors;
    counts.last_error = "ranging/" + err_;
    return;
  }
  const std::int64_t t_ns = rr.frames[i].t_ns;
  // The core has the inputs up to the previous output step: its pose at this exposure.
  ranging::PosePrior prior;
  const bool tracking = pose_prior(core_, t_ns + ranging_offset_ns_, &prior);
  io_.rack_observer->observe(img_, tracking ? &prior : nullptr, &ranging_rec_, &counts);
  ranging_rec_.t_exposure_ns = t_ns;
  ranging_rec_.t_done_ns = t_ns + delay_ns_;
  if (!ranging_ring_->push(ranging_rec_)) ++counts.dropped_queue;
}

void FastRun::process_frame(std::size_t i) {
  if (!recording::load_frame(rec_, i, &img_, &err_)) {
    cam_.error = true;
    result_->camera_error = err_;
    ++result_->camera.errors;
    return;
  }
  cam_.error = false;
  ++result_->camera.frames_delivered;
  cam_.last_frame_ns = rec_.frames[i].t_ns;
  FrameRecord fr;
  const std::int64_t w0 = posix::monotonic_now_ns();
  // The core has the inputs up to the previous output step: its prediction to this exposure.
  loc_.process(img_, core_.prediction_at(rec_.frames[i].t_ns), &fr.fix);
  const std::int64_t w1 = posix::monotonic_now_ns();
  if (io_.diag_frames) io_.diag_frames->offer(img_, rec_.frames[i].t_ns);
  fr.t_exposure_ns = rec_.frames[i].t_ns;
  fr.t_done_ns = fr.t_exposure_ns + delay_ns_;
  localizer::record_vision(fr.fix, 0, w1 - w0, &vstats_);  // exposure->start is not simulated
  if (io_.fixes) io_.fixes->push_back(fr);
  if (fr.fix.status != vision::FixStatus::kNoLandmark && pending_.push(fr.for_fusion()) &&
      fr.fix.status == vision::FixStatus::kOk) {
    if (wake_head_ == wakes_.size()) {
      wakes_.clear();
      wake_head_ = 0;
    }
    wakes_.push_back(fr.t_done_ns);
  }
}

void FastRun::process_frames(std::int64_t now) {
  // Both cameras' frames in exposure order (the floor's first on equal times).
  const std::vector<recording::FrameRow>* ranging =
      ranging_ring_ ? &io_.ranging_frames->frames : nullptr;
  while (true) {
    const bool floor_due = frame_i_ < rec_.frames.size() && rec_.frames[frame_i_].t_ns <= now;
    const bool ranging_due =
        ranging && ranging_i_ < ranging->size() && (*ranging)[ranging_i_].t_ns <= now;
    if (floor_due && (!ranging_due || rec_.frames[frame_i_].t_ns <= (*ranging)[ranging_i_].t_ns)) {
      process_frame(frame_i_++);
    } else if (ranging_due) {
      process_ranging_frame(ranging_i_++);
    } else {
      break;
    }
  }
  cam_.end_of_stream = frame_i_ >= rec_.frames.size();
}

void FastRun::finish(std::int64_t wall_ns) {
  loop_.finish(0);
  result_->output = core_.stats();
  result_->vision = vstats_;
  result_->simulated_time = true;
  result_->fixes_dropped_queue = pending_.dropped();
  result_->odometry_rejected_can = core_.odometry_decoder().counters().rejected();
  result_->odometry_can = core_.odometry_decoder().counters();
  result_->wall_ns = wall_ns;
  if (io_.bus) {
    result_->can = io_.bus->stats();
    result_->can_present = true;
  }
}

// The progress line of a replay on a terminal: one update per percent.
class Progress {
 public:
  Progress(bool show, std::int64_t t_begin, std::int64_t t_end)
      : tty_(show && isatty(STDERR_FILENO)), t_begin_(t_begin), t_end_(t_end) {}
  void update(std::int64_t now, std::size_t frames_done, std::size_t frames,
              std::uint64_t fixes_fused) {
    if (!tty_) return;
    const int pct = static_cast<int>(100.0 * static_cast<double>(now - t_begin_) /
                                     static_cast<double>(t_end_ - t_begin_ + 1));
    if (pct == last_pct_) return;
    std::fprintf(stderr, "\rreplay: %3d %%  frames %zu/%zu  fixes fused %" PRIu64, pct, frames_done,
                 frames, fixes_fused);
    last_pct_ = pct;
  }
  void end() {
    if (tty_) std::fprintf(stderr, "\n");
  }

 private:
  bool tty_;
  std::int64_t t_begin_, t_end_;
  int last_pct_ = -1;
};

}  // namespace

int run_fast(const config::Config& cfg, const LandmarkMap* map, const recording::Recording& rec,
             PipelineIo& io, RunResult* result, bool show_progress) {
  FastRun run(cfg, map, rec, io, result);
  const std::int64_t period_ns = static_cast<std::int64_t>(1e9 / cfg.loop.output_rate_hz);
  std::int64_t t_begin = 0, t_end = 0;
  if (!replay_span(rec, &t_begin, &t_end)) return 0;
  t_end += run.delay_ns();
  const std::int64_t wall0 = posix::monotonic_now_ns();
  Progress progress(show_progress, t_begin, t_end);
  run.start(t_begin);
  for (std::int64_t now = t_begin + period_ns; now <= t_end + period_ns; now += period_ns) {
    if (io.stop && io.stop->load()) break;
    run.process_frames(now);
    run.wake_for_fixes(now);
    run.tick(now);
    progress.update(now, run.frames_done(), rec.frames.size(), run.fixes_fused());
  }
  progress.end();
  run.finish(posix::monotonic_now_ns() - wall0);
  return 0;
}

}  // namespace agv::app

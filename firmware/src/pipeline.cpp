#include "pipeline.hpp"

#include <unistd.h>

#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <cstdlib>
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

LandmarkGeometry geometry_of(const config::Config& cfg) {
  LandmarkGeometry g;
  g.size_mm = cfg.landmark_size_mm;
  return g;
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

}  // namespace

int run_threads(const config::Config& cfg, const LandmarkMap* map, PipelineIo& io,
                RunResult* result) {
  hal::Clock& clock = *io.clock;
  localizer::Localizer core(localizer_config(cfg));
  FixRing fix_queue;
  const std::int64_t log_period_ns =
      io.quiet ? 0 : static_cast<std::int64_t>(cfg.loop.log_period_s * 1e9);
  OutputLoop loop(core, io.bus, clock, io.odometry, fix_queue, log_period_ns, io.imu);
  loop.keep_received_odometry(io.odometry_received);
  loop.set_live_gyro(io.live_gyro);
  loop.set_mqtt(io.mqtt);
  loop.set_diag(io.diag);
  loop.set_log_faults(!io.quiet);
  // loop.pose_on_fix: the vision worker wakes the output thread, which fuses the fix and sends
  // the pose pair at once; it stays the only CAN writer and shares no lock with vision.
  posix::FutexWakeup wakeup(clock);
  const bool pose_on_fix = cfg.loop.pose_on_fix;
  FrameMailbox mailbox;
  std::atomic<bool> done{false};
  std::atomic<bool> camera_eos{false};
  std::atomic<bool> camera_error{false};
  std::atomic<std::int64_t> last_frame_ns{clock.now_ns()};
  std::atomic<std::uint64_t> vision_busy{0};
  VisionStats vstats;
  SnapshotSlot snapshot(core.time_base());
  // Written by one thread each (worker, output), read after both are joined.
  std::uint64_t fixes_not_recorded = 0, ticks_not_recorded = 0;

  if (io.camera->start() != hal::CameraStatus::kOk) {
    std::fprintf(stderr, "agvloc: camera did not start: %s (continuing: dead reckoning only)\n",
                 io.camera->last_error());
    camera_error = true;
  }

  // Capture: never blocks on processing; the mailbox keeps only the newest frame.
  std::thread capture([&] {
    posix::set_thread_name("agv-capture");
    pin_this_thread(cfg.loop.vision_cpus, "capture, loop.vision_cpus");
    apply_fifo_priority(cfg.loop.vision_priority, "capture, loop.vision_priority");
    std::int64_t retry_at_ns = 0;
    while (!done.load()) {
      if (camera_error.load()) {
        // Reopen a vanished camera once a second; fusion dead-reckons meanwhile.
        if (clock.now_ns() < retry_at_ns) {
          clock.sleep_until_ns(std::min(retry_at_ns, clock.now_ns() + 50 * hal::kNsPerMs));
          continue;
        }
        io.camera->stop();
        if (io.camera->start() == hal::CameraStatus::kOk) {
          camera_error = false;
        } else {
          retry_at_ns = clock.now_ns() + 1000 * hal::kNsPerMs;
          continue;
        }
      }
      hal::FrameView f;
      const hal::CameraStatus s = io.camera->next_frame(50 * hal::kNsPerMs, &f);
      if (s == hal::CameraStatus::kOk) {
        last_frame_ns = clock.now_ns();
        hal::FrameView old;
        if (mailbox.put(f, &old)) io.camera->release(old);
      } else if (s == hal::CameraStatus::kEndOfStream) {
        camera_eos = true;
        break;
      } else if (s == hal::CameraStatus::kDisconnected || s == hal::CameraStatus::kDeviceError ||
                 s == hal::CameraStatus::kNotStarted) {
        camera_error = true;
        retry_at_ns = clock.now_ns() + 1000 * hal::kNsPerMs;
      }
    }
    mailbox.close();
  });

  // Vision worker: always the newest frame; results go to the output thread through a fixed ring.
  std::thread worker([&] {
    posix::set_thread_name("agv-vision");
    pin_this_thread(cfg.loop.vision_cpus, "vision, loop.vision_cpus");
    apply_fifo_priority(cfg.loop.vision_priority, "vision, loop.vision_priority");
    vision::LandmarkLocalizer loc(vision_config_with_clock(cfg, &clock), cfg.camera_model,
                                  geometry_of(cfg), map);
    FixRecord rec;
    while (true) {
      hal::FrameView f;
      if (!mailbox.take(100 * hal::kNsPerMs, &f)) {
        if (mailbox.closed() || done.load()) break;
        continue;
      }
      vision_busy = 1;
      const std::int64_t t0 = clock.now_ns();
      const cv::Mat img(f.height_px, f.width_px, CV_8UC1, const_cast<std::uint8_t*>(f.data),
                        static_cast<size_t>(f.stride_bytes));
      const vision::Prediction pred = snapshot.predict_exposure(f.t_exposure_ns);
      loc.process(img, pred, &rec.fix);
      const std::int64_t t1 = clock.now_ns();
      if (io.diag_frames) io.diag_frames->offer(img, f.t_exposure_ns);
      rec.t_exposure_ns = f.t_exposure_ns;
      rec.t_done_ns = t1;
      io.camera->release(f);
      localizer::record_vision(rec.fix, t0 - f.t_exposure_ns, t1 - t0, &vstats);
      if (io.fixes && io.fixes->size() < io.fixes->capacity()) {
        io.fixes->push_back(rec);
      } else if (io.fixes) {
        ++fixes_not_recorded;
      }
      if (rec.fix.status != vision::FixStatus::kNoLandmark && fix_queue.push(rec) && pose_on_fix &&
          rec.fix.status == vision::FixStatus::kOk) {
        wakeup.wake();
      }
      vision_busy = 0;
    }
    hal::FrameView f;
    if (mailbox.drain(&f)) io.camera->release(f);
  });

  // Output: absolute-time periodic timer; between two periods, fix-triggered poses when woken.
  const std::int64_t period_ns = static_cast<std::int64_t>(1e9 / cfg.loop.output_rate_hz);
  const std::int64_t spin_ns = std::int64_t{cfg.loop.spin_before_deadline_us} * 1000;
  std::thread output([&] {
    posix::set_thread_name("agv-output");
    pin_this_thread(cfg.loop.realtime_cpus, "output, loop.realtime_cpus");
    apply_fifo_priority(cfg.loop.realtime_priority, "output, loop.realtime_priority");
    adapters::HybridWaitClock wait(clock, spin_ns);
    std::int64_t next_ns = clock.now_ns() + period_ns;
    while (!done.load()) {
      // A futex timeout carries the thread's timer slack (50 us by default, real-time threads
      // included: +27 us of median jitter measured), the periodic wait none for a SCHED_FIFO
      // thread. So wait for fixes only up to a guard before the deadline and end the period with
      // the same wait as without pose_on_fix; a fix in the guard window goes out with the tick.
      if (pose_on_fix && wakeup.wait_until_ns(next_ns - std::max(spin_ns, kFixWaitGuardNs)) ==
                             hal::WaitResult::kWoken) {
        loop.on_wake(clock.now_ns());
        continue;
      }
      wait.sleep_until_ns(next_ns);
      const std::int64_t now = clock.now_ns();
      core.mutable_stats().period_jitter_ns.record_ns(now - next_ns);
      if (now - next_ns > period_ns) {
        core.note_missed_period();
        // Skip the missed periods instead of bursting to catch up.
        next_ns += ((now - next_ns) / period_ns) * period_ns;
      }
      CameraState cam;
      cam.last_frame_ns = last_frame_ns.load();
      cam.end_of_stream = camera_eos.load();
      cam.error = camera_error.load();
      cam.frames_dropped = mailbox.dropped();
      TickRecord* tr = nullptr;
      if (io.ticks && io.ticks->size() < io.ticks->capacity()) {
        tr = &io.ticks->emplace_back();
      } else if (io.ticks) {
        ++ticks_not_recorded;
      }
      loop.tick(now, cam, tr);
      snapshot.publish(core.snapshot_at(now));
      next_ns += period_ns;
      if (io.stop && io.stop->load()) done = true;
      const bool can_odometry_done = io.can_odometry_end_ns == INT64_MIN ||
                                     now >= io.can_odometry_end_ns + cfg.fusion.health.odom_timeout_ns;
      if (io.stop_at_end_of_stream && camera_eos.load() && vision_busy.load() == 0 &&
          mailbox.closed() && loop.odometry_done() && can_odometry_done) {
        // Hand over what the worker produced, then stop.
        loop.take_inputs(INT64_MAX);
        done = true;
      }
    }
  });

  output.join();
  done = true;
  mailbox.close();
  capture.join();
  worker.join();
  io.camera->stop();
  loop.finish_diag(mailbox.dropped());

  result->output = core.stats();
  result->vision = vstats;
  result->camera = io.camera->stats();
  result->frames_dropped_mailbox = mailbox.dropped();
  result->fixes_dropped_queue = fix_queue.dropped();
  result->odometry_rejected_can = core.odometry_decoder().counters().rejected();
  result->odometry_can = core.odometry_decoder().counters();
  result->ticks_not_recorded = ticks_not_recorded;
  result->fixes_not_recorded = fixes_not_recorded;
  result->odometry_not_recorded = loop.odometry_not_recorded();
  if (io.bus) {
    result->can = io.bus->stats();
    result->can_present = true;
  }
  result->camera_error = io.camera->last_error();
  return 0;
}

int run_fast(const config::Config& cfg, const LandmarkMap* map, const recording::Recording& rec,
             hal::CanBus* bus, adapters::SteppedClock* clock, std::vector<TickRecord>* ticks,
             std::vector<FixRecord>* fixes, std::atomic<bool>* stop, RunResult* result,
             bool show_progress, MqttHandoff* mqtt, DiagHandoff* diag, FrameTap* diag_frames) {
  localizer::Localizer core(localizer_config(cfg));
  // Fixes wait here for their simulated arrival.
  FixRing pending;
  OutputLoop loop(core, bus, *clock, &rec.odom, pending, 0, &rec.imu);
  loop.set_mqtt(mqtt);
  loop.set_diag(diag);
  vision::LandmarkLocalizer loc(vision_config_with_clock(cfg, nullptr), cfg.camera_model,
                                geometry_of(cfg), map);
  VisionStats vstats;
  const bool pose_on_fix = cfg.loop.pose_on_fix;
  const std::int64_t period_ns = static_cast<std::int64_t>(1e9 / cfg.loop.output_rate_hz);
  const std::int64_t delay_ns = static_cast<std::int64_t>(cfg.replay_fix_delay_ms * 1e6);
  std::int64_t t_begin = INT64_MAX, t_end = INT64_MIN;
  if (!rec.frames.empty()) {
    t_begin = std::min(t_begin, rec.frames.front().t_ns);
    t_end = std::max(t_end, rec.frames.back().t_ns);
  }
  if (!rec.odom.empty()) {
    t_begin = std::min(t_begin, rec.odom.front().t_ns);
    t_end = std::max(t_end, rec.odom.back().t_ns);
  }
  if (t_begin > t_end) return 0;
  t_end += delay_ns;

  // Arrival times of the good fixes in `pending`, where the output step is woken (pose_on_fix);
  // arrival = exposure + fixed delay, so FIFO is time order.
  std::vector<std::int64_t> wakes;
  wakes.reserve(64);
  std::size_t wake_head = 0;
  std::size_t frame_i = 0;
  CameraState cam;
  cam.last_frame_ns = t_begin;
  const std::int64_t wall0 = posix::monotonic_now_ns();
  cv::Mat img;
  std::string err;
  int last_pct = -1;
  const bool tty = show_progress && isatty(STDERR_FILENO);
  clock->sleep_until_ns(t_begin);
  for (std::int64_t now = t_begin + period_ns; now <= t_end + period_ns; now += period_ns) {
    if (stop && stop->load()) break;
    // Frames exposed up to now are processed; their fixes arrive after the vision delay.
    while (frame_i < rec.frames.size() && rec.frames[frame_i].t_ns <= now) {
      const std::size_t i = frame_i++;
      if (!recording::load_frame(rec, i, &img, &err)) {
        cam.error = true;
        result->camera_error = err;
        ++result->camera.errors;
        continue;
      }
      cam.error = false;
      ++result->camera.frames_delivered;
      cam.last_frame_ns = rec.frames[i].t_ns;
      FixRecord fr;
      const std::int64_t w0 = posix::monotonic_now_ns();
      // The core has the inputs up to the previous output step: its prediction to this exposure.
      loc.process(img, core.prediction_at(rec.frames[i].t_ns), &fr.fix);
      const std::int64_t w1 = posix::monotonic_now_ns();
      if (diag_frames) diag_frames->offer(img, rec.frames[i].t_ns);
      fr.t_exposure_ns = rec.frames[i].t_ns;
      fr.t_done_ns = fr.t_exposure_ns + delay_ns;
      localizer::record_vision(fr.fix, 0, w1 - w0, &vstats);  // exposure->start is not simulated
      if (fixes) fixes->push_back(fr);
      if (fr.fix.status != vision::FixStatus::kNoLandmark && pending.push(fr) &&
          fr.fix.status == vision::FixStatus::kOk) {
        if (wake_head == wakes.size()) {
          wakes.clear();
          wake_head = 0;
        }
        wakes.push_back(fr.t_done_ns);
      }
    }
    cam.end_of_stream = frame_i >= rec.frames.size();
    // Fix arrivals up to now wake the output step as the vision worker does live.
    while (pose_on_fix && wake_head < wakes.size() && wakes[wake_head] <= now) {
      const std::int64_t t_wake = wakes[wake_head++];
      clock->sleep_until_ns(t_wake);
      loop.on_wake(clock->now_ns());
    }
    clock->sleep_until_ns(now);
    TickRecord tr;
    loop.tick(now, cam, &tr);
    if (ticks) ticks->push_back(tr);
    if (tty) {
      const int pct = static_cast<int>(100.0 * static_cast<double>(now - t_begin) /
                                       static_cast<double>(t_end - t_begin + 1));
      if (pct != last_pct) {
        std::fprintf(stderr, "\rreplay: %3d %%  frames %zu/%zu  fixes fused %" PRIu64, pct, frame_i,
                     rec.frames.size(), core.stats().fixes_fused);
        last_pct = pct;
      }
    }
  }
  if (tty) std::fprintf(stderr, "\n");
  loop.finish_diag(0);
  result->output = core.stats();
  result->vision = vstats;
  result->simulated_time = true;
  result->fixes_dropped_queue = pending.dropped();
  result->odometry_rejected_can = core.odometry_decoder().counters().rejected();
  result->odometry_can = core.odometry_decoder().counters();
  result->wall_ns = posix::monotonic_now_ns() - wall0;
  if (bus) {
    result->can = bus->stats();
    result->can_present = true;
  }
  return 0;
}

}  // namespace agv::app

#include "output_loop.hpp"

#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <utility>

namespace agv::app {

localizer::LocalizerConfig localizer_config(const config::Config& cfg) {
  localizer::LocalizerConfig c;
  c.fusion = cfg.fusion;
  c.protocol = config::protocol_config(cfg);
  c.odometry.speed_scale = cfg.odometry.speed_scale;
  c.odometry.yaw_rate_scale = cfg.odometry.yaw_rate_scale;
  c.odometry.yaw_rate_bias_radps = cfg.odometry.yaw_rate_bias_radps;
  c.odometry.yaw_per_metre_rad = cfg.odometry.yaw_per_metre_rad;
  c.gyro.scale = cfg.imu.scale;
  c.gyro.bias_radps = cfg.imu.bias_radps;
  c.time_base = config::time_base(cfg);
  c.gyro_timeout_ns = std::llround(cfg.can.gyro_timeout_ms * 1e6);
  c.gyro_expected =
      cfg.imu.source == config::ImuSource::kIio;  // the IIO gyro's timeout is can.gyro.timeout_ms
  c.heartbeat_period_ns = static_cast<std::int64_t>(1e9 / cfg.loop.heartbeat_rate_hz);
  c.camera_timeout_ns = static_cast<std::int64_t>(cfg.camera.timeout_ms * 1e6);
  c.ranging.camera_offset_ns = std::llround(cfg.ranging_camera.time_offset_ms * 1e6);
  c.ranging.common_bearing_sigma_rad = config::common_bearing_sigma_rad(cfg.ranging_camera);
  c.ranging.floor_check = cfg.ranging_camera.enabled;
  c.ranging.fix.face_yaw_pairs_below_crossing = cfg.ranging_camera.shallow_pairs_from_face_yaws;
  c.sw_major = AGV_VERSION_MAJOR;
  c.sw_minor = AGV_VERSION_MINOR;
  c.sw_patch = AGV_VERSION_PATCH;
  return c;
}

namespace {

void print_period_line(const OutputStats& o, std::uint64_t dropped) {
  std::fprintf(stderr,
               "agvloc: ticks %" PRIu64 " missed %" PRIu64 " | fixes fused %" PRIu64
               " gated %" PRIu64
               " | e2e p50 %.2f ms p99 %.2f ms | jitter p99 %.0f us | "
               "frames dropped %" PRIu64 " | can tx ok %" PRIu64 " failed %" PRIu64 "\n",
               o.ticks, o.missed_periods, o.fixes_fused, o.fixes_rejected_gate,
               static_cast<double>(o.end_to_end_ns.percentile_ns(0.5)) / 1e6,
               static_cast<double>(o.end_to_end_ns.percentile_ns(0.99)) / 1e6,
               static_cast<double>(o.period_jitter_ns.percentile_ns(0.99)) / 1e3, dropped,
               o.can_tx_ok, o.can_tx_failed);
}

}  // namespace

void FaultLogSink::on_tick(const TickOutput& out) {
  const localizer::FaultTransitions ft = log_.update(out.tick.status.faults, out.tick.t_ns);
  for (int i = 0; i < ft.n; ++i) {
    const localizer::FaultTransition& t = ft.items[static_cast<std::size_t>(i)];
    if (t.changes > 1) {
      std::fprintf(stderr, "agvloc: fault %s (%s) %s (%" PRIu32 " changes since its last line)\n",
                   t.signal, t.name, t.set ? "set" : "cleared", t.changes);
    } else {
      std::fprintf(stderr, "agvloc: fault %s (%s) %s\n", t.signal, t.name,
                   t.set ? "set" : "cleared");
    }
  }
}

OutputLoop::OutputLoop(localizer::Localizer& core, hal::CanBus* bus, const hal::Clock& clock,
                       const std::vector<recording::OdomRow>* odometry, FixRing& fixes,
                       std::int64_t log_period_ns, const std::vector<recording::ImuRow>* imu,
                       std::vector<OutputSink*> sinks)
    : core_(core),
      bus_(bus),
      clock_(clock),
      odometry_(odometry),
      imu_(imu),
      sinks_(std::move(sinks)),
      fixes_(fixes),
      log_period_ns_(log_period_ns),
      log_due_(log_period_ns, /*first_at_start=*/false),
      can_(core.config().protocol) {
  if (bus_) {
    // One filter per enabled input message (odometry, and AGV_Gyro when can.gyro.enabled).
    constexpr int kMax = localizer::Localizer::kMaxReceiveFilters;
    hal::CanFilter f[kMax];
    const int n = core_.receive_filters(f, kMax);
    bus_->set_filters(f, static_cast<std::size_t>(n < kMax ? n : kMax));
  }
}

void OutputLoop::drain_odometry(std::int64_t up_to_ns) {
  const std::size_t n_odom = odometry_ ? odometry_->size() : 0;
  const std::size_t n_imu = imu_ ? imu_->size() : 0;
  while (true) {
    const bool odom_due = odom_i_ < n_odom && (*odometry_)[odom_i_].t_ns <= up_to_ns;
    const bool imu_due = imu_i_ < n_imu && (*imu_)[imu_i_].t_ns <= up_to_ns;
    if (odom_due && (!imu_due || (*odometry_)[odom_i_].t_ns <= (*imu_)[imu_i_].t_ns)) {
      const recording::OdomRow& r = (*odometry_)[odom_i_++];
      core_.on_odometry(r.t_ns, r.v_mps, r.omega_radps);
    } else if (imu_due) {
      const recording::ImuRow& r = (*imu_)[imu_i_++];
      core_.on_gyro(r.t_ns, r.gyro_z_radps);  // counted in stats (gyro_samples / gyro_rejected)
    } else {
      break;
    }
  }
}

int OutputLoop::take_inputs(std::int64_t now_ns) {
  if (bus_) {
    hal::CanFrame frame;
    protocol::OdomSample s;
    // Bounded: at 1 Mbit/s at most ~80 frames arrive in 10 ms.
    for (int i = 0; i < 256; ++i) {
      if (bus_->receive(&frame, 0) != hal::CanStatus::kOk) break;
      if (!core_.on_can_frame(frame, &s) || !received_) continue;
      if (received_->size() < received_->capacity()) {
        received_->push_back({s.t_ns, s.v_mps, s.omega_radps});
      } else {
        ++odometry_not_recorded_;
      }
    }
  }
  if (live_gyro_) {
    GyroRow g;
    // Bounded like the CAN receive: 256 samples are > 1 s at 200 Hz.
    for (int i = 0; i < 256 && live_gyro_->pop(&g); ++i) core_.on_gyro(g.t_ns, g.gyro_z_radps);
  }
  int good = 0;
  FixRecord rec;
  // Floor fixes and second-camera frames in arrival order (a fix first on equal times).
  while (true) {
    const bool fix_due = fixes_.front(&rec) && rec.t_done_ns <= now_ns;
    const bool ranging_due =
        ranging_ && ranging_->front(&ranging_rec_) && ranging_rec_.t_done_ns <= now_ns;
    if (fix_due && (!ranging_due || rec.t_done_ns <= ranging_rec_.t_done_ns)) {
      fixes_.pop(&rec);
      drain_odometry(rec.t_done_ns);
      core_.on_fix(rec.fix, rec.t_exposure_ns, rec.t_done_ns);
      for (OutputSink* sink : sinks_) sink->on_fix(rec);
      if (rec.fix.status == vision::FixStatus::kOk) ++good;
    } else if (ranging_due) {
      ranging_->pop(&ranging_rec_);
      drain_odometry(ranging_rec_.t_done_ns);
      core_.on_ranging(ranging_rec_.t_exposure_ns,
                       std::span(ranging_rec_.obs.data(), ranging_rec_.n));
    } else {
      break;
    }
  }
  drain_odometry(now_ns);
  return good;
}

void OutputLoop::send(const localizer::OutFrames& out) {
  OutputStats& st = core_.mutable_stats();
  // The period's frames in one hand-over (one sendmmsg on SocketCAN): a preemption between
  // two writes once held a pose's heading 262 ms behind its position.
  if (bus_ && out.n > 0) {
    hal::CanStatus status[localizer::OutFrames::kMax];
    const std::size_t n = static_cast<std::size_t>(out.n);
    const std::size_t ok = bus_->send_batch(out.frame, n, status);
    st.can_tx_ok += ok;
    st.can_tx_failed += n - ok;  // counted, never retried: the next period carries fresher data
  }
  // End to end ends when the pose pair (first in the batch) has left, i.e. with the batch.
  if (out.n >= 2 && out.e2e_exposure_ns != INT64_MIN) {
    st.end_to_end_ns.record_ns(clock_.now_ns() - out.e2e_exposure_ns);
  }
}

void OutputLoop::tick(std::int64_t now_ns, const CameraState& camera, TickRecord* rec) {
  take_inputs(now_ns);
  core_.set_camera_state(camera.last_frame_ns, camera.end_of_stream, camera.error);
  if (bus_) core_.set_can_state(bus_->state(), bus_->stats());
  for (OutputSink* sink : sinks_) sink->before_tick(now_ns, core_);
  TickRecord local;
  if (!rec) rec = &local;
  const std::int64_t t_start = clock_.now_ns();
  *rec = core_.tick(now_ns);
  can_.encode(*rec, &frames_);
  const std::int64_t t_fused = clock_.now_ns();
  core_.mutable_stats().fusion_ns.record_ns(t_fused - t_start);
  send(frames_);
  core_.mutable_stats().can_send_ns.record_ns(clock_.now_ns() - t_fused);
  if (!sinks_.empty()) {
    const TickOutput out{*rec, core_.stats(), bus_, camera.frames_dropped};
    for (OutputSink* sink : sinks_) sink->on_tick(out);
    last_tick_ = *rec;
    have_tick_ = true;
  }
  if (log_period_ns_ > 0 && log_due_.take(now_ns)) {
    print_period_line(core_.stats(), camera.frames_dropped);
  }
}

void OutputLoop::finish(std::uint64_t frames_dropped) {
  for (OutputSink* sink : sinks_) {
    sink->finish(have_tick_ ? &last_tick_ : nullptr, core_.stats(), bus_, frames_dropped);
  }
}

bool OutputLoop::on_wake(std::int64_t now_ns) {
  if (take_inputs(now_ns) == 0) return false;
  can_.encode_pose(core_.pose_now(now_ns), &frames_);
  send(frames_);
  return true;
}

}  // namespace agv::app

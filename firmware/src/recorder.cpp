#include "recorder.hpp"

#include <algorithm>
#include <cinttypes>
#include <cstdio>

#include "agv/localizer/localizer.hpp"

namespace agv::app {

Recorder::Recorder(std::string dir, const protocol::ProtocolConfig& pc, hal::Camera& camera,
                   hal::CanBus& bus, std::unique_ptr<hal::Imu> imu, const hal::Clock& clock,
                   RecorderOptions options, hal::Camera* ranging_camera)
    : dir_(std::move(dir)),
      pc_(pc),
      bus_(bus),
      clock_(clock),
      options_(options),
      odom_decoder_(pc),
      gyro_decoder_(pc),
      floor_(dir_, "camera", camera, clock, options.sync_period_ns) {
  if (imu) gyro_reader_ = std::make_unique<GyroReader>(std::move(imu), gyro_ring_);
  if (ranging_camera) {
    ranging_ = std::make_unique<FrameStreamRecorder>(
        dir_ + "/ranging", "ranging camera", *ranging_camera, clock, options.sync_period_ns);
  }
}

Recorder::~Recorder() { stop(); }

bool Recorder::start(std::string* error) {
  // The devices first: a device that does not start leaves no file behind, so the same command
  // can be run again on the same directory.
  auto stop_streams = [this] {
    floor_.stop();
    if (ranging_) ranging_->stop();
  };
  if (!floor_.start_camera(error) || (ranging_ && !ranging_->start_camera(error)) ||
      (gyro_reader_ && !gyro_reader_->start(error))) {
    stop_streams();
    return false;
  }
  const bool files = floor_.start(error) && (!ranging_ || ranging_->start(error)) &&
                     odom_csv_.open(dir_ + "/odom.csv", recording::odom_csv_header(), error);
  if (!files) {
    if (gyro_reader_) gyro_reader_->stop();
    stop_streams();
    return false;
  }
  // The same filters as `agvloc run`: one per enabled input of the signal table.
  hal::CanFilter filters[localizer::Localizer::kMaxReceiveFilters];
  const int n = localizer::receive_filters(pc_, filters, localizer::Localizer::kMaxReceiveFilters);
  bus_.set_filters(filters, static_cast<std::size_t>(
                                std::clamp(n, 0, localizer::Localizer::kMaxReceiveFilters)));
  flushed_ns_ = synced_ns_ = clock_.now_ns();
  running_ = true;
  return true;
}

void Recorder::step(std::int64_t timeout_ns) {
  hal::CanFrame cf;
  if (bus_.receive(&cf, timeout_ns) == hal::CanStatus::kOk) {
    protocol::OdomSample s;
    protocol::GyroSample g;
    if (odom_decoder_.decode(cf, &s) == protocol::DecodeResult::kOk) {
      if (s.t_ns > last_odom_t_ns_) {
        last_odom_t_ns_ = s.t_ns;
        odom_csv_.add(recording::format_odom_row({s.t_ns, s.v_mps, s.omega_radps}));
      } else {
        ++samples_out_of_order_;
      }
    } else if (pc_.gyro.enabled && gyro_decoder_.decode(cf, &g) == protocol::DecodeResult::kOk) {
      // The localizer fuses no saturated sample, so replay must not see one either.
      if (g.saturated) {
        ++gyro_saturated_;
      } else {
        add_imu(g.t_ns, g.gyro_z_radps);
      }
    }
  }
  GyroRow r;
  while (gyro_ring_.pop(&r)) add_imu(r.t_ns, r.gyro_z_radps);
  flush_rows(false);
}

void Recorder::add_imu(std::int64_t t_ns, double gyro_z_radps) {
  if (t_ns <= last_imu_t_ns_) {
    ++samples_out_of_order_;
    return;
  }
  // No sample, no file: an absent imu.csv is what "no gyro" means to replay.
  if (!imu_csv_.is_open()) {
    std::string e;
    if (!imu_csv_.open(dir_ + "/imu.csv", recording::imu_csv_header(), &e)) {
      csv_error(e);
      return;
    }
  }
  last_imu_t_ns_ = t_ns;
  imu_csv_.add(recording::format_imu_row({t_ns, gyro_z_radps}));
}

void Recorder::flush_rows(bool force) {
  const std::int64_t now = clock_.now_ns();
  const bool due = force || now - flushed_ns_ >= options_.flush_period_ns ||
                   odom_csv_.rows_pending() + imu_csv_.rows_pending() >= options_.flush_rows;
  if (!due) return;
  flushed_ns_ = now;
  std::string e;
  if (!odom_csv_.flush(&e)) csv_error(e);
  if (!imu_csv_.flush(&e)) csv_error(e);
  if (force || now - synced_ns_ >= options_.sync_period_ns) {
    synced_ns_ = now;
    if (!odom_csv_.sync(&e)) csv_error(e);
    if (!imu_csv_.sync(&e)) csv_error(e);
  }
}

void Recorder::csv_error(const std::string& what) {
  // Once: a full disk fails every flush, and the count is in the closing line.
  if (csv_write_errors_++ == 0) {
    std::fprintf(stderr, "agvloc record: %s (further write errors are only counted)\n",
                 what.c_str());
  }
}

bool Recorder::stop() {
  if (!running_) return true;
  running_ = false;
  floor_.stop();
  if (ranging_) ranging_->stop();
  if (gyro_reader_) gyro_reader_->stop();
  GyroRow r;
  while (gyro_ring_.pop(&r)) add_imu(r.t_ns, r.gyro_z_radps);
  flush_rows(true);
  std::string e;
  if (!odom_csv_.close(&e)) csv_error(e);
  if (!imu_csv_.close(&e)) csv_error(e);
  return floor_.ok() && (!ranging_ || ranging_->ok()) && csv_write_errors_ == 0;
}

RecorderCounters Recorder::counters() const {
  RecorderCounters c;
  const FrameStreamCounters f = floor_.counters();
  c.frames = f.frames;
  c.frames_dropped = f.frames_dropped;
  c.frames_out_of_order = f.frames_out_of_order;
  c.png_write_errors = f.png_write_errors;
  c.odom = odom_csv_.rows_written() + odom_csv_.rows_pending();
  c.odom_rejected = odom_decoder_.counters().rejected();
  c.gyro = imu_csv_.rows_written() + imu_csv_.rows_pending();
  c.gyro_rejected = gyro_decoder_.counters().rejected();
  c.gyro_saturated = gyro_saturated_;
  c.samples_out_of_order = samples_out_of_order_;
  c.csv_write_errors = csv_write_errors_ + f.csv_write_errors;
  c.rows_lost = f.rows_lost + odom_csv_.rows_lost() + imu_csv_.rows_lost();
  if (ranging_) {
    c.ranging = true;
    c.ranging_frames = ranging_->counters();
    c.png_write_errors += c.ranging_frames.png_write_errors;
    c.csv_write_errors += c.ranging_frames.csv_write_errors;
    c.rows_lost += c.ranging_frames.rows_lost;
  }
  return c;
}

std::string Recorder::summary() const {
  const RecorderCounters c = counters();
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "agvloc record: %" PRIu64 " frames (%" PRIu64 " dropped while encoding, %" PRIu64
                " out of order, %" PRIu64 " PNG write errors), %" PRIu64
                " odometry samples (%" PRIu64 " rejected), %" PRIu64 " gyro samples (%" PRIu64
                " rejected, %" PRIu64 " saturated left out), %" PRIu64
                " samples out of order, %" PRIu64 " CSV write errors (%" PRIu64
                " rows lost) -> %s\n",
                c.frames, c.frames_dropped, c.frames_out_of_order, c.png_write_errors, c.odom,
                c.odom_rejected, c.gyro, c.gyro_rejected, c.gyro_saturated, c.samples_out_of_order,
                c.csv_write_errors, c.rows_lost, dir_.c_str());
  std::string s = buf;
  if (c.ranging) {
    const FrameStreamCounters& r = c.ranging_frames;
    std::snprintf(buf, sizeof buf,
                  "agvloc record: ranging camera: %" PRIu64 " frames (%" PRIu64
                  " dropped while encoding, %" PRIu64 " out of order, %" PRIu64
                  " PNG write errors) -> %s\n",
                  r.frames, r.frames_dropped, r.frames_out_of_order, r.png_write_errors,
                  ranging_->dir().c_str());
    s += buf;
  }
  if (gyro_reader_)
    s += "agvloc record: " + format_gyro_counters(gyro_reader_->counters(), gyro_ring_.dropped());
  return s;
}

}  // namespace agv::app

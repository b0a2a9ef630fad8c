#include "recorder.hpp"

#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <opencv2/core.hpp>

#include "agv/localizer/localizer.hpp"

namespace agv::app {

Recorder::Recorder(std::string dir, const protocol::ProtocolConfig& pc, hal::Camera& camera,
                   hal::CanBus& bus, std::unique_ptr<hal::Imu> imu, const hal::Clock& clock,
                   RecorderOptions options)
    : dir_(std::move(dir)),
      pc_(pc),
      camera_(camera),
      bus_(bus),
      clock_(clock),
      options_(options),
      odom_decoder_(pc),
      gyro_decoder_(pc) {
  if (imu) gyro_reader_ = std::make_unique<GyroReader>(std::move(imu), gyro_ring_);
}

Recorder::~Recorder() { stop(); }

bool Recorder::start(std::string* error) {
  // The devices first: a camera that does not start leaves no frames.csv behind, so the same
  // command can be run again on the same directory.
  if (camera_.start() != hal::CameraStatus::kOk) {
    *error = std::string("camera did not start: ") + camera_.last_error();
    return false;
  }
  if (gyro_reader_ && !gyro_reader_->start(error)) {
    camera_.stop();
    return false;
  }
  std::error_code ec;
  std::filesystem::create_directories(dir_, ec);
  if (!frames_csv_.open(dir_ + "/frames.csv", recording::frames_csv_header(), error) ||
      !odom_csv_.open(dir_ + "/odom.csv", recording::odom_csv_header(), error)) {
    frames_csv_.close(nullptr);
    if (gyro_reader_) gyro_reader_->stop();
    camera_.stop();
    return false;
  }
  // The same filters as `agvloc run`: one per enabled input of the signal table.
  hal::CanFilter filters[localizer::Localizer::kMaxReceiveFilters];
  const int n = localizer::receive_filters(pc_, filters, localizer::Localizer::kMaxReceiveFilters);
  bus_.set_filters(filters, static_cast<std::size_t>(
                                std::clamp(n, 0, localizer::Localizer::kMaxReceiveFilters)));
  flushed_ns_ = synced_ns_ = frames_synced_ns_ = clock_.now_ns();
  done_ = false;
  running_ = true;
  capture_ = std::thread([this] { capture_loop(); });
  writer_ = std::thread([this] { writer_loop(); });
  return true;
}

void Recorder::capture_loop() {
  while (!done_.load()) {
    hal::FrameView f;
    const auto s = camera_.next_frame(50'000'000, &f);
    if (s == hal::CameraStatus::kOk) {
      hal::FrameView old;
      if (mailbox_.put(f, &old)) camera_.release(old);
    } else if (s != hal::CameraStatus::kTimeout) {
      std::fprintf(stderr, "agvloc record: camera: %s (%s)\n", hal::to_string(s),
                   camera_.last_error());
      break;
    }
  }
  mailbox_.close();
}

void Recorder::writer_loop() {
  hal::FrameView f;
  while (mailbox_.take(100'000'000, &f) || !mailbox_.closed()) {
    if (!f.data) continue;
    record_frame(f);
    camera_.release(f);
    f = hal::FrameView{};
  }
}

void Recorder::record_frame(const hal::FrameView& f) {
  // The reader rejects frames.csv unless exposure times strictly increase.
  if (f.t_exposure_ns <= last_frame_t_ns_) {
    ++frames_out_of_order_;
    return;
  }
  char name[64];
  std::snprintf(name, sizeof name, "frames/%08" PRIu64 ".png", frames_.load());
  const cv::Mat img(f.height_px, f.width_px, CV_8UC1, const_cast<std::uint8_t*>(f.data),
                    static_cast<size_t>(f.stride_bytes));
  std::string e;
  if (!recording::write_frame_png(dir_, name, img, &e)) {
    if (png_write_errors_++ == 0) std::fprintf(stderr, "agvloc record: %s\n", e.c_str());
    return;
  }
  // The row after its PNG: a row on disk names a complete file (unless power is lost before
  // the kernel wrote the PNG back).
  std::string row;
  if (!recording::format_frame_row({f.t_exposure_ns, name}, &row, &e)) {
    csv_error(e);
    return;
  }
  last_frame_t_ns_ = f.t_exposure_ns;
  ++frames_;
  frames_csv_.add(row);
  const std::uint64_t lost = frames_csv_.rows_lost();
  // A row per frame: at 30 fps a write() each is nothing beside the PNG.
  if (!frames_csv_.flush(&e)) {
    frames_rows_lost_ += frames_csv_.rows_lost() - lost;
    csv_error(e);
  }
  const std::int64_t now = clock_.now_ns();
  if (now - frames_synced_ns_ >= options_.sync_period_ns) {
    frames_synced_ns_ = now;
    if (!frames_csv_.sync(&e)) csv_error(e);
  }
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
  done_ = true;
  if (capture_.joinable()) capture_.join();
  if (writer_.joinable()) writer_.join();
  camera_.stop();
  if (gyro_reader_) gyro_reader_->stop();
  GyroRow r;
  while (gyro_ring_.pop(&r)) add_imu(r.t_ns, r.gyro_z_radps);
  flush_rows(true);
  std::string e;
  const std::uint64_t lost = frames_csv_.rows_lost();
  if (!frames_csv_.close(&e)) csv_error(e);
  frames_rows_lost_ += frames_csv_.rows_lost() - lost;
  if (!odom_csv_.close(&e)) csv_error(e);
  if (!imu_csv_.close(&e)) csv_error(e);
  return png_write_errors_.load() == 0 && csv_write_errors_.load() == 0;
}

RecorderCounters Recorder::counters() const {
  RecorderCounters c;
  c.frames = frames_.load();
  c.frames_dropped = mailbox_.dropped();
  c.frames_out_of_order = frames_out_of_order_.load();
  c.png_write_errors = png_write_errors_.load();
  c.odom = odom_csv_.rows_written() + odom_csv_.rows_pending();
  c.odom_rejected = odom_decoder_.counters().rejected();
  c.gyro = imu_csv_.rows_written() + imu_csv_.rows_pending();
  c.gyro_rejected = gyro_decoder_.counters().rejected();
  c.gyro_saturated = gyro_saturated_;
  c.samples_out_of_order = samples_out_of_order_;
  c.csv_write_errors = csv_write_errors_.load();
  c.rows_lost = frames_rows_lost_.load() + odom_csv_.rows_lost() + imu_csv_.rows_lost();
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
  if (gyro_reader_)
    s += "agvloc record: " + format_gyro_counters(gyro_reader_->counters(), gyro_ring_.dropped());
  return s;
}

}  // namespace agv::app

#include "frame_stream_recorder.hpp"

#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <opencv2/core.hpp>

#include "agv/recording/recording.hpp"

namespace agv::app {

FrameStreamRecorder::FrameStreamRecorder(std::string dir, std::string name, hal::Camera& camera,
                                         const hal::Clock& clock, std::int64_t sync_period_ns)
    : dir_(std::move(dir)),
      name_(std::move(name)),
      camera_(camera),
      clock_(clock),
      sync_period_ns_(sync_period_ns) {}

FrameStreamRecorder::~FrameStreamRecorder() { stop(); }

bool FrameStreamRecorder::start_camera(std::string* error) {
  if (camera_.start() == hal::CameraStatus::kOk) return camera_started_ = true;
  *error = name_ + " did not start: " + camera_.last_error();
  return false;
}

bool FrameStreamRecorder::start(std::string* error) {
  std::error_code ec;
  std::filesystem::create_directories(dir_, ec);
  if (!frames_csv_.open(dir_ + "/frames.csv", recording::frames_csv_header(), error)) return false;
  synced_ns_ = clock_.now_ns();
  done_ = false;
  running_ = true;
  capture_ = std::thread([this] { capture_loop(); });
  writer_ = std::thread([this] { writer_loop(); });
  return true;
}

void FrameStreamRecorder::capture_loop() {
  while (!done_.load()) {
    hal::FrameView f;
    const auto s = camera_.next_frame(50'000'000, &f);
    if (s == hal::CameraStatus::kOk) {
      hal::FrameView old;
      if (mailbox_.put(f, &old)) camera_.release(old);
    } else if (s != hal::CameraStatus::kTimeout) {
      std::fprintf(stderr, "agvloc record: %s: %s (%s)\n", name_.c_str(), hal::to_string(s),
                   camera_.last_error());
      break;
    }
  }
  mailbox_.close();
}

void FrameStreamRecorder::writer_loop() {
  hal::FrameView f;
  while (mailbox_.take(100'000'000, &f) || !mailbox_.closed()) {
    if (!f.data) continue;
    record_frame(f);
    camera_.release(f);
    f = hal::FrameView{};
  }
}

void FrameStreamRecorder::record_frame(const hal::FrameView& f) {
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
    if (png_write_errors_++ == 0) {
      std::fprintf(stderr, "agvloc record: %s: %s\n", name_.c_str(), e.c_str());
    }
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
    rows_lost_ += frames_csv_.rows_lost() - lost;
    csv_error(e);
  }
  const std::int64_t now = clock_.now_ns();
  if (now - synced_ns_ >= sync_period_ns_) {
    synced_ns_ = now;
    if (!frames_csv_.sync(&e)) csv_error(e);
  }
}

void FrameStreamRecorder::csv_error(const std::string& what) {
  // Once: a full disk fails every flush, and the count is in the closing line.
  if (csv_write_errors_++ == 0) {
    std::fprintf(stderr, "agvloc record: %s: %s (further write errors are only counted)\n",
                 name_.c_str(), what.c_str());
  }
}

void FrameStreamRecorder::stop() {
  if (camera_started_) {
    camera_started_ = false;
    done_ = true;
    if (capture_.joinable()) capture_.join();
    if (writer_.joinable()) writer_.join();
    camera_.stop();
  }
  if (!running_) return;
  running_ = false;
  std::string e;
  const std::uint64_t lost = frames_csv_.rows_lost();
  if (!frames_csv_.close(&e)) csv_error(e);
  rows_lost_ += frames_csv_.rows_lost() - lost;
}

FrameStreamCounters FrameStreamRecorder::counters() const {
  FrameStreamCounters c;
  c.frames = frames_.load();
  c.frames_dropped = mailbox_.dropped();
  c.frames_out_of_order = frames_out_of_order_.load();
  c.png_write_errors = png_write_errors_.load();
  c.csv_write_errors = csv_write_errors_.load();
  c.rows_lost = rows_lost_.load();
  return c;
}

}  // namespace agv::app

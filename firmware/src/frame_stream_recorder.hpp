// One camera's frames into a recording folder (docs/guide/recording.md): a capture thread (camera
// -> mailbox, the newest frame wins) and a PNG writer (mailbox -> DIR/frames/NNNNNNNN.png, then the
// frame's row in DIR/frames.csv, written with each frame and synced every sync_period_ns). The
// floor camera's stream is the recording's folder, the second camera's its ranging/ folder.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <thread>

#include "agv/hal/camera.hpp"
#include "agv/hal/clock.hpp"
#include "agv/recording/csv_stream.hpp"
#include "handoff.hpp"

namespace agv::app {

struct FrameStreamCounters {
  std::uint64_t frames = 0;               // rows of frames.csv
  std::uint64_t frames_dropped = 0;       // replaced in the mailbox while a PNG was encoding
  std::uint64_t frames_out_of_order = 0;  // exposure time not after the previous frame's
  std::uint64_t png_write_errors = 0;
  std::uint64_t csv_write_errors = 0;  // failed flushes, creates and syncs of frames.csv
  std::uint64_t rows_lost = 0;         // rows those failures kept out of the file
};

class FrameStreamRecorder {
 public:
  // `name` starts its log lines ("camera", "ranging camera"). The camera and the clock must
  // outlive the recorder.
  FrameStreamRecorder(std::string dir, std::string name, hal::Camera& camera,
                      const hal::Clock& clock, std::int64_t sync_period_ns);
  ~FrameStreamRecorder();
  FrameStreamRecorder(const FrameStreamRecorder&) = delete;
  FrameStreamRecorder& operator=(const FrameStreamRecorder&) = delete;

  // Starts the camera; false with *error. Before start(), so that a camera that does not start
  // leaves no file behind.
  bool start_camera(std::string* error);
  // Creates DIR and DIR/frames.csv (refusing an existing one) and starts the threads; false with
  // *error.
  bool start(std::string* error);
  // Stops the threads and the camera (whichever started), closes frames.csv. Idempotent.
  void stop();
  FrameStreamCounters counters() const;
  bool ok() const { return png_write_errors_.load() == 0 && csv_write_errors_.load() == 0; }
  const std::string& dir() const { return dir_; }

 private:
  void capture_loop();
  void writer_loop();
  void record_frame(const hal::FrameView& f);
  void csv_error(const std::string& what);

  std::string dir_, name_;
  hal::Camera& camera_;
  const hal::Clock& clock_;
  const std::int64_t sync_period_ns_;
  FrameMailbox mailbox_;
  std::thread capture_, writer_;
  std::atomic<bool> done_{false};
  bool running_ = false, camera_started_ = false;

  // Writer thread only.
  recording::CsvStream frames_csv_;
  std::int64_t last_frame_t_ns_ = -1;
  std::int64_t synced_ns_ = 0;
  std::atomic<std::uint64_t> frames_{0}, frames_out_of_order_{0}, png_write_errors_{0};
  std::atomic<std::uint64_t> csv_write_errors_{0}, rows_lost_{0};
};

}  // namespace agv::app

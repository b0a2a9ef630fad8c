// The recording behind `agvloc record` (docs/guide/recording.md): the camera's frames as PNGs (and
// the second camera's in ranging/ with ranging_camera.enabled), CAN odometry, and the gyro
// (AGV_Gyro on CAN, or a hal::Imu for imu.source iio), each row appended to its CSV as it arrives.
// Rows reach the file at least every flush_period_ns, so a crash loses at most that much; a power
// loss at most sync_period_ns of rows.
//
// Threads: per camera a capture and a PNG writer (frame_stream_recorder.hpp), the IIO gyro reader
// when there is an IIO gyro, and the caller's, which calls step() in a loop: CAN frames ->
// odom.csv / imu.csv, IIO samples -> imu.csv.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>

#include "agv/hal/camera.hpp"
#include "agv/hal/can_bus.hpp"
#include "agv/hal/clock.hpp"
#include "agv/hal/imu.hpp"
#include "agv/protocol/codec.hpp"
#include "agv/recording/csv_stream.hpp"
#include "frame_stream_recorder.hpp"
#include "gyro_reader.hpp"
#include "handoff.hpp"

namespace agv::app {

struct RecorderOptions {
  std::int64_t flush_period_ns = 100'000'000;
  std::uint64_t flush_rows = 64;  // or sooner, when this many rows wait
  std::int64_t sync_period_ns = 1'000'000'000;
};

struct RecorderCounters {
  std::uint64_t frames = 0;               // rows of frames.csv
  std::uint64_t frames_dropped = 0;       // replaced in the mailbox while a PNG was encoding
  std::uint64_t frames_out_of_order = 0;  // exposure time not after the previous frame's
  std::uint64_t png_write_errors = 0;
  std::uint64_t odom = 0;
  std::uint64_t odom_rejected = 0;  // by the decoder (E2E, range)
  std::uint64_t gyro = 0;           // rows of imu.csv
  std::uint64_t gyro_rejected = 0;  // AGV_Gyro frames the decoder rejected
  std::uint64_t gyro_saturated = 0;
  std::uint64_t samples_out_of_order = 0;  // odometry or gyro stamp not after the previous row's
  std::uint64_t csv_write_errors = 0;      // failed flushes, creates and syncs of the CSV files
  std::uint64_t rows_lost = 0;             // rows those failures kept out of the files
  bool ranging = false;                    // the second camera was recorded (ranging/)
  FrameStreamCounters ranging_frames;
};

class Recorder {
 public:
  // `imu`: the IIO gyro of imu.source iio, or null. AGV_Gyro frames are recorded when
  // pc.gyro.enabled. `ranging_camera`: the second camera (ranging_camera.enabled), or null. The
  // devices and the clock must outlive the recorder.
  Recorder(std::string dir, const protocol::ProtocolConfig& pc, hal::Camera& camera,
           hal::CanBus& bus, std::unique_ptr<hal::Imu> imu, const hal::Clock& clock,
           RecorderOptions options = {}, hal::Camera* ranging_camera = nullptr);
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  // Starts the cameras and the IIO gyro, creates frames.csv (ranging/frames.csv) and odom.csv
  // (refusing existing ones) in `dir`, sets the CAN filters and starts the threads. False with
  // *error, nothing left running.
  bool start(std::string* error);
  // Waits up to timeout_ns for one CAN frame and records it, takes the IIO gyro's samples and
  // flushes what is due.
  void step(std::int64_t timeout_ns);
  // Stops the threads and devices, writes what is buffered, syncs and closes the files.
  // Idempotent. True when every frame and row reached its file.
  bool stop();

  RecorderCounters counters() const;
  std::string summary() const;  // the closing line of `agvloc record`

 private:
  void add_imu(std::int64_t t_ns, double gyro_z_radps);
  void flush_rows(bool force);
  void csv_error(const std::string& what);

  std::string dir_;
  protocol::ProtocolConfig pc_;
  hal::CanBus& bus_;
  const hal::Clock& clock_;
  RecorderOptions options_;
  protocol::OdometryDecoder odom_decoder_;
  protocol::GyroDecoder gyro_decoder_;
  GyroRing gyro_ring_;
  std::unique_ptr<GyroReader> gyro_reader_;  // imu.source iio

  FrameStreamRecorder floor_;
  std::unique_ptr<FrameStreamRecorder> ranging_;
  bool running_ = false;

  // step() thread only.
  recording::CsvStream odom_csv_, imu_csv_;  // imu.csv is created by the first sample
  std::int64_t last_odom_t_ns_ = -1, last_imu_t_ns_ = -1;
  std::int64_t flushed_ns_ = 0, synced_ns_ = 0;
  std::uint64_t gyro_saturated_ = 0, samples_out_of_order_ = 0;

  std::uint64_t csv_write_errors_ = 0;
};

}  // namespace agv::app

// One time base for the localizer: every sensor's stamps onto the vehicle's clock, the one that
// stamps odometry and CAN and the one the output runs on. Built once from the configuration
// (config::time_base) and applied where a stamp enters the core, so the fast loop (the core's
// prediction_at) and the threaded loop (the vision worker's snapshot extrapolation) cannot
// disagree on the instant a frame shows.
#pragma once

#include <cstdint>

namespace agv::localizer {

struct TimeBase {
  // vehicle clock = camera clock + camera_offset_ns (key camera.time_offset_ms; + = the camera's
  // stamps are early against the vehicle's). At 1 m/s every ms is 1 mm along track at a fix and
  // in the search windows' prediction.
  std::int64_t camera_offset_ns = 0;
  // gyro clock = vehicle clock + gyro_offset_ns (key imu.time_offset_ms; + = the gyro's stamps are
  // late): the sensor's filter delay plus, for CAN samples stamped on receipt, its transmit
  // latency.
  std::int64_t gyro_offset_ns = 0;

  std::int64_t camera_to_vehicle_ns(std::int64_t t_camera_ns) const {
    return t_camera_ns + camera_offset_ns;
  }
  std::int64_t gyro_to_vehicle_ns(std::int64_t t_gyro_ns) const {
    return t_gyro_ns - gyro_offset_ns;
  }
  // Odometry (CAN or recorded) defines the vehicle's clock: no offset.
  std::int64_t odometry_to_vehicle_ns(std::int64_t t_odometry_ns) const { return t_odometry_ns; }
};

}  // namespace agv::localizer

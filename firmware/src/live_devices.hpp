// Creates the configured live camera driver.
#pragma once

#include <memory>
#include <string>

#include "agv/hal/camera.hpp"
#include "agv/hal/imu.hpp"
#include "config.hpp"

namespace agv::app {

// Null with *error when the driver is not available in this build (libcamera missing) or the
// camera configuration is invalid.
std::unique_ptr<hal::Camera> make_live_camera(const config::Config& cfg, std::string* error);
// The same for any camera section (the floor camera's, "camera"; the second camera's,
// "ranging_camera"), errors named by it.
std::unique_ptr<hal::Camera> make_live_camera(config::CameraDriver driver,
                                              const hal::CameraConfig& camera,
                                              const std::string& section, std::string* error);

// The IIO gyro of imu.source iio (not started). Null with *error when this build has no libiio.
std::unique_ptr<hal::Imu> make_live_imu(const config::Config& cfg, std::string* error);

}  // namespace agv::app

// Creates the configured live camera driver.
#pragma once

#include <memory>
#include <string>

#include "agv/hal/camera.hpp"
#include "config.hpp"

namespace agv::app {

// Null with *error when the driver is not available in this build (libcamera missing) or the
// camera configuration is invalid.
std::unique_ptr<hal::Camera> make_live_camera(const config::Config& cfg, std::string* error);

}  // namespace agv::app

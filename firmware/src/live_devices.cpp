#include "live_devices.hpp"

#include "agv/camera/common.hpp"
#include "agv/v4l2/v4l2_camera.hpp"
#ifdef AGV_HAVE_LIBCAMERA
#include "agv/libcamera/libcamera_camera.hpp"
#endif
#ifdef AGV_HAVE_IIO
#include "agv/iio/iio_imu.hpp"
#endif

namespace agv::app {

std::unique_ptr<hal::Camera> make_live_camera(config::CameraDriver driver,
                                              const hal::CameraConfig& camera,
                                              const std::string& section, std::string* error) {
  const std::string verr = camera::validate_config(camera);
  if (!verr.empty()) {
    *error = section + ": " + verr;
    return nullptr;
  }
  if (driver == config::CameraDriver::kV4l2) return std::make_unique<v4l2::V4l2Camera>(camera);
  if (driver == config::CameraDriver::kLibcamera) {
#ifdef AGV_HAVE_LIBCAMERA
    return std::make_unique<libcam::LibcameraCamera>(camera);
#else
    *error = section +
             ".driver: libcamera is not available in this build (replay-only build; use v4l2 or "
             "rebuild with libcamera-dev installed)";
    return nullptr;
#endif
  }
  *error = section + ".driver: '" + config::camera_driver_name(driver) +
           "' is not a live driver (use libcamera or v4l2)";
  return nullptr;
}

std::unique_ptr<hal::Camera> make_live_camera(const config::Config& cfg, std::string* error) {
  return make_live_camera(cfg.camera.driver, cfg.camera.camera, "camera", error);
}

std::unique_ptr<hal::Imu> make_live_imu(const config::Config& cfg, std::string* error) {
#ifdef AGV_HAVE_IIO
  (void)error;
  hal::ImuConfig ic;
  ic.device = cfg.imu.iio_device;
  ic.trigger = cfg.imu.iio_trigger;
  ic.rate_hz = cfg.imu.iio_rate_hz;
  return std::make_unique<iio::IioImu>(ic);
#else
  (void)cfg;
  *error =
      "imu.source: iio is not available in this build (rebuild with libiio-dev installed, "
      "tools/install-deps.sh)";
  return nullptr;
#endif
}

}  // namespace agv::app

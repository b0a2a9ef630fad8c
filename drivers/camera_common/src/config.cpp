#include <cmath>
#include <sstream>

#include "agv/camera/common.hpp"

namespace agv::camera {

std::string validate_config(const hal::CameraConfig& c) {
  std::ostringstream e;
  if (c.width_px < kMinSizePx || c.width_px > kMaxSizePx || c.height_px < kMinSizePx ||
      c.height_px > kMaxSizePx) {
    e << "camera size " << c.width_px << "x" << c.height_px << " outside [" << kMinSizePx << ", "
      << kMaxSizePx << "]";
  } else if (c.width_px % 2 != 0 || c.height_px % 2 != 0) {
    e << "camera size " << c.width_px << "x" << c.height_px
      << " must be even (YUV formats subsample by 2)";
  } else if (!std::isfinite(c.fps) || c.fps < kMinFps || c.fps > kMaxFps) {
    e << "camera fps " << c.fps << " outside [" << kMinFps << ", " << kMaxFps << "]";
  } else if (c.exposure_us < kMinExposureUs) {
    e << "camera exposure_us " << c.exposure_us << " must be >= " << kMinExposureUs;
  } else if (static_cast<double>(c.exposure_us) > 1e6 / c.fps) {
    e << "camera exposure_us " << c.exposure_us << " longer than one frame period at " << c.fps
      << " fps (" << 1e6 / c.fps << " us)";
  } else if (!std::isfinite(c.analogue_gain) || c.analogue_gain < 1.0 || c.analogue_gain > 64.0) {
    e << "camera analogue_gain " << c.analogue_gain << " outside [1, 64]";
  } else if (c.buffer_count < 2 || c.buffer_count > kMaxBuffers) {
    e << "camera buffer_count " << c.buffer_count << " outside [2, " << kMaxBuffers << "]";
  } else if (c.readout_us < 0 || static_cast<double>(c.readout_us) > 1e6 / c.fps) {
    e << "camera readout_us " << c.readout_us << " outside [0, frame period]";
  } else if (c.pixel_format != hal::PixelFormatPreference::kAuto &&
             c.pixel_format != hal::PixelFormatPreference::kGray &&
             c.pixel_format != hal::PixelFormatPreference::kYuv) {
    e << "camera pixel_format " << static_cast<int>(c.pixel_format) << " unknown";
  }
  return e.str();
}

}  // namespace agv::camera

// The drive wheels' track, one default for every user: the CAN wheel-speed decoding, the
// unequal-wheels correction, the fusion's slip lever arm and the vehicle calibration. The value
// itself is one key, can.odometry.track_width_mm (stored in
// fusion::EkfConfig::slip.wheel_track_mm).
#pragma once

namespace agv {

// A small AGV's track, mm.
inline constexpr double kDefaultTrackWidthMm = 500.0;

}  // namespace agv

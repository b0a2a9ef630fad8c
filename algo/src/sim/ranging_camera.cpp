#include "agv/sim/ranging_camera.hpp"

namespace agv::sim {

VehicleCameraMount render_mount(const ranging::RangingMount& mount) {
  VehicleCameraMount m;
  m.x_mm = mount.x_mm;
  m.y_mm = mount.y_mm;
  m.z_mm = mount.z_mm;
  m.yaw_rad = mount.yaw_rad;
  m.pitch_rad = mount.pitch_rad;
  m.roll_rad = mount.roll_rad;
  return m;
}

RenderCamera ranging_camera(const CameraIntrinsics& intrinsics, const Pose2& vehicle_site,
                            const ranging::RangingMount& mount) {
  return RenderCamera::on_vehicle(intrinsics, vehicle_site, render_mount(mount));
}

}  // namespace agv::sim

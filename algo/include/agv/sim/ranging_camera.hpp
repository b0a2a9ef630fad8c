// A forward or side camera on a vehicle, for the rack-landmark ranging (agv/ranging): its 6-DoF
// mount as the ranging code states it, turned into the site renderer's camera at a vehicle pose
// (from the fleet simulator, a drive, or a random placement).
#pragma once

#include "agv/ranging/range_models.hpp"
#include "agv/sim/site_render.hpp"

namespace agv::sim {

// The same mount in the renderer's terms (both: yaw about vehicle z, then pitch with positive
// down, then roll about the optical axis with positive turning the image's right side down).
VehicleCameraMount render_mount(const ranging::RangingMount& mount);

// The camera at vehicle pose vehicle_site (site frame).
RenderCamera ranging_camera(const CameraIntrinsics& intrinsics, const Pose2& vehicle_site,
                            const ranging::RangingMount& mount);

}  // namespace agv::sim

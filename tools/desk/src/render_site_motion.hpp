// agvloc-desk render-site: the parts between the command line and the renderer. The fleet's
// motion comes from the fleet simulator (routes from the planner, cell reservations); this file
// samples it at frame times and parses the vehicle camera's options.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/sim/fleet.hpp"
#include "agv/sim/site_render.hpp"
#include "agv/site/site.hpp"

namespace agv::desk {

// The fleet's run: every vehicle's truth (pose, v, omega) every fleet odometry period.
struct FleetMotion {
  std::vector<sim::FleetVehicleSpec> specs;
  sim::FleetResult result;
};

// Simulates the site's fleet (random pick-and-drop tasks, deterministic per seed) for
// duration_s. False with *error when the site's fleet cannot be placed or simulated.
bool simulate_site_fleet(const site::Site& site, double duration_s, double speed_mps,
                         std::uint64_t seed, FleetMotion* out, std::string* error);

// Every vehicle's state at t_ns (fleet time, from 0): the nearest truth sample advanced along its
// arc to t_ns, so frames between samples keep the true velocity.
std::vector<sim::AgvState> fleet_states_at(const FleetMotion& m, std::int64_t t_ns);

// People and pallets on free floor clear of every vehicle's path over the run (a person does not
// stand where a vehicle will drive through it), deterministic per seed.
void add_clutter_off_paths(sim::SiteScene* scene, const FleetMotion& m, int count,
                           std::uint64_t seed);

// "x_mm,y_mm,z_mm,yaw_deg,pitch_deg,roll_deg". False with *error when malformed.
bool parse_mount(const std::string& text, sim::VehicleCameraMount* out, std::string* error);
// "WxH,fx,fy,cx,cy" (no distortion). False with *error when malformed.
bool parse_intrinsics(const std::string& text, CameraIntrinsics* out, std::string* error);
// The same lens on a sensor scaled by s (pixel centres kept: c' = (c + 0.5) s - 0.5).
CameraIntrinsics scale_intrinsics(const CameraIntrinsics& k, double s);

}  // namespace agv::desk

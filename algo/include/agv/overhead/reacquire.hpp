// Re-acquisition of a vehicle whose track was lost while its tag was hidden (a parcel on it): the
// tag cannot restart the track, so the learned tray detector sweeps the camera's view where the
// lost vehicles can be (Yang et al. Algorithm 1, the area and whole-image levels), and a box
// becomes a vehicle's only when nothing else explains it: not a vehicle whose tag this frame read
// or whose track is valid, inside the disk the lost vehicle can have reached since its last fix
// (at the fleet's top speed), of its tray's size, and the only such box for the only such vehicle.
// A box is a rectangle: its heading is known up to a half turn. The last heading resolves it while
// the vehicle cannot have turned a quarter turn since (top turn rate); later, two sweeps that find
// the same vehicle's box moved along its long axis resolve it by the direction of travel, for
// vehicles that drive forward (forward_only). Otherwise the vehicle stays lost. Pure.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/overhead/tray_net.hpp"
#include "agv/site/site.hpp"

namespace agv::overhead {

struct ReacquireParams {
  bool enabled = true;
  // Bounds of the fleet's motion: the disk a lost vehicle may be in grows at max_speed_mps from
  // its last fix (plus 3 sigma of that fix), its heading by max_turn_rate_radps.
  double max_speed_mps = 2.0;
  double max_turn_rate_radps = 1.0;
  // A vehicle lost longer than this is not searched for (its disk would hold the whole site).
  double max_lost_s = 30.0;
  // The view is swept every this many frames of a camera while a lost vehicle's disk meets it.
  int sweep_every_frames = 5;
  // A box is a vehicle's tray only if its score is at least this, and its length and width are
  // within this fraction of the tray's.
  double min_score = 0.7;
  double max_size_error_rel = 0.15;
  // A box within this of a vehicle whose tag was read, or of a valid track's position, is that
  // vehicle's (and never a lost one's).
  double explained_mm = 300.0;
  // Heading from travel: the same vehicle's box moved at least this far between two sweeps, at
  // most max_travel_angle_rad off its long axis, and the vehicle drives forward.
  bool forward_only = true;
  double min_travel_mm = 150.0;
  double max_travel_angle_rad = 0.35;
  double max_pair_gap_s = 2.0;  // the two sweeps at most this far apart
};

// Empty string when the parameters are usable, otherwise what is wrong (names the field).
std::string validate(const ReacquireParams& p);

// What is known of a lost vehicle: its pose and sigmas at its last fix.
struct LostVehicle {
  std::size_t agv = 0;
  Pose2 last_pose;
  double last_sigma_xy_mm = 0.0;
  double last_sigma_theta_rad = 0.0;
  std::int64_t last_fix_t_ns = 0;
};

// Radius of the disk around last_pose where the vehicle can be at t_ns.
double reach_radius_mm(const LostVehicle& v, std::int64_t t_ns, const ReacquireParams& p);

// Centres of the rectified windows (side window_mm) that tile the part of the tray plane that
// camera `cam` sees, spaced so that any tray of length at most tray_length_mm lies wholly inside
// one of them.
std::vector<Vec2> sweep_tiles(const site::CeilingCamera& cam, double plane_mm, double window_mm,
                              double tray_length_mm);

// A box seen in a sweep, and the vehicle it was given to (or why none).
enum class ReacquireOutcome : std::uint8_t {
  kAssigned,        // unique box, unique vehicle
  kExplained,       // near a vehicle read or tracked
  kNoCandidate,     // in no lost vehicle's disk, or of no lost vehicle's tray size
  kAmbiguous,       // in the disks of two lost vehicles, or a vehicle with two boxes
  kHeadingUnknown,  // assigned, but neither the last heading nor travel resolves the half turn
};
const char* to_string(ReacquireOutcome o);

struct ReacquireBox {
  PlaneTray tray;
  ReacquireOutcome outcome = ReacquireOutcome::kNoCandidate;
  std::size_t agv = 0;  // with kAssigned or kHeadingUnknown
};

// Boxes from a sweep's windows (in the site frame), merged where two windows saw the same tray
// (centres closer than half the smallest tray width: the higher score is kept).
std::vector<PlaneTray> merge_sweep_boxes(const std::vector<PlaneTray>& boxes, double min_score,
                                         double merge_mm);

// Gives each box to a lost vehicle or says why not. `explained` holds the positions of the
// vehicles read this frame or tracked validly; fleet sizes the trays.
std::vector<ReacquireBox> assign_boxes(const std::vector<PlaneTray>& boxes,
                                       const std::vector<LostVehicle>& lost,
                                       const std::vector<Vec2>& explained,
                                       const std::vector<site::FleetAgv>& fleet, std::int64_t t_ns,
                                       const ReacquireParams& p);

// The heading of an assigned box: from the last heading while the vehicle cannot have turned a
// quarter turn, else from travel since `previous` (the same vehicle's box at previous_t_ns;
// have_previous false when there is none). False when neither resolves it.
bool resolve_heading(const PlaneTray& box, const LostVehicle& v, std::int64_t t_ns,
                     bool have_previous, const PlaneTray& previous, std::int64_t previous_t_ns,
                     const site::FleetAgv& agv, const ReacquireParams& p, double* theta_rad);

}  // namespace agv::overhead

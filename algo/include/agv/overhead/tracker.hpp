// One EKF per vehicle of the fleet (Yang et al. eq. 14-19: x, y, theta, v, omega; constant speed
// and turn rate), fed with tag fixes from every ceiling camera, each stamped with its exposure
// time and arriving after its latency: a fix older than the filter's newest is applied where it
// belongs (the filter rewinds to a stored state and replays the newer fixes). Every fix is gated
// by the track's covariance (chi-square, 3 dof), so a wrong id cannot move another vehicle's
// track. Track states: tentative (first fixes), confirmed, coasting (no fix for a while: sigma
// grows), lost (sigma beyond a limit or too long unseen: never reported confident). Identity is
// the fleet index: a vehicle has one track, so a hand-over between cameras cannot duplicate it.
// The first fix of a new or lost track has nothing to be gated by: the caller gives such fixes
// only from a strict global decode (never from a decode restricted to an area's ids).
// Optionally each vehicle's route (set_route; route_prior.hpp) is the motion prior of its
// coasting track: extrapolated along the route, round its corners, instead of straight on.
// Pure: time is an argument; no allocation per fix (every buffer is sized by the constructor);
// docs/design/overhead.md.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/overhead/route_prior.hpp"
#include "agv/overhead/tag_fix.hpp"

namespace agv::overhead {

enum class TrackState : std::uint8_t { kNone, kTentative, kConfirmed, kCoasting, kLost };
const char* to_string(TrackState s);

struct TrackerParams {
  // Process noise: square roots of the spectral densities of the white linear and angular
  // accelerations (over one second the speed random-walks by accel_noise_mps2, the turn rate by
  // alpha_noise_radps2), integrated over each prediction step through the motion model.
  double accel_noise_mps2 = 1.0;
  double alpha_noise_radps2 = 0.3;
  // A vehicle that starts or stops turning changes its turn rate in a step that a density small
  // enough to keep the turn rate still between turns does not follow (it would gate the fix): a
  // fix whose heading innovation under the steady prediction exceeds maneuver_chi2 (chi2, 1 dof)
  // is predicted with maneuver_alpha_noise_radps2 instead, and gated by that prediction, so the
  // new turn rate is taken from the fixes at once. A prediction over more than coast_after_ms
  // from the track's fix (a coasting track's output and search window, a covered tag's next tray
  // box) takes this density over the whole gap: the missed fixes could have shown a turn start.
  // 0: off.
  double maneuver_alpha_noise_radps2 = 2.0;
  double maneuver_chi2 = 9.0;
  // A fix whose squared Mahalanobis distance exceeds this (chi2, 3 dof, 0.999) is refused.
  double gate_chi2 = 16.27;
  int confirm_fixes = 3;  // fixes within confirm_window_ms to confirm a track
  double confirm_window_ms = 1000.0;
  double coast_after_ms = 300.0;  // no fix for this long: coasting
  double lost_after_ms = 3000.0;  // no fix for this long, or:
  double lost_sigma_mm = 500.0;   // position sigma beyond this: lost
  // A fix older than the track's newest by more than this, or older than the oldest state kept,
  // is refused (kTooOld, counted), not replayed.
  double max_fix_age_ms = 500.0;
  // States kept for delayed fixes; also bounds the fixes replayed (>= confirm_fixes).
  int history = 64;
  // A track starts from a fix with this velocity sigma (at rest unknown).
  double initial_speed_sigma_mps = 1.0;
  double initial_turn_sigma_radps = 1.0;
  // The vehicles' routes as the motion prior of coasting tracks (route_prior.hpp; off: set_route
  // is refused). A track without a fix for coast_after_ms whose newest fix (taken at or after its
  // route was set) lies on the route within route's limits is extrapolated along the route, and
  // the next fix is gated against that extrapolation; otherwise the constant turn-rate model.
  bool route_prior = false;
  RoutePriorParams route;
};

// Empty string when the parameters are usable, otherwise what is wrong (names the field).
std::string validate(const TrackerParams& params);

enum class FixResult : std::uint8_t { kApplied, kStarted, kGated, kTooOld, kInvalid };
const char* to_string(FixResult r);

struct TrackOutput {
  std::size_t agv = 0;
  TrackState state = TrackState::kNone;
  std::int64_t t_ns = 0;  // the time the state was extrapolated to
  Pose2 pose;
  double v_mps = 0.0, omega_radps = 0.0;
  std::array<double, 9> cov{};  // (x_mm, y_mm, theta_rad)
  double sigma_xy_mm = 0.0;     // sqrt of the larger eigenvalue of the position covariance
  double sigma_theta_rad = 0.0;
  std::int64_t last_fix_t_ns = 0;
  bool valid() const { return state == TrackState::kConfirmed || state == TrackState::kCoasting; }
};

// Fixes by result; replays: fixes applied before newer ones (which were replayed after them);
// lost: transitions of a reported track (confirmed or coasting) to lost.
struct TrackerCounters {
  std::uint64_t applied = 0, started = 0, gated = 0, too_old = 0, invalid = 0, replays = 0;
  std::uint64_t lost = 0;
};

class FleetTracker {
 public:
  // Throws std::invalid_argument when validate(params) is not empty.
  FleetTracker(std::size_t fleet_size, const TrackerParams& params = {});
  ~FleetTracker();
  FleetTracker(const FleetTracker&);
  FleetTracker& operator=(const FleetTracker&);
  FleetTracker(FleetTracker&&) noexcept;
  FleetTracker& operator=(FleetTracker&&) noexcept;

  // A fix of vehicle `agv` exposed at t_ns. A vehicle without a track (none, lost, or a
  // tentative track that missed) starts one from it (kStarted, not gated). Fixes may come out of
  // time order: one older than the newest is gated against the state at its time, inserted, and
  // the newer fixes are replayed after it (without a new gate: each passed one on arrival).
  // kInvalid for an index outside the fleet, a non-finite pose, or a covariance that is not
  // finite, symmetric and positive definite.
  FixResult add_fix(std::size_t agv, std::int64_t t_ns, const TagFix& fix);
  // Track states at now_ns (coasting, lost; a tentative track without a fix for coast_after_ms
  // is dropped); call before outputs at every publish tick. output() applies the same rules to
  // its own time, so it never reports a track valid that update_states would have lost.
  void update_states(std::int64_t now_ns);
  // Vehicle `agv` extrapolated to t_ns (the filter is not changed); state kNone for an index
  // outside the fleet.
  TrackOutput output(std::size_t agv, std::int64_t t_ns) const;
  std::vector<TrackOutput> outputs(std::int64_t t_ns) const;
  // Forget a track (operator command; a vehicle taken off the floor). Its route stays.
  void reset(std::size_t agv);
  // Vehicle `agv`'s route (mm), in force from t_ns (the time its order was received): fixes
  // older than that are not extrapolated along it. Replaces the previous route. False with
  // *error (the previous route kept) when the route prior is off, the index is outside the fleet
  // or the waypoints are refused (RoutePath::assign). Allocates: call when an order arrives, not
  // per fix.
  bool set_route(std::size_t agv, const std::vector<Vec2>& waypoints_mm, std::int64_t t_ns,
                 std::string* error = nullptr);
  // No route for vehicle `agv` (its order finished or cancelled); nothing for an index outside.
  void clear_route(std::size_t agv);

  std::size_t size() const;
  const TrackerCounters& counters() const { return counters_; }
  const TrackerParams& params() const { return p_; }

 private:
  struct Track;
  TrackerParams p_;
  std::vector<Track> tracks_;
  TrackerCounters counters_;
};

}  // namespace agv::overhead

// A vehicle's route (the path its fleet manager sent it, e.g. the nodes of a VDA 5050 order
// through vda5050::order_waypoints_mm) as a motion prior for a track that has lost sight of it:
// the vehicle is taken to keep its speed along the route, round its corners, and stop at its end,
// where the constant turn-rate model would carry it straight on past a corner. Only a track whose
// last fix lies on the route (cross-track distance and heading within limits) gets the prior; a
// vehicle off its route or on a stale order gets none. Pure; docs/design/overhead.md.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"

namespace agv::overhead {

struct RoutePriorParams {
  // The last fix must lie within this distance of the route (mm) and its heading within this
  // angle of the direction of the route there (rad), or the route is not used.
  double max_cross_track_mm = 300.0;
  double max_heading_error_rad = 0.5;
  // How closely a vehicle keeps to its route (mm, rad, one sigma): the fleet simulator's
  // vehicles cut the corners on blended arcs, a real one by its controller's tolerance. The
  // prediction's cross-track and heading sigmas are never below these.
  double cross_track_sigma_mm = 150.0;
  double heading_sigma_rad = 0.15;
};

// Empty string when usable, otherwise what is wrong (names the field).
std::string validate(const RoutePriorParams& params);

inline constexpr std::size_t kRouteMaxPoints = 1000;

// A polyline in site mm with the along-route distance of each point.
class RoutePath {
 public:
  // False with *error (the path is then empty) for fewer than two distinct points, a
  // non-finite coordinate or more than kRouteMaxPoints points. Repeated points are dropped.
  bool assign(const std::vector<Vec2>& waypoints_mm, std::string* error);
  void clear();
  bool empty() const { return pts_.empty(); }
  double length_mm() const { return s_.empty() ? 0.0 : s_.back(); }
  const std::vector<Vec2>& points() const { return pts_; }
  // Point at along-route distance s_mm (clamped to the path) and the index of its segment.
  Vec2 point_at(double s_mm, std::size_t* segment) const;
  // Unit direction of segment i.
  Vec2 direction(std::size_t segment) const;
  std::size_t segments() const { return pts_.size() < 2 ? 0 : pts_.size() - 1; }
  double start_of(std::size_t segment) const { return s_[segment]; }

 private:
  std::vector<Vec2> pts_;
  std::vector<double> s_;
};

// A track at its last fix: the pose and speed, the covariance of (x_mm, y_mm, v_mmps) row-major.
struct RouteFixState {
  Pose2 pose;
  double v_mmps = 0.0;
  std::array<double, 9> cov_xyv{};
  double var_theta_rad2 = 0.0;
};

enum class RouteFit : std::uint8_t { kOnRoute, kOffRoute, kInvalid };

struct RoutePrediction {
  Pose2 pose;
  std::array<double, 9> cov{};  // (x_mm, y_mm, theta_rad), row-major
  double s_mm = 0.0;            // along the route, after the advance
  double cross_track_mm = 0.0;  // of the last fix (signed: left of the route positive)
  double heading_error_rad = 0.0;
  bool at_end = false;
};

// The vehicle dt_s after its fix: projected on the route (the nearest segment whose direction
// agrees with its heading), advanced by max(v, 0) dt along it, stopped at its end; heading: the
// direction of the segment it is then on. Covariance: along the route, the fix's along-route
// position and speed covariance carried over dt with the filter's white acceleration
// (accel_density: (mm/s^2)^2 s); across it and in heading, the fix's own or the parameters' sigma,
// whichever is larger. kOffRoute when no segment is within the limits; kInvalid for an empty
// path, non-finite input or dt_s < 0.
RouteFit predict_on_route(const RoutePath& route, const RouteFixState& fix, double dt_s,
                          double accel_density, const RoutePriorParams& params,
                          RoutePrediction* out);

}  // namespace agv::overhead

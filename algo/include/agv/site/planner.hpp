// Routes through a site: obstacles inflated by the vehicle's radius plus a clearance, the
// visibility graph over the inflated polygons, Dijkstra's algorithm with the start and goal
// inserted per query; then a drivable trajectory (corners rounded by clothoid-arc-clothoid
// blends, speed limited by lateral and longitudinal acceleration, time-parametrised).
// Method and what differs from the paper: docs/design/site_planner.md.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/site/site.hpp"

namespace agv::vda5050 {
struct Order;
}

namespace agv::site {

struct PlannerParams {
  double vehicle_radius_mm = 400.0;
  double clearance_mm = 100.0;
  // Inflated corners are approximated by polygon arcs of at most this angle per edge; the
  // approximation lies outside the exact offset curve, never inside it.
  double arc_step_rad = 0.3927;  // 22.5 deg
};

enum class PlanStatus : std::uint8_t {
  kOk,
  kStartBlocked,  // the start lies inside an inflated obstacle or outside the outline
  kGoalBlocked,
  kNoRoute,       // both free but in different components
  kInvalidInput,  // non-finite coordinates
};
const char* to_string(PlanStatus s);

struct Route {
  PlanStatus status = PlanStatus::kNoRoute;
  std::vector<Vec2> waypoints_mm;  // start, corners of inflated obstacles, goal
  double length_mm = 0.0;
  std::string error;  // for a status other than kOk: what and where, for a person
};

// The visibility graph of one site for one vehicle size, built once and queried many times.
// Queries are const and may run concurrently.
class RoutePlanner {
 public:
  // False with *error when the site's geometry cannot be inflated (degenerate polygons).
  static bool build(const Site& site, const PlannerParams& params, RoutePlanner* out,
                    std::string* error);
  RoutePlanner();
  ~RoutePlanner();
  RoutePlanner(RoutePlanner&&) noexcept;
  RoutePlanner& operator=(RoutePlanner&&) noexcept;

  Route plan(Vec2 start_mm, Vec2 goal_mm) const;
  // Whether a point is free (outside every inflated obstacle, inside the shrunk outline), and
  // whether a straight segment between two free points stays free.
  bool point_free(Vec2 p_mm) const;
  bool segment_free(Vec2 a_mm, Vec2 b_mm) const;
  // The inflated obstacles, counter-clockwise (drawing, tests).
  const std::vector<Polygon>& inflated() const;
  // The free space's boundary: closed rings with the free side on the left of every edge
  // (outer boundaries counter-clockwise, enclosed obstacles clockwise). Independent checks.
  std::vector<std::vector<Vec2>> free_boundary() const;
  std::size_t vertex_count() const;
  std::size_t edge_count() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The route through a decoded VDA 5050 order's nodes: planned leg by leg between consecutive
// nodes (positions in metres). On failure the status of the failing leg and an error naming
// the node (id and index) that is blocked or cannot be reached.
Route route_from_order(const RoutePlanner& planner, const vda5050::Order& order);

// A drivable, time-parametrised trajectory along a route.
struct DriveLimits {
  double speed_mps = 1.0;
  double accel_mps2 = 0.5;                    // longitudinal, also braking
  double lateral_accel_mps2 = 0.5;            // limits the speed in blends
  double max_curvature_per_mm = 1.0 / 300.0;  // tightest blend radius the vehicle drives
  double clothoid_length_mm = 200.0;          // each transition of a clothoid-arc-clothoid blend
};

struct TrajectorySample {
  double t_s = 0.0;
  double s_mm = 0.0;
  Pose2 pose;  // site <- vehicle
  double v_mps = 0.0;
  double omega_radps = 0.0;
  double curvature_per_mm = 0.0;
};

class RouteTrajectory {
 public:
  // False with *error when a corner cannot be blended within its neighbouring segments at the
  // limits given (then a tighter max_curvature or shorter clothoids are needed).
  static bool make(const Route& route, const DriveLimits& limits, RouteTrajectory* out,
                   std::string* error);
  // As make, then the path checked every check_step_mm against `collision`, a planner built for
  // the vehicle radius with no clearance: the blends cut inside the polyline's corners, into the
  // clearance margin but never past it. A blend that leaves the collision-free space is redone
  // as a plain arc at max curvature (the smallest cut); if that also leaves it, false, *error.
  static bool make_checked(const Route& route, const DriveLimits& limits,
                           const RoutePlanner& collision, RouteTrajectory* out, std::string* error,
                           double check_step_mm = 20.0);
  double duration_s() const { return duration_s_; }
  // The largest distance from a corner of the route to its blend (how far a blend cuts in).
  double max_corner_deviation_mm() const { return max_deviation_mm_; }
  double length_mm() const { return length_mm_; }
  // State at t_s (clamped to [0, duration]): at rest at the ends.
  TrajectorySample at(double t_s) const;
  // The path as points every step_mm (drawing, collision checks).
  std::vector<Vec2> polyline(double step_mm) const;

  // Implementation data (public for the implementation files; not an API).
  struct Piece {
    double s0_mm = 0.0, length_mm = 0.0;
    double k0_per_mm = 0.0, k1_per_mm = 0.0;  // curvature linear in s over the piece
    Pose2 start;
  };
  std::vector<Piece> pieces;
  std::vector<double> profile_s_mm, profile_v_mps, profile_t_s;  // speed profile knots

 private:
  double duration_s_ = 0.0;
  double length_mm_ = 0.0;
  double max_deviation_mm_ = 0.0;
  friend struct RouteTrajectoryBuilder;
};

}  // namespace agv::site

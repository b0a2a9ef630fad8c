// Internals of the route planner shared by planner_*.cpp: the free space's boundary, the edge
// grid behind the segment test, and the visibility graph. Not an API.
#pragma once

#include <boost/graph/compressed_sparse_row_graph.hpp>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "agv/site/planner.hpp"

namespace agv::site::plan_detail {

inline double pd_cross(Vec2 a, Vec2 b) { return a.x * b.y - a.y * b.x; }
inline Vec2 pd_sub(Vec2 a, Vec2 b) { return {a.x - b.x, a.y - b.y}; }
inline double pd_dot(Vec2 a, Vec2 b) { return a.x * b.x + a.y * b.y; }
inline double pd_norm(Vec2 a) { return std::sqrt(a.x * a.x + a.y * a.y); }

// Points closer than this to a line count as on it (mm): far above the rounding of coordinates
// of a 100 m site, far below anything a vehicle could notice.
inline constexpr double kOnLineMm = 1e-5;

// The free space F (shrunk outline minus the inflated obstacles) as closed rings with F on the
// left of each edge: outer boundaries counter-clockwise, holes clockwise.
struct FreeSpace {
  std::vector<std::vector<Vec2>> rings;
  std::vector<Polygon> inflated;  // merged inflated obstacles, outer rings, counter-clockwise
};

// Inflates and merges the obstacles, shrinks the outline, subtracts. False with *error on
// degenerate input.
bool make_free_space(const Site& site, const PlannerParams& params, FreeSpace* out,
                     std::string* error);

struct EdgeWeight {
  double w = 0.0;
};
using Graph = boost::compressed_sparse_row_graph<boost::directedS, boost::no_property, EdgeWeight,
                                                 boost::no_property, std::uint32_t, std::uint32_t>;

}  // namespace agv::site::plan_detail

namespace agv::site {

// The planner's files use the helpers unqualified; they are internal to this folder.
using plan_detail::kOnLineMm;
using plan_detail::pd_cross;
using plan_detail::pd_dot;
using plan_detail::pd_norm;
using plan_detail::pd_sub;

struct RoutePlanner::Impl {
  PlannerParams params;
  plan_detail::FreeSpace free;
  // Raw obstacles, to name the one that blocks a start or goal.
  std::vector<Obstacle> obstacles;
  Polygon outline;
  // Every boundary vertex, flattened: its ring neighbours (F on the left of prev->v->next).
  std::vector<Vec2> pts;
  std::vector<std::uint32_t> prev, next;
  std::vector<Vec2> pts_next;  // pts[next[i]], side by side for the segment test's first filter
  // Graph nodes: the boundary vertices where F's interior angle exceeds 180 degrees.
  std::vector<std::uint32_t> node_vertex;
  plan_detail::Graph graph;
  std::size_t edge_count = 0;
  // Uniform grid over the edges (edge i runs pts[i] -> pts[next[i]]), CSR layout.
  double grid_x0 = 0.0, grid_y0 = 0.0, cell_mm = 1.0;
  int grid_nx = 1, grid_ny = 1;
  std::vector<std::uint32_t> cell_start, cell_edges;

  void build_grid();
  bool point_free(Vec2 p) const;
  bool segment_free(Vec2 a, Vec2 b) const;
  // segment_free without the endpoint checks (the endpoints are known to be free).
  // With blocker, the edge that blocked a refused segment.
  bool segment_clear(Vec2 a, Vec2 b, std::uint32_t* blocker = nullptr) const;
  // Whether edge e alone makes a->b (of length lab > kOnLineMm) not free.
  bool edge_blocks(Vec2 a, Vec2 b, double lab, std::uint32_t e) const;
  // edge_blocks' first test, inline: false when edge e lies wholly on one side of the line
  // a + s ab beyond tol_ab (then it cannot block).
  bool may_block(Vec2 a, Vec2 ab, double tol_ab, std::uint32_t e) const {
    const double s1 = pd_cross(ab, pd_sub(pts[e], a));
    const double s2 = pd_cross(ab, pd_sub(pts_next[e], a));
    return !((s1 > tol_ab && s2 > tol_ab) || (s1 < -tol_ab && s2 < -tol_ab));
  }
  void build_graph();
  // Whether the direction v leaving boundary vertex i enters the obstacle side at once.
  bool enters_obstacle(std::uint32_t i, Vec2 v) const;
  // Whether the line through boundary vertex i along v keeps both its ring neighbours on one
  // side: only such lines can carry a shortest path bending at the vertex.
  bool tangent_at(std::uint32_t i, Vec2 v) const;
  std::string blocked_reason(Vec2 p) const;
};

}  // namespace agv::site

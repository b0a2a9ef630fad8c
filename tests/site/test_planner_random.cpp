// The route planner on random sites against independent checks: every route keeps the vehicle
// radius plus clearance from every rack and wall (dense sampling, distances computed here), and
// its length equals the shortest path that Floyd-Warshall finds over all free-space vertices
// with this file's own visibility test. AGV_PLANNER_RANDOM_SITES sets the number of sites
// (default 100; the evaluation in docs/design/site_planner.md ran 1000).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "agv/site/planner.hpp"
#include "test_planner_util.hpp"

namespace agv::site {
namespace {

constexpr double kR = 500.0;

double cross(Vec2 o, Vec2 a, Vec2 b) {
  return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
}

struct FreeRings {
  std::vector<std::vector<Vec2>> rings;

  bool point_free(Vec2 p) const {
    bool in = false;
    for (const auto& r : rings) {
      if (test::boundary_dist(r, p) < 1e-6) return true;
      if (test::inside_ring(r, p)) in = !in;
    }
    return in;
  }

  // Free when no ring edge crosses a->b properly and every piece between the vertices that lie
  // on a->b has a free midpoint.
  bool visible(Vec2 a, Vec2 b) const {
    const double l = std::hypot(b.x - a.x, b.y - a.y);
    if (l < 1e-9) return true;
    std::vector<double> ts{0.0, 1.0};
    for (const auto& r : rings) {
      for (std::size_t i = 0; i < r.size(); ++i) {
        const Vec2 c = r[i], d = r[(i + 1) % r.size()];
        const double lcd = std::hypot(d.x - c.x, d.y - c.y);
        const double o1 = cross(a, b, c) / l, o2 = cross(a, b, d) / l;
        const double o3 = cross(c, d, a) / lcd, o4 = cross(c, d, b) / lcd;
        const double e = 1e-6;
        if (((o1 > e && o2 < -e) || (o1 < -e && o2 > e)) &&
            ((o3 > e && o4 < -e) || (o3 < -e && o4 > e))) {
          return false;
        }
        if (std::abs(o1) <= e) {
          const double t = ((c.x - a.x) * (b.x - a.x) + (c.y - a.y) * (b.y - a.y)) / (l * l);
          if (t > 0.0 && t < 1.0) ts.push_back(t);
        }
      }
    }
    std::sort(ts.begin(), ts.end());
    for (std::size_t k = 0; k + 1 < ts.size(); ++k) {
      if (ts[k + 1] - ts[k] < 1e-9) continue;
      const double t = 0.5 * (ts[k] + ts[k + 1]);
      if (!point_free({a.x + t * (b.x - a.x), a.y + t * (b.y - a.y)})) return false;
    }
    return true;
  }
};

// Shortest path length from start to goal through any ring vertices (infinite: none).
double floyd_warshall(const FreeRings& f, Vec2 start, Vec2 goal) {
  std::vector<Vec2> v{start, goal};
  for (const auto& r : f.rings) v.insert(v.end(), r.begin(), r.end());
  const std::size_t n = v.size();
  std::vector<double> d(n * n, std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < n; ++i) {
    d[i * n + i] = 0.0;
    for (std::size_t j = i + 1; j < n; ++j) {
      if (f.visible(v[i], v[j]))
        d[i * n + j] = d[j * n + i] = std::hypot(v[j].x - v[i].x, v[j].y - v[i].y);
    }
  }
  for (std::size_t k = 0; k < n; ++k) {
    for (std::size_t i = 0; i < n; ++i) {
      const double dik = d[i * n + k];
      if (!std::isfinite(dik)) continue;
      for (std::size_t j = 0; j < n; ++j) d[i * n + j] = std::min(d[i * n + j], dik + d[k * n + j]);
    }
  }
  return d[1];
}

Obstacle random_obstacle(std::mt19937& rng, int k) {
  std::uniform_real_distribution<double> ux(1000, 19000), uy(1000, 11000), us(400, 3500),
      ua(0, 3.14159);
  const Vec2 c{ux(rng), uy(rng)};
  const double w = us(rng), h = us(rng) * 0.5;
  const double a = (rng() % 3 == 0) ? 0.0 : ua(rng);
  std::vector<Vec2> local{{-w, -h}, {w, -h}, {w, h}, {-w, h}};
  if (rng() % 5 == 0) local = {{-w, -h}, {w, -h}, {w, 0}, {0, 0}, {0, h}, {-w, h}};  // an L
  Obstacle o;
  o.id = "o" + std::to_string(k);
  for (const Vec2& p : local) {
    o.outline.vertices_mm.push_back(
        {c.x + std::cos(a) * p.x - std::sin(a) * p.y, c.y + std::sin(a) * p.x + std::cos(a) * p.y});
  }
  return o;
}

TEST(PlannerRandom, RoutesAreClearAndShortest) {
  const char* env = std::getenv("AGV_PLANNER_RANDOM_SITES");
  const int sites = env ? std::atoi(env) : 100;
  std::mt19937 rng(20240611);
  int routes = 0, no_route = 0, blocked = 0;
  for (int k = 0; k < sites; ++k) {
    Site s;
    s.outline = test::rect(0, 0, 20000, 12000);
    const int n = 3 + static_cast<int>(rng() % 5);
    for (int i = 0; i < n; ++i) s.obstacles.push_back(random_obstacle(rng, i));
    RoutePlanner p;
    std::string error;
    ASSERT_TRUE(RoutePlanner::build(s, {}, &p, &error)) << error;
    const FreeRings f{p.free_boundary()};
    std::uniform_real_distribution<double> ux(0, 20000), uy(0, 12000);
    for (int q = 0; q < 2; ++q) {
      const Vec2 a{ux(rng), uy(rng)}, b{ux(rng), uy(rng)};
      const Route r = p.plan(a, b);
      SCOPED_TRACE("site " + std::to_string(k) + " query " + std::to_string(q));
      if (r.status == PlanStatus::kStartBlocked || r.status == PlanStatus::kGoalBlocked) {
        const Vec2 bad = r.status == PlanStatus::kStartBlocked ? a : b;
        EXPECT_FALSE(f.point_free(bad));
        EXPECT_LT(test::clearance_mm(s, bad),
                  kR / std::cos(0.5 * PlannerParams{}.arc_step_rad) + 1e-6);
        ++blocked;
        continue;
      }
      ASSERT_TRUE(f.point_free(a) && f.point_free(b));
      EXPECT_GE(test::clearance_mm(s, a), kR - 1e-6);
      const double expected = floyd_warshall(f, a, b);
      if (r.status == PlanStatus::kNoRoute) {
        EXPECT_FALSE(std::isfinite(expected));
        ++no_route;
        continue;
      }
      ASSERT_EQ(r.status, PlanStatus::kOk) << r.error;
      ++routes;
      EXPECT_NEAR(r.length_mm, expected, 1e-6 * expected);
      EXPECT_NEAR(test::polyline_length(r.waypoints_mm), r.length_mm, 1e-6 * (1 + r.length_mm));
      EXPECT_GE(test::min_clearance_mm(s, r.waypoints_mm, 10.0), kR - 1e-6);
      for (std::size_t i = 0; i + 1 < r.waypoints_mm.size(); ++i) {
        EXPECT_TRUE(f.visible(r.waypoints_mm[i], r.waypoints_mm[i + 1]));
      }
    }
  }
  EXPECT_GT(routes, sites / 2);
  std::printf("%d sites: %d routes, %d no route, %d blocked ends\n", sites, routes, no_route,
              blocked);
}

// The graph's edges against brute force over every pair of reflex free-space vertices (tangent
// at both ends by this file's own test, then visible): on a grid of racks most pairs are hidden
// behind other racks, so skipping hidden partners wholesale must not lose a single edge.
TEST(PlannerRandom, RackGridEdgesMatchBruteForce) {
  Site s;
  s.outline = test::rect(0, 0, 30000, 16000);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> jitter(-100, 100);
  for (int c = 0; c < 6; ++c) {
    for (int r = 0; r < 5; ++r) {
      const double x0 = 1500 + c * 4800 + jitter(rng), y0 = 1200 + r * 2900 + jitter(rng);
      s.obstacles.push_back(test::rack("r" + std::to_string(c) + "_" + std::to_string(r), x0, y0,
                                       x0 + 3600, y0 + 1000));
    }
  }
  RoutePlanner p;
  std::string error;
  ASSERT_TRUE(RoutePlanner::build(s, {}, &p, &error)) << error;
  const FreeRings f{p.free_boundary()};
  struct Node {
    Vec2 at, prev, next;
  };
  std::vector<Node> nodes;
  for (const auto& ring : f.rings) {
    for (std::size_t i = 0; i < ring.size(); ++i) {
      const Vec2 a = ring[(i + ring.size() - 1) % ring.size()], b = ring[i],
                 c = ring[(i + 1) % ring.size()];
      if (cross(a, b, c) < 0.0) nodes.push_back({b, a, c});  // turns right: F is reflex there
    }
  }
  // Both ring neighbours of n on one side of the line n -> m (or on it, within 1e-6 mm).
  const auto tangent = [](const Node& n, Vec2 m) {
    const double l = std::hypot(m.x - n.at.x, m.y - n.at.y);
    const double sp = cross(n.at, m, n.prev) / l, sn = cross(n.at, m, n.next) / l;
    return !((sp > 1e-6 && sn < -1e-6) || (sp < -1e-6 && sn > 1e-6));
  };
  std::size_t edges = 0;
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    for (std::size_t j = i + 1; j < nodes.size(); ++j) {
      const Vec2 a = nodes[i].at, b = nodes[j].at;
      edges += tangent(nodes[i], b) && tangent(nodes[j], a) && f.visible(a, b);
    }
  }
  EXPECT_EQ(p.vertex_count(), nodes.size());
  EXPECT_EQ(p.edge_count(), edges);
  EXPECT_GT(edges, nodes.size());  // more than the racks' own outlines
}

}  // namespace
}  // namespace agv::site

// The warehouse of the fleet benchmark and of its regression test: 40 m x 25 m, four rack rows
// of 24 m x 1.2 m with 3.5 m aisles, cross aisles at both ends, two pillars.
#pragma once

#include <string>

#include "agv/site/site.hpp"

namespace agv::fleet_bench {

inline agv::site::Polygon box(double x0, double y0, double x1, double y1) {
  return {{{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}}};
}

inline agv::site::Site warehouse() {
  agv::site::Site s;
  s.name = "bench warehouse";
  s.outline = box(0, 0, 40000, 25000);
  s.clearance_mm = 100.0;
  for (int row = 0; row < 4; ++row) {
    agv::site::Obstacle o;
    o.id = "rack-" + std::to_string(row);
    const double y = 4000.0 + row * 4700.0;
    o.outline = box(8000, y, 32000, y + 1200);
    s.obstacles.push_back(o);
  }
  for (int i = 0; i < 2; ++i) {
    agv::site::Obstacle o;
    o.id = "pillar-" + std::to_string(i);
    o.kind = agv::site::ObstacleKind::kPillar;
    o.outline = box(3500, 8000 + i * 8000.0, 4000, 8500 + i * 8000.0);
    s.obstacles.push_back(o);
  }
  return s;
}

}  // namespace agv::fleet_bench

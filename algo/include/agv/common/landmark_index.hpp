// Spatial index over a landmark map's positions (docs/design/large_maps.md): a uniform grid of
// square cells hashed by cell coordinates, so the within-radius and nearest queries of every frame
// visit the landmarks near the query point only, whatever the size of the map. Pure; built once
// from a map that must not change while the index lives (the localizer's contract for its map).
#pragma once

#include <cstddef>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/common/landmark.hpp"

namespace agv {

class LandmarkIndex {
 public:
  // cell_mm: the grid's cell side. About the landmark spacing keeps a query's cell visits and its
  // candidates per cell both small (1 m: a site's grid; a denser map costs a few more per cell).
  explicit LandmarkIndex(const LandmarkMap& map, double cell_mm = 1000.0);

  // The entries whose centre lies within radius_mm of centre_mm (world), in ascending id order
  // (the map's own order, so callers that keep the first of equal scores decide as a scan of the
  // whole map would). A radius that would cover more cells than the map has landmarks scans the
  // whole map instead (same answer, bounded cost).
  void within(Vec2 centre_mm, double radius_mm, std::vector<const LandmarkMapEntry*>* out) const;

  // The k entries nearest centre_mm (fewer when the map has fewer), nearest first, ties by id.
  void nearest(Vec2 centre_mm, size_t k, std::vector<const LandmarkMapEntry*>* out) const;

  size_t size() const { return points_.size(); }
  // Landmarks whose distance the last query computed: a test's proof that a query visited the
  // neighbourhood, not the map (not thread-safe; the localizer queries from one thread).
  size_t last_visited() const { return last_visited_; }

 private:
  struct Point {
    double x_mm = 0.0, y_mm = 0.0;
    const LandmarkMapEntry* entry = nullptr;
  };
  std::int64_t cell_of(double v_mm) const;
  static std::uint64_t key(std::int64_t cx, std::int64_t cy);
  // Appends the points of cell (cx, cy) within radius of c; returns how many it looked at.
  void scan_cell(std::int64_t cx, std::int64_t cy, Vec2 c, double r2,
                 std::vector<const LandmarkMapEntry*>* out) const;

  double cell_mm_;
  // Points sorted by cell; cells_ maps a cell key to its [begin, end) range in points_.
  std::vector<Point> points_;
  std::unordered_map<std::uint64_t, std::pair<std::uint32_t, std::uint32_t>> cells_;
  std::int64_t min_cx_ = 0, max_cx_ = -1, min_cy_ = 0, max_cy_ = -1;
  mutable size_t last_visited_ = 0;
};

}  // namespace agv

// Uniform-grid spatial index over landmark positions (landmark_index.hpp).
#include "agv/common/landmark_index.hpp"

#include <algorithm>
#include <cmath>

namespace agv {

namespace {

bool by_id(const LandmarkMapEntry* a, const LandmarkMapEntry* b) { return a->id < b->id; }

}  // namespace

LandmarkIndex::LandmarkIndex(const LandmarkMap& map, double cell_mm)
    : cell_mm_(cell_mm > 0.0 && std::isfinite(cell_mm) ? cell_mm : 1000.0) {
  points_.reserve(map.entries.size());
  for (const auto& [id, e] : map.entries) points_.push_back({e.pose.x_mm, e.pose.y_mm, &e});
  std::vector<std::pair<std::uint64_t, std::uint32_t>> keyed;
  keyed.reserve(points_.size());
  for (std::uint32_t i = 0; i < points_.size(); ++i) {
    const std::int64_t cx = cell_of(points_[i].x_mm), cy = cell_of(points_[i].y_mm);
    if (i == 0) {
      min_cx_ = max_cx_ = cx;
      min_cy_ = max_cy_ = cy;
    }
    min_cx_ = std::min(min_cx_, cx);
    max_cx_ = std::max(max_cx_, cx);
    min_cy_ = std::min(min_cy_, cy);
    max_cy_ = std::max(max_cy_, cy);
    keyed.emplace_back(key(cx, cy), i);
  }
  // Sorted by cell (stable: ascending id within a cell), each cell one contiguous range.
  std::stable_sort(keyed.begin(), keyed.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<Point> sorted;
  sorted.reserve(points_.size());
  cells_.reserve(points_.size());
  for (const auto& [k, i] : keyed) {
    auto [it, added] = cells_.try_emplace(k, static_cast<std::uint32_t>(sorted.size()),
                                          static_cast<std::uint32_t>(sorted.size()));
    sorted.push_back(points_[i]);
    it->second.second = static_cast<std::uint32_t>(sorted.size());
  }
  points_ = std::move(sorted);
}

std::int64_t LandmarkIndex::cell_of(double v_mm) const {
  // Clamped so that a map built in code with a non-finite or absurd coordinate cannot make the
  // conversion undefined; such a point fails every distance test wherever it is filed.
  const double c = std::floor(v_mm / cell_mm_);
  return std::isnan(c) ? 0 : static_cast<std::int64_t>(std::clamp(c, -1e9, 1e9));
}

std::uint64_t LandmarkIndex::key(std::int64_t cx, std::int64_t cy) {
  return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(cx)) << 32) |
         static_cast<std::uint32_t>(cy);
}

void LandmarkIndex::scan_cell(std::int64_t cx, std::int64_t cy, Vec2 c, double r2,
                              std::vector<const LandmarkMapEntry*>* out) const {
  const auto it = cells_.find(key(cx, cy));
  if (it == cells_.end()) return;
  for (std::uint32_t i = it->second.first; i < it->second.second; ++i) {
    const Point& p = points_[i];
    ++last_visited_;
    const double dx = p.x_mm - c.x, dy = p.y_mm - c.y;
    if (dx * dx + dy * dy <= r2) out->push_back(p.entry);
  }
}

void LandmarkIndex::within(Vec2 c, double radius_mm,
                           std::vector<const LandmarkMapEntry*>* out) const {
  out->clear();
  last_visited_ = 0;
  if (points_.empty() || !std::isfinite(c.x) || !std::isfinite(c.y) || std::isnan(radius_mm) ||
      radius_mm < 0.0) {
    return;
  }
  const double r2 = radius_mm * radius_mm;
  // Cells of the query's bounding square, clipped to the map's; as doubles first, so that an
  // infinite radius cannot overflow.
  const double x0 =
      std::max(std::floor((c.x - radius_mm) / cell_mm_), static_cast<double>(min_cx_));
  const double x1 =
      std::min(std::floor((c.x + radius_mm) / cell_mm_), static_cast<double>(max_cx_));
  const double y0 =
      std::max(std::floor((c.y - radius_mm) / cell_mm_), static_cast<double>(min_cy_));
  const double y1 =
      std::min(std::floor((c.y + radius_mm) / cell_mm_), static_cast<double>(max_cy_));
  if (x0 > x1 || y0 > y1) return;
  if ((x1 - x0 + 1.0) * (y1 - y0 + 1.0) > static_cast<double>(points_.size())) {
    for (const Point& p : points_) {
      const double dx = p.x_mm - c.x, dy = p.y_mm - c.y;
      if (dx * dx + dy * dy <= r2) out->push_back(p.entry);
    }
    last_visited_ = points_.size();
  } else {
    for (auto cy = static_cast<std::int64_t>(y0); cy <= static_cast<std::int64_t>(y1); ++cy) {
      for (auto cx = static_cast<std::int64_t>(x0); cx <= static_cast<std::int64_t>(x1); ++cx) {
        scan_cell(cx, cy, c, r2, out);
      }
    }
  }
  std::sort(out->begin(), out->end(), by_id);
}

void LandmarkIndex::nearest(Vec2 c, size_t k, std::vector<const LandmarkMapEntry*>* out) const {
  out->clear();
  last_visited_ = 0;
  if (points_.empty() || k == 0 || !std::isfinite(c.x) || !std::isfinite(c.y)) return;
  const auto d2_of = [&](const LandmarkMapEntry* e) {
    const double dx = e->pose.x_mm - c.x, dy = e->pose.y_mm - c.y;
    return dx * dx + dy * dy;
  };
  const auto closer = [&](const LandmarkMapEntry* a, const LandmarkMapEntry* b) {
    const double da = d2_of(a), db = d2_of(b);
    return da != db ? da < db : a->id < b->id;
  };
  const double inf = HUGE_VAL;
  const std::int64_t ccx = cell_of(std::clamp(c.x, -1e12, 1e12)),
                     ccy = cell_of(std::clamp(c.y, -1e12, 1e12));
  std::vector<const LandmarkMapEntry*> found;
  size_t cells_seen = 0;
  bool complete = false;
  for (std::int64_t r = 0;; ++r) {
    // Ring r: the cells at Chebyshev distance r from the query's cell.
    for (std::int64_t cy = ccy - r; cy <= ccy + r; ++cy) {
      const bool edge_row = cy == ccy - r || cy == ccy + r;
      for (std::int64_t cx = ccx - r; cx <= ccx + r; cx += edge_row || r == 0 ? 1 : 2 * r) {
        ++cells_seen;
        if (cx >= min_cx_ && cx <= max_cx_ && cy >= min_cy_ && cy <= max_cy_) {
          scan_cell(cx, cy, c, inf, &found);
        }
      }
    }
    // Every point not yet seen lies outside the scanned square of cells.
    const double outside_mm = std::min({c.x - static_cast<double>(ccx - r) * cell_mm_,
                                        static_cast<double>(ccx + r + 1) * cell_mm_ - c.x,
                                        c.y - static_cast<double>(ccy - r) * cell_mm_,
                                        static_cast<double>(ccy + r + 1) * cell_mm_ - c.y});
    const bool covers_map =
        ccx - r <= min_cx_ && ccx + r >= max_cx_ && ccy - r <= min_cy_ && ccy + r >= max_cy_;
    if (covers_map) {
      complete = true;
      break;
    }
    if (found.size() >= k) {
      std::nth_element(found.begin(), found.begin() + static_cast<std::ptrdiff_t>(k - 1),
                       found.end(), closer);
      if (d2_of(found[k - 1]) < outside_mm * outside_mm) {
        complete = true;
        break;
      }
    }
    // A query far from the map would walk empty rings: scan the map instead.
    if (cells_seen > points_.size()) break;
  }
  if (!complete) {
    found.clear();
    for (const Point& p : points_) found.push_back(p.entry);
    last_visited_ = points_.size();
  }
  const size_t n = std::min(k, found.size());
  std::partial_sort(found.begin(), found.begin() + static_cast<std::ptrdiff_t>(n), found.end(),
                    closer);
  found.resize(n);
  *out = std::move(found);
}

}  // namespace agv

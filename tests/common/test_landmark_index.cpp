// The spatial index over landmark positions (docs/design/large_maps.md): the same answers as a scan
// of the whole map on random maps, and, on a 60 000-landmark grid, a number of landmarks visited
// per query that does not grow with the map (no timing: a regression to a per-frame scan fails
// here).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "agv/common/landmark_index.hpp"

using namespace agv;

namespace {

LandmarkMap random_map(int n, double extent_mm, std::mt19937_64* rng) {
  std::uniform_real_distribution<double> u(-extent_mm, extent_mm);
  LandmarkMap m;
  for (int i = 0; i < n; ++i) {
    const auto id = static_cast<std::uint32_t>(i + 1);
    // A few exact duplicates of a position: ties in distance are ordered by id.
    const double x = i % 17 == 5 ? 0.0 : u(*rng), y = i % 17 == 5 ? 0.0 : u(*rng);
    m.entries[id] = {id, {x, y, 0.0}};
  }
  return m;
}

LandmarkMap grid_map(int side, double spacing_mm) {
  LandmarkMap m;
  std::uint32_t id = 1;
  for (int r = 0; r < side; ++r) {
    for (int c = 0; c < side; ++c, ++id)
      m.entries[id] = {id, {c * spacing_mm, r * spacing_mm, 0.0}};
  }
  return m;
}

std::vector<std::uint32_t> ids(const std::vector<const LandmarkMapEntry*>& v) {
  std::vector<std::uint32_t> out;
  for (const LandmarkMapEntry* e : v) out.push_back(e->id);
  return out;
}

double dist2(const LandmarkMapEntry& e, Vec2 c) {
  const double dx = e.pose.x_mm - c.x, dy = e.pose.y_mm - c.y;
  return dx * dx + dy * dy;
}

}  // namespace

TEST(LandmarkIndex, WithinRadiusIsTheBruteForceAnswerInIdOrder) {
  std::mt19937_64 rng(1);
  for (const double cell_mm : {250.0, 1000.0, 7000.0}) {
    const LandmarkMap map = random_map(3000, 20000.0, &rng);
    const LandmarkIndex index(map, cell_mm);
    std::uniform_real_distribution<double> u(-25000.0, 25000.0), r(0.0, 6000.0);
    std::vector<const LandmarkMapEntry*> got;
    for (int q = 0; q < 300; ++q) {
      const Vec2 c{u(rng), u(rng)};
      // Mostly local queries, some that cover the whole map.
      const double radius = q % 10 == 0 ? 1e7 : r(rng);
      index.within(c, radius, &got);
      std::vector<std::uint32_t> want;
      for (const auto& [id, e] : map.entries) {
        if (dist2(e, c) <= radius * radius) want.push_back(id);
      }
      ASSERT_EQ(ids(got), want) << "cell " << cell_mm << " query " << q;
    }
  }
}

TEST(LandmarkIndex, NearestIsTheBruteForceAnswer) {
  std::mt19937_64 rng(2);
  const LandmarkMap map = random_map(2000, 15000.0, &rng);
  const LandmarkIndex index(map, 1000.0);
  std::uniform_real_distribution<double> u(-20000.0, 20000.0);
  std::vector<const LandmarkMapEntry*> got;
  for (int q = 0; q < 300; ++q) {
    // Some queries far outside the map.
    const Vec2 c = q % 25 == 0 ? Vec2{1e6, -3e6} : Vec2{u(rng), u(rng)};
    const size_t k = 1 + static_cast<size_t>(q % 30);
    index.nearest(c, k, &got);
    std::vector<const LandmarkMapEntry*> all;
    for (const auto& [id, e] : map.entries) all.push_back(&e);
    std::stable_sort(all.begin(), all.end(),
                     [&](const LandmarkMapEntry* a, const LandmarkMapEntry* b) {
                       return dist2(*a, c) < dist2(*b, c);
                     });
    all.resize(k);
    ASSERT_EQ(ids(got), ids(all)) << "query " << q;
  }
  index.nearest({0.0, 0.0}, 5000, &got);  // more than the map holds
  EXPECT_EQ(got.size(), map.entries.size());
}

TEST(LandmarkIndex, EmptyMapAndBadQueriesGiveNothing) {
  const LandmarkMap empty;
  const LandmarkIndex index(empty);
  std::vector<const LandmarkMapEntry*> got;
  index.within({0.0, 0.0}, 1e9, &got);
  EXPECT_TRUE(got.empty());
  index.nearest({0.0, 0.0}, 3, &got);
  EXPECT_TRUE(got.empty());
  const LandmarkMap map = grid_map(10, 1000.0);
  const LandmarkIndex idx(map);
  idx.within({NAN, 0.0}, 100.0, &got);
  EXPECT_TRUE(got.empty());
  idx.within({0.0, 0.0}, -1.0, &got);
  EXPECT_TRUE(got.empty());
  idx.within({0.0, 0.0}, INFINITY, &got);
  EXPECT_EQ(got.size(), 100u);
}

// The per-frame queries on a site's map: a few landmarks visited, the same on a 60 000-landmark
// map as on a 1 000-landmark one.
TEST(LandmarkIndex, QueriesVisitTheNeighbourhoodNotTheMap) {
  for (const int side : {32, 245}) {  // 1 024 and 60 025 landmarks on a 1 m grid
    const LandmarkMap map = grid_map(side, 1000.0);
    const LandmarkIndex index(map);
    std::vector<const LandmarkMapEntry*> got;
    index.within({15400.0, 15700.0}, 1500.0, &got);
    EXPECT_EQ(got.size(), 7u);  // counted by hand
    // The 4 x 4 cells around the disc, one landmark each.
    EXPECT_LE(index.last_visited(), 16u) << side;
    index.nearest({15400.0, 15700.0}, 25, &got);
    EXPECT_EQ(got.size(), 25u);
    EXPECT_LE(index.last_visited(), 81u) << side;
  }
}

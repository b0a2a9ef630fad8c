// Landmark map CSV (docs/landmark.md). Property: an accepted map has finite poses, and
// format_landmark_map writes text that parses back to the same map (ids and poses).
#include <cmath>

#include "agv/common/landmark.hpp"
#include "fuzz_check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  agv::LandmarkMap map;
  std::string error;
  if (!agv::parse_landmark_map(agv::fuzz::as_text(data, size), &map, &error)) {
    FUZZ_CHECK(!error.empty(), "a rejected map says why");
    return 0;
  }
  for (const auto& [id, e] : map.entries) {
    FUZZ_CHECK(id == e.id && id != 0, "id %u", id);
    FUZZ_CHECK(
        std::isfinite(e.pose.x_mm) && std::isfinite(e.pose.y_mm) && std::isfinite(e.pose.theta_rad),
        "landmark %u has a non-finite pose", id);
    FUZZ_CHECK(map.find(id) == &e, "find(%u)", id);
  }
  const std::string text = agv::format_landmark_map(map);
  agv::LandmarkMap back;
  FUZZ_CHECK(agv::parse_landmark_map(text, &back, &error), "formatted map rejected: %s",
             error.c_str());
  FUZZ_CHECK(back.entries.size() == map.entries.size(), "%zu vs %zu entries", back.entries.size(),
             map.entries.size());
  for (const auto& [id, e] : map.entries) {
    const agv::LandmarkMapEntry* b = back.find(id);
    FUZZ_CHECK(b != nullptr, "landmark %u lost", id);
    // The writer keeps 0.1 mm and 0.01 degrees (the payload's resolution, docs/landmark.md).
    FUZZ_CHECK(std::abs(b->pose.x_mm - e.pose.x_mm) <= 0.05 + 1e-9 * std::abs(e.pose.x_mm) &&
                   std::abs(b->pose.y_mm - e.pose.y_mm) <= 0.05 + 1e-9 * std::abs(e.pose.y_mm) &&
                   std::abs(agv::wrap_angle_rad(b->pose.theta_rad - e.pose.theta_rad)) <=
                       agv::deg_to_rad(0.005) + 1e-12,
               "landmark %u: (%.17g, %.17g, %.17g) -> (%.17g, %.17g, %.17g)", id, e.pose.x_mm,
               e.pose.y_mm, e.pose.theta_rad, b->pose.x_mm, b->pose.y_mm, b->pose.theta_rad);
  }
  return 0;
}

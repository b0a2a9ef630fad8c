// Landmark map CSV (docs/design/landmark.md). Property: an accepted map has ids (0..65535: 0 is
// tag36h11's first tag) that match their entries, and finite poses.
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
    FUZZ_CHECK(id == e.id && id <= 65535u, "id %u", id);
    FUZZ_CHECK(
        std::isfinite(e.pose.x_mm) && std::isfinite(e.pose.y_mm) && std::isfinite(e.pose.theta_rad),
        "landmark %u has a non-finite pose", id);
    FUZZ_CHECK(map.find(id) == &e, "find(%u)", id);
  }
  return 0;
}

// Names of the site model's enumerations, as the site file spells them (docs/guide/site.md).
#include <cstddef>

#include "agv/site/site.hpp"

namespace agv::site {
namespace {
constexpr const char* kObstacleNames[] = {"rack", "pillar", "conveyor", "wall", "other"};
constexpr const char* kFamilyNames[] = {"tag36h11", "agvloc"};
}  // namespace

const char* to_string(ObstacleKind k) { return kObstacleNames[static_cast<std::size_t>(k)]; }

bool parse_obstacle_kind(const std::string& name, ObstacleKind* out) {
  for (std::size_t i = 0; i < std::size(kObstacleNames); ++i) {
    if (name == kObstacleNames[i]) {
      *out = static_cast<ObstacleKind>(i);
      return true;
    }
  }
  return false;
}

const char* to_string(LandmarkFamily f) { return kFamilyNames[static_cast<std::size_t>(f)]; }

bool parse_landmark_family(const std::string& name, LandmarkFamily* out) {
  for (std::size_t i = 0; i < std::size(kFamilyNames); ++i) {
    if (name == kFamilyNames[i]) {
      *out = static_cast<LandmarkFamily>(i);
      return true;
    }
  }
  return false;
}

}  // namespace agv::site

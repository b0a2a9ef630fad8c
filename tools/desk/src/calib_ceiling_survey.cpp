// The survey of the ceiling camera calibration: a CSV of tags, or the site's floor map.
// Conventions: calib_ceiling.hpp.
#include <cmath>
#include <cstdlib>
#include <sstream>

#include "calib_ceiling.hpp"

namespace agv::desk::ccal {

namespace {

constexpr std::uint32_t kMaxTagId = 586;
constexpr double kMaxCoordMm = 1e7;

bool split_csv(const std::string& line, std::vector<std::string>* f) {
  f->clear();
  std::stringstream ss(line);
  std::string item;
  while (std::getline(ss, item, ',')) {
    const auto b = item.find_first_not_of(" \t\r");
    const auto e = item.find_last_not_of(" \t\r");
    f->push_back(b == std::string::npos ? "" : item.substr(b, e - b + 1));
  }
  return true;
}

bool to_number(const std::string& s, double* v) {
  if (s.empty()) return false;
  char* end = nullptr;
  *v = std::strtod(s.c_str(), &end);
  return end == s.c_str() + s.size() && std::isfinite(*v);
}

}  // namespace

bool parse_survey_csv(std::string_view text, std::map<std::uint32_t, SurveyedTag>* out,
                      std::string* error) {
  out->clear();
  std::stringstream in{std::string(text)};
  std::string line;
  std::vector<std::string> f;
  int n = 0;
  bool header = false;
  auto fail = [&](const std::string& why) {
    *error = "line " + std::to_string(n) + ": " + why;
    out->clear();
    return false;
  };
  while (std::getline(in, line)) {
    ++n;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const auto first = line.find_first_not_of(" \t");
    if (first == std::string::npos || line[first] == '#') continue;
    split_csv(line, &f);
    if (!header) {
      const std::vector<std::string> want = {"id", "x_mm", "y_mm", "z_mm", "yaw_deg", "size_mm"};
      if (f != want) return fail("the header must be id,x_mm,y_mm,z_mm,yaw_deg,size_mm");
      header = true;
      continue;
    }
    if (f.size() != 6) return fail("expected 6 fields, got " + std::to_string(f.size()));
    double v[6];
    for (int i = 0; i < 6; ++i) {
      if (!to_number(f[static_cast<std::size_t>(i)], &v[i])) {
        return fail("field " + std::to_string(i + 1) + " '" + f[static_cast<std::size_t>(i)] +
                    "' is not a finite number");
      }
    }
    if (v[0] < 0 || v[0] > kMaxTagId || v[0] != std::floor(v[0])) {
      return fail("id must be a tag36h11 id 0..586");
    }
    for (int i = 1; i <= 3; ++i) {
      if (std::abs(v[i]) > kMaxCoordMm) return fail("coordinate beyond 10 km");
    }
    if (std::abs(v[4]) > 360.0) return fail("yaw_deg must be in -360..360");
    if (v[5] < 10.0 || v[5] > 5000.0) return fail("size_mm must be in 10..5000");
    const auto id = static_cast<std::uint32_t>(v[0]);
    if (out->count(id)) return fail("tag " + std::to_string(id) + " listed twice");
    (*out)[id] = SurveyedTag{id, v[1], v[2], v[3], deg_to_rad(v[4]), v[5]};
  }
  if (!header) {
    n = 0;
    return fail("no header line (id,x_mm,y_mm,z_mm,yaw_deg,size_mm)");
  }
  return true;
}

std::map<std::uint32_t, SurveyedTag> survey_from_floor_map(const LandmarkMap& map, double size_mm) {
  std::map<std::uint32_t, SurveyedTag> out;
  for (const auto& [id, e] : map.entries) {
    if (id > kMaxTagId) continue;
    out[id] = SurveyedTag{id, e.pose.x_mm, e.pose.y_mm, 0.0, e.pose.theta_rad, size_mm};
  }
  return out;
}

}  // namespace agv::desk::ccal

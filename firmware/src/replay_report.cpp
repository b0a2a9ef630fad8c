#include "replay_report.hpp"

#include <algorithm>
#include <cinttypes>
#include <cmath>
#include <cstdio>

namespace agv::app {

bool write_poses_csv(const std::string& path, const std::vector<TickRecord>& ticks,
                     std::string* error) {
  FILE* f = std::fopen(path.c_str(), "w");
  if (!f) {
    *error = path + ": cannot open for writing";
    return false;
  }
  std::fprintf(f,
               "t_ns,valid,health,x_mm,y_mm,theta_deg,v_mps,omega_radps,sigma_x_mm,sigma_y_mm,"
               "sigma_theta_deg,time_since_fix_ms,faults,rejections\n");
  for (const auto& t : ticks) {
    const auto& e = t.estimate;
    std::fprintf(
        f, "%" PRId64 ",%d,%d,%.4f,%.4f,%.5f,%.5f,%.6f,%.4f,%.4f,%.5f,%.1f,%u,%u\n", t.t_ns,
        e.valid ? 1 : 0, static_cast<int>(e.health), e.pose.x_mm, e.pose.y_mm,
        rad_to_deg(e.pose.theta_rad), e.v_mps, e.omega_radps, std::sqrt(std::max(0.0, e.cov(0, 0))),
        std::sqrt(std::max(0.0, e.cov(1, 1))), rad_to_deg(std::sqrt(std::max(0.0, e.cov(2, 2)))),
        e.time_since_fix_ns < 0 ? -1.0 : static_cast<double>(e.time_since_fix_ns) / 1e6,
        static_cast<unsigned>(t.status.faults), static_cast<unsigned>(t.status.rejections));
  }
  const bool ok = std::fclose(f) == 0;
  if (!ok) *error = path + ": write failed";
  return ok;
}

bool write_fixes_csv(const std::string& path, const std::vector<FixRecord>& fixes,
                     std::string* error) {
  FILE* f = std::fopen(path.c_str(), "w");
  if (!f) {
    *error = path + ": cannot open for writing";
    return false;
  }
  std::fprintf(f,
               "t_ns,status,landmark_id,e_x_mm,e_y_mm,e_phi_deg,x_mm,y_mm,theta_deg,sigma_x_mm,"
               "sigma_y_mm,sigma_theta_deg,vision_ms,search,identity\n");
  for (const auto& r : fixes) {
    const auto& x = r.fix;
    const bool ok = x.status == vision::FixStatus::kOk;
    std::fprintf(f, "%" PRId64 ",%s,%u,%.4f,%.4f,%.5f,%.4f,%.4f,%.5f,%.4f,%.4f,%.5f,%.3f,%s,%s\n",
                 r.t_exposure_ns, vision::to_string(x.status), static_cast<unsigned>(x.landmark_id),
                 ok ? x.e_x_mm : 0.0, ok ? x.e_y_mm : 0.0, ok ? x.e_phi_deg : 0.0,
                 ok ? x.vehicle_in_world.x_mm : 0.0, ok ? x.vehicle_in_world.y_mm : 0.0,
                 ok ? rad_to_deg(x.vehicle_in_world.theta_rad) : 0.0,
                 ok ? std::sqrt(std::max(0.0, x.cov_world(0, 0))) : 0.0,
                 ok ? std::sqrt(std::max(0.0, x.cov_world(1, 1))) : 0.0,
                 ok ? rad_to_deg(std::sqrt(std::max(0.0, x.cov_world(2, 2)))) : 0.0,
                 x.timings.total_ms, vision::to_string(x.search), vision::to_string(x.identity));
  }
  const bool ok = std::fclose(f) == 0;
  if (!ok) *error = path + ": write failed";
  return ok;
}

bool write_odometry_csv(const std::string& path, const std::vector<recording::OdomRow>& rows,
                        std::string* error) {
  FILE* f = std::fopen(path.c_str(), "w");
  if (!f) {
    *error = path + ": cannot open for writing";
    return false;
  }
  std::fprintf(f, "t_ns,v_mps,omega_radps\n");
  for (const auto& r : rows) {
    std::fprintf(f, "%" PRId64 ",%.17g,%.17g\n", r.t_ns, r.v_mps, r.omega_radps);
  }
  const bool ok = std::fclose(f) == 0;
  if (!ok) *error = path + ": write failed";
  return ok;
}

std::string no_fix_hint(const localizer::RunResult& r, const std::vector<FixRecord>& fixes,
                        const NoFixContext& c) {
  const localizer::VisionStats& v = r.vision;
  if (v.frames_processed == 0 || v.by_status[static_cast<int>(vision::FixStatus::kOk)] > 0) {
    return {};
  }
  auto count = [&](vision::FixStatus s) { return v.by_status[static_cast<int>(s)]; };
  std::string said;
  for (int i = 0; i < localizer::kFixStatusCount; ++i) {
    if (v.by_status[i] == 0) continue;
    said += (said.empty() ? "" : ", ") + std::to_string(v.by_status[i]) + " " +
            vision::to_string(static_cast<vision::FixStatus>(i));
  }
  const bool tag = c.family == LandmarkFamily::kTag36h11;
  const std::string family = std::string("landmark.family (") + (tag ? "tag36h11" : "qr") + ", " +
                             (c.family_source.empty() ? "the default: neither --config nor "
                                                        "meta.yaml sets it"
                                                      : "from " + c.family_source) +
                             ")";
  std::string head = "replay: no landmark fix in " + std::to_string(v.frames_processed) +
                     " frames (" + said + "): likely cause: ";
  // Landmarks read but not in the map: the ids say which.
  const std::uint64_t unknown =
      count(vision::FixStatus::kUnknownLandmark) + count(vision::FixStatus::kPayloadInvalid);
  // Tags whose fitted square is off the printed size (apriltag.cpp's 3 % gate): the metric frame's
  // scale is the configured height's, so the median ratio says how far off the height (or print)
  // is. A true height H' shows the square H / H' of its size.
  std::vector<double> ratios;
  for (const FixRecord& f : fixes) {
    if (f.fix.status == vision::FixStatus::kTooFewEdgePoints && f.fix.outer_half_mm > 0.0 &&
        c.size_mm > 0.0) {
      ratios.push_back(f.fix.outer_half_mm / (c.size_mm / 2.0));
    }
  }
  const std::uint64_t seen = v.frames_processed - count(vision::FixStatus::kNoLandmark) -
                             count(vision::FixStatus::kBadInput);
  char b[512];
  if (unknown > 0 && unknown * 2 >= seen) {
    std::string ids;
    std::vector<std::uint32_t> listed;
    for (const FixRecord& f : fixes) {
      if (f.fix.status != vision::FixStatus::kUnknownLandmark &&
          f.fix.status != vision::FixStatus::kPayloadInvalid) {
        continue;
      }
      if (std::find(listed.begin(), listed.end(), f.fix.landmark_id) != listed.end()) continue;
      listed.push_back(f.fix.landmark_id);
      if (listed.size() <= 5) ids += (ids.empty() ? "" : ", ") + std::to_string(f.fix.landmark_id);
    }
    if (listed.size() > 5) ids += ", ...";
    return head + "the map: landmarks " + ids + " were read but " +
           (c.have_map ? "are not in the map (or disagree with it): check --map / landmark.map"
                       : "there is no map (--map, landmark.map or the recording's map.csv)" +
                             std::string(tag ? ", which a tag36h11 floor needs" : "")) +
           "\n";
  }
  if (ratios.size() * 2 >= std::max<std::uint64_t>(seen, 1) && !ratios.empty()) {
    std::sort(ratios.begin(), ratios.end());
    const double s = ratios[ratios.size() / 2];
    std::snprintf(b, sizeof b,
                  "the camera height or the print size: %zu landmarks were found but their "
                  "square measures %.1f %% %s than landmark.size_mm %g (more than the 3 %% "
                  "allowed); with the print right, the camera is about %.0f mm above the floor, "
                  "not mounting.height_mm %g (agvloc-desk calibrate vehicle measures it)\n",
                  ratios.size(), std::abs(s - 1.0) * 100.0, s < 1.0 ? "smaller" : "larger",
                  c.size_mm, c.height_mm / s, c.height_mm);
    return head + b;
  }
  // Nothing of the family was read in any frame: a QR floor run as tags finds no tag; a tag floor
  // run as QR finds the tags' black squares as borders (an inner edge broken by the data cells,
  // no code inside), but no frame reads a code.
  const bool read_any =
      tag ? seen > 0 : unknown + count(vision::FixStatus::kDirectionAmbiguous) > 0;
  if (!read_any) {
    return head + "the family: is " + family + " the family printed on the floor? " +
           (tag ? "A QR floor needs landmark.family: qr"
                : "A tag36h11 floor needs landmark.family: tag36h11 and the map") +
           " (--config, or a recording whose meta.yaml records it); otherwise the drive passes "
           "over no landmark\n";
  }
  return head + "see the statuses; " + family +
         ", the camera height and the map are the usual suspects\n";
}

}  // namespace agv::app

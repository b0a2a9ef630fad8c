#include "replay_report.hpp"

#include <algorithm>
#include <cinttypes>
#include <cmath>
#include <cstdio>

namespace agv::app {

namespace {

// Writes the header and one line per row (write_row) to path; false with *error when the file
// cannot be opened or written.
template <typename Row, typename WriteRow>
bool write_csv(const std::string& path, const char* header, const std::vector<Row>& rows,
               WriteRow write_row, std::string* error) {
  FILE* f = std::fopen(path.c_str(), "w");
  if (!f) {
    *error = path + ": cannot open for writing";
    return false;
  }
  std::fputs(header, f);
  for (const Row& r : rows) write_row(f, r);
  const bool ok = std::fclose(f) == 0;
  if (!ok) *error = path + ": write failed";
  return ok;
}

}  // namespace

bool write_poses_csv(const std::string& path, const std::vector<TickRecord>& ticks,
                     std::string* error) {
  return write_csv(
      path,
      "t_ns,valid,health,x_mm,y_mm,theta_deg,v_mps,omega_radps,sigma_x_mm,sigma_y_mm,"
      "sigma_theta_deg,time_since_fix_ms,faults,rejections\n",
      ticks,
      [](FILE* f, const TickRecord& t) {
        const auto& e = t.estimate;
        std::fprintf(
            f, "%" PRId64 ",%d,%d,%.4f,%.4f,%.5f,%.5f,%.6f,%.4f,%.4f,%.5f,%.1f,%u,%u\n", t.t_ns,
            e.valid ? 1 : 0, static_cast<int>(e.health), e.pose.x_mm, e.pose.y_mm,
            rad_to_deg(e.pose.theta_rad), e.v_mps, e.omega_radps,
            std::sqrt(std::max(0.0, e.cov(0, 0))), std::sqrt(std::max(0.0, e.cov(1, 1))),
            rad_to_deg(std::sqrt(std::max(0.0, e.cov(2, 2)))),
            e.time_since_fix_ns < 0 ? -1.0 : static_cast<double>(e.time_since_fix_ns) / 1e6,
            static_cast<unsigned>(t.status.faults), static_cast<unsigned>(t.status.rejections));
      },
      error);
}

bool write_fixes_csv(const std::string& path, const std::vector<FrameRecord>& fixes,
                     std::string* error) {
  return write_csv(
      path,
      "t_ns,status,landmark_id,e_x_mm,e_y_mm,e_phi_deg,x_mm,y_mm,theta_deg,sigma_x_mm,"
      "sigma_y_mm,sigma_theta_deg,vision_ms,search,identity\n",
      fixes,
      [](FILE* f, const FrameRecord& r) {
        const auto& x = r.fix;
        const bool ok = x.status == vision::FixStatus::kOk;
        std::fprintf(
            f, "%" PRId64 ",%s,%u,%.4f,%.4f,%.5f,%.4f,%.4f,%.5f,%.4f,%.4f,%.5f,%.3f,%s,%s\n",
            r.t_exposure_ns, vision::to_string(x.status), static_cast<unsigned>(x.landmark_id),
            ok ? x.e_x_mm : 0.0, ok ? x.e_y_mm : 0.0, ok ? x.e_phi_deg : 0.0,
            ok ? x.vehicle_in_world.x_mm : 0.0, ok ? x.vehicle_in_world.y_mm : 0.0,
            ok ? rad_to_deg(x.vehicle_in_world.theta_rad) : 0.0,
            ok ? std::sqrt(std::max(0.0, x.cov_world(0, 0))) : 0.0,
            ok ? std::sqrt(std::max(0.0, x.cov_world(1, 1))) : 0.0,
            ok ? rad_to_deg(std::sqrt(std::max(0.0, x.cov_world(2, 2)))) : 0.0, x.timings.total_ms,
            vision::to_string(x.search), vision::to_string(x.identity));
      },
      error);
}

bool write_odometry_csv(const std::string& path, const std::vector<recording::OdomRow>& rows,
                        std::string* error) {
  return write_csv(
      path, "t_ns,v_mps,omega_radps\n", rows,
      [](FILE* f, const recording::OdomRow& r) {
        std::fprintf(f, "%" PRId64 ",%.17g,%.17g\n", r.t_ns, r.v_mps, r.omega_radps);
      },
      error);
}

std::string no_fix_hint(const localizer::RunResult& r, const std::vector<FrameRecord>& fixes,
                        const NoFixContext& c) {
  std::vector<localizer::FrameOutcome> frames;
  frames.reserve(fixes.size());
  for (const FrameRecord& f : fixes) frames.push_back(localizer::frame_outcome(f.fix));
  const localizer::NoFixDiagnosis d =
      localizer::diagnose_no_fix(r.vision.frames_processed, r.vision.by_status, frames, c);
  if (d.cause == localizer::NoFixCause::kNone) return {};
  return "replay: no landmark fix in " + std::to_string(r.vision.frames_processed) + " frames (" +
         d.statuses + "): likely cause: " + d.text + "\n";
}

}  // namespace agv::app

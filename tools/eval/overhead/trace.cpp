// CSV traces of eval_overhead (trace.hpp).
#include "trace.hpp"

#include <algorithm>
#include <cmath>

namespace agv::eval {

Trace::~Trace() {
  if (ticks_) std::fclose(ticks_);
  if (fixes_) std::fclose(fixes_);
}

bool Trace::open(const std::string& prefix, std::string* error) {
  ticks_ = std::fopen((prefix + "_ticks.csv").c_str(), "w");
  fixes_ = std::fopen((prefix + "_fixes.csv").c_str(), "w");
  if (!ticks_ || !fixes_) {
    *error = "cannot write " + prefix + "_ticks.csv / _fixes.csv";
    return false;
  }
  std::fputs(
      "t_s,agv,state,valid,true_x_mm,true_y_mm,true_theta_rad,true_v_mps,true_omega_radps,"
      "x_mm,y_mm,theta_rad,v_mps,omega_radps,sigma_xy_mm,sigma_theta_rad,fix_age_ms,"
      "pos_err_mm,head_err_deg,cov0,cov1,cov2,cov3,cov4,cov5,cov6,cov7,cov8\n",
      ticks_);
  std::fputs(
      "t_s,camera,agv,level,result,fix_theta_rad,sigma_theta_rad,true_theta_rad,"
      "true_omega_radps,true_v_mps,head_err_deg,pos_err_mm,arrival_s,x_mm,y_mm",
      fixes_);
  for (int i = 0; i < 9; ++i) std::fprintf(fixes_, ",cov%d", i);
  for (int i = 0; i < 9; ++i) std::fprintf(fixes_, ",cov_camera%d", i);
  std::fputc('\n', fixes_);
  return true;
}

void Trace::tick(std::int64_t t_ns, const std::vector<overhead::TrackOutput>& outs,
                 const std::vector<sim::AgvState>& truth) {
  if (!ticks_) return;
  for (const overhead::TrackOutput& o : outs) {
    if (o.agv >= truth.size()) continue;
    const sim::AgvState& s = truth[o.agv];
    const double pos = std::hypot(o.pose.x_mm - s.pose.x_mm, o.pose.y_mm - s.pose.y_mm);
    const double head = rad_to_deg(wrap_angle_rad(o.pose.theta_rad - s.pose.theta_rad));
    std::fprintf(ticks_,
                 "%.9f,%zu,%s,%d,%.3f,%.3f,%.6f,%.4f,%.5f,%.3f,%.3f,%.6f,%.4f,%.5f,%.4f,%.6f,"
                 "%.2f,%.4f,%.5f",
                 1e-9 * static_cast<double>(t_ns), o.agv, overhead::to_string(o.state),
                 o.valid() ? 1 : 0, s.pose.x_mm, s.pose.y_mm, s.pose.theta_rad, s.v_mps,
                 s.omega_radps, o.pose.x_mm, o.pose.y_mm, o.pose.theta_rad, o.v_mps, o.omega_radps,
                 o.sigma_xy_mm, o.sigma_theta_rad,
                 1e-6 * static_cast<double>(t_ns - o.last_fix_t_ns), pos, head);
    for (double c : o.cov) std::fprintf(ticks_, ",%.9g", c);  // (x_mm, y_mm, theta_rad)
    std::fputc('\n', ticks_);
  }
}

void Trace::fixes(std::int64_t arrival_ns, const std::vector<overhead::Detection>& dets,
                  const std::vector<sim::AgvState>& truth_at_exposure) {
  if (!fixes_) return;
  for (const overhead::Detection& d : dets) {
    if (!d.has_fix || !d.in_fleet || d.agv >= truth_at_exposure.size()) continue;
    const sim::AgvState& s = truth_at_exposure[d.agv];
    const Pose2& p = d.fix.pose;
    std::fprintf(fixes_, "%.9f,%zu,%zu,%d,%s,%.9f,%.6f,%.6f,%.5f,%.4f,%.5f,%.4f",
                 1e-9 * static_cast<double>(d.t_ns), d.camera, d.agv, static_cast<int>(d.level),
                 overhead::to_string(d.result), p.theta_rad, std::sqrt(std::max(0.0, d.fix.cov[8])),
                 s.pose.theta_rad, s.omega_radps, s.v_mps,
                 rad_to_deg(wrap_angle_rad(p.theta_rad - s.pose.theta_rad)),
                 std::hypot(p.x_mm - s.pose.x_mm, p.y_mm - s.pose.y_mm));
    std::fprintf(fixes_, ",%.9f,%.6f,%.6f", 1e-9 * static_cast<double>(arrival_ns), p.x_mm, p.y_mm);
    for (double c : d.fix.cov) std::fprintf(fixes_, ",%.9g", c);
    for (double c : d.fix.cov_camera) std::fprintf(fixes_, ",%.9g", c);
    std::fputc('\n', fixes_);
  }
}

}  // namespace agv::eval

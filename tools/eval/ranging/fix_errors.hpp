// What both ranging evaluations (eval_ranging, eval_ranging_frames) count of fixes against the
// truth; each adds its own covariance check. Header-only; not part of algo.
#pragma once

#include <Eigen/Dense>
#include <cmath>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/ranging/fix.hpp"

namespace agv::ranging_eval {

inline constexpr double kNees3Sigma = 14.16;  // chi2(3) at 0.9973

struct FixErrors {
  int tried = 0, ok = 0;
  int wrong = 0;  // more than a metre off: the other solution of an ambiguous geometry
  std::vector<double> pos_mm, heading_deg;
  std::map<std::string, int> refusals;  // by status name

  // Counts f; its error (x, y in mm, heading in rad) when it is a fix, else nothing.
  std::optional<Eigen::Vector3d> add(const ranging::FixResult& f, const Pose2& truth) {
    ++tried;
    if (f.status != ranging::FixStatus::kOk) {
      ++refusals[ranging::fix_status_name(f.status)];
      return std::nullopt;
    }
    ++ok;
    const Eigen::Vector3d e(f.pose.x_mm - truth.x_mm, f.pose.y_mm - truth.y_mm,
                            wrap_angle_rad(f.pose.theta_rad - truth.theta_rad));
    pos_mm.push_back(std::hypot(e.x(), e.y()));
    heading_deg.push_back(std::abs(rad_to_deg(e.z())));
    if (pos_mm.back() > 1000.0) ++wrong;
    return e;
  }
};

}  // namespace agv::ranging_eval

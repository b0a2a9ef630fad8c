// Hand-run evaluation of the ceiling camera pose calibration on rendered frames (not a test: a
// 3840x2160 trial takes seconds). Each trial draws a camera pose (height, yaw, a tilt of up to
// 5 degrees), parks vehicles at random pixels of the view, renders frames with the realistic
// effects (noise, vignetting, gradient), calibrates from the tray tags and compares with the
// truth. Prints each trial and the summary: largest errors and how often |error| <= k sigma.
//   eval_calib_ceiling [--width 3840 --height 2160 --f 2100 --z 6000 --tag 160 --tags 8
//                       --frames 2 --trials 10 --seed 1 --survey-error-mm 0]
// --survey-error-mm: each surveyed coordinate (x, y, z) off by a Gaussian error of that sigma.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>

#include "agv/sim/site_render.hpp"
#include "calib_ceiling.hpp"
#include "ceiling_world.hpp"

namespace {

using namespace agv;
constexpr double kDeg = kPi / 180.0;

struct Args {
  int width = 3840, height = 2160, tags = 8, frames = 2, trials = 10;
  double f = 2100.0, z_mm = 6000.0, tag_mm = 160.0, survey_mm = 0.0;
  unsigned seed = 1;
};

bool parse(int argc, char** argv, Args* a) {
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    const double v = std::atof(argv[i + 1]);
    if (k == "--width")
      a->width = static_cast<int>(v);
    else if (k == "--height")
      a->height = static_cast<int>(v);
    else if (k == "--f")
      a->f = v;
    else if (k == "--z")
      a->z_mm = v;
    else if (k == "--tag")
      a->tag_mm = v;
    else if (k == "--tags")
      a->tags = static_cast<int>(v);
    else if (k == "--frames")
      a->frames = static_cast<int>(v);
    else if (k == "--trials")
      a->trials = static_cast<int>(v);
    else if (k == "--survey-error-mm")
      a->survey_mm = v;
    else if (k == "--seed")
      a->seed = static_cast<unsigned>(v);
    else
      return false;
  }
  return argc % 2 == 1 && a->width > 0 && a->height > 0 && a->tags >= 3 && a->frames > 0 &&
         a->survey_mm >= 0.0;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  if (!parse(argc, argv, &a)) {
    std::fprintf(stderr, "usage: see the comment at the top of eval_calib_ceiling.cpp\n");
    return 2;
  }
  std::mt19937 rng(a.seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  CameraIntrinsics k;
  k.width_px = a.width;
  k.height_px = a.height;
  k.fx = a.f;
  k.fy = a.f;
  k.cx = 0.5 * (a.width - 1);
  k.cy = 0.5 * (a.height - 1);
  k.k1 = -0.05;
  k.k2 = 0.01;
  const sim::SiteFrameRenderer renderer(k);
  const char* names[6] = {"x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"};
  double worst[6] = {}, within[3] = {};
  int n_par = 0, solved = 0;
  double worst_rms = 0.0, worst_floor = 0.0;
  for (int t = 0; t < a.trials; ++t) {
    const desk::ccal::CameraPose truth{uni(rng) * 1000.0,
                                       uni(rng) * 1000.0,
                                       a.z_mm,
                                       (uni(rng) * 360.0 - 180.0) * kDeg,
                                       (uni(rng) * 10.0 - 5.0) * kDeg,
                                       (uni(rng) * 10.0 - 5.0) * kDeg};
    sim::SiteScene scene;
    site::CeilingCamera cam;
    cam.id = "cam";
    cam.intrinsics = k;
    desk::ccal::set_pose(truth, &cam);
    scene.site.outline.vertices_mm = {
        {-20000, -20000}, {20000, -20000}, {20000, 20000}, {-20000, 20000}};
    scene.site.cameras.push_back(cam);
    std::map<std::uint32_t, desk::ccal::SurveyedTag> survey;
    // Vehicles on a jittered grid over the view (apart by more than a vehicle), trays 350..450 mm.
    const int cols = (a.tags + 1) / 2;
    for (int i = 0; i < a.tags; ++i) {
      const double u = (i % cols + 0.5 + 0.3 * (uni(rng) - 0.5)) / cols * a.width;
      const double v = (i / cols + 0.5 + 0.3 * (uni(rng) - 0.5)) / 2.0 * a.height;
      site::FleetAgv agv;
      agv.id = "agv-" + std::to_string(i);
      agv.tag_id = static_cast<std::uint32_t>(10 + i);
      agv.tag_size_mm = a.tag_mm;
      agv.tray_height_mm = 350.0 + 100.0 * uni(rng);
      scene.site.fleet.push_back(agv);
      const Vec2 p = desk::test::on_plane(cam, u, v, agv.tray_height_mm);
      const double heading = (uni(rng) * 360.0 - 180.0) * kDeg;
      scene.agvs.push_back({{p.x, p.y, heading}, 0.0, 0.0});
      std::normal_distribution<double> unit(0.0, 1.0);
      const auto off = [&] { return a.survey_mm * unit(rng); };
      survey[agv.tag_id] = {agv.tag_id, p.x + off(), p.y + off(), agv.tray_height_mm + off(),
                            heading,    a.tag_mm};
    }
    scene.floor.amplitude = 30.0;
    std::vector<desk::ccal::TagSighting> sightings;
    for (int f = 0; f < a.frames; ++f) {
      const sim::RenderResult r =
          renderer.render(scene, sim::RenderCamera::from_ceiling(cam), sim::realistic_site_params(),
                          a.seed * 1000u + static_cast<unsigned>(t * 16 + f));
      const auto s = desk::ccal::detect_tags(r.image, f);
      sightings.insert(sightings.end(), s.begin(), s.end());
    }
    const desk::ccal::Result res = desk::ccal::solve_camera_pose(k, survey, sightings);
    if (res.error != desk::ccal::Error::kNone) {
      std::printf("trial %d: %s: %s\n", t, desk::ccal::to_string(res.error), res.message.c_str());
      continue;
    }
    ++solved;
    const double e[6] = {res.pose.x_mm - truth.x_mm,
                         res.pose.y_mm - truth.y_mm,
                         res.pose.z_mm - truth.z_mm,
                         std::remainder(res.pose.roll_rad - truth.roll_rad, 2 * kPi),
                         std::remainder(res.pose.pitch_rad - truth.pitch_rad, 2 * kPi),
                         std::remainder(res.pose.yaw_rad - truth.yaw_rad, 2 * kPi)};
    std::printf("trial %d: %d tags, rms %.3f px, floor max %.2f mm; err/sigma:", t, res.tags_used,
                res.eval.rms_px, res.eval.max_floor_mm);
    for (int i = 0; i < 6; ++i) {
      const double s = i < 3 ? 1.0 : 1.0 / kDeg;
      std::printf(" %s %+.3f/%.3f", names[i], e[i] * s, res.sigma[static_cast<std::size_t>(i)] * s);
      worst[i] = std::max(worst[i], std::abs(e[i]) * s);
      const double z = std::abs(e[i]) / res.sigma[static_cast<std::size_t>(i)];
      for (int m = 0; m < 3; ++m) within[m] += z <= m + 1 ? 1.0 : 0.0;
      ++n_par;
    }
    std::printf("\n");
    worst_rms = std::max(worst_rms, res.eval.rms_px);
    worst_floor = std::max(worst_floor, res.eval.max_floor_mm);
  }
  std::printf(
      "\n%dx%d f=%.0f px, camera %.0f mm up, %d tags of %.0f mm, %d frame(s): %d/%d solved\n",
      a.width, a.height, a.f, a.z_mm, a.tags, a.tag_mm, a.frames, solved, a.trials);
  std::printf("largest |error|:");
  for (int i = 0; i < 6; ++i) std::printf(" %s %.3f", names[i], worst[i]);
  std::printf("\nlargest reprojection RMS %.3f px, largest floor residual %.2f mm\n", worst_rms,
              worst_floor);
  if (n_par > 0) {
    std::printf("|error| within 1/2/3 sigma: %.0f %% / %.0f %% / %.0f %% of %d parameter values\n",
                100.0 * within[0] / n_par, 100.0 * within[1] / n_par, 100.0 * within[2] / n_par,
                n_par);
  }
  return solved == a.trials ? 0 : 1;
}

// agvloc-desk calibrate ceiling | ceiling-check: a ceiling camera's pose in the site frame from
// tag36h11 tags at surveyed positions, and the check of the site file's pose against such
// frames (solver: calib_ceiling.hpp; procedure: docs/guide/site.md, "Calibrating the ceiling
// cameras"). Exit 0 success / pass, 1 no pose (named error) / check failed / write failure,
// 2 bad input.
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/core.hpp>
#include <set>
#include <sstream>

#include "agv/site/site_file.hpp"
#include "calib_ceiling.hpp"
#include "calib_cli.hpp"
#include "commands.hpp"
#include "desk_input.hpp"
#include "site_io.hpp"

namespace agv::desk {

namespace {

namespace fs = std::filesystem;
constexpr double kRadToDeg = 180.0 / kPi;

struct CeilingArgs {
  std::string site_path, camera_id, frames_dir, survey_path;
  double floor_tag_size_mm = 0.0;
};

struct CeilingInput {
  site::Site site;
  std::size_t camera = 0;
  std::map<std::uint32_t, ccal::SurveyedTag> survey;
  std::vector<ccal::TagSighting> sightings;
  int frames = 0;
};

void add_common_options(CLI::App& app, CeilingArgs* a) {
  app.add_option("--site", a->site_path, "Site file (docs/guide/site.md)")->required();
  app.add_option("--camera", a->camera_id, "The camera's id in the site file")->required();
  app.add_option("--frames", a->frames_dir,
                 "Folder of the camera's PNG frames (or a recording folder with frames/)")
      ->required();
  app.add_option("--survey", a->survey_path,
                 "Surveyed tags, CSV id,x_mm,y_mm,z_mm,yaw_deg,size_mm (yaw: the page's up)");
  app.add_option("--floor-tag-size-mm", a->floor_tag_size_mm,
                 "Instead of --survey: the site's floor-landmark map as tag36h11 tags of this "
                 "size on the floor")
      ->check(calib::finite_in(10.0, 5000.0));
}

// Prints "<cmd>: error <name>: <what>" and returns code.
int named_error(const char* cmd, const char* name, const std::string& what, int code) {
  std::fprintf(stderr, "agvloc-desk %s: error %s: %s\n", cmd, name, what.c_str());
  return code;
}

bool read_text(const std::string& path, std::string* text, std::string* error) {
  if (!input::regular_file(path, 8u << 20, error)) return false;
  std::ifstream f(path, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  if (!f && !f.eof()) {
    *error = path + ": cannot be read";
    return false;
  }
  *text = s.str();
  return true;
}

// Loads the site, finds the camera, reads the survey and every frame and detects the tags.
// Returns 0, or the exit code after printing the error.
int load_input(const char* cmd, const CeilingArgs& a, CeilingInput* in) {
  std::string err;
  if (!load_site(a.site_path, &in->site, &err)) {
    std::fprintf(stderr, "%s", err.c_str());
    return 2;
  }
  std::string ids;
  bool found = false;
  for (std::size_t i = 0; i < in->site.cameras.size(); ++i) {
    ids += (ids.empty() ? "" : ", ") + in->site.cameras[i].id;
    if (in->site.cameras[i].id == a.camera_id) {
      in->camera = i;
      found = true;
    }
  }
  if (!found) {
    return named_error(cmd, "unknown-camera",
                       "no camera '" + a.camera_id + "' in " + a.site_path +
                           " (cameras: " + (ids.empty() ? "none" : ids) + ")",
                       2);
  }
  if (a.survey_path.empty() == (a.floor_tag_size_mm <= 0.0)) {
    return named_error(cmd, "no-survey",
                       "give exactly one of --survey CSV and --floor-tag-size-mm SIZE", 2);
  }
  if (!a.survey_path.empty()) {
    std::string text;
    if (!read_text(a.survey_path, &text, &err)) return named_error(cmd, "bad-survey", err, 2);
    if (!ccal::parse_survey_csv(text, &in->survey, &err)) {
      return named_error(cmd, "bad-survey", a.survey_path + ": " + err, 2);
    }
  } else {
    if (in->site.floor_map.entries.empty()) {
      return named_error(cmd, "no-survey", a.site_path + " has no floor-landmark map", 2);
    }
    in->survey = ccal::survey_from_floor_map(in->site.floor_map, a.floor_tag_size_mm);
  }
  std::vector<fs::path> files;
  std::vector<std::string> skipped;
  if (!input::list_pngs(a.frames_dir, &files, &skipped, &err)) {
    return named_error(cmd, "unreadable-frames", err, 2);
  }
  std::error_code ec;
  if (files.empty() && fs::is_directory(fs::path(a.frames_dir) / "frames", ec) &&
      !input::list_pngs((fs::path(a.frames_dir) / "frames").string(), &files, &skipped, &err)) {
    return named_error(cmd, "unreadable-frames", err, 2);
  }
  if (files.empty()) {
    return named_error(cmd, "unreadable-frames", "no PNG frames in " + a.frames_dir, 2);
  }
  const CameraIntrinsics& k = in->site.cameras[in->camera].intrinsics;
  for (const fs::path& f : files) {
    cv::Mat img;
    if (!input::read_gray(f.string(), &img, &err)) {
      return named_error(cmd, "unreadable-frames", err, 2);
    }
    if (img.cols != k.width_px || img.rows != k.height_px) {
      return named_error(cmd, "unreadable-frames",
                         f.string() + " is " + std::to_string(img.cols) + "x" +
                             std::to_string(img.rows) + ", the camera's intrinsics are " +
                             std::to_string(k.width_px) + "x" + std::to_string(k.height_px),
                         2);
    }
    const auto found_tags = ccal::detect_tags(img, in->frames++);
    in->sightings.insert(in->sightings.end(), found_tags.begin(), found_tags.end());
  }
  return 0;
}

void print_pose(const ccal::CameraPose& p, const std::array<double, 6>* sigma) {
  const double v[6] = {p.x_mm,
                       p.y_mm,
                       p.z_mm,
                       p.roll_rad * kRadToDeg,
                       p.pitch_rad * kRadToDeg,
                       p.yaw_rad * kRadToDeg};
  const char* names[6] = {"x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"};
  for (int i = 0; i < 6; ++i) {
    std::printf("  %-10s %12.3f", names[i], v[i]);
    if (sigma) {
      const double s = (*sigma)[static_cast<std::size_t>(i)] * (i < 3 ? 1.0 : kRadToDeg);
      if (std::isfinite(s)) {
        std::printf("  sigma %.4f", s);
      } else {
        std::printf("  sigma not determined");
      }
    }
    std::printf("\n");
  }
}

void print_residuals(const ccal::Evaluation& ev) {
  std::printf("reprojection: RMS %.3f px, max %.3f px over %d corners\n", ev.rms_px, ev.max_px,
              ev.corners);
  std::printf("  tag  sightings   rms_px  floor_dx_mm  floor_dy_mm  floor_mm\n");
  for (const ccal::TagResidual& t : ev.tags) {
    std::printf("  %3u  %9d  %7.3f  %11.2f  %11.2f  %8.2f\n", t.id, t.sightings, t.rms_px,
                t.floor_dx_mm, t.floor_dy_mm, t.floor_mm);
  }
  std::printf("floor residual sigma per axis %.2f mm (what no pose explains: lens, survey)\n",
              ev.floor_sigma_mm);
}

void print_ignored(const std::vector<ccal::TagSighting>& sightings,
                   const std::map<std::uint32_t, ccal::SurveyedTag>& survey) {
  std::set<std::uint32_t> ids;
  for (const auto& s : sightings) {
    if (!survey.count(s.id)) ids.insert(s.id);
  }
  if (ids.empty()) return;
  std::printf("ignored (seen, not surveyed):");
  for (std::uint32_t id : ids) std::printf(" %u", id);
  std::printf("\n");
}

// The site file with the camera's new pose and its sigma (pose_sigma, which the overhead tracker
// adds to every fix of the camera), written next to it and renamed over it. A sigma that is not
// determined (a singular covariance) or beyond the site file's limits is not written: such a
// pose is not one to track with.
bool write_pose(const std::string& path, site::Site site, std::size_t camera, const ccal::Result& r,
                std::string* error) {
  site::CeilingCamera& cam = site.cameras[camera];
  ccal::set_pose(r.pose, &cam);
  for (std::size_t i = 0; i < 6; ++i) {
    const bool angle = i >= 3;
    const double limit = angle ? 10.0 / kRadToDeg : 1000.0;  // docs/guide/site.md, pose_sigma
    if (!(r.sigma[i] >= 0.0 && r.sigma[i] <= limit)) {
      *error = "the pose's sigma is not determined or too large (" +
               std::to_string(angle ? r.sigma[i] * kRadToDeg : r.sigma[i]) +
               (angle ? " deg" : " mm") + "): not written";
      return false;
    }
    (angle ? cam.angle_sigma_rad[i - 3] : cam.position_sigma_mm[i]) = r.sigma[i];
  }
  cam.pose_correlation = r.correlation;
  if (!(r.eval.floor_sigma_mm >= 0.0 && r.eval.floor_sigma_mm <= 1000.0)) {
    *error = "the tags' floor residual is not determined or too large: not written";
    return false;
  }
  cam.floor_sigma_mm = r.eval.floor_sigma_mm;
  const std::string tmp = path + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    f << site::write_site(site);
    if (!f) {
      *error = tmp + ": cannot be written";
      return false;
    }
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    *error = path + ": cannot be replaced: " + ec.message();
    return false;
  }
  return true;
}

}  // namespace

int calibrate_ceiling(int argc, char** argv) {
  CLI::App app{
      "A ceiling camera's pose in the site frame from frames of tag36h11 tags at surveyed "
      "positions (the intrinsics come from the site file). Exit 0 solved, 1 no pose (named "
      "error) or write failure, 2 bad input (docs/guide/site.md)",
      "agvloc-desk calibrate ceiling"};
  CeilingArgs a;
  ccal::Options opt;
  bool write = false, start_from_site = false;
  add_common_options(app, &a);
  app.add_option("--robust-px", opt.robust_px, "Huber loss scale on the corner residual (px)")
      ->check(calib::finite_in(0.05, 100.0))
      ->capture_default_str();
  app.add_flag("--start-from-site", start_from_site,
               "Start the refinement from the site file's pose instead of PnP");
  app.add_flag("--write", write, "Write the solved pose into the site file's camera entry");
  CLI11_PARSE(app, argc, argv);
  const char* cmd = "calibrate ceiling";
  CeilingInput in;
  if (const int rc = load_input(cmd, a, &in); rc != 0) return rc;
  const site::CeilingCamera& cam = in.site.cameras[in.camera];
  const ccal::CameraPose site_pose = ccal::pose_of(cam);
  if (start_from_site) opt.initial = &site_pose;
  const ccal::Result r = ccal::solve_camera_pose(cam.intrinsics, in.survey, in.sightings, opt);
  print_ignored(in.sightings, in.survey);
  if (r.error != ccal::Error::kNone) {
    return named_error(cmd, ccal::to_string(r.error), r.message, 1);
  }
  for (std::uint32_t id : r.rejected_ids) {
    for (const ccal::TagResidual& t : r.eval.tags) {
      if (t.id != id) continue;
      std::printf(
          "rejected tag %u: RMS %.2f px, floor residual %.1f mm against the others' pose "
          "(surveyed wrong, or moved?)\n",
          id, t.rms_px, t.floor_mm);
    }
  }
  std::printf("camera %s: %d tags, %d corners in %d frames\n", cam.id.c_str(), r.tags_used,
              r.corners_used, in.frames);
  std::printf("pose (site frame; sigma from the covariance, corner residual sigma %.3f px):\n",
              r.residual_sigma_px);
  print_pose(r.pose, &r.sigma);
  print_residuals(r.eval);
  if (write) {
    std::string err;
    if (!write_pose(a.site_path, in.site, in.camera, r, &err)) {
      std::fprintf(stderr, "agvloc-desk %s: %s\n", cmd, err.c_str());
      return 1;
    }
    std::printf("wrote the pose of %s into %s\n", cam.id.c_str(), a.site_path.c_str());
  }
  return 0;
}

int calibrate_ceiling_check(int argc, char** argv) {
  CLI::App app{
      "Check a ceiling camera's pose in the site file against frames of tag36h11 tags at "
      "surveyed positions: reprojection and floor-position residuals. Exit 0 pass, 1 fail, "
      "2 bad input (docs/guide/site.md)",
      "agvloc-desk calibrate ceiling-check"};
  CeilingArgs a;
  double max_rms_px = 1.0, max_floor_mm = 5.0;
  add_common_options(app, &a);
  app.add_option("--max-rms-px", max_rms_px, "Pass: corner reprojection RMS at most this (px)")
      ->check(calib::finite_in(0.01, 100.0))
      ->capture_default_str();
  app.add_option("--max-floor-mm", max_floor_mm,
                 "Pass: every tag's floor-position residual at most this (mm)")
      ->check(calib::finite_in(0.1, 10000.0))
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  const char* cmd = "calibrate ceiling-check";
  CeilingInput in;
  if (const int rc = load_input(cmd, a, &in); rc != 0) return rc;
  const site::CeilingCamera& cam = in.site.cameras[in.camera];
  const ccal::Evaluation ev =
      ccal::evaluate(cam.intrinsics, in.survey, in.sightings, ccal::pose_of(cam));
  print_ignored(in.sightings, in.survey);
  if (ev.tags.size() < 2) {
    return named_error(
        cmd, "too-few-tags",
        std::to_string(ev.tags.size()) + " surveyed tag(s) seen; the check needs at least 2", 1);
  }
  std::printf("camera %s, the site file's pose:\n", cam.id.c_str());
  print_pose(ccal::pose_of(cam), nullptr);
  print_residuals(ev);
  const bool rms_ok = ev.rms_px <= max_rms_px;
  const bool floor_ok = ev.max_floor_mm <= max_floor_mm;  // false for NaN (a missed plane)
  std::printf("reprojection RMS %.3f px (limit %.3f): %s\n", ev.rms_px, max_rms_px,
              rms_ok ? "ok" : "FAIL");
  std::printf("largest floor-position residual %.2f mm (limit %.2f): %s\n", ev.max_floor_mm,
              max_floor_mm, floor_ok ? "ok" : "FAIL");
  std::printf("%s\n", rms_ok && floor_ok ? "PASS" : "FAIL");
  return rms_ok && floor_ok ? 0 : 1;
}

}  // namespace agv::desk

#include "calib_check.hpp"

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <map>
#include <opencv2/core.hpp>
#include <sstream>

#include "agv/config/keys.hpp"

namespace agv::desk::calib {

namespace {

std::string fmt(const char* f, ...) __attribute__((format(printf, 1, 2)));
std::string fmt(const char* f, ...) {
  char buf[1024];
  va_list ap;
  va_start(ap, f);
  std::vsnprintf(buf, sizeof buf, f, ap);
  va_end(ap);
  return buf;
}

Vec2 rotate(Vec2 p, double a) {
  const double c = std::cos(a), s = std::sin(a);
  return {c * p.x - s * p.y, s * p.x + c * p.y};
}

}  // namespace

const char* to_string(Cause c) {
  switch (c) {
    case Cause::kPose:
      return "pose";
    case Cause::kYaw:
      return "mounting yaw";
    case Cause::kHeight:
      return "height";
    case Cause::kOffset:
      return "mounting offset";
    case Cause::kDistortion:
      return "distortion/intrinsics";
    case Cause::kFocus:
      return "focus/blur";
  }
  return "?";
}

bool CheckResult::within_tolerance() const {
  return std::all_of(findings.begin(), findings.end(), [](const Finding& f) { return f.ok; });
}

namespace {

// What the frames of one placement gave: the fixes' poses and the sums for the means.
struct PlacementFrames {
  std::vector<Pose2> poses;
  double sum_out = 0, sum_in = 0, sum_res = 0;
  int n_size = 0;
  std::string first_failure;  // the first frame without a fix, with the vision status
};

// Runs the vision stage on every frame of the placement (pr->frames, frames_total, landmark_id).
// False with *error on a frame that cannot be loaded, is empty or of the wrong size, or shows
// another landmark than the earlier frames.
bool run_frames(vision::LandmarkLocalizer& loc, const CameraModel& camera, const PlacementInput& in,
                const std::string& where, PlacementResult* pr, PlacementFrames* got,
                std::string* error) {
  pr->frames_total = static_cast<int>(in.frames.size());
  for (const FrameInput& f : in.frames) {
    FrameResult fr;
    fr.name = f.name;
    cv::Mat loaded;
    const cv::Mat* image = f.image;
    if (!image && f.load) {
      std::string e;
      if (!f.load(&loaded, &e)) {
        *error = e;
        return false;
      }
      image = &loaded;
    }
    if (!image || image->empty()) {
      *error = f.name + ": empty image";
      return false;
    }
    const vision::FixStatus st = loc.process(*image, &fr.fix);
    if (st == vision::FixStatus::kBadInput) {
      *error = fmt("%s: %dx%d image (%d channels) but the configured camera is %dx%d 8-bit gray",
                   f.name.c_str(), image->cols, image->rows, image->channels(),
                   camera.intrinsics.width_px, camera.intrinsics.height_px);
      return false;
    }
    if (st == vision::FixStatus::kOk) {
      if (!got->poses.empty() && fr.fix.landmark_id != pr->landmark_id) {
        *error =
            fmt("%s: %s shows landmark %u, earlier frames landmark %u (one landmark per "
                "placement)",
                where.c_str(), f.name.c_str(), fr.fix.landmark_id, pr->landmark_id);
        return false;
      }
      pr->landmark_id = fr.fix.landmark_id;
      got->poses.push_back(fr.fix.landmark_in_vehicle);
      got->sum_res += fr.fix.residual_rms_mm;
      if (fr.fix.outer_half_mm > 0 && fr.fix.inner_half_mm > 0) {
        got->sum_out += fr.fix.outer_half_mm;
        got->sum_in += fr.fix.inner_half_mm;
        ++got->n_size;
      }
    } else if (got->first_failure.empty()) {
      got->first_failure = f.name + ": " + vision::to_string(st);
    }
    pr->frames.push_back(std::move(fr));
  }
  return true;
}

// The taped pose as V<-L. False with *error when the vehicle's world pose was taped and the
// landmark the frames show is not in the map.
bool taped_landmark(const PlacementInput& in, const LandmarkMap* map, const std::string& where,
                    PlacementResult* pr, std::string* error) {
  if (in.taped_is_vehicle_in_world) {
    const LandmarkMapEntry* e = map ? map->find(pr->landmark_id) : nullptr;
    if (!e) {
      *error = fmt("%s: the vehicle's world pose was taped, but landmark %u is not in %s",
                   where.c_str(), pr->landmark_id, map ? "the map" : "a map (none given)");
      return false;
    }
    pr->taped_landmark_in_vehicle = compose(inverse(in.taped), e->pose);
  } else {
    pr->taped_landmark_in_vehicle = in.taped;
  }
  return true;
}

// The placement's mean pose and spread, its deviation from the tape, the measured size and the
// mounting offset and height it implies.
void evaluate_placement(const PlacementFrames& got, const CameraModel& camera, double printed_mid,
                        PlacementResult* pr) {
  const std::vector<Pose2>& poses = got.poses;
  const double h_c = camera.mount.height_mm;
  const Vec2 o_c{camera.mount.offset_x_mm, camera.mount.offset_y_mm};
  // Mean pose (heading as the mean of the wrapped differences to the first frame).
  const double n = static_cast<double>(poses.size());
  double mx = 0, my = 0, mth = 0;
  for (const Pose2& p : poses) {
    mx += p.x_mm / n;
    my += p.y_mm / n;
    mth += wrap_angle_rad(p.theta_rad - poses[0].theta_rad) / n;
  }
  pr->measured_landmark_in_vehicle = {mx, my, wrap_angle_rad(poses[0].theta_rad + mth)};
  if (poses.size() > 1) {
    double vx = 0, vy = 0, vt = 0;
    for (const Pose2& p : poses) {
      vx += (p.x_mm - mx) * (p.x_mm - mx);
      vy += (p.y_mm - my) * (p.y_mm - my);
      const double dt = wrap_angle_rad(p.theta_rad - pr->measured_landmark_in_vehicle.theta_rad);
      vt += dt * dt;
    }
    pr->spread_mm = std::sqrt((vx + vy) / (n - 1));
    pr->spread_deg = rad_to_deg(std::sqrt(vt / (n - 1)));
  }
  pr->residual_rms_mm = got.sum_res / n;
  const Pose2& m = pr->measured_landmark_in_vehicle;
  const Pose2& t = pr->taped_landmark_in_vehicle;
  pr->dx_mm = m.x_mm - t.x_mm;
  pr->dy_mm = m.y_mm - t.y_mm;
  const double dpsi = wrap_angle_rad(m.theta_rad - t.theta_rad);
  pr->dheading_deg = rad_to_deg(dpsi);
  double s = 1.0;
  if (got.n_size > 0) {
    const double ho = got.sum_out / got.n_size, hi = got.sum_in / got.n_size;
    pr->outer_side_mm = 2 * ho;
    pr->border_width_mm = ho - hi;
    pr->scale = (ho + hi) / printed_mid;
    pr->implied_height_mm = h_c / pr->scale;
    s = pr->scale;
  }
  // o_t = p - R(-dpsi) (p' - o_c) / s.
  const Vec2 back = rotate({m.x_mm - o_c.x, m.y_mm - o_c.y}, -dpsi);
  pr->implied_offset_mm = {t.x_mm - back.x / s, t.y_mm - back.y / s};
}

// One placement: its frames through the vision stage, then the comparison with the tape.
bool measure_placement(vision::LandmarkLocalizer& loc, const CameraModel& camera,
                       const vision::VisionConfig& vision_config, const LandmarkMap* map,
                       double printed_mid, const PlacementInput& in, const std::string& where,
                       PlacementResult* pr, std::string* error) {
  if (in.frames.empty()) {
    *error = where + ": no frames";
    return false;
  }
  PlacementFrames got;
  if (!run_frames(loc, camera, in, where, pr, &got, error)) return false;
  pr->frames_ok = static_cast<int>(got.poses.size());
  if (got.poses.empty()) {
    *error = where + ": no landmark fix in any of its " + std::to_string(pr->frames_total) +
             " frame(s) (first: " + got.first_failure +
             "); is the whole landmark in the image, in focus, lit, its id in the map, and " +
             "landmark.family (" + landmark_family_name(vision_config.family) +
             ") the family printed?";
    return false;
  }
  if (!taped_landmark(in, map, where, pr, error)) return false;
  evaluate_placement(got, camera, printed_mid, pr);
  return true;
}

// The mean over the placements: heading difference, implied offset, and the sum and count of the
// measured scales.
struct Combined {
  double dpsi_deg = 0, ox = 0, oy = 0, sc = 0;
  int nsc = 0;
};

// Combines the placements into the recovered mounting (out->yaw_deg, offsets, height).
Combined combine_placements(const CameraModel& camera, CheckResult* out) {
  const double h_c = camera.mount.height_mm;
  const auto& P = out->placements;
  const double np = static_cast<double>(P.size());
  Combined c;
  for (const auto& p : P) {
    c.dpsi_deg += p.dheading_deg / np;
    c.ox += p.implied_offset_mm.x / np;
    c.oy += p.implied_offset_mm.y / np;
    if (p.scale > 0) {
      c.sc += p.scale;
      ++c.nsc;
    }
  }
  out->yaw_deg = wrap_angle_deg(rad_to_deg(camera.mount.yaw_rad) - c.dpsi_deg);
  out->offset_x_mm = c.ox;
  out->offset_y_mm = c.oy;
  out->height_known = c.nsc > 0;
  out->height_mm = c.nsc > 0 ? h_c / (c.sc / c.nsc) : h_c;
  return c;
}

void add_finding(CheckResult* out, Cause c, double value, double limit, std::string msg) {
  out->findings.push_back({c, std::abs(value) <= limit, value, limit, std::move(msg)});
}

// 1. The raw comparison with the tape, per placement.
void pose_findings(const Tolerances& tol, CheckResult* out) {
  const auto& P = out->placements;
  for (size_t i = 0; i < P.size(); ++i) {
    const auto& p = P[i];
    const double d = std::hypot(p.dx_mm, p.dy_mm);
    add_finding(
        out, Cause::kPose, d, tol.position_mm,
        fmt("placement %zu: landmark %u measured %.2f mm from the taped position (dx %+.2f, "
            "dy %+.2f mm in the vehicle frame)",
            i + 1, p.landmark_id, d, p.dx_mm, p.dy_mm));
  }
}

// 2.-4. Heading -> mounting yaw, size -> height, what is left -> offset.
void mounting_findings(const CameraModel& camera, const LandmarkGeometry& geom, const Combined& c,
                       const Tolerances& tol, CheckResult* out) {
  const auto& P = out->placements;
  const double h_c = camera.mount.height_mm;
  const Vec2 o_c{camera.mount.offset_x_mm, camera.mount.offset_y_mm};
  // 2. Heading -> mounting yaw.
  add_finding(
      out, Cause::kYaw, c.dpsi_deg, tol.heading_deg,
      fmt("heading %+.3f deg from the tape -> mounting yaw: mounting.yaw_deg %.3f (configured "
          "%.3f)",
          c.dpsi_deg, out->yaw_deg, rad_to_deg(camera.mount.yaw_rad)));
  // 3. Size -> height.
  if (out->height_known) {
    const double s = c.sc / c.nsc;
    double ow = 0, bw = 0;
    for (const auto& p : P) {
      if (p.scale > 0) {
        ow += p.outer_side_mm / c.nsc;
        bw += p.border_width_mm / c.nsc;
      }
    }
    add_finding(
        out, Cause::kHeight, out->height_mm - h_c, tol.height_mm,
        fmt("landmark measured %.3f %% too %s (outer side %.3f mm, border %.3f mm; printed %.3f "
            "/ %.3f mm) -> height: mounting.height_mm %.2f (configured %.2f) -- or fx, or the "
            "print is not at 100 %% (measure it with calipers: --printed-size-mm)",
            std::abs(s - 1) * 100, s >= 1 ? "large" : "small", ow, bw, geom.size_mm,
            geom.border_width_mm(), out->height_mm, h_c));
  } else {
    add_finding(
        out, Cause::kHeight, 0, tol.height_mm,
        "landmark size not measured (no border axis with both sides in the image): height not "
        "checked; put the whole landmark in the image");
  }
  // 4. What is left -> offset.
  const double doff = std::hypot(c.ox - o_c.x, c.oy - o_c.y);
  add_finding(out, Cause::kOffset, doff, tol.position_mm,
              fmt("after yaw and height, a constant offset of %.2f mm -> mounting offset: "
                  "mounting.offset_x_mm %.2f, offset_y_mm %.2f (configured %.2f, %.2f)",
                  doff, c.ox, c.oy, o_c.x, o_c.y));
}

// 5. Position dependence -> distortion / intrinsics. True when a distortion finding failed.
bool distortion_findings(const Combined& c, const Tolerances& tol, CheckResult* out) {
  const auto& P = out->placements;
  if (P.size() <= 1) {
    add_finding(out, Cause::kDistortion, 0, 0,
                "not checked with one placement: repeat with the landmark near two opposite image "
                "corners (--placements) to separate distortion from height and offset");
    return false;
  }
  double worst = 0, smin = 1e300, smax = -1e300;
  for (const auto& p : P) {
    worst = std::max(worst, std::hypot(p.implied_offset_mm.x - c.ox, p.implied_offset_mm.y - c.oy));
    if (p.scale > 0) {
      smin = std::min(smin, p.implied_height_mm);
      smax = std::max(smax, p.implied_height_mm);
    }
  }
  add_finding(
      out, Cause::kDistortion, worst, tol.position_mm,
      fmt("the offset implied by the %zu placements differs by up to %.2f mm between places in "
          "the image -> %s",
          P.size(), worst,
          worst > tol.position_mm ? "position-dependent error: distortion/intrinsics "
                                    "(recalibrate: agvloc-desk calibrate intrinsics)"
                                  : "not position-dependent"));
  if (smax >= smin) {
    add_finding(
        out, Cause::kDistortion, smax - smin, tol.height_mm,
        fmt("the height implied by the landmark size varies by %.2f mm between places in the "
            "image -> %s",
            smax - smin,
            smax - smin > tol.height_mm
                ? "distortion/intrinsics (a tilted camera does this too: mounting roll/pitch)"
                : "uniform scale"));
  }
  return std::any_of(out->findings.begin(), out->findings.end(),
                     [](const Finding& f) { return f.cause == Cause::kDistortion && !f.ok; });
}

// 6. Edge quality and repeatability -> focus / blur / light (or distortion, which bends the
// edges too: attributed to it when the placements disagree).
void focus_findings(bool distortion, const Tolerances& tol, CheckResult* out) {
  const auto& P = out->placements;
  double res = 0;
  for (const auto& p : P) res = std::max(res, p.residual_rms_mm);
  add_finding(out, distortion ? Cause::kDistortion : Cause::kFocus, res, tol.residual_mm,
              fmt("edge points lie %.3f mm rms from the fitted square (worst placement) -> %s", res,
                  res <= tol.residual_mm ? "sharp, straight edges"
                  : distortion           ? "edges bent by the uncorrected distortion"
                               : "blurred or noisy edges: focus, light/gain, dirt on the print "
                                 "(or distortion: compare placements)"));
  for (size_t i = 0; i < P.size(); ++i) {
    const auto& p = P[i];
    if (p.frames_ok < p.frames_total) {
      std::string first;
      for (const auto& f : p.frames) {
        if (f.fix.status != vision::FixStatus::kOk) {
          first = f.name + ": " + vision::to_string(f.fix.status);
          break;
        }
      }
      add_finding(out, Cause::kFocus, p.frames_total - p.frames_ok, 0,
                  fmt("placement %zu: %d of %d frames gave no fix (first %s) -> focus, blur, light",
                      i + 1, p.frames_total - p.frames_ok, p.frames_total, first.c_str()));
    }
    if (p.frames_ok > 1) {
      add_finding(
          out, Cause::kFocus, p.spread_mm, tol.spread_mm,
          fmt("placement %zu: position spread %.3f mm, heading %.4f deg (std over %d frames) -> "
              "%s",
              i + 1, p.spread_mm, p.spread_deg, p.frames_ok,
              p.spread_mm > tol.spread_mm ? "not repeatable: vibration, the vehicle or landmark "
                                            "moved, or focus/blur"
                                          : "repeatable"));
    }
  }
}

}  // namespace

bool run_check(const CameraModel& camera, const vision::VisionConfig& vision_config,
               double printed_size_mm, const LandmarkMap* map,
               const std::vector<PlacementInput>& placements, const Tolerances& tol,
               CheckResult* out, std::string* error) {
  *out = CheckResult{};
  // The configuration's range for the landmark size (keys.hpp): outside it the templates and
  // windows of the vision stage are not meaningful (an infinite size reached the corner
  // template as INT_MIN pixels).
  const config::Key* size_key = config::find_key("landmark.size_mm");
  if (!(printed_size_mm >= size_key->lo && printed_size_mm <= size_key->hi)) {
    *error = fmt("printed landmark size %g mm: must be in %g..%g mm (landmark.size_mm)",
                 printed_size_mm, size_key->lo, size_key->hi);
    return false;
  }
  if (placements.empty()) {
    *error = "no placement (taped pose with frames) given";
    return false;
  }
  LandmarkGeometry geom;
  geom.size_mm = printed_size_mm;
  // Desk work takes every pixel row: the vehicle's edge_row_step trades a little precision for
  // cost per frame, which a parked check on a few frames does not need.
  vision::VisionConfig every_row = vision_config;
  every_row.edge_row_step = 1;
  vision::LandmarkLocalizer loc(every_row, camera, geom, map);
  const double printed_mid = geom.outer_half_mm() + geom.inner_half_mm();
  for (size_t pi = 0; pi < placements.size(); ++pi) {
    const std::string where = "placement " + std::to_string(pi + 1);
    PlacementResult pr;
    if (!measure_placement(loc, camera, vision_config, map, printed_mid, placements[pi], where, &pr,
                           error)) {
      return false;
    }
    out->placements.push_back(std::move(pr));
  }
  const Combined c = combine_placements(camera, out);
  pose_findings(tol, out);
  mounting_findings(camera, geom, c, tol, out);
  const bool distortion = distortion_findings(c, tol, out);
  focus_findings(distortion, tol, out);
  out->lens_suspect = distortion;
  return true;
}

bool parse_pose(const std::string& text, Pose2* out) {
  double x = 0, y = 0, h = 0;
  char tail = 0;
  if (std::sscanf(text.c_str(), "%lf,%lf,%lf%c", &x, &y, &h, &tail) != 3) return false;
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(h)) return false;
  *out = {x, y, deg_to_rad(h)};
  return true;
}

bool parse_placements_csv(const std::string& text, const std::string& name,
                          std::vector<PlacementRows>* out, std::string* error) {
  out->clear();
  std::istringstream is(text);
  std::string line;
  int ln = 0;
  std::map<std::string, size_t> index;
  bool header = false;
  while (std::getline(is, line)) {
    ++ln;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    // A NUL would cut the frame path where the file is opened and the pose where it is parsed
    // (fuzz_placements found "c\0\01.png" read as frame "c").
    if (line.find('\0') != std::string::npos) {
      *error = name + ":" + std::to_string(ln) + ": NUL byte (not a text file?)";
      return false;
    }
    if (!header) {
      if (line != "frame,x_mm,y_mm,heading_deg") {
        *error = name + ":" + std::to_string(ln) + ": header must be frame,x_mm,y_mm,heading_deg";
        return false;
      }
      header = true;
      continue;
    }
    const auto comma = line.find(',');
    Pose2 p;
    if (comma == std::string::npos || comma == 0 || !parse_pose(line.substr(comma + 1), &p)) {
      *error = name + ":" + std::to_string(ln) + ": expected FRAME,X,Y,DEG";
      return false;
    }
    // A lone CR (old Mac line ends) or another control character in a path is a damaged file,
    // not a file name to open (fuzz_placements; frames.csv refuses them the same way).
    if (std::any_of(line.begin(), line.begin() + static_cast<std::ptrdiff_t>(comma),
                    [](char ch) { return static_cast<unsigned char>(ch) < 0x20 || ch == 0x7f; })) {
      *error = name + ":" + std::to_string(ln) + ": control character in the frame path";
      return false;
    }
    const std::string key = line.substr(comma + 1);
    auto it = index.find(key);
    if (it == index.end()) {
      it = index.emplace(key, out->size()).first;
      out->push_back({p, {}});
    }
    (*out)[it->second].frames.push_back(line.substr(0, comma));
  }
  if (out->empty()) {
    *error = name + ": no rows";
    return false;
  }
  return true;
}

std::string format_report(const CameraModel& camera, const CheckResult& r) {
  std::string s;
  s += "placement  landmark  frames  taped x,y,deg               measured x,y,deg            "
       "dx_mm   dy_mm   dh_deg   outer_mm  border_mm  spread_mm  resid_mm\n";
  for (size_t i = 0; i < r.placements.size(); ++i) {
    const auto& p = r.placements[i];
    const auto& t = p.taped_landmark_in_vehicle;
    const auto& m = p.measured_landmark_in_vehicle;
    s +=
        fmt("%9zu  %8u  %3d/%-3d %8.2f,%8.2f,%7.2f  %8.3f,%8.3f,%8.3f  %+6.2f  %+6.2f  %+7.3f  "
            "%8.3f  %9.3f  %9.3f  %8.3f\n",
            i + 1, p.landmark_id, p.frames_ok, p.frames_total, t.x_mm, t.y_mm,
            rad_to_deg(t.theta_rad), m.x_mm, m.y_mm, rad_to_deg(m.theta_rad), p.dx_mm, p.dy_mm,
            p.dheading_deg, p.outer_side_mm, p.border_width_mm, p.spread_mm, p.residual_rms_mm);
  }
  s += "\nfindings:\n";
  for (const auto& f : r.findings) {
    s += fmt("  [%s] %-21s %s\n", f.ok ? " ok " : "FAIL", to_string(f.cause), f.message.c_str());
  }
  s += "\nmounting implied by the check (configuration keys, docs/guide/config.md):\n";
  s += fmt("mounting:\n  offset_x_mm: %.2f\n  offset_y_mm: %.2f\n  yaw_deg: %.3f\n", r.offset_x_mm,
           r.offset_y_mm, r.yaw_deg);
  if (r.height_known) {
    s += fmt("  height_mm: %.2f\n", r.height_mm);
  } else {
    s += fmt("  # height_mm: not measured (configured %.2f)\n", camera.mount.height_mm);
  }
  if (r.lens_suspect) {
    s += "  # the placements disagree: these values assume a correct lens model; recalibrate the\n"
         "  # intrinsics first (agvloc-desk calibrate intrinsics), then repeat the check\n";
  }
  s += r.within_tolerance() ? "\nresult: within tolerance\n"
                            : "\nresult: OUT OF TOLERANCE (see FAIL lines)\n";
  return s;
}

}  // namespace agv::desk::calib

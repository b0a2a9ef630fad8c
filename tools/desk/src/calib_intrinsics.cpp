// Intrinsics calibration (calib_intrinsics.hpp): which views calibrate, OpenCV's calibrateCamera
// and the checks of its result. The board: calib_intrinsics_board.cpp; detection:
// calib_intrinsics_detect.cpp; texts and pictures: calib_intrinsics_report.cpp.
#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>

#include "calib_intrinsics_internal.hpp"
#include "key_ranges.hpp"

namespace agv::desk::calib {

using detail::fmt;

namespace {

// Two views whose common corners all lie within this many pixels of each other show the board
// in the same pose (a still camera over a still board: corner noise is about 0.05 px).
constexpr double kSameViewPx = 1.0;
// An overall RMS above this is not blur or a bent board but corners matched to the wrong board
// points (a wrong board description).
constexpr double kWrongBoardRmsPx = 5.0;

// The used view (indices `used` into views) showing the board where `v` does, or null.
const View* same_view(const std::vector<View>& views, const std::vector<size_t>& used,
                      const View& v) {
  for (size_t j : used) {
    const View& u = views[j];
    size_t common = 0;
    double worst = 0.0;
    for (size_t a = 0; a < v.ids.size(); ++a) {
      for (size_t b = 0; b < u.ids.size(); ++b) {
        if (v.ids[a] != u.ids[b]) continue;
        ++common;
        worst =
            std::max(worst, static_cast<double>(cv::norm(v.image_points[a] - u.image_points[b])));
        break;
      }
    }
    // Most corners in common (a partly hidden board still counts as the same pose).
    if (2 * common >= std::max(v.ids.size(), u.ids.size()) && worst <= kSameViewPx) return &u;
  }
  return nullptr;
}

// The views calibrateCamera gets, in the order of Result::views.
struct Selection {
  std::vector<std::vector<cv::Point3f>> obj;
  std::vector<std::vector<cv::Point2f>> img;
  std::vector<size_t> used;  // indices into Result::views
  cv::Size size;
};

// Marks the detected views with enough corners, one per board pose, as used. False with
// r->error (and no view used) when the views differ in size.
bool select_views(const Options& o, Result* r, Selection* sel) {
  auto& obj = sel->obj;
  auto& img = sel->img;
  auto& used = sel->used;
  cv::Size& size = sel->size;
  for (size_t i = 0; i < r->views.size(); ++i) {
    View& v = r->views[i];
    v.used = false;
    if (!v.detected || !v.reject_reason.empty()) continue;
    if (static_cast<int>(v.image_points.size()) < std::max(4, o.min_corners)) {
      v.reject_reason = "only " + std::to_string(v.image_points.size()) + " corners (< " +
                        std::to_string(std::max(4, o.min_corners)) + ", --min-corners)";
      continue;
    }
    if (size.area() == 0) size = v.size;
    if (v.size != size) {
      // No view is used then: the table must not say "used" beside "usable 0".
      int same = 0, other = 0;
      for (const View& w : r->views) {
        if (!w.detected || !w.reject_reason.empty()) continue;
        (w.size == size ? same : other) += 1;
      }
      for (View& w : r->views) w.used = false;
      r->error = "the views differ in size: " + std::to_string(same) + " at " +
                 std::to_string(size.width) + "x" + std::to_string(size.height) + ", " +
                 std::to_string(other) + " at other sizes (first: " + v.name + " " +
                 std::to_string(v.size.width) + "x" + std::to_string(v.size.height) +
                 "); calibrate one resolution at a time; no intrinsics written";
      return false;
    }
    if (const View* twin = same_view(r->views, used, v)) {
      // A repeated view adds no geometry but weighs as a new one: 30 copies of one view gave a
      // "result" 26 % off with a tiny RMS. Counted once.
      v.reject_reason = "same board pose as " + twin->name + " (corners within " +
                        fmt("%.1f", kSameViewPx) + " px): move or tilt the board between views";
      continue;
    }
    v.used = true;
    obj.push_back(v.object_points);
    img.push_back(v.image_points);
    used.push_back(i);
  }
  return true;
}

// The error for fewer usable views than o.min_views, naming the first rejected ones.
std::string too_few_views_error(const Result& r, const Options& o) {
  std::string why;
  int shown = 0;
  for (const auto& v : r.views) {
    if (v.used) continue;
    if (shown++ < 8) why += "\n  " + v.name + ": " + v.reject_reason;
  }
  if (shown > 8) why += "\n  ... and " + std::to_string(shown - 8) + " more";
  return "only " + std::to_string(r.usable) + " usable view(s) of " +
         std::to_string(r.views.size()) + ", at least " + std::to_string(o.min_views) +
         " needed (--min-views); no intrinsics written" +
         (why.empty() ? std::string() : "; rejected:" + why);
}

// calibrateCamera over the selected views: fills the RMS, intrinsics, standard deviations, the
// per-view RMS and the corner count; returns the distortion coefficients as OpenCV gave them.
cv::Mat solve_camera(const Selection& sel, const Options& o, Result* r) {
  int flags = 0;
  if (o.fix_k3) flags |= cv::CALIB_FIX_K3;
  if (o.zero_tangent) flags |= cv::CALIB_ZERO_TANGENT_DIST;
  if (o.fix_aspect) flags |= cv::CALIB_FIX_ASPECT_RATIO;
  if (o.fix_principal_point) flags |= cv::CALIB_FIX_PRINCIPAL_POINT;
  cv::Mat k = cv::Mat::eye(3, 3, CV_64F), d = cv::Mat::zeros(5, 1, CV_64F);
  std::vector<cv::Mat> rvecs, tvecs;
  cv::Mat sd_intr, sd_extr, per_view;
  r->rms_px = cv::calibrateCamera(
      sel.obj, sel.img, sel.size, k, d, rvecs, tvecs, sd_intr, sd_extr, per_view, flags,
      cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, DBL_EPSILON));
  auto& in = r->intrinsics;
  in.width_px = sel.size.width;
  in.height_px = sel.size.height;
  in.fx = k.at<double>(0, 0);
  in.fy = k.at<double>(1, 1);
  in.cx = k.at<double>(0, 2);
  in.cy = k.at<double>(1, 2);
  in.k1 = d.at<double>(0);
  in.k2 = d.at<double>(1);
  in.p1 = d.at<double>(2);
  in.p2 = d.at<double>(3);
  in.k3 = d.at<double>(4);
  for (int i = 0; i < 9 && i < sd_intr.rows; ++i) {
    r->stddev[static_cast<size_t>(i)] = sd_intr.at<double>(i);
  }
  for (size_t j = 0; j < sel.used.size(); ++j) {
    r->views[sel.used[j]].rms_px = per_view.at<double>(static_cast<int>(j));
    r->corners += static_cast<int>(r->views[sel.used[j]].image_points.size());
  }
  return d;
}

// Pixels of error, not tenths: the corners were matched to the wrong board points. That is
// what an 11 x 8 board description of a 9 x 7 print gives (117 px); named with any error.
std::string wrong_board_hint(const Result& r, const BoardSpec& spec) {
  std::string board_hint;
  if (r.rms_px > kWrongBoardRmsPx) {
    board_hint = "; an RMS of " + fmt("%.1f", r.rms_px) +
                 " px means the corners do not fit the board described: do --board, "
                 "--squares-x/--squares-y (" +
                 std::to_string(spec.squares_x) + " x " + std::to_string(spec.squares_y) +
                 "), --square-mm, --marker-mm and --dictionary match the printed board?";
  }
  return board_hint;
}

// Starts the warnings with the coverage's and names the views whose RMS stands out; returns the
// used views by RMS, worst first.
std::vector<size_t> warn_view_outliers(const std::vector<size_t>& used, const Options& o,
                                       Result* r) {
  r->warnings = r->coverage.warnings;
  std::vector<double> rms;
  for (size_t j : used) rms.push_back(r->views[j].rms_px);
  std::vector<double> sorted = rms;
  std::sort(sorted.begin(), sorted.end());
  const double median = sorted[sorted.size() / 2];
  std::vector<size_t> by_rms = used;
  std::sort(by_rms.begin(), by_rms.end(),
            [&](size_t a, size_t b) { return r->views[a].rms_px > r->views[b].rms_px; });
  for (size_t j : by_rms) {
    if (r->views[j].rms_px > o.view_outlier_factor * median && r->views[j].rms_px > 0.1) {
      r->warnings.push_back(r->views[j].name + ": RMS " + fmt("%.3f", r->views[j].rms_px) +
                            " px is more than " + fmt("%g", o.view_outlier_factor) +
                            " x the median " + fmt("%.3f", median) +
                            " px (motion, a bent board, a wrong detection?): check or drop it");
    }
  }
  return by_rms;
}

// Why the result is not a camera the configuration takes (not finite, the principal point
// outside the image, a key out of its range); empty when it is.
std::string camera_error(const Result& r, const cv::Mat& d, cv::Size size) {
  const auto& in = r.intrinsics;
  const double vals[4] = {in.fx, in.fy, in.cx, in.cy};
  bool finite = true;
  for (int i = 0; i < 9; ++i) {
    const double x = i < 4 ? vals[i] : d.at<double>(i - 4);
    finite = finite && std::isfinite(x);
  }
  if (!finite || !(in.fx > 0.0) || !(in.fy > 0.0) || in.cx < -0.5 || in.cy < -0.5 ||
      in.cx > size.width - 0.5 || in.cy > size.height - 0.5) {
    return "calibration did not converge to a camera (fx " + fmt("%.4g", in.fx) + ", fy " +
           fmt("%.4g", in.fy) + ", principal point (" + fmt("%.4g", in.cx) + ", " +
           fmt("%.4g", in.cy) + ")): add tilted views covering the whole image";
  }
  const char* keys[9] = {"intrinsics.fx", "intrinsics.fy", "intrinsics.cx",
                         "intrinsics.cy", "intrinsics.k1", "intrinsics.k2",
                         "intrinsics.p1", "intrinsics.p2", "intrinsics.k3"};
  const double got[9] = {in.fx, in.fy, in.cx, in.cy, in.k1, in.k2, in.p1, in.p2, in.k3};
  std::string bad;
  for (int i = 0; i < 9; ++i) {
    const std::string why = outside_key_range(keys[i], got[i]);
    if (!why.empty()) bad += (bad.empty() ? "" : "; ") + why;
  }
  if (!bad.empty()) {
    return "calibration result the configuration would reject: " + bad + "; no intrinsics written";
  }
  return {};
}

// Warns about a focal length whose standard deviation is large relative to it.
void warn_poorly_determined(Result* r) {
  const char* names[4] = {"fx", "fy", "cx", "cy"};
  const double vals[4] = {r->intrinsics.fx, r->intrinsics.fy, r->intrinsics.cx, r->intrinsics.cy};
  for (int i = 0; i < 2; ++i) {
    const double rel = r->stddev[static_cast<size_t>(i)] / vals[i];
    if (rel > 0.002) {
      r->warnings.push_back(std::string(names[i]) + " is poorly determined (std. dev. " +
                            fmt("%.3f", r->stddev[static_cast<size_t>(i)]) +
                            " px): add views with the board tilted by 20-40 degrees");
    }
  }
}

// The error for an RMS above o.max_rms_px, naming the three worst views.
std::string rms_error(const Result& r, const std::vector<size_t>& by_rms, const Options& o) {
  std::string worst;
  for (size_t j = 0; j < by_rms.size() && j < 3; ++j) {
    worst += std::string(j ? ", " : "") + r.views[by_rms[j]].name + " " +
             fmt("%.3f", r.views[by_rms[j]].rms_px) + " px";
  }
  return "RMS reprojection error " + fmt("%.3f", r.rms_px) + " px is above " +
         fmt("%.3f", o.max_rms_px) + " px (--max-rms-px); worst views: " + worst +
         "; no intrinsics written";
}
}  // namespace

Coverage measure_coverage(const std::vector<View>& views, cv::Size size) {
  Coverage c;
  c.counts.assign(static_cast<size_t>(c.cols * c.rows), 0);
  const double w = size.width, h = size.height;
  int quad[4] = {0, 0, 0, 0};
  int band[4] = {0, 0, 0, 0};  // left, right, top, bottom: 10 % of the side
  for (const auto& v : views) {
    if (!v.used) continue;
    for (const auto& pf : v.image_points) {
      const cv::Point2d p(static_cast<double>(pf.x), static_cast<double>(pf.y));
      const int col = std::clamp(static_cast<int>((p.x + 0.5) / w * c.cols), 0, c.cols - 1);
      const int row = std::clamp(static_cast<int>((p.y + 0.5) / h * c.rows), 0, c.rows - 1);
      ++c.counts[static_cast<size_t>(row * c.cols + col)];
      const bool right = p.x + 0.5 >= 0.5 * w, bottom = p.y + 0.5 >= 0.5 * h;
      ++quad[(bottom ? 2 : 0) + (right ? 1 : 0)];
      if (p.x + 0.5 < 0.1 * w) ++band[0];
      if (p.x + 0.5 > 0.9 * w) ++band[1];
      if (p.y + 0.5 < 0.1 * h) ++band[2];
      if (p.y + 0.5 > 0.9 * h) ++band[3];
    }
  }
  int covered = 0;
  for (int n : c.counts) covered += n > 0 ? 1 : 0;
  c.covered = static_cast<double>(covered) / static_cast<double>(c.counts.size());
  const char* quad_names[4] = {"top-left", "top-right", "bottom-left", "bottom-right"};
  for (int q = 0; q < 4; ++q) {
    if (quad[q] == 0) {
      c.warnings.push_back(std::string("no corner seen in the ") + quad_names[q] +
                           " quadrant: add views with the board there");
    }
  }
  const char* band_names[4] = {"left", "right", "top", "bottom"};
  for (int b = 0; b < 4; ++b) {
    if (band[b] == 0) {
      c.warnings.push_back(std::string("no corner seen in the ") + band_names[b] +
                           " border band (outer 10 % of the image): the distortion there is "
                           "extrapolated; add views with the board at that edge");
    }
  }
  return c;
}

Result calibrate(std::vector<View> views, const BoardSpec& spec, const Options& o) {
  Result r;
  r.views = std::move(views);
  std::string error;
  if (!validate_board(spec, &error)) {
    r.error = error;
    return r;
  }
  if (o.min_views < 3) {
    r.error = "--min-views " + std::to_string(o.min_views) + ": at least 3";
    return r;
  }
  Selection sel;
  if (!select_views(o, &r, &sel)) return r;
  r.usable = static_cast<int>(sel.used.size());
  r.intrinsics.width_px = sel.size.width;
  r.intrinsics.height_px = sel.size.height;
  r.coverage = measure_coverage(r.views, sel.size);
  if (r.usable < o.min_views) {
    r.error = too_few_views_error(r, o);
    return r;
  }
  const cv::Mat d = solve_camera(sel, o, &r);
  const std::string board_hint = wrong_board_hint(r, spec);
  const std::vector<size_t> by_rms = warn_view_outliers(sel.used, o, &r);
  r.error = camera_error(r, d, sel.size);
  if (!r.error.empty()) {
    r.error += board_hint;
    return r;
  }
  warn_poorly_determined(&r);
  if (r.rms_px > o.max_rms_px) {
    r.error = rms_error(r, by_rms, o) + board_hint;
    return r;
  }
  r.ok = true;
  return r;
}

}  // namespace agv::desk::calib

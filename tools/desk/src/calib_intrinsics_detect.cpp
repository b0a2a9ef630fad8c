// Board detection for the intrinsics calibration (calib_intrinsics.hpp): the corners of one view,
// refined to the saddle point, and the view's edge blur.
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "calib_intrinsics_internal.hpp"

namespace agv::desk::calib {

using detail::fmt;
using detail::kNoAruco;
#if AGV_HAVE_ARUCO
using detail::charuco_board;
#endif

namespace {

double percentile(std::vector<float> v, double q) {
  if (v.empty()) return 0.0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return static_cast<double>(v[k]);
}

// Adjacent-corner distance (px) in a detected view: the smallest distance from any corner to
// its nearest neighbour, which bounds the cornerSubPix window.
double min_neighbour_px(const std::vector<cv::Point2f>& pts) {
  double best = 1e9;
  for (size_t i = 0; i < pts.size(); ++i) {
    for (size_t j = i + 1; j < pts.size(); ++j) {
      best = std::min(best, static_cast<double>(cv::norm(pts[i] - pts[j])));
    }
  }
  return best;
}

constexpr double kSaddleSigma = 1.0;
// Corners whose smoothed neighbourhood is this asymmetric (relative RMS, refine_saddle) are
// dropped: a marker or the image edge reaches into the window (steep, distant views), and the
// corner would be biased by 0.1..1 px. Clean simulated corners measure < 0.005, with noise
// sigma 1 about 0.003..0.02.
constexpr double kMaxAsymmetry = 0.05;

// Saddle-fit window radius for a white gap of gap_px around the corner: the window plus the
// smoothing (2 sigma) stays inside the gap, 2..5 px.
int saddle_radius(double gap_px) {
  return std::clamp(static_cast<int>(gap_px - 2.0 * kSaddleSigma), 2, 5);
}

}  // namespace

bool refine_saddle(const cv::Mat& gray, std::vector<cv::Point2f>* points, int radius, double sigma,
                   std::vector<double>* asymmetry) {
  if (gray.empty() || radius < 1) return false;
  cv::Mat smooth;
  gray.convertTo(smooth, CV_64F);
  cv::GaussianBlur(smooth, smooth, cv::Size(0, 0), sigma, sigma, cv::BORDER_REPLICATE);
  // Least-squares fit of I = a x^2 + b xy + c y^2 + d x + e y + f over the (2r+1)^2 pixels
  // around the current estimate; the normal matrix depends only on the offsets.
  const int n = 2 * radius + 1;
  cv::Mat A(n * n, 6, CV_64F);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const double x = i - radius, y = j - radius;
      double* r = A.ptr<double>(j * n + i);
      r[0] = x * x;
      r[1] = x * y;
      r[2] = y * y;
      r[3] = x;
      r[4] = y;
      r[5] = 1.0;
    }
  }
  cv::Mat pinv;
  cv::invert(A, pinv, cv::DECOMP_SVD);
  bool all = true;
  if (asymmetry) asymmetry->assign(points->size(), 1.0);
  auto sample = [&](double sx, double sy) {
    const int x0 = static_cast<int>(std::floor(sx)), y0 = static_cast<int>(std::floor(sy));
    const int x1 = std::min(x0 + 1, gray.cols - 1), y1 = std::min(y0 + 1, gray.rows - 1);
    const double ax = sx - x0, ay = sy - y0;
    return (1 - ay) * ((1 - ax) * smooth.at<double>(y0, x0) + ax * smooth.at<double>(y0, x1)) +
           ay * ((1 - ax) * smooth.at<double>(y1, x0) + ax * smooth.at<double>(y1, x1));
  };
  for (size_t k = 0; k < points->size(); ++k) {
    auto& pt = (*points)[k];
    cv::Point2d p(static_cast<double>(pt.x), static_cast<double>(pt.y));
    bool ok = false;
    for (int it = 0; it < 10; ++it) {
      const int cx = cvRound(p.x), cy = cvRound(p.y);
      if (cx - radius < 0 || cy - radius < 0 || cx + radius >= gray.cols ||
          cy + radius >= gray.rows) {
        break;
      }
      // Sample the smoothed image at the offsets from p (bilinear), so the window is centred on
      // the estimate rather than on a pixel.
      cv::Mat v(n * n, 1, CV_64F);
      const double fx = p.x - cx, fy = p.y - cy;
      for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
          const double sx = cx + (i - radius) + fx, sy = cy + (j - radius) + fy;
          const int x0 = static_cast<int>(std::floor(sx)), y0 = static_cast<int>(std::floor(sy));
          const int x1 = std::min(x0 + 1, gray.cols - 1), y1 = std::min(y0 + 1, gray.rows - 1);
          const double ax = sx - x0, ay = sy - y0;
          v.at<double>(j * n + i) =
              (1 - ay) * ((1 - ax) * smooth.at<double>(y0, x0) + ax * smooth.at<double>(y0, x1)) +
              ay * ((1 - ax) * smooth.at<double>(y1, x0) + ax * smooth.at<double>(y1, x1));
        }
      }
      const cv::Mat c = pinv * v;
      const double a = c.at<double>(0), b = c.at<double>(1), cc = c.at<double>(2);
      const double d = c.at<double>(3), e = c.at<double>(4);
      const double det = 4 * a * cc - b * b;
      if (!(det < 0.0)) break;  // not a saddle: no X-corner here
      const double dx = (-2 * cc * d + b * e) / det;
      const double dy = (b * d - 2 * a * e) / det;
      if (std::hypot(dx, dy) > radius) break;
      p += cv::Point2d(dx, dy);
      if (std::hypot(dx, dy) < 1e-4) {
        ok = true;
        break;
      }
      ok = it == 9;
    }
    if (ok && asymmetry) {
      // An X-junction is point-symmetric about its centre: I(c + d) = I(c - d). A marker or
      // the image edge inside the window breaks that (and biases the fit).
      const int rs = radius + 1;
      double num = 0.0, lo = 1e18, hi = -1e18;
      int cnt = 0;
      bool inside =
          p.x - rs >= 0 && p.y - rs >= 0 && p.x + rs + 1 < gray.cols && p.y + rs + 1 < gray.rows;
      for (int j = -rs; inside && j <= rs; ++j) {
        for (int i = -rs; i <= rs; ++i) {
          const double a = sample(p.x + i, p.y + j), b = sample(p.x - i, p.y - j);
          num += (a - b) * (a - b);
          lo = std::min(lo, a);
          hi = std::max(hi, a);
          ++cnt;
        }
      }
      if (inside && hi > lo) (*asymmetry)[k] = std::sqrt(num / cnt) / (hi - lo);
    }
    if (ok) {
      pt = cv::Point2f(static_cast<float>(p.x), static_cast<float>(p.y));
    } else {
      all = false;
    }
  }
  return all;
}

double edge_blur_px(const cv::Mat& gray, const std::vector<cv::Point2f>& points) {
  cv::Mat mask(gray.size(), CV_8U, cv::Scalar(0));
  if (points.size() >= 3) {
    std::vector<cv::Point> hull;
    std::vector<cv::Point> ip;
    for (const auto& p : points) ip.emplace_back(cvRound(p.x), cvRound(p.y));
    cv::convexHull(ip, hull);
    cv::fillConvexPoly(mask, hull, cv::Scalar(255));
  } else {
    mask.setTo(255);
  }
  cv::Mat gx, gy;
  cv::Sobel(gray, gx, CV_32F, 1, 0, 3, 1.0 / 8.0);
  cv::Sobel(gray, gy, CV_32F, 0, 1, 3, 1.0 / 8.0);
  std::vector<float> values, grads;
  for (int y = 1; y + 1 < gray.rows; ++y) {
    const uchar* m = mask.ptr<uchar>(y);
    const uchar* g = gray.ptr<uchar>(y);
    const float* ax = gx.ptr<float>(y);
    const float* ay = gy.ptr<float>(y);
    for (int x = 1; x + 1 < gray.cols; ++x) {
      if (!m[x]) continue;
      values.push_back(g[x]);
      grads.push_back(std::hypot(ax[x], ay[x]));
    }
  }
  if (values.size() < 100) return 0.0;
  const double contrast = percentile(values, 0.98) - percentile(values, 0.02);
  std::sort(grads.begin(), grads.end(), std::greater<float>());
  const size_t top = std::max<size_t>(1, grads.size() / 100);
  double peak = 0.0;
  for (size_t i = 0; i < top; ++i) peak += static_cast<double>(grads[i]);
  peak /= static_cast<double>(top);
  // Flat: no edge at all; infinite, so a flat view is never taken for a sharp one (callers name
  // it as "no edge" rather than printing a number).
  if (!(peak > 0.0) || !(contrast > 0.0)) return std::numeric_limits<double>::infinity();
  return contrast / (std::sqrt(2.0 * M_PI) * peak);
}

View detect_view(const cv::Mat& gray, const std::string& name, const BoardSpec& spec,
                 const Options& options) {
  View v;
  v.name = name;
  v.size = gray.size();
  if (gray.empty() || gray.type() != CV_8UC1) {
    v.reject_reason = "not an 8-bit gray image";
    return v;
  }
  std::string error;
  if (!validate_board(spec, &error)) {
    v.reject_reason = error;
    return v;
  }
  // A failed view names blur first when the image is blurred: that is what to fix.
  auto blur_reason = [&](double blur) {
    return "blurred: edge blur " + fmt("%.2f", blur) + " px > " + fmt("%.2f", options.max_blur_px) +
           " px (--max-blur-px)";
  };
  auto fail = [&](const std::string& what, const std::vector<cv::Point2f>& pts) {
    v.blur_px = edge_blur_px(gray, pts.size() >= 3 ? pts : std::vector<cv::Point2f>{});
    if (std::isinf(v.blur_px)) {
      v.blur_px = 0.0;
      v.reject_reason = "no edge in the image (uniform: lens cap, no light, or nothing in view)";
      return v;
    }
    v.reject_reason = v.blur_px > options.max_blur_px ? blur_reason(v.blur_px) + "; " + what : what;
    return v;
  };
  if (spec.type == BoardType::kChessboard) {
    const cv::Size pattern(spec.squares_x - 1, spec.squares_y - 1);
    std::vector<cv::Point2f> corners;
    const bool found = cv::findChessboardCorners(
        gray, pattern, corners, cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE);
    if (!found) {
      return fail("chessboard with " + std::to_string(pattern.width) + " x " +
                      std::to_string(pattern.height) +
                      " inner corners not found (the whole board must be in view)",
                  {});
    }
    const double square_px = min_neighbour_px(corners);
    const int half = std::clamp(static_cast<int>(0.3 * square_px), 2, 11);
    cv::cornerSubPix(gray, corners, cv::Size(half, half), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
    std::vector<double> asym;
    refine_saddle(gray, &corners, saddle_radius(0.5 * square_px), kSaddleSigma, &asym);
    for (size_t i = 0; i < corners.size(); ++i) {
      if (asym[i] > kMaxAsymmetry) {
        ++v.dropped;
        continue;
      }
      cv::Point3f p;
      board_corner(spec, static_cast<int>(i), &p);
      v.ids.push_back(static_cast<int>(i));
      v.image_points.push_back(corners[i]);
      v.object_points.push_back(p);
    }
  } else {
#if AGV_HAVE_ARUCO
    const auto board = charuco_board(spec, &error);
    std::vector<std::vector<cv::Point2f>> marker_corners, rejected;
    std::vector<int> marker_ids;
    auto params = cv::aruco::DetectorParameters::create();
    cv::aruco::detectMarkers(gray, board->dictionary, marker_corners, marker_ids, params, rejected);
    if (!marker_ids.empty()) {
      cv::aruco::refineDetectedMarkers(gray, board, marker_corners, marker_ids, rejected);
    }
    std::vector<cv::Point2f> corners;
    std::vector<int> ids;
    if (!marker_ids.empty()) {
      cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, gray, board, corners, ids);
    }
    if (ids.empty()) {
      return fail(marker_ids.empty() ? "no " + spec.dictionary + " marker found"
                                     : std::to_string(marker_ids.size()) +
                                           " markers but no ChArUco corner interpolated",
                  {});
    }
    if (ids.size() >= 2 && cv::aruco::testCharucoCornersCollinear(board, ids)) {
      v.ids = ids;
      v.image_points = corners;
      return fail("the " + std::to_string(ids.size()) + " corners seen lie on one line", corners);
    }
    // interpolateCornersCharuco's cornerSubPix leaves errors of ~0.05 px (pixel locking);
    // the saddle fit brings them to ~0.01 px on simulated views. Its window must stay inside the
    // white gap between a corner and the adjacent markers ((square - marker) / 2).
    const double gap = 0.5 * (spec.square_mm - spec.marker_mm) / spec.square_mm;
    std::vector<double> asym;
    refine_saddle(gray, &corners, saddle_radius(gap * min_neighbour_px(corners)), kSaddleSigma,
                  &asym);
    for (size_t i = 0; i < ids.size(); ++i) {
      if (asym[i] > kMaxAsymmetry) {
        ++v.dropped;
        continue;
      }
      v.ids.push_back(ids[i]);
      v.image_points.push_back(corners[i]);
      v.object_points.push_back(board->chessboardCorners[static_cast<size_t>(ids[i])]);
    }
#else
    v.reject_reason = kNoAruco;
    return v;
#endif
  }
  v.detected = true;
  v.blur_px = edge_blur_px(gray, v.image_points);
  if (v.blur_px > options.max_blur_px) v.reject_reason = blur_reason(v.blur_px);
  return v;
}

}  // namespace agv::desk::calib

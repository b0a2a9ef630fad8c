// Intrinsics calibration (calib_intrinsics.hpp).
#include "calib_intrinsics.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#if AGV_HAVE_ARUCO
#include <opencv2/aruco/charuco.hpp>
#endif

#include "key_ranges.hpp"

namespace agv::desk::calib {

namespace {

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

#if AGV_HAVE_ARUCO
struct DictName {
  const char* name;
  cv::aruco::PREDEFINED_DICTIONARY_NAME id;
};
const DictName kDicts[] = {
    {"DICT_4X4_50", cv::aruco::DICT_4X4_50},
    {"DICT_4X4_100", cv::aruco::DICT_4X4_100},
    {"DICT_4X4_250", cv::aruco::DICT_4X4_250},
    {"DICT_4X4_1000", cv::aruco::DICT_4X4_1000},
    {"DICT_5X5_50", cv::aruco::DICT_5X5_50},
    {"DICT_5X5_100", cv::aruco::DICT_5X5_100},
    {"DICT_5X5_250", cv::aruco::DICT_5X5_250},
    {"DICT_5X5_1000", cv::aruco::DICT_5X5_1000},
    {"DICT_6X6_50", cv::aruco::DICT_6X6_50},
    {"DICT_6X6_100", cv::aruco::DICT_6X6_100},
    {"DICT_6X6_250", cv::aruco::DICT_6X6_250},
    {"DICT_6X6_1000", cv::aruco::DICT_6X6_1000},
    {"DICT_7X7_50", cv::aruco::DICT_7X7_50},
    {"DICT_7X7_100", cv::aruco::DICT_7X7_100},
    {"DICT_7X7_250", cv::aruco::DICT_7X7_250},
    {"DICT_7X7_1000", cv::aruco::DICT_7X7_1000},
    {"DICT_ARUCO_ORIGINAL", cv::aruco::DICT_ARUCO_ORIGINAL},
    {"DICT_APRILTAG_16h5", cv::aruco::DICT_APRILTAG_16h5},
    {"DICT_APRILTAG_25h9", cv::aruco::DICT_APRILTAG_25h9},
    {"DICT_APRILTAG_36h10", cv::aruco::DICT_APRILTAG_36h10},
    {"DICT_APRILTAG_36h11", cv::aruco::DICT_APRILTAG_36h11},
};

cv::Ptr<cv::aruco::CharucoBoard> charuco_board(const BoardSpec& s, std::string* error) {
  for (const auto& d : kDicts) {
    if (s.dictionary != d.name) continue;
    auto dict = cv::aruco::getPredefinedDictionary(d.id);
    const int needed = s.squares_x * s.squares_y / 2;
    if (dict->bytesList.rows < needed) {
      *error = "dictionary " + s.dictionary + " has " + std::to_string(dict->bytesList.rows) +
               " markers, the board needs " + std::to_string(needed);
      return {};
    }
    return cv::aruco::CharucoBoard::create(s.squares_x, s.squares_y,
                                           static_cast<float>(s.square_mm),
                                           static_cast<float>(s.marker_mm), dict);
  }
  std::string names;
  for (const auto& d : kDicts) names += std::string(names.empty() ? "" : ", ") + d.name;
  *error = "unknown dictionary '" + s.dictionary + "' (one of " + names + ")";
  return {};
}
#endif

const char* kNoAruco =
    "this build has no OpenCV aruco module (Debian libopencv-contrib-dev), so no ChArUco "
    "boards: use --board chessboard or rebuild with libopencv-contrib-dev";

double percentile(std::vector<float> v, double q) {
  if (v.empty()) return 0.0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
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

bool have_charuco() { return AGV_HAVE_ARUCO != 0; }

bool validate_board(const BoardSpec& s, std::string* error) {
  if (s.squares_x < 3 || s.squares_y < 3 || s.squares_x > 100 || s.squares_y > 100) {
    *error = "board squares " + std::to_string(s.squares_x) + " x " + std::to_string(s.squares_y) +
             ": each side needs 3..100 squares";
    return false;
  }
  if (!(s.square_mm > 0.0 && s.square_mm < 1000.0)) {
    *error = "square size " + fmt("%g", s.square_mm) + " mm: must be in (0, 1000)";
    return false;
  }
  if (s.type == BoardType::kCharuco) {
    if (!have_charuco()) {
      *error = kNoAruco;
      return false;
    }
    if (!(s.marker_mm > 0.0 && s.marker_mm < s.square_mm)) {
      *error = "marker size " + fmt("%g", s.marker_mm) + " mm: must be positive and below the " +
               "square size " + fmt("%g", s.square_mm) + " mm";
      return false;
    }
#if AGV_HAVE_ARUCO
    if (!charuco_board(s, error)) return false;
#endif
  }
  return true;
}

bool make_sim_board(const BoardSpec& s, double margin_mm, sim::CalibBoard* out,
                    std::string* error) {
  if (!validate_board(s, error)) return false;
  if (s.type == BoardType::kChessboard) {
    *out = sim::make_chessboard(s.squares_x, s.squares_y, s.square_mm, margin_mm);
    return true;
  }
#if AGV_HAVE_ARUCO
  const auto board = charuco_board(s, error);
  sim::CalibBoard b = sim::make_chessboard(s.squares_x, s.squares_y, s.square_mm, margin_mm);
  const int n_bits = board->dictionary->markerSize;
  for (size_t m = 0; m < board->ids.size(); ++m) {
    sim::CalibBoard::Marker mk;
    for (int c = 0; c < 4; ++c) {
      mk.corners[static_cast<size_t>(c)] = {board->objPoints[m][static_cast<size_t>(c)].x,
                                            board->objPoints[m][static_cast<size_t>(c)].y};
    }
    const int id = board->ids[m];
    const cv::Mat bits = cv::aruco::Dictionary::getBitsFromByteList(
        board->dictionary->bytesList.rowRange(id, id + 1), n_bits);
    mk.cells = n_bits + 2;  // one black border cell each side (borderBits = 1)
    mk.black.assign(static_cast<size_t>(mk.cells * mk.cells), 1);
    for (int r = 0; r < n_bits; ++r) {
      for (int c = 0; c < n_bits; ++c) {
        mk.black[static_cast<size_t>((r + 1) * mk.cells + c + 1)] = bits.at<uchar>(r, c) ? 0 : 1;
      }
    }
    b.markers.push_back(std::move(mk));
  }
  // Squares holding a marker are white, the others black (the ChArUco layout).
  std::fill(b.square_black.begin(), b.square_black.end(), 1);
  for (const auto& mk : b.markers) {
    const double mx =
        0.25 * (mk.corners[0].x + mk.corners[1].x + mk.corners[2].x + mk.corners[3].x);
    const double my =
        0.25 * (mk.corners[0].y + mk.corners[1].y + mk.corners[2].y + mk.corners[3].y);
    const int i = static_cast<int>(std::floor(mx / s.square_mm));
    const int j = static_cast<int>(std::floor(my / s.square_mm));
    if (i >= 0 && j >= 0 && i < s.squares_x && j < s.squares_y) {
      b.square_black[static_cast<size_t>(j * s.squares_x + i)] = 0;
    }
  }
  *out = std::move(b);
  return true;
#else
  (void)out;
  *error = kNoAruco;
  return false;
#endif
}

bool board_corner(const BoardSpec& s, int id, cv::Point3f* out) {
  const int cx = s.squares_x - 1, cy = s.squares_y - 1;
  if (id < 0 || id >= cx * cy) return false;
  // Both layouts number the inner corners row by row from the board origin (OpenCV's
  // CharucoBoard::chessboardCorners and the chessboard object points used here).
  *out = cv::Point3f(static_cast<float>((id % cx + 1) * s.square_mm),
                     static_cast<float>((id / cx + 1) * s.square_mm), 0.0f);
  return true;
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
  std::vector<std::vector<cv::Point3f>> obj;
  std::vector<std::vector<cv::Point2f>> img;
  std::vector<size_t> used;
  cv::Size size;
  for (size_t i = 0; i < r.views.size(); ++i) {
    View& v = r.views[i];
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
      for (const View& w : r.views) {
        if (!w.detected || !w.reject_reason.empty()) continue;
        (w.size == size ? same : other) += 1;
      }
      for (View& w : r.views) w.used = false;
      r.error = "the views differ in size: " + std::to_string(same) + " at " +
                std::to_string(size.width) + "x" + std::to_string(size.height) + ", " +
                std::to_string(other) + " at other sizes (first: " + v.name + " " +
                std::to_string(v.size.width) + "x" + std::to_string(v.size.height) +
                "); calibrate one resolution at a time; no intrinsics written";
      return r;
    }
    if (const View* twin = same_view(r.views, used, v)) {
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
  r.usable = static_cast<int>(used.size());
  r.intrinsics.width_px = size.width;
  r.intrinsics.height_px = size.height;
  r.coverage = measure_coverage(r.views, size);
  if (r.usable < o.min_views) {
    std::string why;
    int shown = 0;
    for (const auto& v : r.views) {
      if (v.used) continue;
      if (shown++ < 8) why += "\n  " + v.name + ": " + v.reject_reason;
    }
    if (shown > 8) why += "\n  ... and " + std::to_string(shown - 8) + " more";
    r.error = "only " + std::to_string(r.usable) + " usable view(s) of " +
              std::to_string(r.views.size()) + ", at least " + std::to_string(o.min_views) +
              " needed (--min-views); no intrinsics written" +
              (why.empty() ? std::string() : "; rejected:" + why);
    return r;
  }
  int flags = 0;
  if (o.fix_k3) flags |= cv::CALIB_FIX_K3;
  if (o.zero_tangent) flags |= cv::CALIB_ZERO_TANGENT_DIST;
  if (o.fix_aspect) flags |= cv::CALIB_FIX_ASPECT_RATIO;
  if (o.fix_principal_point) flags |= cv::CALIB_FIX_PRINCIPAL_POINT;
  cv::Mat k = cv::Mat::eye(3, 3, CV_64F), d = cv::Mat::zeros(5, 1, CV_64F);
  std::vector<cv::Mat> rvecs, tvecs;
  cv::Mat sd_intr, sd_extr, per_view;
  r.rms_px = cv::calibrateCamera(
      obj, img, size, k, d, rvecs, tvecs, sd_intr, sd_extr, per_view, flags,
      cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, DBL_EPSILON));
  // Pixels of error, not tenths: the corners were matched to the wrong board points. That is
  // what an 11 x 8 board description of a 9 x 7 print gives (117 px); named with any error.
  std::string board_hint;
  if (r.rms_px > kWrongBoardRmsPx) {
    board_hint = "; an RMS of " + fmt("%.1f", r.rms_px) +
                 " px means the corners do not fit the board described: do --board, "
                 "--squares-x/--squares-y (" +
                 std::to_string(spec.squares_x) + " x " + std::to_string(spec.squares_y) +
                 "), --square-mm, --marker-mm and --dictionary match the printed board?";
  }
  auto& in = r.intrinsics;
  in.width_px = size.width;
  in.height_px = size.height;
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
    r.stddev[static_cast<size_t>(i)] = sd_intr.at<double>(i);
  }
  for (size_t j = 0; j < used.size(); ++j) {
    r.views[used[j]].rms_px = per_view.at<double>(static_cast<int>(j));
    r.corners += static_cast<int>(r.views[used[j]].image_points.size());
  }
  r.warnings = r.coverage.warnings;
  std::vector<double> rms;
  for (size_t j : used) rms.push_back(r.views[j].rms_px);
  std::vector<double> sorted = rms;
  std::sort(sorted.begin(), sorted.end());
  const double median = sorted[sorted.size() / 2];
  std::vector<size_t> by_rms = used;
  std::sort(by_rms.begin(), by_rms.end(),
            [&](size_t a, size_t b) { return r.views[a].rms_px > r.views[b].rms_px; });
  for (size_t j : by_rms) {
    if (r.views[j].rms_px > o.view_outlier_factor * median && r.views[j].rms_px > 0.1) {
      r.warnings.push_back(r.views[j].name + ": RMS " + fmt("%.3f", r.views[j].rms_px) +
                           " px is more than " + fmt("%g", o.view_outlier_factor) +
                           " x the median " + fmt("%.3f", median) +
                           " px (motion, a bent board, a wrong detection?): check or drop it");
    }
  }
  const char* names[4] = {"fx", "fy", "cx", "cy"};
  const double vals[4] = {in.fx, in.fy, in.cx, in.cy};
  bool finite = true;
  for (int i = 0; i < 9; ++i) {
    const double x = i < 4 ? vals[i] : d.at<double>(i - 4);
    finite = finite && std::isfinite(x);
  }
  if (!finite || !(in.fx > 0.0) || !(in.fy > 0.0) || in.cx < -0.5 || in.cy < -0.5 ||
      in.cx > size.width - 0.5 || in.cy > size.height - 0.5) {
    r.error = "calibration did not converge to a camera (fx " + fmt("%.4g", in.fx) + ", fy " +
              fmt("%.4g", in.fy) + ", principal point (" + fmt("%.4g", in.cx) + ", " +
              fmt("%.4g", in.cy) + ")): add tilted views covering the whole image" + board_hint;
    return r;
  }
  {
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
      r.error = "calibration result the configuration would reject: " + bad +
                "; no intrinsics written" + board_hint;
      return r;
    }
  }
  for (int i = 0; i < 2; ++i) {
    const double rel = r.stddev[static_cast<size_t>(i)] / vals[i];
    if (rel > 0.002) {
      r.warnings.push_back(std::string(names[i]) + " is poorly determined (std. dev. " +
                           fmt("%.3f", r.stddev[static_cast<size_t>(i)]) +
                           " px): add views with the board tilted by 20-40 degrees");
    }
  }
  if (r.rms_px > o.max_rms_px) {
    std::string worst;
    for (size_t j = 0; j < by_rms.size() && j < 3; ++j) {
      worst += std::string(j ? ", " : "") + r.views[by_rms[j]].name + " " +
               fmt("%.3f", r.views[by_rms[j]].rms_px) + " px";
    }
    r.error = "RMS reprojection error " + fmt("%.3f", r.rms_px) + " px is above " +
              fmt("%.3f", o.max_rms_px) + " px (--max-rms-px); worst views: " + worst +
              "; no intrinsics written";
    r.error += board_hint;
    return r;
  }
  r.ok = true;
  return r;
}

std::string coverage_svg(const Result& r) {
  const int w = r.intrinsics.width_px > 0 ? r.intrinsics.width_px
                                          : (r.views.empty() ? 640 : r.views[0].size.width);
  const int h = r.intrinsics.height_px > 0 ? r.intrinsics.height_px
                                           : (r.views.empty() ? 480 : r.views[0].size.height);
  const Coverage& c = r.coverage;
  const int pad = 30;
  std::ostringstream s;
  s << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << w + 2 * pad << "\" height=\""
    << h + 2 * pad + 20 << "\" viewBox=\"" << -pad << " " << -pad - 20 << " " << w + 2 * pad << " "
    << h + 2 * pad + 20 << "\" font-family=\"sans-serif\" font-size=\"12\">\n";
  s << "<text x=\"0\" y=\"-24\">Corners seen in " << r.usable << " used views (" << r.corners
    << " corners), " << fmt("%.0f", 100.0 * c.covered) << " % of the " << c.cols << "x" << c.rows
    << " cells</text>\n";
  s << "<rect x=\"-0.5\" y=\"-0.5\" width=\"" << w << "\" height=\"" << h
    << "\" fill=\"white\" stroke=\"black\"/>\n";
  if (!c.counts.empty()) {
    const double cw = static_cast<double>(w) / c.cols, ch = static_cast<double>(h) / c.rows;
    for (int row = 0; row < c.rows; ++row) {
      for (int col = 0; col < c.cols; ++col) {
        const bool empty = c.counts[static_cast<size_t>(row * c.cols + col)] == 0;
        s << "<rect x=\"" << col * cw - 0.5 << "\" y=\"" << row * ch - 0.5 << "\" width=\"" << cw
          << "\" height=\"" << ch << "\" fill=\"" << (empty ? "#f4c7c3" : "none")
          << "\" stroke=\"#cccccc\" stroke-width=\"0.5\"/>\n";
      }
    }
  }
  // Quadrant lines and the 10 % border bands.
  s << "<g stroke=\"#888888\" stroke-dasharray=\"4 3\" fill=\"none\">\n";
  s << "<line x1=\"" << 0.5 * w - 0.5 << "\" y1=\"-0.5\" x2=\"" << 0.5 * w - 0.5 << "\" y2=\""
    << h - 0.5 << "\"/>\n";
  s << "<line x1=\"-0.5\" y1=\"" << 0.5 * h - 0.5 << "\" x2=\"" << w - 0.5 << "\" y2=\""
    << 0.5 * h - 0.5 << "\"/>\n";
  s << "<rect x=\"" << 0.1 * w - 0.5 << "\" y=\"" << 0.1 * h - 0.5 << "\" width=\"" << 0.8 * w
    << "\" height=\"" << 0.8 * h << "\"/>\n</g>\n";
  int n = 0;
  for (const auto& v : r.views) {
    if (!v.used) continue;
    const int hue = (n++ * 47) % 360;
    s << "<g fill=\"hsl(" << hue << ",80%,40%)\"><title>" << v.name << "</title>";
    for (const auto& p : v.image_points) {
      s << "<circle cx=\"" << fmt("%.1f", p.x) << "\" cy=\"" << fmt("%.1f", p.y)
        << "\" r=\"1.8\"/>";
    }
    s << "</g>\n";
  }
  int y = h + 14;
  for (const auto& wmsg : c.warnings) {
    s << "<text x=\"0\" y=\"" << y << "\" fill=\"#b00000\">" << wmsg << "</text>\n";
    y += 14;
  }
  s << "</svg>\n";
  return s.str();
}

std::string report_text(const Result& r) {
  std::ostringstream s;
  s << "views: " << r.views.size() << ", usable " << r.usable << "\n";
  s << "  view                          corners  dropped  blur_px  rms_px  status\n";
  for (const auto& v : r.views) {
    char line[160];
    std::snprintf(line, sizeof line, "  %-30s %7zu  %7d  %7.2f  %6s  ", v.name.c_str(),
                  v.image_points.size(), v.dropped, v.blur_px,
                  v.used && r.corners > 0 ? fmt("%.3f", v.rms_px).c_str() : "-");
    s << line << (v.used ? "used" : "rejected: " + v.reject_reason) << "\n";
  }
  if (r.usable > 0 && r.rms_px > 0.0) {
    const auto& k = r.intrinsics;
    s << "RMS reprojection error: " << fmt("%.4f", r.rms_px) << " px over " << r.corners
      << " corners\n";
    // OpenCV's standard deviation is NaN when the problem is degenerate: say so, not "-nan".
    auto sd = [&](int i) {
      const double v = r.stddev[static_cast<size_t>(i)];
      return std::isfinite(v) ? fmt("%.4f", v) : std::string("(undetermined)");
    };
    s << "fx " << fmt("%.4f", k.fx) << " +- " << sd(0) << "  fy " << fmt("%.4f", k.fy) << " +- "
      << sd(1) << "\n";
    s << "cx " << fmt("%.4f", k.cx) << " +- " << sd(2) << "  cy " << fmt("%.4f", k.cy) << " +- "
      << sd(3) << "\n";
    s << "k1 " << fmt("%.6f", k.k1) << "  k2 " << fmt("%.6f", k.k2) << "  p1 " << fmt("%.6f", k.p1)
      << "  p2 " << fmt("%.6f", k.p2) << "  k3 " << fmt("%.6f", k.k3) << "\n";
    s << "coverage: " << fmt("%.0f", 100.0 * r.coverage.covered) << " % of the " << r.coverage.cols
      << "x" << r.coverage.rows << " image cells hold a corner\n";
  }
  for (const auto& w : r.warnings) s << "warning: " << w << "\n";
  if (!r.ok && !r.error.empty()) s << "error: " << r.error << "\n";
  return s.str();
}

std::string board_svg(const BoardSpec& spec, const sim::CalibBoard& b) {
  const Vec2 lo = b.paper_min(), hi = b.paper_max();
  const double w = hi.x - lo.x, h = hi.y - lo.y + 8.0;  // 8 mm for the caption
  std::ostringstream s;
  s << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << w << "mm\" height=\"" << h
    << "mm\" viewBox=\"" << lo.x << " " << lo.y << " " << w << " " << h << "\">\n";
  s << "<rect x=\"" << lo.x << "\" y=\"" << lo.y << "\" width=\"" << w << "\" height=\"" << h
    << "\" fill=\"white\"/>\n<g fill=\"black\" shape-rendering=\"crispEdges\"";
  // A board frame with y up (not Debian's OpenCV 4.6, tests/calib checks) is drawn flipped, or the
  // printed markers would be mirror images the detector cannot read.
  if (!b.y_down()) s << " transform=\"translate(0 " << lo.y + hi.y << ") scale(1 -1)\"";
  s << ">\n";
  for (int j = 0; j < b.squares_y; ++j) {
    for (int i = 0; i < b.squares_x; ++i) {
      if (!b.square_black[static_cast<size_t>(j * b.squares_x + i)]) continue;
      s << "<rect x=\"" << i * b.square_mm << "\" y=\"" << j * b.square_mm << "\" width=\""
        << b.square_mm << "\" height=\"" << b.square_mm << "\"/>\n";
    }
  }
  // Marker cells as parallelograms from the corners (the board frame may have y up).
  for (const auto& mk : b.markers) {
    const Vec2 c0 = mk.corners[0];
    const Vec2 e1{(mk.corners[1].x - c0.x) / mk.cells, (mk.corners[1].y - c0.y) / mk.cells};
    const Vec2 e3{(mk.corners[3].x - c0.x) / mk.cells, (mk.corners[3].y - c0.y) / mk.cells};
    for (int r = 0; r < mk.cells; ++r) {
      for (int c = 0; c < mk.cells; ++c) {
        if (!mk.black[static_cast<size_t>(r * mk.cells + c)]) continue;
        s << "<polygon points=\"";
        for (const auto& [u, v] : {std::pair{c, r}, {c + 1, r}, {c + 1, r + 1}, {c, r + 1}}) {
          s << c0.x + u * e1.x + v * e3.x << "," << c0.y + u * e1.y + v * e3.y << " ";
        }
        s << "\"/>\n";
      }
    }
  }
  s << "</g>\n<text x=\"" << lo.x + 1 << "\" y=\"" << hi.y + 5 << "\" font-size=\"3\" "
    << "font-family=\"sans-serif\">"
    << (spec.type == BoardType::kChessboard ? "chessboard " : "ChArUco ") << spec.squares_x << " x "
    << spec.squares_y << " squares of " << spec.square_mm << " mm";
  if (spec.type == BoardType::kCharuco) {
    s << ", markers " << spec.marker_mm << " mm " << spec.dictionary;
  }
  s << " (print at 100 %, measure the squares)</text>\n</svg>\n";
  return s.str();
}

std::string config_snippet(const Result& r, const std::string& source) {
  const auto& k = r.intrinsics;
  std::ostringstream s;
  s << "# Camera calibration by agvloc-desk calibrate intrinsics from " << source << ":\n";
  s << "# " << r.usable << " of " << r.views.size() << " views, " << r.corners
    << " corners, RMS reprojection error " << fmt("%.4f", r.rms_px) << " px.\n";
  s << "# Merge into the configuration (docs/guide/config.md); camera.width/height are the\n";
  s << "# calibrated resolution and must stay so.\n";
  s << "camera:\n";
  s << "  width: " << k.width_px << "\n";
  s << "  height: " << k.height_px << "\n";
  s << "intrinsics:\n";
  s << "  fx: " << fmt("%.12g", k.fx) << "\n";
  s << "  fy: " << fmt("%.12g", k.fy) << "\n";
  s << "  cx: " << fmt("%.12g", k.cx) << "\n";
  s << "  cy: " << fmt("%.12g", k.cy) << "\n";
  s << "  k1: " << fmt("%.12g", k.k1) << "\n";
  s << "  k2: " << fmt("%.12g", k.k2) << "\n";
  s << "  p1: " << fmt("%.12g", k.p1) << "\n";
  s << "  p2: " << fmt("%.12g", k.p2) << "\n";
  s << "  k3: " << fmt("%.12g", k.k3) << "\n";
  return s.str();
}

}  // namespace agv::desk::calib

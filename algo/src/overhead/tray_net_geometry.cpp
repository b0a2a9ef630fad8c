// The learned tray detector's geometry: the rectified window on the tray plane, the decoding of
// the network's cells, oriented-box overlap and suppression, the box turned into a vehicle fix,
// and the ONNX input shape. No network here (tray_net.cpp), so this part builds everywhere.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <opencv2/imgproc.hpp>

#include "agv/overhead/tray_net.hpp"

namespace agv::overhead {

Vec2 window_to_plane(const RectifiedWindow& w, double u, double v) {
  const double half = 0.5 * w.gray.cols;
  return {w.centre_mm.x + (u + 0.5 - half) * w.mm_per_px,
          w.centre_mm.y - (v + 0.5 - half) * w.mm_per_px};
}

Vec2 plane_to_window(const RectifiedWindow& w, Vec2 xy_mm) {
  const double half = 0.5 * w.gray.cols;
  return {(xy_mm.x - w.centre_mm.x) / w.mm_per_px + half - 0.5,
          -(xy_mm.y - w.centre_mm.y) / w.mm_per_px + half - 0.5};
}

namespace tray_net_detail {

constexpr int kGridStep = 8;  // the map is exact every kGridStep pixels, bilinear between

// Frame pixel of each grid node of the window (NaN where the plane point is behind the camera).
cv::Mat grid_map(const site::CeilingCamera& cam, const RectifiedWindow& w, int n) {
  const int g = n / kGridStep + 1;
  cv::Mat m(g, g, CV_32FC2);
  for (int j = 0; j < g; ++j) {
    for (int i = 0; i < g; ++i) {
      const Vec2 p = window_to_plane(w, i * kGridStep, j * kGridStep);
      Vec2 px;
      const bool ok = site_to_pixel(cam, p.x, p.y, w.plane_mm, &px);
      m.at<cv::Vec2f>(j, i) =
          ok ? cv::Vec2f(static_cast<float>(px.x), static_cast<float>(px.y)) : cv::Vec2f(NAN, NAN);
    }
  }
  return m;
}

}  // namespace tray_net_detail

bool rectify_window(const cv::Mat& gray, const site::CeilingCamera& cam, Vec2 centre_mm,
                    double plane_mm, int n, double mm_per_px, RectifiedWindow* out,
                    std::string* why) {
  using namespace tray_net_detail;
  auto fail = [&](const std::string& s) {
    if (why) *why = s;
    return false;
  };
  const CameraIntrinsics& k = cam.intrinsics;
  if (!out) return fail("no output");
  if (gray.empty() || gray.type() != CV_8UC1 || gray.cols != k.width_px ||
      gray.rows != k.height_px) {
    return fail("frame is not 8-bit gray of the camera's size");
  }
  if (n < 8 || n % kGridStep != 0 || !(mm_per_px > 0.0) || !std::isfinite(mm_per_px) ||
      !std::isfinite(centre_mm.x) || !std::isfinite(centre_mm.y) || !std::isfinite(plane_mm)) {
    return fail("bad window (size a multiple of 8, positive scale, finite centre)");
  }
  out->centre_mm = centre_mm;
  out->plane_mm = plane_mm;
  out->mm_per_px = mm_per_px;
  out->gray = cv::Mat::zeros(n, n, CV_8UC1);
  const cv::Mat grid = grid_map(cam, *out, n);
  // Source region and the frame's scale against the window's (frame pixels per window pixel).
  float x0 = 1e9f, y0 = 1e9f, x1 = -1e9f, y1 = -1e9f;
  for (auto it = grid.begin<cv::Vec2f>(); it != grid.end<cv::Vec2f>(); ++it) {
    if (!std::isfinite((*it)[0])) continue;
    x0 = std::min(x0, (*it)[0]), x1 = std::max(x1, (*it)[0]);
    y0 = std::min(y0, (*it)[1]), y1 = std::max(y1, (*it)[1]);
  }
  const int g = grid.cols;
  const cv::Vec2f c0 = grid.at<cv::Vec2f>(g / 2, g / 2), c1 = grid.at<cv::Vec2f>(g / 2, g / 2 + 1);
  const double scale =
      std::hypot(static_cast<double>(c1[0] - c0[0]), static_cast<double>(c1[1] - c0[1])) /
      kGridStep;
  if (!(x1 >= 0.0f && y1 >= 0.0f && x0 <= k.width_px - 1 && y0 <= k.height_px - 1) ||
      !std::isfinite(scale)) {
    return fail("window outside the frame");
  }
  // Halve the frame while it is at least twice as fine as the window (no aliasing).
  const int levels = scale >= 2.0 ? static_cast<int>(std::floor(std::log2(scale))) : 0;
  const int pad = 4 << levels;
  const cv::Rect roi = cv::Rect(cv::Point(static_cast<int>(std::floor(x0)) - pad,
                                          static_cast<int>(std::floor(y0)) - pad),
                                cv::Point(static_cast<int>(std::ceil(x1)) + pad + 1,
                                          static_cast<int>(std::ceil(y1)) + pad + 1)) &
                       cv::Rect(0, 0, gray.cols, gray.rows);
  cv::Mat src = gray(roi);
  for (int l = 0; l < levels; ++l) {
    cv::Mat d;
    cv::pyrDown(src, d);
    src = d;
  }
  const float f = 1.0f / static_cast<float>(1 << levels);
  cv::Mat map(n, n, CV_32FC2);
  int inside = 0;
  for (int v = 0; v < n; ++v) {
    const int gj = std::min(v / kGridStep, g - 2);
    const float fy = static_cast<float>(v - gj * kGridStep) / kGridStep;
    for (int u = 0; u < n; ++u) {
      const int gi = std::min(u / kGridStep, g - 2);
      const float fx = static_cast<float>(u - gi * kGridStep) / kGridStep;
      const cv::Vec2f p =
          (1 - fy) * ((1 - fx) * grid.at<cv::Vec2f>(gj, gi) + fx * grid.at<cv::Vec2f>(gj, gi + 1)) +
          fy *
              ((1 - fx) * grid.at<cv::Vec2f>(gj + 1, gi) + fx * grid.at<cv::Vec2f>(gj + 1, gi + 1));
      inside += p[0] >= 0.0f && p[1] >= 0.0f && p[0] <= k.width_px - 1 && p[1] <= k.height_px - 1;
      map.at<cv::Vec2f>(v, u) = std::isfinite(p[0])
                                    ? cv::Vec2f((p[0] - static_cast<float>(roi.x)) * f,
                                                (p[1] - static_cast<float>(roi.y)) * f)
                                    : cv::Vec2f(-1e6f, -1e6f);
    }
  }
  cv::remap(src, out->gray, map, cv::noArray(), cv::INTER_LINEAR, cv::BORDER_CONSTANT,
            cv::Scalar(0));
  out->inside_fraction = static_cast<double>(inside) / (static_cast<double>(n) * n);
  return true;
}

bool decode_tray_output(const float* data, int channels, int rows, int cols, int stride_px,
                        double min_score, std::vector<OrientedBox>* out, std::string* why) {
  if (!data || !out || channels != TrayNetGeometry::kChannels || rows <= 0 || cols <= 0 ||
      stride_px <= 0) {
    if (why) {
      *why = "the network's output is " + std::to_string(channels) + " x " + std::to_string(rows) +
             " x " + std::to_string(cols) + ", expected " +
             std::to_string(TrayNetGeometry::kChannels) + " channels";
    }
    return false;
  }
  const std::size_t plane = static_cast<std::size_t>(rows) * static_cast<std::size_t>(cols);
  auto at = [&](int c, int r, int q) {
    return static_cast<double>(data[static_cast<std::size_t>(c) * plane +
                                    static_cast<std::size_t>(r) * static_cast<std::size_t>(cols) +
                                    static_cast<std::size_t>(q)]);
  };
  out->clear();
  for (int r = 0; r < rows; ++r) {
    for (int q = 0; q < cols; ++q) {
      const double score = at(0, r, q);
      if (!(score >= min_score)) continue;
      OrientedBox b;
      b.score = score;
      b.cx = (q + at(1, r, q)) * stride_px - 0.5;
      b.cy = (r + at(2, r, q)) * stride_px - 0.5;
      b.length = at(3, r, q);
      b.width = at(4, r, q);
      double a = 0.5 * std::atan2(at(6, r, q), at(5, r, q));
      if (a < 0.0) a += kPi;
      b.angle_rad = a >= kPi ? a - kPi : a;
      if (std::isfinite(b.cx) && std::isfinite(b.cy) && b.length > 0.0 && b.width > 0.0 &&
          std::isfinite(b.length) && std::isfinite(b.width)) {
        out->push_back(b);
      }
    }
  }
  return true;
}

double oriented_iou(const OrientedBox& a, const OrientedBox& b) {
  if (!(a.length > 0.0 && a.width > 0.0 && b.length > 0.0 && b.width > 0.0)) return 0.0;
  const cv::RotatedRect ra(cv::Point2f(static_cast<float>(a.cx), static_cast<float>(a.cy)),
                           cv::Size2f(static_cast<float>(a.length), static_cast<float>(a.width)),
                           static_cast<float>(rad_to_deg(a.angle_rad)));
  const cv::RotatedRect rb(cv::Point2f(static_cast<float>(b.cx), static_cast<float>(b.cy)),
                           cv::Size2f(static_cast<float>(b.length), static_cast<float>(b.width)),
                           static_cast<float>(rad_to_deg(b.angle_rad)));
  std::vector<cv::Point2f> poly;
  if (cv::rotatedRectangleIntersection(ra, rb, poly) == cv::INTERSECT_NONE || poly.size() < 3) {
    return 0.0;
  }
  std::vector<cv::Point2f> hull;
  cv::convexHull(poly, hull);
  const double inter = cv::contourArea(hull);
  const double uni = a.length * a.width + b.length * b.width - inter;
  return uni > 0.0 ? inter / uni : 0.0;
}

std::vector<OrientedBox> nms_oriented(std::vector<OrientedBox> boxes, double iou) {
  std::stable_sort(boxes.begin(), boxes.end(),
                   [](const OrientedBox& a, const OrientedBox& b) { return a.score > b.score; });
  std::vector<OrientedBox> kept;
  for (const OrientedBox& b : boxes) {
    bool keep = true;
    for (const OrientedBox& k : kept) keep = keep && oriented_iou(b, k) <= iou;
    if (keep) kept.push_back(b);
  }
  return kept;
}

std::vector<OrientedBox> nms_fused(std::vector<OrientedBox> boxes, double iou) {
  std::stable_sort(boxes.begin(), boxes.end(),
                   [](const OrientedBox& a, const OrientedBox& b) { return a.score > b.score; });
  std::vector<bool> taken(boxes.size(), false);
  std::vector<OrientedBox> kept;
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    if (taken[i]) continue;
    const OrientedBox& k = boxes[i];
    double w = 0.0, cx = 0.0, cy = 0.0, len = 0.0, wid = 0.0, c2 = 0.0, s2 = 0.0;
    for (std::size_t j = i; j < boxes.size(); ++j) {
      if (taken[j] || (j != i && oriented_iou(boxes[j], k) <= iou)) continue;
      taken[j] = true;
      const OrientedBox& b = boxes[j];
      w += b.score;
      cx += b.score * b.cx;
      cy += b.score * b.cy;
      len += b.score * b.length;
      wid += b.score * b.width;
      c2 += b.score * std::cos(2.0 * b.angle_rad);
      s2 += b.score * std::sin(2.0 * b.angle_rad);
    }
    OrientedBox f = k;
    if (w > 0.0) {
      f.cx = cx / w;
      f.cy = cy / w;
      f.length = len / w;
      f.width = wid / w;
      double a = 0.5 * std::atan2(s2, c2);
      if (a < 0.0) a += kPi;
      f.angle_rad = a >= kPi ? a - kPi : a;
    }
    kept.push_back(f);
  }
  return kept;
}

std::string validate(const TrayNetParams& p) {
  if (!(p.min_score > 0.0 && p.min_score < 1.0)) return "min_score must be in (0, 1)";
  if (!(p.nms_iou > 0.0 && p.nms_iou < 1.0)) return "nms_iou must be in (0, 1)";
  if (!(p.centre_sigma_px > 0.0) || !std::isfinite(p.centre_sigma_px)) {
    return "centre_sigma_px must be positive";
  }
  if (!(p.angle_sigma_rad > 0.0) || !std::isfinite(p.angle_sigma_rad)) {
    return "angle_sigma_rad must be positive";
  }
  if (!(p.max_size_error_rel > 0.0)) return "max_size_error_rel must be positive";
  return {};
}

bool tray_box_fix(const PlaneTray& t, const site::FleetAgv& agv, const Pose2& predicted,
                  const std::array<double, 9>& predicted_cov, const TrayNetParams& p,
                  double mm_per_px, TagFix* out, std::string* why) {
  auto fail = [&](const std::string& s) {
    if (why) *why = s;
    return false;
  };
  if (!out || !(mm_per_px > 0.0)) return fail("bad input");
  const bool long_is_x = agv.tray_length_mm >= agv.tray_width_mm;
  const double known_long = std::max(agv.tray_length_mm, agv.tray_width_mm);
  const double known_short = std::min(agv.tray_length_mm, agv.tray_width_mm);
  if (std::abs(known_long - known_short) < 0.1 * known_long) {
    return fail("a square tray's box does not give the heading");
  }
  if (std::abs(t.length_mm / known_long - 1.0) > p.max_size_error_rel ||
      std::abs(t.width_mm / known_short - 1.0) > p.max_size_error_rel) {
    return fail("box of " + std::to_string(static_cast<int>(t.length_mm)) + " x " +
                std::to_string(static_cast<int>(t.width_mm)) + " mm is not the vehicle's tray");
  }
  const double sigma_theta = std::sqrt(std::max(predicted_cov[8], 0.0));
  if (!std::isfinite(sigma_theta) || 3.0 * sigma_theta >= 0.5 * kPi) {
    return fail("the prediction's heading cannot resolve the box's half-turn");
  }
  const double axis = long_is_x ? t.axis_rad : t.axis_rad + 0.5 * kPi;
  double heading = wrap_angle_rad(axis);
  if (std::abs(wrap_angle_rad(heading - predicted.theta_rad)) > 0.5 * kPi) {
    heading = wrap_angle_rad(heading + kPi);
  }
  out->pose = {t.centre_mm.x, t.centre_mm.y, heading};
  const double s_mm = p.centre_sigma_px * mm_per_px;
  out->cov = {s_mm * s_mm, 0, 0, 0, s_mm * s_mm, 0, 0, 0, p.angle_sigma_rad * p.angle_sigma_rad};
  out->size_error_rel = t.length_mm / known_long - 1.0;
  out->residual_mm = 0.0;
  return true;
}

}  // namespace agv::overhead

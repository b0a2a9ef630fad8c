// Simulated calibration-board views (agv/sim/calib_board.hpp).
#include "agv/sim/calib_board.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>

namespace agv::sim {

namespace {

constexpr double kPi = 3.14159265358979323846;

// Ink lookup with the markers indexed by square (the public CalibBoard::at searches them).
class BoardInk {
 public:
  explicit BoardInk(const CalibBoard& b) : b_(b) {
    marker_of_square_.assign(static_cast<size_t>(std::max(0, b.squares_x * b.squares_y)), -1);
    for (size_t m = 0; m < b.markers.size(); ++m) {
      const auto& c = b.markers[m].corners;
      const double mx = 0.25 * (c[0].x + c[1].x + c[2].x + c[3].x);
      const double my = 0.25 * (c[0].y + c[1].y + c[2].y + c[3].y);
      const int i = static_cast<int>(std::floor(mx / b.square_mm));
      const int j = static_cast<int>(std::floor(my / b.square_mm));
      if (i >= 0 && j >= 0 && i < b.squares_x && j < b.squares_y) {
        marker_of_square_[static_cast<size_t>(j * b.squares_x + i)] = static_cast<int>(m);
      }
    }
  }

  PageInk at(Vec2 p) const {
    const Vec2 lo = b_.paper_min(), hi = b_.paper_max();
    if (!(p.x >= lo.x && p.y >= lo.y && p.x < hi.x && p.y < hi.y)) return PageInk::kOutside;
    const int i = static_cast<int>(std::floor(p.x / b_.square_mm));
    const int j = static_cast<int>(std::floor(p.y / b_.square_mm));
    if (i < 0 || j < 0 || i >= b_.squares_x || j >= b_.squares_y) return PageInk::kWhite;
    const size_t sq = static_cast<size_t>(j * b_.squares_x + i);
    if (b_.square_black[sq]) return PageInk::kBlack;
    const int m = marker_of_square_[sq];
    if (m < 0) return PageInk::kWhite;
    return marker_ink(b_.markers[static_cast<size_t>(m)], p);
  }

  static PageInk marker_ink(const CalibBoard::Marker& mk, Vec2 p) {
    const Vec2 c0 = mk.corners[0];
    const Vec2 e1{mk.corners[1].x - c0.x, mk.corners[1].y - c0.y};
    const Vec2 e3{mk.corners[3].x - c0.x, mk.corners[3].y - c0.y};
    const Vec2 d{p.x - c0.x, p.y - c0.y};
    const double u = (d.x * e1.x + d.y * e1.y) / (e1.x * e1.x + e1.y * e1.y);
    const double v = (d.x * e3.x + d.y * e3.y) / (e3.x * e3.x + e3.y * e3.y);
    if (!(u >= 0.0 && u < 1.0 && v >= 0.0 && v < 1.0) || mk.cells <= 0) return PageInk::kWhite;
    const int col = std::min(mk.cells - 1, static_cast<int>(u * mk.cells));
    const int row = std::min(mk.cells - 1, static_cast<int>(v * mk.cells));
    return mk.black[static_cast<size_t>(row * mk.cells + col)] ? PageInk::kBlack : PageInk::kWhite;
  }

 private:
  const CalibBoard& b_;
  std::vector<int> marker_of_square_;
};

cv::Matx33d rot_x(double a) {
  const double c = std::cos(a), s = std::sin(a);
  return {1, 0, 0, 0, c, -s, 0, s, c};
}
cv::Matx33d rot_y(double a) {
  const double c = std::cos(a), s = std::sin(a);
  return {c, 0, s, 0, 1, 0, -s, 0, c};
}
cv::Matx33d rot_z(double a) {
  const double c = std::cos(a), s = std::sin(a);
  return {c, -s, 0, s, c, 0, 0, 0, 1};
}

// Height of a board bowed by bow_mm at its centre over its corners (a paraboloid of revolution).
double bow_at(const CalibBoard& board, double bow_mm, Vec2 p) {
  const Vec2 lo = board.paper_min(), hi = board.paper_max();
  const double cx = 0.5 * (lo.x + hi.x), cy = 0.5 * (lo.y + hi.y);
  const double r2 = 0.25 * ((hi.x - lo.x) * (hi.x - lo.x) + (hi.y - lo.y) * (hi.y - lo.y));
  return bow_mm * (1.0 - ((p.x - cx) * (p.x - cx) + (p.y - cy) * (p.y - cy)) / r2);
}

}  // namespace

PageInk CalibBoard::at(Vec2 p) const { return BoardInk(*this).at(p); }

bool CalibBoard::y_down() const {
  if (markers.empty()) return true;
  const auto& c = markers.front().corners;
  const double cross =
      (c[1].x - c[0].x) * (c[3].y - c[0].y) - (c[1].y - c[0].y) * (c[3].x - c[0].x);
  return cross > 0.0;
}

CalibBoard make_chessboard(int squares_x, int squares_y, double square_mm, double margin_mm) {
  CalibBoard b;
  b.squares_x = squares_x;
  b.squares_y = squares_y;
  b.square_mm = square_mm;
  b.margin_mm = margin_mm;
  b.square_black.resize(static_cast<size_t>(std::max(0, squares_x * squares_y)));
  for (int j = 0; j < squares_y; ++j) {
    for (int i = 0; i < squares_x; ++i) {
      b.square_black[static_cast<size_t>(j * squares_x + i)] = ((i + j) % 2 == 0) ? 1 : 0;
    }
  }
  return b;
}

std::vector<Vec2> board_inner_corners(const CalibBoard& board) {
  std::vector<Vec2> out;
  for (int j = 1; j < board.squares_y; ++j) {
    for (int i = 1; i < board.squares_x; ++i) {
      out.push_back({i * board.square_mm, j * board.square_mm});
    }
  }
  return out;
}

cv::Mat render_board_view(const CalibBoard& board, const CameraIntrinsics& intrinsics,
                          const BoardPose& pose, const BoardImageOptions& o) {
  const int w = intrinsics.width_px, h = intrinsics.height_px;
  if (w <= 0 || h <= 0 || !(intrinsics.fx > 0.0) || !(intrinsics.fy > 0.0) ||
      !(board.square_mm > 0.0)) {
    return {};
  }
  CameraModel cam;
  cam.intrinsics = intrinsics;
  const BoardInk ink(board);
  // Board coordinates of every pixel corner (x - 0.5, y - 0.5): ray through the undistorted
  // point, intersected with the board plane. Inside one pixel the map is interpolated bilinearly
  // (its curvature over one pixel is far below the sampling resolution).
  const cv::Vec3d n(pose.R(0, 2), pose.R(1, 2), pose.R(2, 2));  // board normal in the camera
  const double nt = n.dot(pose.t);
  const cv::Matx33d rt = pose.R.t();
  const size_t gw = static_cast<size_t>(w + 1);
  std::vector<Vec2> grid(gw * static_cast<size_t>(h + 1));
  std::vector<std::uint8_t> valid(grid.size(), 0);
  for (int y = 0; y <= h; ++y) {
    for (int x = 0; x <= w; ++x) {
      Vec2 xn;
      if (!cam.undistort_pixel_to_normalized({x - 0.5, y - 0.5}, &xn)) continue;
      const cv::Vec3d d(xn.x, xn.y, 1.0);
      const double nd = n.dot(d);
      if (std::abs(nd) < 1e-12) continue;
      double lambda = nt / nd;
      cv::Vec3d xb = rt * (lambda * d - pose.t);
      // A bowed board: the ray meets the surface z = bow(x, y) in the board frame; the bow is
      // under a millimetre, so a few fixed-point steps from the plane converge.
      for (int it = 0; it < 3 && o.bow_mm != 0.0; ++it) {
        lambda = (nt + bow_at(board, o.bow_mm, {xb[0], xb[1]})) / nd;
        xb = rt * (lambda * d - pose.t);
      }
      if (!(lambda > 0.0)) continue;
      const size_t k = static_cast<size_t>(y) * gw + static_cast<size_t>(x);
      grid[k] = {xb[0], xb[1]};
      valid[k] = 1;
    }
  }
  auto value = [&](PageInk i) {
    return i == PageInk::kBlack ? o.ink_black : i == PageInk::kWhite ? o.paper_white : o.background;
  };
  const int ns = std::max(1, o.supersample);
  cv::Mat img(h, w, CV_32F);
  for (int y = 0; y < h; ++y) {
    float* row = img.ptr<float>(y);
    for (int x = 0; x < w; ++x) {
      const size_t k00 = static_cast<size_t>(y) * gw + static_cast<size_t>(x);
      const size_t k10 = k00 + 1, k01 = k00 + gw, k11 = k01 + 1;
      if (!(valid[k00] && valid[k10] && valid[k01] && valid[k11])) {
        row[x] = static_cast<float>(o.background);
        continue;
      }
      const Vec2 a = grid[k00], b = grid[k10], c = grid[k01], d = grid[k11];
      auto at = [&](double u, double v) {
        const double px = (1 - v) * ((1 - u) * a.x + u * b.x) + v * ((1 - u) * c.x + u * d.x);
        const double py = (1 - v) * ((1 - u) * a.y + u * b.y) + v * ((1 - u) * c.y + u * d.y);
        return ink.at({px, py});
      };
      // Uniform pixel: the same ink at the corners, edge midpoints and centre.
      const PageInk first = at(0.5, 0.5);
      bool uniform = true;
      for (int s = 0; s < 9 && uniform; ++s) {
        uniform = at(0.5 * (s % 3), 0.5 * (s / 3)) == first;
      }
      if (uniform || ns == 1) {
        row[x] = static_cast<float>(value(first));
        continue;
      }
      double sum = 0.0;
      for (int sy = 0; sy < ns; ++sy) {
        for (int sx = 0; sx < ns; ++sx) {
          sum += value(at((sx + 0.5) / ns, (sy + 0.5) / ns));
        }
      }
      row[x] = static_cast<float>(sum / (ns * ns));
    }
  }
  if (o.blur_sigma_px > 0.0) {
    cv::GaussianBlur(img, img, cv::Size(0, 0), o.blur_sigma_px, o.blur_sigma_px,
                     cv::BORDER_REPLICATE);
  }
  if (o.noise_sigma > 0.0) {
    std::mt19937_64 rng(o.seed);
    std::normal_distribution<float> noise(0.0f, static_cast<float>(o.noise_sigma));
    for (int y = 0; y < h; ++y) {
      float* row = img.ptr<float>(y);
      for (int x = 0; x < w; ++x) row[x] += noise(rng);
    }
  }
  cv::Mat out;
  img.convertTo(out, CV_8U);  // rounds and saturates
  return out;
}

std::vector<BoardPose> calib_view_poses(const CalibBoard& board, const CameraIntrinsics& intrinsics,
                                        int n, std::uint64_t seed, const BoardPoseOptions& o) {
  std::vector<BoardPose> poses;
  CameraModel cam;
  cam.intrinsics = intrinsics;
  const double w = intrinsics.width_px, h = intrinsics.height_px;
  // Undistorted radius of the image corners: points beyond it are outside the image (the
  // distortion polynomial may fold far-away points back into it).
  double r_max = 0.0;
  for (const Vec2 c :
       {Vec2{-0.5, -0.5}, Vec2{w - 0.5, -0.5}, Vec2{-0.5, h - 0.5}, Vec2{w - 0.5, h - 0.5}}) {
    Vec2 xn;
    if (!cam.undistort_pixel_to_normalized(c, &xn)) return {};
    r_max = std::max(r_max, std::hypot(xn.x, xn.y));
  }
  auto inside = [&](const cv::Vec3d& pc) {
    if (!(pc[2] > 1e-6)) return false;
    const Vec2 xn{pc[0] / pc[2], pc[1] / pc[2]};
    if (std::hypot(xn.x, xn.y) > 1.02 * r_max) return false;
    const Vec2 px = cam.distort_normalized_to_pixel(xn);
    return px.x >= o.border_px - 0.5 && px.y >= o.border_px - 0.5 &&
           px.x <= w - 0.5 - o.border_px && px.y <= h - 0.5 - o.border_px;
  };
  const std::vector<Vec2> inner = board_inner_corners(board);
  const Vec2 lo = board.paper_min(), hi = board.paper_max();
  const std::vector<Vec2> outline{lo, {hi.x, lo.y}, hi, {lo.x, hi.y}};
  const cv::Vec3d centre(0.5 * board.squares_x * board.square_mm,
                         0.5 * board.squares_y * board.square_mm, 0.0);
  // A board whose y axis points up is turned over about x so the camera sees it non-mirrored.
  const cv::Matx33d base = board.y_down() ? cv::Matx33d::eye() : rot_x(kPi);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  const double grid[3] = {0.2, 0.5, 0.8};
  for (int v = 0; v < n; ++v) {
    const int cell = v % 9;
    bool found = false;
    for (int attempt = 0; attempt < 400 && !found; ++attempt) {
      // Later attempts pull the target towards the image centre and the board further away.
      const double pull = std::min(1.0, attempt / 200.0);
      const double fx_img = grid[cell % 3] + 0.06 * (uni(rng) - 0.5);
      const double fy_img = grid[cell / 3] + 0.06 * (uni(rng) - 0.5);
      const Vec2 target{((1 - pull) * fx_img + pull * 0.5) * w - 0.5,
                        ((1 - pull) * fy_img + pull * 0.5) * h - 0.5};
      Vec2 xn;
      if (!cam.undistort_pixel_to_normalized(target, &xn)) continue;
      const double dist = o.near_mm + (o.far_mm - o.near_mm) * (pull + (1 - pull) * uni(rng));
      const double tilt = o.max_tilt_deg * kPi / 180.0;
      const double ax = tilt * (2 * uni(rng) - 1), ay = tilt * (2 * uni(rng) - 1);
      const double spin = 2 * kPi * uni(rng);
      BoardPose p;
      p.R = rot_z(spin) * rot_x(ax) * rot_y(ay) * base;
      const cv::Vec3d at_target(xn.x * dist, xn.y * dist, dist);
      p.t = at_target - p.R * centre;
      int seen = 0;
      for (const Vec2 c : inner) seen += inside(p.R * cv::Vec3d(c.x, c.y, 0.0) + p.t) ? 1 : 0;
      bool ok = seen >= static_cast<int>(std::ceil(o.min_visible * inner.size())) && seen > 0;
      if (ok && o.min_visible >= 1.0) {
        for (const Vec2 c : outline) ok = ok && inside(p.R * cv::Vec3d(c.x, c.y, 0.0) + p.t);
      }
      if (ok) {
        poses.push_back(p);
        found = true;
      }
    }
    if (!found) return {};
  }
  return poses;
}

}  // namespace agv::sim

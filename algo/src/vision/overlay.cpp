// Debug overlay of LandmarkLocalizer (Li et al. figures 5-9): edge points coloured by class,
// fitted lines, corners, centre, the numbers. Desk use only; not on the vehicle's per-frame path.
#include <cstdio>
#include <opencv2/imgproc.hpp>

#include "localizer_impl.hpp"

namespace agv::vision {

void LandmarkLocalizer::draw_overlay(const cv::Mat& gray8, const LandmarkFix& fix,
                                     cv::Mat* bgr_out) const {
  if (!bgr_out) return;
  if (gray8.empty() || gray8.type() != CV_8UC1) {
    *bgr_out = cv::Mat();
    return;
  }
  cv::cvtColor(gray8, *bgr_out, cv::COLOR_GRAY2BGR);
  const Impl& m = *impl_;
  const SquarePixels& sq = m.square.pixels();
  char text[160];
  if (m.have_overlay) {
    // Colours by class relative to the landmark's forward direction (page up/right/down/left).
    const cv::Scalar colours[4] = {{0, 255, 0}, {0, 0, 255}, {255, 0, 0}, {0, 255, 255}};
    for (int l = 0; l < kNumLines; ++l) {
      const int side = l / 2;
      const int cls_img = (l % 2 == 0) ? side : (side + 2) % 4;  // gradient class
      const int cls = ((cls_img - m.quadrant) % 4 + 4) % 4;
      for (const Vec2& p : m.square.edge_points().px[static_cast<size_t>(l)]) {
        const int x = static_cast<int>(std::lround(p.x)), y = static_cast<int>(std::lround(p.y));
        if (x >= 0 && y >= 0 && x < bgr_out->cols && y < bgr_out->rows) {
          bgr_out->at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<std::uint8_t>(colours[cls][0]),
                                                   static_cast<std::uint8_t>(colours[cls][1]),
                                                   static_cast<std::uint8_t>(colours[cls][2]));
        }
      }
    }
    for (int e = 0; e < 2; ++e) {
      for (int k = 0; k < 4; ++k) {
        const Vec2 a = sq.corners_px[static_cast<size_t>(e * 4 + k)];
        const Vec2 b = sq.corners_px[static_cast<size_t>(e * 4 + (k + 1) % 4)];
        cv::line(*bgr_out, cv::Point2d(a.x, a.y), cv::Point2d(b.x, b.y), {0, 0, 255}, 1,
                 cv::LINE_AA);
      }
    }
    for (const Vec2& c : sq.corners_px) {
      cv::circle(*bgr_out, cv::Point2d(c.x, c.y), 3, {0, 0, 255}, -1, cv::LINE_AA);
    }
    cv::circle(*bgr_out, cv::Point2d(sq.centre_px.x, sq.centre_px.y), 4, {255, 0, 255}, -1,
               cv::LINE_AA);
    // Forward arrow.
    const double fwd_img = sq.up_angle_px + m.quadrant * kPi / 2.0;
    const double len = 0.6 * m.geom.outer_half_mm() / m.mm_per_px;
    cv::arrowedLine(*bgr_out, cv::Point2d(sq.centre_px.x, sq.centre_px.y),
                    cv::Point2d(sq.centre_px.x + len * std::cos(fwd_img),
                                sq.centre_px.y + len * std::sin(fwd_img)),
                    {255, 0, 255}, 2, cv::LINE_AA);
  }
  std::snprintf(text, sizeof text, "%s id=%u", to_string(fix.status),
                static_cast<unsigned>(fix.landmark_id));
  cv::putText(*bgr_out, text, {8, 20}, cv::FONT_HERSHEY_SIMPLEX, 0.5, {0, 0, 255}, 1, cv::LINE_AA);
  if (fix.status == FixStatus::kOk) {
    std::snprintf(text, sizeof text, "ex=%.2f mm ey=%.2f mm ephi=%.3f deg", fix.e_x_mm, fix.e_y_mm,
                  fix.e_phi_deg);
    cv::putText(*bgr_out, text, {8, 40}, cv::FONT_HERSHEY_SIMPLEX, 0.5, {0, 0, 255}, 1,
                cv::LINE_AA);
  }
}

}  // namespace agv::vision

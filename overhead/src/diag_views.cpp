#include "diag_views.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace agv::overhead_app {

void fill_camera_view(const site::Site& site, std::size_t camera,
                      const overhead::FleetTracker& tracker,
                      const std::vector<overhead::Detection>& detections,
                      const overhead::SearchParams& search, std::int64_t t_ns, const cv::Mat& gray,
                      CameraView* out) {
  out->t_ns = t_ns;
  gray.copyTo(out->gray);  // same size every time: allocates once
  out->detections.clear();
  for (const overhead::Detection& d : detections)
    if (d.camera == camera) out->detections.push_back(d);
  out->tracks.clear();
  if (camera >= site.cameras.size()) return;
  // As if every window had hit on a frame after the first: only the tracks' own windows.
  overhead::CameraSearchState state;
  state.frames = 1;
  state.missed.assign(site.fleet.size(), 0);
  for (const overhead::SearchWindow& w :
       overhead::plan_search(site.cameras[camera], site.fleet, tracker, t_ns, search, state)) {
    if (w.level != overhead::SearchLevel::kTrack || w.agvs.empty()) continue;
    TrackMark m;
    m.agv = w.agvs.front();
    m.state = tracker.output(m.agv, t_ns).state;
    m.window = w.rect;
    m.predicted_corners_px = w.predicted_corners_px;
    out->tracks.push_back(m);
  }
}

namespace {

const cv::Scalar kApplied(0, 200, 0), kRefused(0, 140, 255), kStranger(0, 0, 230),
    kTrack(255, 120, 0);

cv::Scalar detection_colour(const overhead::Detection& d) {
  if (!d.in_fleet) return kStranger;
  return d.result == overhead::FixResult::kApplied || d.result == overhead::FixResult::kStarted
             ? kApplied
             : kRefused;
}

cv::Point scaled(Vec2 p, double s) {
  return {static_cast<int>(std::lround(p.x * s)), static_cast<int>(std::lround(p.y * s))};
}

void polygon(cv::Mat* img, const std::array<Vec2, 4>& corners, double s, const cv::Scalar& c,
             int thickness) {
  std::vector<cv::Point> pts;
  for (const Vec2& p : corners) pts.push_back(scaled(p, s));
  cv::polylines(*img, pts, true, c, thickness, cv::LINE_AA);
}

void label(cv::Mat* img, const std::string& text, cv::Point at, const cv::Scalar& c) {
  cv::putText(*img, text, at, cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 0), 3, cv::LINE_AA);
  cv::putText(*img, text, at, cv::FONT_HERSHEY_SIMPLEX, 0.4, c, 1, cv::LINE_AA);
}

}  // namespace

cv::Mat draw_camera_view(const CameraView& v, const std::vector<std::string>& agv_ids,
                         int width_px) {
  if (v.gray.empty() || width_px <= 0) return {};
  const double s = v.gray.cols > width_px ? static_cast<double>(width_px) / v.gray.cols : 1.0;
  cv::Mat small, bgr;
  if (s < 1.0) {
    const int h = std::max(1, static_cast<int>(std::lround(v.gray.rows * s)));
    cv::resize(v.gray, small, cv::Size(width_px, h), 0, 0, cv::INTER_AREA);
  } else {
    small = v.gray;
  }
  cv::cvtColor(small, bgr, cv::COLOR_GRAY2BGR);
  for (const TrackMark& t : v.tracks) {
    const cv::Rect r(
        scaled({static_cast<double>(t.window.x), static_cast<double>(t.window.y)}, s),
        scaled({static_cast<double>(t.window.br().x), static_cast<double>(t.window.br().y)}, s));
    cv::rectangle(bgr, r, kTrack, 1);
    polygon(&bgr, t.predicted_corners_px, s, kTrack, 1);
    const std::string name = t.agv < agv_ids.size() ? agv_ids[t.agv] : std::to_string(t.agv);
    label(&bgr, name + " " + overhead::to_string(t.state), r.tl() + cv::Point(2, -4), kTrack);
  }
  for (const overhead::Detection& d : v.detections) {
    const cv::Scalar c = detection_colour(d);
    polygon(&bgr, d.tag.corners_px, s, c, 2);
    const std::array<Vec2, 4>& q = d.tag.corners_px;
    const Vec2 centre{(q[0].x + q[1].x + q[2].x + q[3].x) / 4,
                      (q[0].y + q[1].y + q[2].y + q[3].y) / 4};
    cv::circle(bgr, scaled(q[0], s), 3, c, cv::FILLED);  // the tag's top-left: its heading
    label(&bgr, std::to_string(d.tag.id), scaled(centre, s) + cv::Point(-8, 4), c);
  }
  return bgr;
}

}  // namespace agv::overhead_app

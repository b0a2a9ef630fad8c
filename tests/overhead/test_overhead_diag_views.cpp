// agvloc-overhead's diagnostics pictures (overhead/src/diag_views.hpp, diag_site_svg.cpp;
// docs/guide/overhead.md "Diagnostics page and metrics"): /site.svg with every vehicle and its
// track state, /camera/<index>.png downscaled to diag.view_width_px with the detections and
// track windows drawn where they are, 404 for a camera that is not the site's, 503 before a frame,
// and the tracker's hand-off only when the page asked and not closer than its bound. Served from
// views put in place before each request: nothing here depends on timing.
#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "../support/loopback_client.hpp"
#include "diag.hpp"
#include "two_camera_site.hpp"

namespace agv::overhead_app {
namespace {

struct Reply {
  std::string head, body;
};

// GET path from 127.0.0.1:port.
Reply http_get(int port, const std::string& path) {
  const std::string out = agv::test::http_get_raw(port, path);
  const std::size_t split = out.find("\r\n\r\n");
  if (split == std::string::npos) return {out, ""};
  return {out.substr(0, split), out.substr(split + 4)};
}

bool status_is(const Reply& r, int code) {
  return r.head.rfind("HTTP/1.1 " + std::to_string(code), 0) == 0;
}

cv::Mat decode(const Reply& r) {
  const std::vector<unsigned char> bytes(r.body.begin(), r.body.end());
  return cv::imdecode(bytes, cv::IMREAD_COLOR);
}

class OverheadDiagViews : public ::testing::Test {
 protected:
  void SetUp() override {
    cfg_.port = 0;
    cfg_.view_width_px = 480;
    diag_ = std::make_unique<OverheadDiag>(cfg_);
    std::string err;
    ASSERT_TRUE(diag_->start(&err)) << err;
  }
  void TearDown() override { diag_->stop(); }

  Reply get(const std::string& path) { return http_get(diag_->port(), path); }

  const site::Site site_ = test::two_camera_site();
  DiagOutput cfg_;
  std::unique_ptr<OverheadDiag> diag_;
};

// A 1920 x 1080 mid-grey frame with one applied detection (tag 7, a 80 px square at 800..880,
// 400..480) and agv-1's track window (600..1000, 300..600).
CameraView fixed_view() {
  CameraView v;
  v.t_ns = 123'000'000'000;
  v.gray = cv::Mat(1080, 1920, CV_8UC1, cv::Scalar(128));
  overhead::Detection d;
  d.tag.corners_px = {Vec2{800, 400}, Vec2{880, 400}, Vec2{880, 480}, Vec2{800, 480}};
  d.tag.id = 7;
  d.in_fleet = true;
  d.result = overhead::FixResult::kApplied;
  v.detections.push_back(d);
  TrackMark t;
  t.agv = 0;
  t.state = overhead::TrackState::kConfirmed;
  t.window = cv::Rect(600, 300, 400, 300);
  t.predicted_corners_px = d.tag.corners_px;
  v.tracks.push_back(t);
  return v;
}

TEST_F(OverheadDiagViews, SiteSvgShowsEveryVehicleWithItsState) {
  EXPECT_TRUE(status_is(get("/site.svg"), 404)) << "no site attached yet";
  diag_->attach(site_, {});
  ASSERT_GE(site_.fleet.size(), 2u);
  DiagView v;
  const overhead::TrackState states[] = {overhead::TrackState::kConfirmed,
                                         overhead::TrackState::kCoasting};
  for (std::size_t i = 0; i < site_.fleet.size(); ++i) {
    AgvDiag a;
    a.id = site_.fleet[i].id;
    a.track.state = i < 2 ? states[i] : overhead::TrackState::kNone;
    a.track.pose = {1000.0 + 1500.0 * static_cast<double>(i), 2000.0, 0.5};
    a.track.cov = {25.0, 0.0, 0.0, 0.0, 9.0, 0.0, 0.0, 0.0, 1e-4};
    a.track.sigma_xy_mm = 5.0;
    v.agvs.push_back(a);
  }
  v.agvs.push_back({"agv-unseen", {}, ""});
  diag_->update(v);
  const Reply r = get("/site.svg");
  ASSERT_TRUE(status_is(r, 200)) << r.head;
  EXPECT_NE(r.head.find("Content-Type: image/svg+xml"), std::string::npos) << r.head;
  const std::string& svg = r.body;
  EXPECT_EQ(svg.rfind("<svg xmlns=\"http://www.w3.org/2000/svg\"", 0), 0u) << svg.substr(0, 200);
  EXPECT_NE(svg.find("data-agv=\"" + site_.fleet[0].id + "\" data-state=\"confirmed\""),
            std::string::npos)
      << svg;
  EXPECT_NE(svg.find("data-agv=\"" + site_.fleet[1].id + "\" data-state=\"coasting\""),
            std::string::npos)
      << svg;
  // The 3-sigma ellipse of agv-1: sigma 5 mm along x, 3 mm along y.
  EXPECT_NE(svg.find("<ellipse cx=\"1000.0\" cy=\"-2000.0\" rx=\"15.0\" ry=\"9.0\""),
            std::string::npos)
      << svg;
  EXPECT_NE(svg.find("never seen (none): agv-unseen"), std::string::npos);
  EXPECT_EQ(svg.find("data-agv=\"agv-unseen\""), std::string::npos) << "drawn without a pose";
  for (const site::CeilingCamera& c : site_.cameras)
    EXPECT_NE(svg.find("<title>" + c.id + "</title>"), std::string::npos) << c.id;
  const Reply status = get("/api/status.json");
  EXPECT_NE(status.body.find("\"views\":[{\"index\":0,\"id\":\"" + site_.cameras[0].id + "\"}"),
            std::string::npos)
      << status.body;
}

TEST_F(OverheadDiagViews, CameraViewAtTheConfiguredWidthWithTheDetectionDrawn) {
  diag_->attach(site_, {});
  diag_->put_view(0, fixed_view());
  const Reply r = get("/camera/0.png");
  ASSERT_TRUE(status_is(r, 200)) << r.head << r.body;
  EXPECT_NE(r.head.find("X-Frame-Exposure-Ns: 123000000000"), std::string::npos) << r.head;
  const cv::Mat img = decode(r);
  ASSERT_FALSE(img.empty());
  EXPECT_EQ(img.cols, 480);
  EXPECT_EQ(img.rows, 270);
  // The detection's right edge, x = 880 / 4 = 220, halfway down it (y = 110): green.
  const cv::Vec3b edge = img.at<cv::Vec3b>(110, 220);
  EXPECT_GT(edge[1], 150) << edge;
  EXPECT_LT(edge[2], 80) << edge;
  // The track window's left edge, x = 600 / 4 = 150, at y = 140: blue.
  const cv::Vec3b window = img.at<cv::Vec3b>(140, 150);
  EXPECT_GT(window[0], 200) << window;
  EXPECT_LT(window[2], 80) << window;
  // Away from anything drawn: the frame's grey.
  EXPECT_EQ(img.at<cv::Vec3b>(250, 20), cv::Vec3b(128, 128, 128));
}

TEST_F(OverheadDiagViews, UnknownCameraIsNotFoundAndNoFrameYetIsUnavailable) {
  EXPECT_TRUE(status_is(get("/camera/0.png"), 404)) << "no site attached yet";
  diag_->attach(site_, {});
  const std::string n = std::to_string(site_.cameras.size());
  EXPECT_TRUE(status_is(get("/camera/" + n + ".png"), 404));
  EXPECT_TRUE(status_is(get("/camera/999.png"), 404));
  EXPECT_TRUE(status_is(get("/camera/01.png"), 404));
  EXPECT_TRUE(status_is(get("/camera/-1.png"), 404));
  EXPECT_TRUE(status_is(get("/camera/1234.png"), 404));
  EXPECT_TRUE(status_is(get("/camera/0.jpg"), 404));
  const Reply r = get("/camera/1.png");
  EXPECT_TRUE(status_is(r, 503)) << r.head;
  EXPECT_NE(r.body.find(site_.cameras[1].id + ": no frame yet"), std::string::npos) << r.body;
  EXPECT_NE(r.head.find("Retry-After: 1"), std::string::npos) << r.head;
}

// The tracker's side: a frame is copied only after the page asked for its camera, and not
// within CameraViewTap::kMinCopyIntervalNs of the last copy however often it asks.
TEST_F(OverheadDiagViews, TrackerHandsAFrameOverOnlyWhenAskedAndBounded) {
  diag_->attach(site_, {});
  const overhead::FleetTracker tracker(site_.fleet.size());
  const std::vector<overhead::Detection> none;
  const cv::Mat dark(270, 480, CV_8UC1, cv::Scalar(40)), light(270, 480, CV_8UC1, cv::Scalar(200));
  const std::int64_t t0 = 5'000'000'000;
  diag_->offer_frame(0, t0, dark, tracker, none);
  EXPECT_TRUE(status_is(get("/camera/0.png"), 503)) << "copied before anyone asked";
  diag_->offer_frame(0, t0 + 100'000'000, dark, tracker, none);
  Reply r = get("/camera/0.png");
  ASSERT_TRUE(status_is(r, 200)) << r.head;
  EXPECT_EQ(decode(r).at<cv::Vec3b>(10, 10), cv::Vec3b(40, 40, 40));
  const std::int64_t too_soon = t0 + 100'000'000 + CameraViewTap::kMinCopyIntervalNs - 1;
  diag_->offer_frame(0, too_soon, light, tracker, none);
  r = get("/camera/0.png");
  EXPECT_EQ(decode(r).at<cv::Vec3b>(10, 10), cv::Vec3b(40, 40, 40)) << "copied too soon";
  diag_->offer_frame(0, too_soon + 1, light, tracker, none);
  r = get("/camera/0.png");
  EXPECT_EQ(decode(r).at<cv::Vec3b>(10, 10), cv::Vec3b(200, 200, 200));
  EXPECT_NE(r.head.find("X-Frame-Exposure-Ns: " + std::to_string(too_soon + 1)), std::string::npos);
  // Camera 1 was never asked for.
  diag_->offer_frame(1, too_soon + 1, light, tracker, none);
  EXPECT_TRUE(status_is(get("/camera/1.png"), 503));
}

}  // namespace
}  // namespace agv::overhead_app

// Search windows of a ceiling camera (algo/src/overhead/search.cpp): the predicted tag's corners
// against the renderer's own projection and corner order, the widened window holding the truth,
// the area fall-back, the full-sweep cadence, the ids an area may hold, clipping at the border,
// nothing behind the camera or beyond the lens model. Tracks from synthetic fixes.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "agv/overhead/search.hpp"
#include "agv/sim/site_render.hpp"

using namespace agv;
using namespace agv::overhead;

namespace {

constexpr std::int64_t kMs = 1'000'000;
constexpr std::int64_t kNow = 1000 * kMs;

// 1280 x 720 at 6 m looking down, mild barrel distortion: about 1.2 px/cm... on the tray (tags of
// 160 mm are ~40 px); the view on the tray plane is about +-2.6 m by +-1.5 m around the origin.
// Image right is site +x, image down is site -y.
site::CeilingCamera camera(double k1 = -0.05) {
  site::CeilingCamera c;
  c.id = "c0";
  c.intrinsics.width_px = 1280;
  c.intrinsics.height_px = 720;
  c.intrinsics.fx = c.intrinsics.fy = 1400.0;
  c.intrinsics.cx = 639.5;
  c.intrinsics.cy = 359.5;
  c.intrinsics.k1 = k1;
  c.intrinsics.k2 = 0.01;
  return c;
}

std::vector<site::FleetAgv> fleet_of(std::size_t n) {
  std::vector<site::FleetAgv> f(n);
  for (std::size_t i = 0; i < n; ++i) {
    f[i].id = "agv" + std::to_string(i);
    f[i].tag_id = static_cast<std::uint32_t>(10 + i);
  }
  return f;
}

TagFix fix_at(const Pose2& p, double sigma_mm = 5.0) {
  TagFix f;
  f.pose = p;
  f.cov = {sigma_mm * sigma_mm, 0, 0, 0, sigma_mm * sigma_mm, 0, 0, 0, 1e-4};
  return f;
}

// Confirms a track of vehicle i: ten fixes 100 ms apart ending at kNow, driving at v_mps along
// its heading to `p`.
void track(FleetTracker* tr, std::size_t i, const Pose2& p, double v_mps = 0.0) {
  for (int k = 9; k >= 0; --k) {
    const double back_mm = v_mps * 100.0 * k;
    const Pose2 q{p.x_mm - back_mm * std::cos(p.theta_rad),
                  p.y_mm - back_mm * std::sin(p.theta_rad), p.theta_rad};
    tr->add_fix(i, kNow - k * 100 * kMs, fix_at(q));
  }
  ASSERT_EQ(tr->output(i, kNow).state, TrackState::kConfirmed);
}

// The tag's corners at pose p, projected with the renderer's own projection (page order: up is
// the vehicle's +x, right its -y).
std::vector<Vec2> truth_corners(const site::CeilingCamera& cam, const site::FleetAgv& a,
                                const Pose2& p) {
  const double h = 0.5 * a.tag_size_mm;
  std::vector<sim::Vec3> pts;
  for (const Vec2& c : {Vec2{h, h}, Vec2{h, -h}, Vec2{-h, -h}, Vec2{-h, h}}) {
    const Vec2 s = transform(p, c);
    pts.push_back({s.x, s.y, a.tray_height_mm});
  }
  return sim::project_points(sim::RenderCamera::from_ceiling(cam), pts);
}

bool contains(const cv::Rect& r, Vec2 p) {
  return p.x >= r.x - 0.5 && p.x <= r.x + r.width - 0.5 && p.y >= r.y - 0.5 &&
         p.y <= r.y + r.height - 0.5;
}

std::vector<const SearchWindow*> windows_of(const std::vector<SearchWindow>& ws, std::size_t agv) {
  std::vector<const SearchWindow*> out;
  for (const SearchWindow& w : ws) {
    for (std::size_t a : w.agvs) {
      if (a == agv) out.push_back(&w);
    }
  }
  return out;
}

int count_level(const std::vector<SearchWindow>& ws, SearchLevel l) {
  int n = 0;
  for (const SearchWindow& w : ws) n += w.level == l ? 1 : 0;
  return n;
}

CameraSearchState state_at_frame(std::int64_t frames, std::size_t fleet) {
  CameraSearchState s;
  s.frames = frames;
  s.missed.assign(fleet, 0);
  return s;
}

TEST(OverheadSearch, TrackWindowsHoldTheTruthCorners) {
  const site::CeilingCamera cam = camera();
  const std::vector<site::FleetAgv> fleet = fleet_of(5);
  const std::vector<Pose2> poses = {
      {0, 0, 0}, {1500, 800, 0.7}, {-2000, -1000, -2.5}, {2300, -1200, kPi}, {-600, 1100, 1.9}};
  FleetTracker tr(fleet.size());
  for (std::size_t i = 0; i < poses.size(); ++i) track(&tr, i, poses[i], i % 2 ? 0.8 : 0.0);
  const std::vector<SearchWindow> ws =
      plan_search(cam, fleet, tr, kNow, SearchParams{}, state_at_frame(5, fleet.size()));
  EXPECT_EQ(count_level(ws, SearchLevel::kFull), 0);
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const std::vector<const SearchWindow*> mine = windows_of(ws, i);
    ASSERT_EQ(mine.size(), 1u) << i;
    const SearchWindow& w = *mine[0];
    EXPECT_EQ(w.level, SearchLevel::kTrack);
    EXPECT_EQ(w.agvs.size(), 1u);
    const std::vector<Vec2> truth = truth_corners(cam, fleet[i], tr.output(i, kNow).pose);
    const std::vector<Vec2> at_fix = truth_corners(cam, fleet[i], poses[i]);
    for (std::size_t c = 0; c < 4; ++c) {
      // The prediction is the track's pose projected as the renderer does, corner for corner.
      EXPECT_NEAR(w.predicted_corners_px[c].x, truth[c].x, 1e-6) << i << " " << c;
      EXPECT_NEAR(w.predicted_corners_px[c].y, truth[c].y, 1e-6) << i << " " << c;
      EXPECT_TRUE(contains(w.rect, at_fix[c])) << i << " " << c;
    }
    // Small: the tag (about 40 px), 3 sigma of a few millimetres, the margin.
    EXPECT_LT(w.rect.width, 110) << i;
    EXPECT_LT(w.rect.height, 110) << i;
  }
  // A moving vehicle 150 ms later: the window at that time still holds its tag.
  const Pose2 later = tr.output(1, kNow + 150 * kMs).pose;
  const std::vector<SearchWindow> ws2 =
      plan_search(cam, fleet, tr, kNow + 150 * kMs, SearchParams{}, state_at_frame(6, 5));
  const Pose2 truth_later{poses[1].x_mm + 120.0 * std::cos(0.7),
                          poses[1].y_mm + 120.0 * std::sin(0.7), 0.7};
  EXPECT_LT(std::hypot(later.x_mm - truth_later.x_mm, later.y_mm - truth_later.y_mm), 10.0);
  for (const Vec2& c : truth_corners(cam, fleet[1], truth_later)) {
    EXPECT_TRUE(contains(windows_of(ws2, 1).at(0)->rect, c));
  }
}

// The corner order and projection against a rendered frame's truth (a tiny image).
TEST(OverheadSearch, PredictedCornersMatchTheRenderersTruth) {
  site::CeilingCamera cam = camera(-0.08);
  cam.intrinsics.width_px = 320;
  cam.intrinsics.height_px = 180;
  cam.intrinsics.fx = cam.intrinsics.fy = 350.0;
  cam.intrinsics.cx = 159.5;
  cam.intrinsics.cy = 89.5;
  sim::SiteScene scene;
  scene.site.outline.vertices_mm = {{-5000, -5000}, {5000, -5000}, {5000, 5000}, {-5000, 5000}};
  scene.site.fleet = fleet_of(2);
  scene.site.fleet[1].tray_height_mm = 550.0;
  scene.site.fleet[1].tag_size_mm = 200.0;
  const std::vector<Pose2> poses = {{-700, 300, 0.52}, {900, -400, -2.2}};
  for (const Pose2& p : poses) scene.agvs.push_back({p, 0.0, 0.0});
  sim::SiteRenderParams rp;
  rp.edge_supersample = 1;
  rp.visibility_grid = 2;
  const sim::SiteFrameRenderer renderer(cam.intrinsics);
  const sim::RenderResult r = renderer.render(scene, sim::RenderCamera::from_ceiling(cam), rp, 1);
  ASSERT_EQ(r.agvs.size(), 2u);
  FleetTracker tr(2);
  for (std::size_t i = 0; i < 2; ++i) {
    for (int k = 2; k >= 0; --k) tr.add_fix(i, kNow - k * 100 * kMs, fix_at(poses[i], 1.0));
  }
  const std::vector<SearchWindow> ws =
      plan_search(cam, scene.site.fleet, tr, kNow, SearchParams{}, state_at_frame(1, 2));
  for (std::size_t i = 0; i < 2; ++i) {
    ASSERT_TRUE(r.agvs[i].projected);
    const SearchWindow& w = *windows_of(ws, i).at(0);
    ASSERT_EQ(w.level, SearchLevel::kTrack);
    for (std::size_t c = 0; c < 4; ++c) {
      EXPECT_NEAR(w.predicted_corners_px[c].x, r.agvs[i].tag_corners_px[c].x, 0.01) << i << c;
      EXPECT_NEAR(w.predicted_corners_px[c].y, r.agvs[i].tag_corners_px[c].y, 0.01) << i << c;
    }
  }
}

TEST(OverheadSearch, MissedWindowFallsBackToTheArea) {
  const site::CeilingCamera cam = camera();
  const std::vector<site::FleetAgv> fleet = fleet_of(3);
  FleetTracker tr(3);
  track(&tr, 0, {-2200, 1200, 0.0});  // top-left tile (image x ~ 70, y ~ 60)
  track(&tr, 1, {-2000, 1000, 1.0});  // same tile
  track(&tr, 2, {1000, 0, 0.3});
  CameraSearchState st = state_at_frame(3, 3);
  st.missed[0] = st.missed[1] = 1;
  const std::vector<SearchWindow> ws = plan_search(cam, fleet, tr, kNow, SearchParams{}, st);
  ASSERT_EQ(count_level(ws, SearchLevel::kArea), 1);  // one window for both
  const SearchWindow& area = *windows_of(ws, 0).at(0);
  EXPECT_EQ(area.level, SearchLevel::kArea);
  EXPECT_EQ(area.agvs, (std::vector<std::size_t>{0, 1}));
  // Tiles of 320 x 240 (4 x 3): the top-left one and its neighbours.
  EXPECT_EQ(area.rect, cv::Rect(0, 0, 640, 480));
  for (std::size_t i = 0; i < 2; ++i) {
    for (const Vec2& c : truth_corners(cam, fleet[i], tr.output(i, kNow).pose)) {
      EXPECT_TRUE(contains(area.rect, c));
    }
  }
  EXPECT_EQ(windows_of(ws, 2).at(0)->level, SearchLevel::kTrack);
  // A centre tile's area is 3 x 3 tiles.
  st.missed = {0, 0, 1};
  const std::vector<SearchWindow> ws2 = plan_search(cam, fleet, tr, kNow, SearchParams{}, st);
  EXPECT_EQ(windows_of(ws2, 2).at(0)->rect, cv::Rect(320, 0, 960, 720));
  EXPECT_EQ(windows_of(ws2, 0).at(0)->level, SearchLevel::kTrack);
  EXPECT_EQ(count_level(ws2, SearchLevel::kFull), 0);
  // Missed in its area too: the whole image as well once no camera sees it (coasting), not
  // while another camera keeps its track fresh. The area stays (searched first).
  st.missed = {0, 0, 2};
  EXPECT_EQ(count_level(plan_search(cam, fleet, tr, kNow, SearchParams{}, st), SearchLevel::kFull),
            0);
  const std::int64_t later = kNow + 400 * kMs;
  ASSERT_EQ(tr.output(2, later).state, TrackState::kCoasting);
  const std::vector<SearchWindow> ws3 = plan_search(cam, fleet, tr, later, SearchParams{}, st);
  EXPECT_EQ(windows_of(ws3, 2).at(0)->level, SearchLevel::kArea);
  EXPECT_EQ(count_level(ws3, SearchLevel::kFull), 1);
}

TEST(OverheadSearch, WideWindowFallsBackToTheArea) {
  const site::CeilingCamera cam = camera();
  const std::vector<site::FleetAgv> fleet = fleet_of(1);
  FleetTracker tr(1);
  track(&tr, 0, {0, 0, 0}, 0.5);
  SearchParams sp;
  const CameraSearchState st = state_at_frame(2, 1);
  EXPECT_EQ(plan_search(cam, fleet, tr, kNow, sp, st).at(0).level, SearchLevel::kTrack);
  // 600 ms without a fix: coasting, sigma of tens of centimetres.
  const std::int64_t later = kNow + 600 * kMs;
  ASSERT_EQ(tr.output(0, later).state, TrackState::kCoasting);
  sp.max_window_px = 300;
  const SearchWindow w = plan_search(cam, fleet, tr, later, sp, st).at(0);
  EXPECT_EQ(w.level, SearchLevel::kArea);
  sp.max_window_px = 2000;
  const SearchWindow wide = plan_search(cam, fleet, tr, later, sp, st).at(0);
  EXPECT_EQ(wide.level, SearchLevel::kTrack);
  EXPECT_GT(wide.rect.width, 300);
  // The area (the centre tile's 3 x 3) searched only where the window lies: the window holds the
  // tag at 3 sigma. After a miss, the whole area.
  const cv::Rect area(320, 0, 960, 720);
  EXPECT_EQ(w.rect, wide.rect & area);
  EXPECT_LT(w.rect.area(), area.area() / 2);
  sp.max_window_px = 300;
  CameraSearchState missed = st;
  missed.missed[0] = 1;
  EXPECT_EQ(plan_search(cam, fleet, tr, later, sp, missed).at(0).rect, area);
}

// A large tag's window is searched shrunk (its smallest side over decimated_side_px, at most
// max_decimation times), and its size is judged in the pixels it is searched at; an area holding
// a large and a small tag is shrunk for the small one.
TEST(OverheadSearch, LargeTagsAreSearchedShrunk) {
  const site::CeilingCamera cam = camera();
  std::vector<site::FleetAgv> fleet = fleet_of(2);
  fleet[0].tag_size_mm = 640.0;  // about 160 px in this view
  FleetTracker tr(2);
  track(&tr, 0, {-2000, 1000, 0.4}, 0.5);
  track(&tr, 1, {-1700, 900, 1.0});  // same tile
  SearchParams sp;
  CameraSearchState st = state_at_frame(2, 2);
  std::vector<SearchWindow> ws = plan_search(cam, fleet, tr, kNow, sp, st);
  ASSERT_EQ(windows_of(ws, 0).at(0)->level, SearchLevel::kTrack);
  EXPECT_EQ(windows_of(ws, 0).at(0)->decimation, 4);
  EXPECT_EQ(windows_of(ws, 1).at(0)->decimation, 1);
  sp.decimated_side_px = 60.0;
  EXPECT_EQ(windows_of(plan_search(cam, fleet, tr, kNow, sp, st), 0).at(0)->decimation, 2);
  sp.decimated_side_px = 32.0;
  sp.max_decimation = 1;
  EXPECT_EQ(windows_of(plan_search(cam, fleet, tr, kNow, sp, st), 0).at(0)->decimation, 1);
  // Coasting: a window wider than max_window_px at full resolution, not shrunk 4 times.
  const std::int64_t later = kNow + 600 * kMs;
  ASSERT_EQ(tr.output(0, later).state, TrackState::kCoasting);
  sp.max_decimation = 4;
  const int width = windows_of(plan_search(cam, fleet, tr, later, sp, st), 0).at(0)->rect.width;
  sp.max_window_px = width / 2;
  ASSERT_GT(width, sp.max_window_px);
  EXPECT_EQ(windows_of(plan_search(cam, fleet, tr, later, sp, st), 0).at(0)->level,
            SearchLevel::kTrack);
  sp.max_decimation = 1;
  EXPECT_EQ(windows_of(plan_search(cam, fleet, tr, later, sp, st), 0).at(0)->level,
            SearchLevel::kArea);
  // Areas: the large tag's alone is shrunk, one shared with the small tag is not.
  sp = SearchParams{};
  st.missed = {1, 0};
  ws = plan_search(cam, fleet, tr, kNow, sp, st);
  ASSERT_EQ(windows_of(ws, 0).at(0)->level, SearchLevel::kArea);
  EXPECT_EQ(windows_of(ws, 0).at(0)->decimation, 4);
  st.missed = {1, 1};
  ws = plan_search(cam, fleet, tr, kNow, sp, st);
  ASSERT_EQ(count_level(ws, SearchLevel::kArea), 1);
  EXPECT_EQ(windows_of(ws, 0).at(0)->decimation, 1);
  sp.max_decimation = 0;
  EXPECT_NE(validate(sp), "");
  sp.max_decimation = 4;
  sp.decimated_side_px = 4.0;
  EXPECT_NE(validate(sp), "");
}

TEST(OverheadSearch, FullSweepCadence) {
  const site::CeilingCamera cam = camera();
  const std::vector<site::FleetAgv> fleet = fleet_of(2);
  FleetTracker tr(2);
  track(&tr, 0, {0, 0, 0});
  track(&tr, 1, {500, 500, 0});
  SearchParams sp;
  sp.full_sweep_every_frames = 15;
  auto fulls = [&](const FleetTracker& t, std::int64_t frames) {
    return count_level(plan_search(cam, fleet, t, kNow, sp, state_at_frame(frames, 2)),
                       SearchLevel::kFull);
  };
  // Every vehicle tracked: the camera's first frame only.
  EXPECT_EQ(fulls(tr, 0), 1);
  for (std::int64_t f = 1; f <= 45; ++f) EXPECT_EQ(fulls(tr, f), 0) << f;
  // One vehicle without a track: every 15th frame, covering the whole image, last.
  tr.reset(1);
  for (std::int64_t f = 0; f <= 45; ++f) EXPECT_EQ(fulls(tr, f), f % 15 == 0 ? 1 : 0) << f;
  const std::vector<SearchWindow> ws = plan_search(cam, fleet, tr, kNow, sp, state_at_frame(30, 2));
  EXPECT_EQ(ws.back().level, SearchLevel::kFull);
  EXPECT_EQ(ws.back().rect, cv::Rect(0, 0, 1280, 720));
  EXPECT_TRUE(ws.back().agvs.empty());
  EXPECT_EQ(ws.front().level, SearchLevel::kTrack);  // the tracked one keeps its window
  // A lost track counts as none; a fleet longer than the tracker too.
  FleetTracker lost(2);
  track(&lost, 0, {0, 0, 0});
  track(&lost, 1, {500, 500, 0});
  const std::int64_t much_later = kNow + 5000 * kMs;
  lost.update_states(much_later);
  EXPECT_EQ(count_level(plan_search(cam, fleet, lost, much_later, sp, state_at_frame(15, 2)),
                        SearchLevel::kFull),
            1);
  EXPECT_EQ(count_level(plan_search(cam, fleet_of(3), tr, kNow, sp, state_at_frame(15, 3)),
                        SearchLevel::kFull),
            1);
  sp.full_sweep_every_frames = 0;
  EXPECT_EQ(fulls(tr, 15), 0);
  EXPECT_EQ(fulls(tr, 0), 1);
}

// The same view on a sensor 3 times larger (3840 x 2160: 8.3 Mpx, 160 mm tags about 120 px).
site::CeilingCamera camera_4k() {
  site::CeilingCamera c = camera();
  CameraIntrinsics& k = c.intrinsics;
  k.width_px *= 3;
  k.height_px *= 3;
  k.fx *= 3;
  k.fy *= 3;
  k.cx = (k.cx + 0.5) * 3 - 0.5;
  k.cy = (k.cy + 0.5) * 3 - 0.5;
  return c;
}

// A large image's interval sweep is one horizontal strip per frame (4 for 3840 x 2160 at
// 2.5 Mpx), together the whole image, each two overlapping by more than any tag's extent; the
// camera's first frame stays whole. Whole-image windows are shrunk for the smallest tag in view.
TEST(OverheadSearch, LargeImagesAreSweptAStripAFrame) {
  const site::CeilingCamera cam = camera_4k();
  const std::vector<site::FleetAgv> fleet = fleet_of(2);
  FleetTracker tr(2);
  track(&tr, 0, {0, 0, 0});  // vehicle 1 has no track: the sweep is due
  const SearchParams sp;
  const ViewTagSizes sizes = view_tag_sizes(cam, fleet);
  ASSERT_TRUE(sizes.ok);
  // 160 mm at 5.6 m with fx 4200: 120 px at the centre, less at the corners (barrel).
  EXPECT_GT(sizes.min_side_px, 100.0);
  EXPECT_LE(sizes.min_side_px, 120.5);
  EXPECT_GE(sizes.max_extent_px, 120.0 * std::sqrt(2.0) - 0.5);
  const auto full_of = [&](std::int64_t frames, const SearchParams& p) -> const SearchWindow* {
    static std::vector<SearchWindow> ws;
    ws = plan_search(cam, fleet, tr, kNow, p, state_at_frame(frames, 2));
    return ws.back().level == SearchLevel::kFull ? &ws.back() : nullptr;
  };
  ASSERT_NE(full_of(0, sp), nullptr);
  EXPECT_EQ(full_of(0, sp)->rect, cv::Rect(0, 0, 3840, 2160));
  EXPECT_EQ(full_of(0, sp)->decimation, 3);
  std::vector<cv::Rect> strips;
  for (std::int64_t f = 15; f < 30; ++f) {
    const SearchWindow* w = full_of(f, sp);
    if (f < 19) {
      ASSERT_NE(w, nullptr) << f;
      strips.push_back(w->rect);
      EXPECT_EQ(w->decimation, 3);
    } else {
      EXPECT_EQ(w, nullptr) << f;
    }
  }
  EXPECT_EQ(strips.front().y, 0);
  EXPECT_EQ(strips.back().y + strips.back().height, 2160);
  for (std::size_t i = 0; i < strips.size(); ++i) {
    EXPECT_EQ(strips[i].x, 0);
    EXPECT_EQ(strips[i].width, 3840);
    EXPECT_LT(strips[i].height, 2160 / 2);
    if (i == 0) continue;
    const int overlap = strips[i - 1].y + strips[i - 1].height - strips[i].y;
    EXPECT_GT(overlap, sizes.max_extent_px) << i;
  }
  // 0: the whole image at once, at the interval only.
  SearchParams whole = sp;
  whole.sweep_max_pixels = 0;
  ASSERT_NE(full_of(15, whole), nullptr);
  EXPECT_EQ(full_of(15, whole)->rect, cv::Rect(0, 0, 3840, 2160));
  EXPECT_EQ(full_of(16, whole), nullptr);
  // Never more strips than frames between sweeps.
  SearchParams often = sp;
  often.full_sweep_every_frames = 2;
  ASSERT_NE(full_of(3, often), nullptr);
  EXPECT_EQ(full_of(3, often)->rect.y + full_of(3, often)->rect.height, 2160);
  // An image under the limit: whole, as before.
  const site::CeilingCamera small = camera();
  EXPECT_EQ(plan_search(small, fleet, tr, kNow, sp, state_at_frame(15, 2)).back().rect,
            cv::Rect(0, 0, 1280, 720));
  whole.sweep_max_pixels = -1;
  EXPECT_NE(validate(whole), "");
  // The tags' extent unknown (no usable tag size): the interval's first frame whole, no strips.
  std::vector<site::FleetAgv> unsized = fleet;
  for (site::FleetAgv& a : unsized) a.tag_size_mm = 0.0;
  EXPECT_FALSE(view_tag_sizes(cam, unsized).ok);
  const std::vector<SearchWindow> w15 =
      plan_search(cam, unsized, tr, kNow, sp, state_at_frame(15, 2));
  EXPECT_EQ(w15.back().level, SearchLevel::kFull);
  EXPECT_EQ(w15.back().rect, cv::Rect(0, 0, 3840, 2160));
  EXPECT_EQ(w15.back().decimation, 1);
  EXPECT_EQ(count_level(plan_search(cam, unsized, tr, kNow, sp, state_at_frame(16, 2)),
                        SearchLevel::kFull),
            0);
}

// On a large image with tags too small to shrink, an area (3 x 3 tiles: most of the image) and
// the whole-image search for a vehicle lost in view are a strip per frame: an area's part in the
// prediction's strip first, the others on later misses in a row, together all of it, each holding
// a whole tag wherever it lies; the lost vehicle's search the image's strips in turn. Small
// images, and sweep_max_pixels 0, search them at once.
TEST(OverheadSearch, LargeAreasAndLostSearchesAreAStripAFrame) {
  const site::CeilingCamera cam = camera_4k();
  std::vector<site::FleetAgv> fleet = fleet_of(2);
  for (site::FleetAgv& a : fleet) a.tag_size_mm = 80.0;  // about 60 px: never shrunk
  FleetTracker tr(2);
  track(&tr, 0, {-300, 200, 0.4});  // centre tile: its area is 3 x 3 tiles, 6.2 Mpx
  track(&tr, 1, {1800, -1000, 0.0});
  const ViewTagSizes sizes = view_tag_sizes(cam, fleet);
  ASSERT_TRUE(sizes.ok);
  ASSERT_LT(sizes.min_side_px, 64.0);
  const auto area_after = [&](int misses, const SearchParams& sp) {
    CameraSearchState st = state_at_frame(7, 2);
    st.missed[0] = static_cast<std::uint8_t>(misses);
    const std::vector<SearchWindow> ws = plan_search(cam, fleet, tr, kNow, sp, st);
    EXPECT_EQ(count_level(ws, SearchLevel::kFull), 0);
    const SearchWindow w = *windows_of(ws, 0).at(0);
    EXPECT_EQ(w.level, SearchLevel::kArea);
    EXPECT_EQ(w.decimation, 1);
    return w.rect;
  };
  SearchParams at_once;
  at_once.sweep_max_pixels = 0;
  const cv::Rect whole_area = area_after(1, at_once);
  EXPECT_EQ(whole_area, cv::Rect(0, 0, 2880, 2160));
  const std::vector<Vec2> truth = truth_corners(cam, fleet[0], tr.output(0, kNow).pose);
  for (const Vec2& c : truth) EXPECT_TRUE(contains(area_after(1, SearchParams{}), c));
  std::vector<cv::Rect> parts;
  cv::Rect covered;
  for (int m = 1; m <= 3; ++m) {
    const cv::Rect r = area_after(m, SearchParams{});
    EXPECT_LE(static_cast<long long>(r.area()), SearchParams{}.sweep_max_pixels) << m;
    EXPECT_EQ((r & whole_area), r) << m;
    for (const cv::Rect& q : parts) EXPECT_NE(q, r) << m;
    parts.push_back(r);
    covered = covered.empty() ? r : (covered | r);
  }
  EXPECT_EQ(covered, whole_area);
  EXPECT_EQ(area_after(4, SearchParams{}), parts[0]);  // and round again
  // Any tag in the area lies wholly in one part: neighbours overlap by its largest extent.
  std::sort(parts.begin(), parts.end(),
            [](const cv::Rect& a, const cv::Rect& b) { return a.y < b.y; });
  for (std::size_t i = 1; i < parts.size(); ++i) {
    EXPECT_GT(parts[i - 1].y + parts[i - 1].height - parts[i].y, sizes.max_extent_px) << i;
  }
  // The other vehicle stays on its track window throughout.
  EXPECT_EQ(windows_of(plan_search(cam, fleet, tr, kNow, SearchParams{}, state_at_frame(7, 2)), 1)
                .at(0)
                ->level,
            SearchLevel::kTrack);

  // Lost in view (coasting, missed its area too): the whole image's strips in turn.
  const std::int64_t later = kNow + 400 * kMs;
  ASSERT_EQ(tr.output(0, later).state, TrackState::kCoasting);
  const auto lost_search = [&](std::int64_t frames, const SearchParams& sp) {
    CameraSearchState st = state_at_frame(frames, 2);
    st.missed[0] = 2;
    const std::vector<SearchWindow> ws = plan_search(cam, fleet, tr, later, sp, st);
    EXPECT_EQ(count_level(ws, SearchLevel::kFull), 1);
    return ws.back().rect;
  };
  EXPECT_EQ(lost_search(7, at_once), cv::Rect(0, 0, 3840, 2160));
  EXPECT_EQ(lost_search(0, SearchParams{}), cv::Rect(0, 0, 3840, 2160));  // the first frame
  cv::Rect image_covered;
  for (std::int64_t f = 8; f < 12; ++f) {
    const cv::Rect r = lost_search(f, SearchParams{});
    EXPECT_EQ(r.width, 3840);
    EXPECT_LT(r.height, 2160 / 2);
    image_covered = image_covered.empty() ? r : (image_covered | r);
  }
  EXPECT_EQ(image_covered, cv::Rect(0, 0, 3840, 2160));
  // A small image: at once, as before.
  const site::CeilingCamera small = camera();
  CameraSearchState st = state_at_frame(7, 2);
  st.missed[0] = 2;
  const std::vector<SearchWindow> ws = plan_search(small, fleet, tr, later, SearchParams{}, st);
  EXPECT_EQ(ws.back().rect, cv::Rect(0, 0, 1280, 720));
  EXPECT_EQ(windows_of(ws, 0).at(0)->rect, cv::Rect(0, 0, 960, 720));
}

TEST(OverheadSearch, IdsInAreaHoldNearVehiclesOnly) {
  const site::CeilingCamera cam = camera();
  std::vector<site::FleetAgv> fleet = fleet_of(6);
  FleetTracker tr(6);
  track(&tr, 0, {0, 0, 0});
  track(&tr, 1, {250, 0, 1.0});               // beside it: its tag reaches into the window
  track(&tr, 2, {1500, 800, 0.0});            // 1.7 m away
  track(&tr, 3, {-2000, -1000, 0});           // far
  tr.add_fix(4, kNow, fix_at({2000, 0, 0}));  // tentative: could be anywhere
  // 5: no track at all.
  const std::vector<SearchWindow> ws =
      plan_search(cam, fleet, tr, kNow, SearchParams{}, state_at_frame(1, 6));
  const SearchWindow& w0 = *windows_of(ws, 0).at(0);
  EXPECT_EQ(ids_in_area(cam, fleet, tr, kNow, w0.rect),
            (std::vector<std::uint32_t>{10, 11, 14, 15}));
  // Vehicle 3's sigma widened by coasting reaches a window that its position alone would not.
  const std::int64_t later = kNow + 600 * kMs;
  ASSERT_EQ(tr.output(3, later).state, TrackState::kCoasting);
  const cv::Rect near3 = windows_of(ws, 3).at(0)->rect + cv::Point(150, 0);
  EXPECT_EQ(ids_in_area(cam, fleet, tr, kNow, near3), (std::vector<std::uint32_t>{14, 15}));
  const std::vector<std::uint32_t> ids_later = ids_in_area(cam, fleet, tr, later, near3);
  EXPECT_NE(std::find(ids_later.begin(), ids_later.end(), 13u), ids_later.end());
  // A valid vehicle behind the camera (its tray above it) is in no set; the whole image holds
  // every other one.
  fleet[2].tray_height_mm = 6500.0;
  EXPECT_EQ(ids_in_area(cam, fleet, tr, kNow, cv::Rect(0, 0, 1280, 720)),
            (std::vector<std::uint32_t>{10, 11, 13, 14, 15}));
}

TEST(OverheadSearch, WindowsAreClippedAtTheBorder) {
  const site::CeilingCamera cam = camera();
  const std::vector<site::FleetAgv> fleet = fleet_of(3);
  FleetTracker tr(3);
  track(&tr, 0, {2560, 0, 0.4});    // tag across the right edge (x ~ 1273 px)
  track(&tr, 1, {-100, -1420, 0});  // across the bottom edge (y ~ 713 px)
  track(&tr, 2, {4000, 0, 0});      // 1.4 m beyond the view
  const std::vector<SearchWindow> ws =
      plan_search(cam, fleet, tr, kNow, SearchParams{}, state_at_frame(1, 3));
  const cv::Rect image(0, 0, 1280, 720);
  const SearchWindow& right = *windows_of(ws, 0).at(0);
  EXPECT_EQ(right.rect & image, right.rect);
  EXPECT_EQ(right.rect.x + right.rect.width, 1280);
  EXPECT_GT(right.rect.width, 10);
  const SearchWindow& bottom = *windows_of(ws, 1).at(0);
  EXPECT_EQ(bottom.rect & image, bottom.rect);
  EXPECT_EQ(bottom.rect.y + bottom.rect.height, 720);
  EXPECT_TRUE(windows_of(ws, 2).empty());
  // A missed one near the border: the border tiles.
  CameraSearchState st = state_at_frame(1, 3);
  st.missed[0] = 1;
  EXPECT_EQ(windows_of(plan_search(cam, fleet, tr, kNow, SearchParams{}, st), 0).at(0)->rect,
            cv::Rect(640, 0, 640, 720));
}

TEST(OverheadSearch, NoWindowBehindTheCameraOrBeyondTheLens) {
  std::vector<site::FleetAgv> fleet = fleet_of(2);
  fleet[0].tray_height_mm = 6500.0;  // above a camera at 6 m
  FleetTracker tr(2);
  track(&tr, 0, {0, 0, 0});
  // Strong barrel distortion folds rays 60 degrees off the axis back into the image.
  const site::CeilingCamera fisheye = camera(-0.3);
  const double off_mm = 5600.0 * 1.65;  // normalised radius 1.65
  track(&tr, 1, {off_mm, 0, 0});
  Vec2 folded;
  ASSERT_TRUE(site_to_pixel(fisheye, off_mm, 0.0, 400.0, &folded));
  ASSERT_TRUE(contains(cv::Rect(0, 0, 1280, 720), folded));  // the fold the check must catch
  const std::vector<SearchWindow> ws =
      plan_search(fisheye, fleet, tr, kNow, SearchParams{}, state_at_frame(1, 2));
  EXPECT_TRUE(ws.empty());
  EXPECT_TRUE(ids_in_area(fisheye, fleet, tr, kNow, cv::Rect(0, 0, 1280, 720)).empty());
}

TEST(OverheadSearch, BadInput) {
  SearchParams sp;
  EXPECT_EQ(validate(sp), "");
  sp.area_cols = 0;
  EXPECT_NE(validate(sp).find("area_cols"), std::string::npos);
  const site::CeilingCamera cam = camera();
  const std::vector<site::FleetAgv> fleet = fleet_of(2);
  FleetTracker tr(2);
  track(&tr, 0, {0, 0, 0});
  const std::vector<SearchWindow> ws = plan_search(cam, fleet, tr, kNow, sp, state_at_frame(3, 2));
  ASSERT_EQ(ws.size(), 1u);
  EXPECT_EQ(ws[0].level, SearchLevel::kFull);
  sp = {};
  sp.window_sigmas = std::nan("");
  EXPECT_NE(validate(sp).find("window_sigmas"), std::string::npos);
  // Invalid intrinsics: nothing to look at.
  site::CeilingCamera broken = cam;
  broken.intrinsics.width_px = 0;
  EXPECT_TRUE(plan_search(broken, fleet, tr, kNow, SearchParams{}, state_at_frame(0, 2)).empty());
  broken = cam;
  broken.intrinsics.fx = 0.0;
  const std::vector<SearchWindow> none_tracked =
      plan_search(broken, fleet, tr, kNow, SearchParams{}, state_at_frame(0, 2));
  EXPECT_EQ(none_tracked.size(), 1u);  // the first frame's sweep only
  // A missed vector shorter than the fleet, a fleet shorter than the tracker.
  CameraSearchState st;
  st.frames = 4;
  EXPECT_EQ(plan_search(cam, fleet_of(1), tr, kNow, SearchParams{}, st).size(), 1u);
}

}  // namespace

// CameraFrameProcessor (algo/src/overhead/camera_frame.cpp) on rendered frames of one 1280 x 720
// ceiling camera 4 m up: three vehicles of the fleet (a fourth is away) and a vehicle whose tag
// is not the fleet's. The first frame sweeps the whole image; later frames read the tracked tags on
// their windows; a stranger's tag is counted, never a fix; a parcel over one tag leaves that track
// coasting; bad input is refused with a reason.
#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <string>
#include <vector>

#include "agv/overhead/camera_frame.hpp"
#include "agv/sim/site_render.hpp"

namespace agv::overhead {
namespace {

constexpr int kFrames = 7;
constexpr int kCoveredFrom = 4;  // frames from here on have a parcel over vehicle 1's tag
constexpr std::int64_t kPeriodNs = 100'000'000;

site::CeilingCamera test_camera() {
  site::CeilingCamera c;
  c.id = "ceiling";
  c.intrinsics.width_px = 1280;
  c.intrinsics.height_px = 720;
  c.intrinsics.fx = c.intrinsics.fy = 900.0;  // 160 mm tags at 3.6 m: 40 px
  c.intrinsics.cx = 639.5;
  c.intrinsics.cy = 359.5;
  c.intrinsics.k1 = -0.05;
  c.t_site_cam_mm = {0.0, 0.0, 4000.0};
  return c;
}

site::FleetAgv agv(const std::string& id, std::uint32_t tag) {
  site::FleetAgv a;
  a.id = id;
  a.tag_id = tag;
  return a;
}

struct Sequence {
  std::vector<std::vector<Detection>> dets;    // per frame
  std::vector<FrameCounters> counters;         // after each frame
  std::vector<std::vector<TrackOutput>> outs;  // at each frame's time, after it
  std::vector<std::vector<sim::AgvState>> truth;
  std::vector<std::vector<std::uint8_t>> missed;
  TrackerCounters tracker;
};

// The frames are rendered and processed once for every test below, with the tray fit off (the
// tag path alone) and on; and once with the tray fit on and a parcel wider than the tray on every
// side, which hides its outline.
Sequence run_sequence(bool tray_fit, double parcel_mm = 320.0) {
  {
    Sequence out;
    sim::SiteScene scene;
    scene.site.outline.vertices_mm = {{-5000, -5000}, {5000, -5000}, {5000, 5000}, {-5000, 5000}};
    scene.site.fleet = {agv("a1", 1), agv("a2", 2), agv("a3", 3), agv("stranger", 99)};
    // Slow enough that the first prediction (a track of one fix has no speed yet) puts the
    // predicted square within the detector's reach of the real one.
    const std::vector<sim::AgvState> start{{{-1200, -300, 0.3}, 0.1, 0.05},
                                           {{0, 350, 2.0}, 0.08, -0.05},
                                           {{1300, -200, -1.0}, 0.1, 0.0},
                                           {{700, 950, 0.5}, 0.0, 0.0}};
    const site::CeilingCamera cam = test_camera();
    // The fleet: the three vehicles on the floor and one that is not (never tracked, so the
    // camera keeps sweeping the whole image for it).
    std::vector<site::FleetAgv> fleet(scene.site.fleet.begin(), scene.site.fleet.begin() + 3);
    fleet.push_back(agv("away", 4));
    SearchParams sp;
    sp.full_sweep_every_frames = 3;  // frames 0, 3, 6 also sweep the whole image
    CameraFrameProcessor proc({cam}, fleet, {}, sp);
    proc.set_tray_fit(tray_fit);
    FleetTracker tracker(fleet.size());
    const sim::SiteFrameRenderer renderer(cam.intrinsics);
    sim::SiteRenderParams rp;
    rp.read_noise_sigma = 2.0;
    rp.defocus_sigma_px = 0.5;
    rp.edge_supersample = 2;  // keeps the seven renders short under qemu
    for (int f = 0; f < kFrames; ++f) {
      const std::int64_t t = f * kPeriodNs;
      scene.agvs.clear();
      for (const sim::AgvState& s : start) {
        sim::AgvState now = s;
        now.pose = sim::advance_agv_pose(s, 1e-9 * static_cast<double>(t));
        scene.agvs.push_back(now);
      }
      scene.parcels.clear();
      if (f >= kCoveredFrom)
        scene.parcels.push_back({1, 0.0, 0.0, 0.3, parcel_mm, parcel_mm, 200, 150});
      const cv::Mat img =
          renderer.render(scene, sim::RenderCamera::from_ceiling(cam), rp, 5 + f).image;
      std::vector<Detection> d;
      std::string error;
      EXPECT_TRUE(proc.process(0, t, img, &tracker, &d, &error)) << error;
      out.dets.push_back(d);
      out.counters.push_back(proc.counters());
      tracker.update_states(t);
      out.outs.push_back(tracker.outputs(t));
      out.truth.push_back(scene.agvs);
      out.missed.push_back(proc.search_state(0).missed);
    }
    out.tracker = tracker.counters();
    return out;
  }
}

const Sequence& sequence() {
  static const Sequence r = run_sequence(false);
  return r;
}

const Sequence& sequence_with_trays() {
  static const Sequence r = run_sequence(true);
  return r;
}

const Sequence& sequence_tray_hidden() {
  static const Sequence r = run_sequence(true, 900.0);
  return r;
}

const Detection* find(const std::vector<Detection>& d, std::uint32_t tag) {
  for (const Detection& x : d) {
    if (x.tag.id == tag) return &x;
  }
  return nullptr;
}

TEST(CameraFrame, FirstFrameSweepsTheImageAndStartsEveryTrack) {
  const Sequence& r = sequence();
  EXPECT_EQ(r.counters[0].windows_full, 1u);
  EXPECT_EQ(r.counters[0].windows_track, 0u);
  for (std::uint32_t tag : {1u, 2u, 3u}) {
    const Detection* d = find(r.dets[0], tag);
    ASSERT_NE(d, nullptr) << "tag " << tag;
    EXPECT_TRUE(d->in_fleet);
    EXPECT_EQ(d->agv, tag - 1);
    EXPECT_EQ(d->level, SearchLevel::kFull);
    EXPECT_TRUE(d->has_fix);
    EXPECT_EQ(d->result, FixResult::kStarted);
    // The fix lies on the vehicle (tray-plane fit of the rendered tag).
    const Pose2& truth = r.truth[0][tag - 1].pose;
    EXPECT_LT(std::hypot(d->fix.pose.x_mm - truth.x_mm, d->fix.pose.y_mm - truth.y_mm), 15.0);
    EXPECT_LT(std::abs(wrap_angle_rad(d->fix.pose.theta_rad - truth.theta_rad)), deg_to_rad(1.0));
  }
}

TEST(CameraFrame, LaterFramesReadTheTracksOnTheirWindows) {
  const Sequence& r = sequence();
  for (int f = 1; f < kCoveredFrom; ++f) {
    const FrameCounters& before = r.counters[static_cast<std::size_t>(f - 1)];
    const FrameCounters& now = r.counters[static_cast<std::size_t>(f)];
    EXPECT_EQ(now.windows_track - before.windows_track, 3u) << "frame " << f;
    EXPECT_EQ(now.predicted_reads - before.predicted_reads, 3u) << "frame " << f;
    for (std::uint32_t tag : {1u, 2u, 3u}) {
      const Detection* d = find(r.dets[static_cast<std::size_t>(f)], tag);
      ASSERT_NE(d, nullptr) << "frame " << f << " tag " << tag;
      EXPECT_EQ(d->level, SearchLevel::kTrack);
      EXPECT_TRUE(d->tag.restricted);
      EXPECT_EQ(d->result, FixResult::kApplied);
    }
  }
  EXPECT_EQ(r.counters[kCoveredFrom - 1].windows_area, 0u);
  // Confirmed tracks on their vehicles.
  const std::size_t f = kCoveredFrom - 1;
  for (std::size_t i = 0; i < 3; ++i) {
    const TrackOutput& o = r.outs[f][i];
    EXPECT_EQ(o.state, TrackState::kConfirmed) << "vehicle " << i;
    const Pose2& truth = r.truth[f][i].pose;
    EXPECT_LT(std::hypot(o.pose.x_mm - truth.x_mm, o.pose.y_mm - truth.y_mm), 20.0);
  }
}

TEST(CameraFrame, AFrameThatAlsoSweepsReadsEveryTagOnce) {
  const Sequence& r = sequence();
  // Frame 3: track windows and the periodic full sweep see the same tags.
  EXPECT_EQ(r.counters[3].windows_full - r.counters[2].windows_full, 1u);
  for (const auto& frame : r.dets) {
    std::multiset<std::uint32_t> ids;
    for (const Detection& d : frame) ids.insert(d.tag.id);
    for (std::uint32_t id : ids) EXPECT_EQ(ids.count(id), 1u) << "tag " << id;
  }
  EXPECT_EQ(r.tracker.started, 3u);
  EXPECT_EQ(r.tracker.gated, 0u);
}

TEST(CameraFrame, AStrangersTagIsCountedNeverApplied) {
  const Sequence& r = sequence();
  const Detection* d = find(r.dets[0], 99);
  ASSERT_NE(d, nullptr);
  EXPECT_FALSE(d->in_fleet);
  EXPECT_FALSE(d->has_fix);
  EXPECT_EQ(d->result, FixResult::kInvalid);
  // Seen by every full sweep (frames 0, 3, 6) and counted each time; every fix the tracker got
  // came from a tag of the fleet.
  std::uint64_t strangers = 0, fixes = 0;
  for (const auto& frame : r.dets) {
    for (const Detection& x : frame) {
      strangers += x.in_fleet ? 0 : 1;
      fixes += x.has_fix ? 1 : 0;
      EXPECT_TRUE(x.in_fleet || x.result == FixResult::kInvalid);
    }
  }
  for (std::size_t f : {0u, 3u, 6u}) EXPECT_NE(find(r.dets[f], 99), nullptr) << "frame " << f;
  EXPECT_EQ(r.counters.back().unknown_ids, strangers);
  EXPECT_GE(strangers, 3u);
  EXPECT_EQ(r.tracker.started + r.tracker.applied + r.tracker.gated + r.tracker.too_old +
                r.tracker.invalid,
            fixes);
}

TEST(CameraFrame, ACoveredTagGetsNoFixAndItsTrackCoasts) {
  const Sequence& r = sequence();
  const std::size_t last_seen = kCoveredFrom - 1;
  for (std::size_t f = kCoveredFrom; f < kFrames; ++f) {
    EXPECT_EQ(find(r.dets[f], 2), nullptr) << "frame " << f;
    EXPECT_EQ(r.missed[f][1], f - kCoveredFrom + 1) << "frame " << f;  // misses in a row
    EXPECT_EQ(r.missed[f][0], 0u);
    const TrackOutput& o = r.outs[f][1];
    EXPECT_EQ(o.last_fix_t_ns, r.outs[last_seen][1].last_fix_t_ns);
    EXPECT_GT(o.sigma_xy_mm, r.outs[f - 1][1].sigma_xy_mm) << "frame " << f;
    EXPECT_NE(o.state, TrackState::kLost);
    // The others keep their fixes.
    EXPECT_NE(find(r.dets[f], 1), nullptr);
    EXPECT_NE(find(r.dets[f], 3), nullptr);
  }
  // Its window missed: the next frame searched its area.
  EXPECT_GT(r.counters.back().windows_area, 0u);
}

TEST(CameraFrame, ACoveredTagsTrackIsKeptByItsTrayBox) {
  const Sequence& r = sequence_with_trays();
  const FrameCounters& c = r.counters.back();
  EXPECT_GT(c.tray_fixes, 0u);
  for (std::size_t f = kCoveredFrom; f < kFrames; ++f) {
    EXPECT_EQ(find(r.dets[f], 2), nullptr) << "frame " << f;
    const TrackOutput& o = r.outs[f][1];
    EXPECT_EQ(o.state, TrackState::kConfirmed) << "frame " << f;
    const sim::AgvState& truth = r.truth[f][1];
    EXPECT_LT(std::hypot(o.pose.x_mm - truth.pose.x_mm, o.pose.y_mm - truth.pose.y_mm), 10.0)
        << "frame " << f;
    EXPECT_LT(std::abs(wrap_angle_rad(o.pose.theta_rad - truth.pose.theta_rad)), deg_to_rad(1.0));
  }
  // The tray box kept the track's fixes coming: its last fix is the last frame's.
  EXPECT_EQ(r.outs.back()[1].last_fix_t_ns, r.outs.back()[1].t_ns);
  // Without the tray fit the same frames leave it coasting (the test above).
  EXPECT_EQ(sequence().counters.back().tray_fixes, 0u);
}

// A vehicle placed by its tray box is no miss: it keeps its track window, and its camera searches
// no area for a tag that lies under a parcel (SearchParams::tray_box_holds_window).
TEST(CameraFrame, ATrayBoxKeepsTheTrackWindowAndSearchesNoArea) {
  const Sequence& r = sequence_with_trays();
  int boxed = 0;
  for (std::size_t f = kCoveredFrom; f < kFrames; ++f) {
    if (r.counters[f].tray_fixes == r.counters[f - 1].tray_fixes) continue;
    ++boxed;
    EXPECT_EQ(r.missed[f][1], 0u) << "frame " << f;
  }
  EXPECT_EQ(boxed, kFrames - kCoveredFrom);
  EXPECT_EQ(r.counters.back().windows_area, r.counters[kCoveredFrom - 1].windows_area);
  EXPECT_GT(r.counters.back().windows_track, r.counters[kCoveredFrom - 1].windows_track);
}

// A parcel over the whole tray hides its outline: no box, and the refusals are counted by why,
// so that a site can tell a hidden outline from a prediction gone too loose.
TEST(CameraFrame, ATrayHiddenByItsParcelIsRefusedAndCountedByReason) {
  const Sequence& r = sequence_tray_hidden();
  const FrameCounters& c = r.counters.back();
  EXPECT_EQ(c.tray_fixes, 0u);
  EXPECT_GT(c.tray_refused, 0u);
  std::uint64_t sum = 0;
  for (const std::uint64_t n : c.tray_refused_by) sum += n;
  EXPECT_EQ(sum, c.tray_refused);
  EXPECT_EQ(c.tray_refused_by[static_cast<std::size_t>(TrayRefusal::kNone)], 0u);
  const std::uint64_t hidden =
      c.tray_refused_by[static_cast<std::size_t>(TrayRefusal::kSidesHidden)] +
      c.tray_refused_by[static_cast<std::size_t>(TrayRefusal::kNoOutline)];
  EXPECT_GT(hidden, 0u) << "sides_hidden " << c.tray_refused_by[5] << ", no_outline "
                        << c.tray_refused_by[4] << ", uncertain " << c.tray_refused_by[2];
  // The tray boxes of the visible trays are counted apart: the two uncovered vehicles get none
  // (their tags are read), so every refusal is the covered one's.
  EXPECT_LE(c.tray_refused, static_cast<std::uint64_t>(kFrames - kCoveredFrom));
}

TEST(CameraFrame, ATagPredictedAcrossTheImageEdgeIsNoMiss) {
  // Two tracks, no tags in the frame: the one predicted wholly inside the image missed, the one
  // predicted across the right edge (x about 2.6 m at tray height) may simply be out of view.
  const site::CeilingCamera cam = test_camera();
  CameraFrameProcessor proc({cam}, {agv("inside", 1), agv("edge", 2)}, {}, {});
  FleetTracker tracker(2);
  TagFix fix;
  fix.cov = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1e-4};
  fix.pose = {0.0, 0.0, 0.0};
  ASSERT_EQ(tracker.add_fix(0, 0, fix), FixResult::kStarted);
  fix.pose = {2620.0, 0.0, 0.0};
  ASSERT_EQ(tracker.add_fix(1, 0, fix), FixResult::kStarted);
  const cv::Mat blank(720, 1280, CV_8UC1, cv::Scalar(128));
  std::string error;
  ASSERT_TRUE(proc.process(0, 10'000'000, blank, &tracker, nullptr, &error)) << error;
  EXPECT_EQ(proc.counters().windows_track, 2u);
  EXPECT_EQ(proc.search_state(0).missed[0], 1u);
  EXPECT_EQ(proc.search_state(0).missed[1], 0u);
}

// Areas are costly (most of a large image): one whose vehicles an earlier window of the frame
// already read, or that lies inside a region the frame already searched, is not searched again.
TEST(CameraFrame, AnAreaAlreadyReadOrSearchedIsSkipped) {
  const site::CeilingCamera cam = test_camera();
  const std::vector<site::FleetAgv> fleet{agv("a1", 1), agv("a2", 2)};
  SearchParams sp;
  sp.max_window_px = 30;  // every track window too large: an area per vehicle
  sp.full_sweep_every_frames = 0;
  const auto run = [&](const std::vector<Pose2>& poses, bool render) {
    CameraFrameProcessor proc({cam}, fleet, {}, sp);
    FleetTracker tracker(2);
    TagFix fix;
    fix.cov = {4.0, 0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0, 1e-4};
    for (std::size_t i = 0; i < 2; ++i) {
      fix.pose = poses[i];
      EXPECT_EQ(tracker.add_fix(i, 0, fix), FixResult::kStarted);
    }
    const cv::Mat blank(720, 1280, CV_8UC1, cv::Scalar(128));
    std::string error;
    EXPECT_TRUE(proc.process(0, 0, blank, &tracker, nullptr, &error)) << error;  // first: whole
    sim::SiteScene scene;
    scene.site.fleet = fleet;
    for (const Pose2& p : poses) scene.agvs.push_back({p, 0.0, 0.0});
    const cv::Mat img = render ? sim::SiteFrameRenderer(cam.intrinsics)
                                     .render(scene, sim::RenderCamera::from_ceiling(cam),
                                             sim::SiteRenderParams{}, 3)
                                     .image
                               : blank;
    const FrameCounters before = proc.counters();
    std::vector<Detection> dets;
    EXPECT_TRUE(proc.process(0, 50'000'000, img, &tracker, &dets, &error)) << error;
    FrameCounters c = proc.counters();
    c.windows_area -= before.windows_area;
    c.windows_skipped -= before.windows_skipped;
    return std::make_pair(c, dets);
  };
  // Both tags in view, a2's inside a1's area but its own area reaching beyond: a1's area reads
  // both, a2's is skipped.
  const auto [read, dets] = run({{-900, 0, 0.3}, {300, 0, 1.0}}, true);
  EXPECT_EQ(read.windows_area, 2u);
  EXPECT_EQ(read.windows_skipped, 1u);
  ASSERT_EQ(dets.size(), 2u);
  for (const Detection& d : dets) EXPECT_EQ(d.level, SearchLevel::kArea);
  // No tags: the area of a vehicle near the image's side lies inside the other's: skipped.
  const auto [empty, none] = run({{0, 0, 0.0}, {-1500, 0, 0.0}}, false);
  EXPECT_EQ(empty.windows_area, 2u);
  EXPECT_EQ(empty.windows_skipped, 1u);
  EXPECT_TRUE(none.empty());
}

TEST(CameraFrame, BadInputIsRefusedWithAReason) {
  const site::CeilingCamera cam = test_camera();
  CameraFrameProcessor proc({cam}, {agv("a1", 1)}, {}, {});
  FleetTracker tracker(1), wrong_size(2);
  const cv::Mat ok(720, 1280, CV_8UC1, cv::Scalar(128));
  std::string error;
  EXPECT_FALSE(proc.process(1, 0, ok, &tracker, nullptr, &error));
  EXPECT_NE(error.find("out of range"), std::string::npos) << error;
  EXPECT_FALSE(proc.process(0, 0, ok, &wrong_size, nullptr, &error));
  EXPECT_FALSE(proc.process(0, 0, ok, nullptr, nullptr, &error));
  EXPECT_FALSE(
      proc.process(0, 0, cv::Mat(360, 640, CV_8UC1, cv::Scalar(0)), &tracker, nullptr, &error));
  EXPECT_NE(error.find("1280x720"), std::string::npos) << error;
  EXPECT_FALSE(proc.process(0, 0, cv::Mat(720, 1280, CV_8UC3), &tracker, nullptr, &error));
  EXPECT_FALSE(proc.process(0, 0, cv::Mat(), &tracker, nullptr, &error));
  EXPECT_EQ(proc.counters().rejected_frames, 6u);
  EXPECT_EQ(proc.counters().frames, 0u);
  EXPECT_TRUE(proc.process(0, 0, ok, &tracker, nullptr, &error));
  EXPECT_EQ(proc.counters().frames, 1u);
}

}  // namespace
}  // namespace agv::overhead

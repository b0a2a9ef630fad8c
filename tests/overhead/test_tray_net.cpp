// The learned tray detector (algo/src/overhead/tray_net*.cpp): the committed model
// (models/tray_obb.onnx) on rendered frames from a camera height and a lighting it was not trained
// on, its refusal of a corrupt buffer and of a model for another window size, the decoding and
// suppression of oriented boxes, the box turned into a fix, and the tracker's use of it for a
// covered tag.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

#include "agv/overhead/camera_frame.hpp"
#include "agv/overhead/tray_net.hpp"
#include "tray_scene.hpp"

namespace agv::overhead {
namespace {

std::string read_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

const std::string& model() {
  static const std::string m = read_bytes(AGV_SOURCE_DIR "/models/tray_obb.onnx");
  return m;
}

// The committed model loaded once; null where the build has no dnn module (the arm64 cross
// build), where the tests that need it skip.
const TrayNet* net() {
  static TrayNet n;
  static const bool ok = [] {
    std::string e;
    const bool r = n.load(model().data(), model().size(), &e);
    if (!r) std::printf("model not loaded: %s\n", e.c_str());
    return r;
  }();
  return ok ? &n : nullptr;
}

bool dnn_missing() {
  TrayNet n;
  std::string e;
  n.load(model().data(), model().size(), &e);
  return e.find("no dnn module") != std::string::npos;
}

TEST(TrayNetModel, CommittedModelDeclaresItsWindow) {
  ASSERT_FALSE(model().empty()) << "models/tray_obb.onnx missing";
  EXPECT_LE(model().size(), 5u * 1024 * 1024);
  std::array<long long, 4> shape{};
  std::string why;
  ASSERT_TRUE(onnx_input_shape(model().data(), model().size(), &shape, &why)) << why;
  EXPECT_EQ(shape[1], 1);
  EXPECT_EQ(shape[2], 256);
  EXPECT_EQ(shape[3], 256);
  if (dnn_missing()) GTEST_SKIP() << "OpenCV without dnn in this build";
  EXPECT_NE(net(), nullptr);
}

TEST(TrayNetModel, CorruptOrEmptyBufferIsANamedError) {
  TrayNet n;
  std::string e;
  EXPECT_FALSE(n.load(nullptr, 0, &e));
  EXPECT_EQ(e, "tray model: empty model");
  const std::string half = model().substr(0, model().size() / 2);
  EXPECT_FALSE(n.load(half.data(), half.size(), &e));
  EXPECT_EQ(e.rfind("tray model: ", 0), 0u) << e;
  EXPECT_FALSE(n.loaded());
  std::string junk(4096, '\0');
  for (std::size_t i = 0; i < junk.size(); ++i) junk[i] = static_cast<char>((i * 7919u) >> 3);
  EXPECT_FALSE(n.load(junk.data(), junk.size(), &e));
  EXPECT_EQ(e.rfind("tray model: ", 0), 0u) << e;
  const std::string text = "this is not a model\n";
  EXPECT_FALSE(n.load(text.data(), text.size(), &e));
  EXPECT_EQ(e.rfind("tray model: ", 0), 0u) << e;
  EXPECT_TRUE(n.detect(cv::Mat::zeros(256, 256, CV_8UC1), {}).empty());
}

TEST(TrayNetModel, ModelForAnotherWindowIsRefused) {
  const std::string m = read_bytes(AGV_SOURCE_DIR "/tests/overhead/data/tray_obb_128.onnx");
  ASSERT_FALSE(m.empty());
  TrayNet n;
  std::string e;
  EXPECT_FALSE(n.load(m.data(), m.size(), &e));
  EXPECT_NE(e.find("input is 1 x 1 x 128 x 128, expected 1 x 1 x 256 x 256"), std::string::npos)
      << e;
  // The same model is accepted by a detector made for its window.
  TrayNetGeometry g;
  g.input_px = 128;
  const bool ok = n.load(m.data(), m.size(), &e, g);
  if (!dnn_missing()) {
    EXPECT_TRUE(ok) << e;
  }
}

// One cell's output: score, offsets, size, (cos 2a, sin 2a).
void set_cell(std::vector<float>* out, int rows, int cols, int r, int c,
              const std::array<float, 7>& v) {
  for (int k = 0; k < 7; ++k) (*out)[static_cast<std::size_t>((k * rows + r) * cols + c)] = v[k];
}

TEST(TrayNetDecode, CellsToBoxesAndSuppression) {
  const int rows = 4, cols = 5;
  std::vector<float> out(7 * rows * cols, 0.0f);
  const float a = static_cast<float>(deg_to_rad(30.0));
  set_cell(&out, rows, cols, 1, 2,
           {0.9f, 0.25f, 0.75f, 75.f, 50.f, std::cos(2 * a), std::sin(2 * a)});
  // Its neighbour sees the same tray, less sure: suppressed.
  set_cell(&out, rows, cols, 1, 3,
           {0.8f, -0.45f, 0.7f, 74.f, 51.f, std::cos(2 * a), std::sin(2 * a)});
  // Below the score: dropped.
  set_cell(&out, rows, cols, 3, 0, {0.2f, 0.5f, 0.5f, 75.f, 50.f, 1.f, 0.f});
  // A tray far away at 170 degrees (cos 2a, sin 2a unnormalised): kept.
  const float b = static_cast<float>(deg_to_rad(170.0));
  set_cell(&out, rows, cols, 3, 4,
           {0.7f, 0.5f, 0.5f, 75.f, 50.f, 2 * std::cos(2 * b), 2 * std::sin(2 * b)});
  std::vector<OrientedBox> boxes;
  std::string why;
  ASSERT_TRUE(decode_tray_output(out.data(), 7, rows, cols, 64, 0.5, &boxes, &why)) << why;
  ASSERT_EQ(boxes.size(), 3u);
  EXPECT_NEAR(boxes[0].cx, (2 + 0.25) * 64 - 0.5, 1e-4);
  EXPECT_NEAR(boxes[0].cy, (1 + 0.75) * 64 - 0.5, 1e-4);
  EXPECT_NEAR(rad_to_deg(boxes[0].angle_rad), 30.0, 1e-3);
  const std::vector<OrientedBox> kept = nms_oriented(boxes, 0.3);
  ASSERT_EQ(kept.size(), 2u);
  EXPECT_FLOAT_EQ(static_cast<float>(kept[0].score), 0.9f);
  EXPECT_NEAR(rad_to_deg(kept[1].angle_rad), 170.0, 1e-3);
  // Fused: the kept box is the score-weighted mean of itself and the neighbour it suppressed.
  const std::vector<OrientedBox> fused = nms_fused(boxes, 0.3);
  ASSERT_EQ(fused.size(), 2u);
  EXPECT_FLOAT_EQ(static_cast<float>(fused[0].score), 0.9f);
  EXPECT_NEAR(fused[0].cx, (0.9 * boxes[0].cx + 0.8 * boxes[1].cx) / 1.7, 1e-4);
  EXPECT_NEAR(fused[0].cy, (0.9 * boxes[0].cy + 0.8 * boxes[1].cy) / 1.7, 1e-4);
  EXPECT_NEAR(fused[0].length, (0.9 * 75.0 + 0.8 * 74.0) / 1.7, 1e-4);
  EXPECT_NEAR(rad_to_deg(fused[0].angle_rad), 30.0, 1e-3);
  EXPECT_NEAR(fused[1].cx, kept[1].cx, 1e-9);
  EXPECT_NEAR(rad_to_deg(fused[1].angle_rad), 170.0, 1e-3);
  EXPECT_FALSE(decode_tray_output(out.data(), 6, rows, cols, 8, 0.5, &boxes, &why));
  EXPECT_NE(why.find("expected 7 channels"), std::string::npos);
}

TEST(TrayNetDecode, OrientedOverlap) {
  const OrientedBox a{50, 50, 80, 40, 0.0, 1.0};
  EXPECT_NEAR(oriented_iou(a, a), 1.0, 1e-3);
  OrientedBox b = a;
  b.angle_rad = kPi - 1e-9;  // half a turn: the same rectangle
  EXPECT_NEAR(oriented_iou(a, b), 1.0, 1e-3);
  b.angle_rad = 0.5 * kPi;  // crossed: the overlap is 40 x 40
  EXPECT_NEAR(oriented_iou(a, b), 1600.0 / (2 * 3200.0 - 1600.0), 1e-3);
  b = a;
  b.cx += 200;
  EXPECT_EQ(oriented_iou(a, b), 0.0);
  b.length = 0;
  EXPECT_EQ(oriented_iou(a, b), 0.0);
}

TEST(TrayNetFix, HalfTurnFromThePredictionOrRefused) {
  site::FleetAgv agv;  // 600 x 400 tray
  PlaneTray t;
  t.centre_mm = {1000, 2000};
  t.axis_rad = deg_to_rad(20.0);
  t.length_mm = 605;
  t.width_mm = 398;
  const std::array<double, 9> cov{100, 0, 0, 0, 100, 0, 0, 0, 0.01};
  TagFix f;
  std::string why;
  ASSERT_TRUE(tray_box_fix(t, agv, {1010, 1990, deg_to_rad(-165.0)}, cov, {}, 8.0, &f, &why));
  EXPECT_NEAR(rad_to_deg(f.pose.theta_rad), -160.0, 1e-9);
  EXPECT_NEAR(f.cov[0], std::pow(TrayNetParams{}.centre_sigma_px * 8.0, 2), 1e-9);
  ASSERT_TRUE(tray_box_fix(t, agv, {1010, 1990, deg_to_rad(10.0)}, cov, {}, 8.0, &f, &why));
  EXPECT_NEAR(rad_to_deg(f.pose.theta_rad), 20.0, 1e-9);
  const std::array<double, 9> wide{100, 0, 0, 0, 100, 0, 0, 0, 0.3};
  EXPECT_FALSE(tray_box_fix(t, agv, {1010, 1990, 0.0}, wide, {}, 8.0, &f, &why));
  EXPECT_NE(why.find("half-turn"), std::string::npos) << why;
  t.length_mm = 450;
  EXPECT_FALSE(tray_box_fix(t, agv, {1010, 1990, 0.0}, cov, {}, 8.0, &f, &why));
  EXPECT_NE(why.find("not the vehicle's tray"), std::string::npos) << why;
}

// Frames of the held-out split: a camera height (7 m) and a lighting (dim, steep gradient) that
// no training frame had; a window around each tray as the tracker places it (the prediction a
// few centimetres off), every box in it matched against the truth.
TEST(TrayNetModel, RecallAndPrecisionOnHeldOutFrames) {
  if (!net()) GTEST_SKIP() << "no model loaded (OpenCV without dnn)";
  tray_obb::SceneOptions o;
  o.width_px = 960;
  o.height_px = 540;
  int tp = 0, fn = 0, fp = 0, windows = 0;
  double max_centre_mm = 0.0;
  for (std::uint64_t f = 0; f < 6; ++f) {
    const tray_obb::SceneDraw d = tray_obb::draw_scene(9000 + f, tray_obb::Split::kTest, o);
    const sim::RenderResult r =
        sim::render_site_frame(d.scene, sim::RenderCamera::from_ceiling(d.cam), d.render, f);
    for (const sim::AgvTruth& t : r.agvs) {
      if (!tray_obb::tray_in_frame(t, o.width_px, o.height_px)) continue;
      ++windows;
      const Vec2 c{t.pose.x_mm + 30.0, t.pose.y_mm - 20.0};
      const std::vector<PlaneTray> found =
          net()->detect_on_plane(r.image, d.cam, c, o.tray_height_mm, {});
      bool hit = false;
      for (const PlaneTray& p : found) {
        bool matched = false;
        for (const sim::AgvTruth& u : r.agvs) {
          const double e = std::hypot(p.centre_mm.x - u.pose.x_mm, p.centre_mm.y - u.pose.y_mm);
          if (e > 60.0) continue;
          matched = true;
          if (u.index == t.index) hit = true, max_centre_mm = std::max(max_centre_mm, e);
        }
        fp += matched ? 0 : 1;
      }
      (hit ? tp : fn) += 1;
    }
  }
  const double recall = tp / std::max(1.0, static_cast<double>(tp + fn));
  const double precision = tp / std::max(1.0, static_cast<double>(tp + fp));
  std::printf("held-out: %d windows, recall %.3f precision %.3f, worst centre %.1f mm\n", windows,
              recall, precision, max_centre_mm);
  ASSERT_GE(windows, 10);
  // A regression bound, not the 99 % target, which this model misses: 0.946 / 0.946 on
  // 298 held-out trays (eval_tray_net, 100 frames). The committed model reads all 14 windows in
  // the g++ build; floating point differs between builds (an earlier model read 13 under clang's
  // ASan), so a model that falls below 85 % here has regressed.
  EXPECT_GE(recall, 0.85);
  EXPECT_GE(precision, 0.85);
}

// A confirmed track whose tag is under a parcel: the learned box keeps it fixed near the truth.
TEST(TrayNetTracker, CoveredTagFixedFromTheLearnedBox) {
  if (!net()) GTEST_SKIP() << "no model loaded (OpenCV without dnn)";
  tray_obb::SceneOptions o;
  o.width_px = 960;
  o.height_px = 540;
  o.fixed_height_mm = 6000.0;
  o.all_covered = true;
  // The first scene (from a fixed seed) with at least two trays wholly in the frame.
  tray_obb::SceneDraw d;
  sim::RenderResult r;
  for (std::uint64_t seed = 77;; ++seed) {
    d = tray_obb::draw_scene(seed, tray_obb::Split::kTest, o);
    int n = 0;
    for (const sim::AgvState& a : d.scene.agvs) {
      Vec2 px;
      n += site_to_pixel(d.cam, a.pose.x_mm, a.pose.y_mm, o.tray_height_mm, &px) && px.x > 60 &&
           px.y > 60 && px.x < o.width_px - 60 && px.y < o.height_px - 60;
    }
    if (n >= 2 || seed > 200) break;
  }
  r = sim::render_site_frame(d.scene, sim::RenderCamera::from_ceiling(d.cam), d.render, 5);
  CameraFrameProcessor proc(d.scene.site.cameras, d.scene.site.fleet, {}, {});
  auto shared = std::make_shared<TrayNet>();
  std::string e;
  ASSERT_TRUE(shared->load(model().data(), model().size(), &e)) << e;
  proc.set_tray_net(shared);
  EXPECT_TRUE(proc.tray_learned());
  FleetTracker tracker(d.scene.site.fleet.size());
  const std::int64_t t0 = 1'000'000'000;
  int in_view = 0;
  for (const sim::AgvTruth& t : r.agvs) {
    if (!tray_obb::tray_in_frame(t, o.width_px, o.height_px)) continue;
    ++in_view;
    EXPECT_LT(t.tag_visible_fraction, 0.05);
    TagFix f;
    f.pose = {t.pose.x_mm + 10.0, t.pose.y_mm - 10.0, t.pose.theta_rad + 0.02};
    f.cov = {100, 0, 0, 0, 100, 0, 0, 0, 1e-3};
    for (int k = 0; k < 3; ++k) tracker.add_fix(t.index, t0 - (3 - k) * 50'000'000LL, f);
  }
  ASSERT_GE(in_view, 2) << r.agvs.size() << " vehicles";
  ASSERT_TRUE(proc.process(0, t0, r.image, &tracker, nullptr, &e)) << e;
  EXPECT_GE(proc.counters().tray_fixes, static_cast<std::uint64_t>(in_view - 1));
  EXPECT_EQ(proc.counters().tray_net_windows,
            proc.counters().tray_fixes + proc.counters().tray_gated + proc.counters().tray_refused);
  for (const sim::AgvTruth& t : r.agvs) {
    if (!tray_obb::tray_in_frame(t, o.width_px, o.height_px)) continue;
    const TrackOutput out = tracker.output(t.index, t0);
    EXPECT_LT(std::hypot(out.pose.x_mm - t.pose.x_mm, out.pose.y_mm - t.pose.y_mm), 25.0);
  }
  // Back to the classical fit.
  proc.set_tray_net(nullptr);
  EXPECT_FALSE(proc.tray_learned());
}

// Two vehicles side by side: A's tag under a parcel (tracked, fixed from its learned box), B's
// tag readable. B's box lies in A's window: it agrees with B's tag fix, unless the processor is
// told B's tray is turned a quarter (its long side across): then the box disagrees with the tag,
// the tag wins (B's box is never used) and the disagreement is counted.
std::uint64_t disagreements(bool b_tray_turned) {
  tray_obb::SceneOptions o;
  o.width_px = 960;
  o.height_px = 540;
  o.fixed_height_mm = 6000.0;
  o.fixed_native_mm_per_px = 4.0;
  tray_obb::SceneDraw d = tray_obb::draw_scene(31, tray_obb::Split::kTrain, o);
  sim::SiteScene& s = d.scene;
  s.agvs.resize(2);
  s.site.fleet.resize(2);
  s.clutter.clear();
  Vec2 c;
  EXPECT_TRUE(pixel_to_plane(d.cam, {480, 270}, o.tray_height_mm, &c));
  s.agvs[0].pose = {c.x - 450.0, c.y, 0.5 * kPi};
  s.agvs[1].pose = {c.x + 450.0, c.y, 0.5 * kPi + 0.1};
  s.parcels.clear();
  sim::Parcel p;
  p.agv = 0;
  p.length_mm = 300;
  p.width_mm = 260;
  p.height_mm = 150;
  p.grey = 180;
  s.parcels.push_back(p);
  const sim::RenderResult r =
      sim::render_site_frame(s, sim::RenderCamera::from_ceiling(d.cam), d.render, 3);
  EXPECT_EQ(r.agvs[0].tag_visible_fraction, 0.0);
  EXPECT_EQ(r.agvs[1].tag_visible_fraction, 1.0);
  std::vector<site::FleetAgv> fleet = s.site.fleet;
  if (b_tray_turned) std::swap(fleet[1].tray_length_mm, fleet[1].tray_width_mm);
  CameraFrameProcessor proc(s.site.cameras, fleet, {}, {});
  auto n = std::make_shared<TrayNet>();
  std::string e;
  EXPECT_TRUE(n->load(model().data(), model().size(), &e)) << e;
  proc.set_tray_net(n);
  FleetTracker tracker(2);
  const std::int64_t t0 = 1'000'000'000;
  TagFix f;
  f.pose = r.agvs[0].pose;
  f.cov = {100, 0, 0, 0, 100, 0, 0, 0, 1e-3};
  for (int k = 0; k < 3; ++k) tracker.add_fix(0, t0 - (3 - k) * 50'000'000LL, f);
  EXPECT_TRUE(proc.process(0, t0, r.image, &tracker, nullptr, &e)) << e;
  EXPECT_EQ(proc.counters().tray_net_windows, 1u);  // A only: B's tag was read
  EXPECT_EQ(proc.counters().tray_fixes, 1u);
  EXPECT_TRUE(tracker.output(1, t0).state != TrackState::kNone);  // started from B's tag
  return proc.counters().tray_tag_disagree;
}

TEST(TrayNetTracker, BoxDisagreeingWithAReadTagIsCountedAndTheTagWins) {
  if (!net()) GTEST_SKIP() << "no model loaded (OpenCV without dnn)";
  EXPECT_EQ(disagreements(false), 0u);
  EXPECT_EQ(disagreements(true), 1u);
}

}  // namespace
}  // namespace agv::overhead

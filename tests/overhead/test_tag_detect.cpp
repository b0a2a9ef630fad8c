// Tag detection on rendered ceiling-camera frames (algo/src/overhead/tag_detect*.cpp): every
// visible tag found with its id, corners against the renderer's truth, the predicted path with
// corrupted cells against a small and the global set, and bad input.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>
#include <random>

#include "agv/overhead/tag_code.hpp"
#include "agv/overhead/tag_detect.hpp"
#include "tag_test_scene.hpp"

namespace agv::overhead {
namespace {

struct Frame {
  sim::SiteScene scene;
  sim::RenderResult r;
};

Frame render(double side_px, std::uint64_t seed) {
  Frame f;
  f.scene = test::tag_scene(side_px, 6, seed);
  f.r = sim::render_site_frame(f.scene, sim::RenderCamera::from_ceiling(f.scene.site.cameras[0]),
                               sim::realistic_site_params(), seed);
  return f;
}

const Frame& frame(double side_px) {
  static const Frame f40 = render(40.0, 3), f60 = render(60.0, 4);
  return side_px < 50 ? f40 : f60;
}

bool inside(const sim::AgvTruth& t, const cv::Mat& img, double margin) {
  for (const Vec2& c : t.tag_corners_px) {
    if (c.x < margin || c.y < margin || c.x > img.cols - margin || c.y > img.rows - margin) {
      return false;
    }
  }
  return t.projected && t.tag_visible_fraction > 0.999;
}

double corner_err2(const std::array<Vec2, 4>& a, const std::array<Vec2, 4>& b) {
  double s = 0;
  for (std::size_t k = 0; k < 4; ++k)
    s += std::pow(a[k].x - b[k].x, 2) + std::pow(a[k].y - b[k].y, 2);
  return s;
}

class TagDetectSizes : public ::testing::TestWithParam<double> {};

// The search path over the whole frame, then on a 256 x 256 window around each tag.
TEST_P(TagDetectSizes, EveryVisibleTagFoundWithRightIdAndSubpixelCorners) {
  const Frame& f = frame(GetParam());
  ASSERT_FALSE(f.r.image.empty());
  const TagDetector det;
  const auto all = det.detect(f.r.image, cv::Rect(0, 0, f.r.image.cols, f.r.image.rows));
  int visible = 0;
  double sum2 = 0, max_sigma = 0;
  int n = 0;
  for (const sim::AgvTruth& t : f.r.agvs) {
    if (!inside(t, f.r.image, 20.0)) continue;
    ++visible;
    const TagObservation* hit = nullptr;
    for (const TagObservation& o : all) {
      if (o.id == t.tag_id) hit = &o;
    }
    ASSERT_NE(hit, nullptr) << "tag " << t.tag_id;
    EXPECT_FALSE(hit->restricted);
    EXPECT_GE(hit->contrast, 20.0);
    EXPECT_GT(hit->margin, 0);
    EXPECT_EQ(hamming36(hit->code, tag36h11_code(t.tag_id)), hit->hamming);
    EXPECT_LE(hit->hamming, 2);
    sum2 += corner_err2(hit->corners_px, t.tag_corners_px);
    n += 4;
    max_sigma = std::max(max_sigma, hit->corner_sigma_px);
    // The same tag from a window around it.
    Vec2 c{0, 0};
    for (const Vec2& p : t.tag_corners_px) c.x += 0.25 * p.x, c.y += 0.25 * p.y;
    const cv::Rect win(static_cast<int>(c.x) - 128, static_cast<int>(c.y) - 128, 256, 256);
    const auto local = det.detect(f.r.image, win);
    bool again = false;
    for (const TagObservation& o : local) {
      if (o.id == t.tag_id) again = corner_err2(o.corners_px, hit->corners_px) < 1e-3 * 4;
    }
    EXPECT_TRUE(again) << "tag " << t.tag_id << " from its window";
  }
  for (const TagObservation& o : all) {
    bool known = false;
    for (const sim::AgvTruth& t : f.r.agvs) known = known || t.tag_id == o.id;
    EXPECT_TRUE(known) << "id " << o.id << " is no vehicle's";
  }
  ASSERT_GE(visible, 4);
  const double rms = std::sqrt(sum2 / n);
  std::printf("[ measured ] %.0f px tags: %d visible, corner RMS %.3f px, largest sigma %.3f px\n",
              GetParam(), visible, rms, max_sigma);
  EXPECT_LT(rms, 0.3);
  EXPECT_GT(max_sigma, 0.0);
}

// libapriltag's tile contrast floor is the detector's: a faint tag (a fifth of the contrast) is
// skipped at the default floor of 40 and found at libapriltag's own default of 5.
TEST(TagDetectParamsTest, QuadContrastFloorReachesLibapriltag) {
  const Frame& f = frame(60.0);
  cv::Mat faint;
  f.r.image.convertTo(faint, CV_8UC1, 0.2, 100.0);
  const cv::Rect full(0, 0, faint.cols, faint.rows);
  EXPECT_TRUE(TagDetector().detect(faint, full).empty());
  TagDetectParams p;
  p.quad_min_white_black_diff = 5;
  EXPECT_FALSE(TagDetector(p).detect(faint, full).empty());
}

const sim::AgvTruth& first_visible(const Frame& f) {
  for (const sim::AgvTruth& t : f.r.agvs) {
    if (inside(t, f.r.image, 30.0)) return t;
  }
  return f.r.agvs.front();
}

std::array<Vec2, 4> shifted(const std::array<Vec2, 4>& c, double dx, double dy, double rot_rad) {
  Vec2 m{0, 0};
  for (const Vec2& p : c) m.x += 0.25 * p.x, m.y += 0.25 * p.y;
  std::array<Vec2, 4> out{};
  const double cs = std::cos(rot_rad), sn = std::sin(rot_rad);
  for (std::size_t k = 0; k < 4; ++k) {
    const double x = c[k].x - m.x, y = c[k].y - m.y;
    out[k] = {m.x + cs * x - sn * y + dx, m.y + sn * x + cs * y + dy};
  }
  return out;
}

TEST(TagDetectPredicted, FindsTagFromOffPrediction) {
  const Frame& f = frame(40.0);
  const sim::AgvTruth& t = first_visible(f);
  const TagDetector det;
  TagObservation o;
  const std::vector<std::uint32_t> area{t.tag_id, 2, 3, 100};
  ASSERT_TRUE(
      det.detect_predicted(f.r.image, shifted(t.tag_corners_px, 4.0, -3.0, 0.05), area, &o));
  EXPECT_EQ(o.id, t.tag_id);
  EXPECT_TRUE(o.restricted);
  EXPECT_EQ(hamming36(o.code, tag36h11_code(t.tag_id)), o.hamming);
  EXPECT_EQ(o.hamming, 0);
  EXPECT_LT(std::sqrt(corner_err2(o.corners_px, t.tag_corners_px) / 4), 0.3);
  // A tag the area does not hold is not read.
  EXPECT_FALSE(det.detect_predicted(f.r.image, t.tag_corners_px, {2, 3, 100}, &o));
  // Nothing there: the prediction 40 px off, on the tray or floor.
  EXPECT_FALSE(
      det.detect_predicted(f.r.image, shifted(t.tag_corners_px, 0.0, 60.0, 0.0), area, &o));
}

// A prediction a quarter turn off (corners listed from the wrong one) still gives the corners in
// the tag's own page order.
TEST(TagDetectPredicted, QuarterTurnedPredictionGivesPageOrder) {
  const Frame& f = frame(60.0);
  const sim::AgvTruth& t = first_visible(f);
  const TagDetector det;
  for (int q = 1; q < 4; ++q) {
    std::array<Vec2, 4> turned{};
    for (std::size_t k = 0; k < 4; ++k)
      turned[k] = t.tag_corners_px[(k + static_cast<std::size_t>(q)) % 4];
    TagObservation o;
    ASSERT_TRUE(det.detect_predicted(f.r.image, turned, {t.tag_id, 7}, &o)) << q;
    EXPECT_EQ(o.id, t.tag_id);
    EXPECT_EQ(hamming36(o.code, tag36h11_code(t.tag_id)), o.hamming);
    EXPECT_LT(std::sqrt(corner_err2(o.corners_px, t.tag_corners_px) / 4), 0.3) << q;
  }
}

// Paints the given data cells (row, column) of the tag in the opposite colour through the truth
// corners' homography.
void corrupt_cells(cv::Mat* img, const std::array<Vec2, 4>& corners, std::uint32_t id,
                   const std::vector<std::pair<int, int>>& cells) {
  const std::array<cv::Point2f, 4> src{cv::Point2f(0, 0), cv::Point2f(8, 0), cv::Point2f(8, 8),
                                       cv::Point2f(0, 8)};
  std::array<cv::Point2f, 4> dst;
  for (std::size_t k = 0; k < 4; ++k) {
    dst[k] = cv::Point2f(static_cast<float>(corners[k].x), static_cast<float>(corners[k].y));
  }
  const cv::Matx33d h = cv::getPerspectiveTransform(src.data(), dst.data());
  const std::uint64_t code = tag36h11_code(id);
  for (const auto& [row, col] : cells) {
    std::vector<cv::Point> poly;
    for (const auto& uv : {std::pair{0, 0}, std::pair{1, 0}, std::pair{1, 1}, std::pair{0, 1}}) {
      const double u = col + 1 + uv.first, v = row + 1 + uv.second;
      const double w = h(2, 0) * u + h(2, 1) * v + h(2, 2);
      poly.emplace_back(static_cast<int>(std::lround((h(0, 0) * u + h(0, 1) * v + h(0, 2)) / w)),
                        static_cast<int>(std::lround((h(1, 0) * u + h(1, 1) * v + h(1, 2)) / w)));
    }
    const bool white = (code >> (35 - (row * 6 + col))) & 1U;
    cv::fillConvexPoly(*img, poly, cv::Scalar(white ? 35 : 190));
  }
}

cv::Mat corrupt_six_cells(const cv::Mat& img, const sim::AgvTruth& t) {
  cv::Mat out = img.clone();
  corrupt_cells(&out, t.tag_corners_px, t.tag_id, {{0, 0}, {1, 4}, {2, 2}, {3, 5}, {4, 1}, {5, 3}});
  return out;
}

// An area of four ids around `id` whose codes (every turn) are at least 13 apart, so 6 bits are
// correctable; empty when none is found among the first ids.
std::vector<std::uint32_t> spread_area(std::uint32_t id) {
  std::vector<std::uint32_t> area{id};
  for (std::uint32_t c = 0; c < 200 && area.size() < 4; ++c) {
    std::vector<std::uint32_t> t = area;
    t.push_back(c);
    if (c != id && min_distance(t) >= 13) area = t;
  }
  return area.size() == 4 ? area : std::vector<std::uint32_t>{};
}

// Random 6-cell corruptions of every visible tag, read on the predicted path against its area:
// the rate of right reads, and never a wrong id.
TEST_P(TagDetectSizes, RandomSixCellCorruptionsReadInSpreadArea) {
  const Frame& f = frame(GetParam());
  const TagDetector det;
  std::mt19937 rng(17);
  int tried = 0, right = 0, wrong = 0;
  for (const sim::AgvTruth& t : f.r.agvs) {
    if (!inside(t, f.r.image, 40.0)) continue;
    const std::vector<std::uint32_t> area = spread_area(t.tag_id);
    if (area.empty()) continue;
    // A crop around the tag keeps each trial's copy small.
    Vec2 c{0, 0};
    for (const Vec2& p : t.tag_corners_px) c.x += 0.25 * p.x, c.y += 0.25 * p.y;
    const cv::Rect roi(static_cast<int>(c.x) - 80, static_cast<int>(c.y) - 80, 160, 160);
    std::array<Vec2, 4> local = t.tag_corners_px;
    for (Vec2& p : local) p.x -= roi.x, p.y -= roi.y;
    for (int trial = 0; trial < 20; ++trial) {
      std::vector<int> idx(36);
      for (int i = 0; i < 36; ++i) idx[static_cast<std::size_t>(i)] = i;
      std::shuffle(idx.begin(), idx.end(), rng);
      std::vector<std::pair<int, int>> cells;
      for (int i = 0; i < 6; ++i)
        cells.emplace_back(idx[static_cast<std::size_t>(i)] / 6,
                           idx[static_cast<std::size_t>(i)] % 6);
      cv::Mat img = f.r.image(roi).clone();
      corrupt_cells(&img, local, t.tag_id, cells);
      TagObservation o;
      ++tried;
      if (det.detect_predicted(img, local, area, &o)) {
        right += o.id == t.tag_id ? 1 : 0;
        wrong += o.id != t.tag_id ? 1 : 0;
      }
    }
  }
  ASSERT_GE(tried, 60);
  std::printf("[ measured ] %.0f px tags: %d of %d six-cell corruptions read right, %d wrong\n",
              GetParam(), right, tried, wrong);
  EXPECT_EQ(wrong, 0);
  EXPECT_GE(right, tried * 99 / 100);
}

TEST(TagDetectPredicted, SixCorruptedCellsReadInSmallAreaRefusedGlobally) {
  const Frame& f = frame(60.0);
  const sim::AgvTruth& t = first_visible(f);
  const cv::Mat bad = corrupt_six_cells(f.r.image, t);
  const TagDetector det;
  // Area of four vehicles whose codes are at least 13 apart (6 bits correctable).
  const std::vector<std::uint32_t> area{t.tag_id, 0, 2, 3};
  ASSERT_GE(min_distance(area), 13);
  TagObservation o;
  ASSERT_TRUE(det.detect_predicted(bad, t.tag_corners_px, area, &o));
  EXPECT_EQ(o.id, t.tag_id);
  EXPECT_EQ(o.hamming, 6);
  // Against the whole family only 5 bits are correctable: refused on the predicted path, and the
  // search path (libapriltag, 2 bits) finds no tag there.
  std::vector<std::uint32_t> all(kTag36h11Count);
  for (std::uint32_t i = 0; i < kTag36h11Count; ++i) all[i] = i;
  EXPECT_FALSE(det.detect_predicted(bad, t.tag_corners_px, all, &o));
  Vec2 c{0, 0};
  for (const Vec2& p : t.tag_corners_px) c.x += 0.25 * p.x, c.y += 0.25 * p.y;
  const auto found =
      det.detect(bad, cv::Rect(static_cast<int>(c.x) - 128, static_cast<int>(c.y) - 128, 256, 256));
  for (const TagObservation& d : found) EXPECT_NE(d.id, t.tag_id);
  // The clean image around it is still read by both.
  EXPECT_TRUE(det.detect_predicted(f.r.image, t.tag_corners_px, all, &o));
}

// Boxes over one corner of each tag (a parcel on the tray): a reading either refuses the tag or
// gives corners as good as an unhidden tag's, on both paths; a line fitted through the box's
// outline must not pass as the square's side.
TEST(TagDetectOcclusion, CornerHiddenByParcelRefusedOrRight) {
  for (double side : {40.0, 60.0}) {
    sim::SiteScene s = test::tag_scene(side, 6, 5);
    for (std::size_t i = 0; i < s.agvs.size(); ++i) {
      sim::Parcel p;
      p.agv = i;
      // Over the page's top-left corner (vehicle front-left), 10 to 50 mm into the square.
      const double in = 10.0 + 8.0 * static_cast<double>(i);
      p.x_mm = 80.0 - in + 100.0;
      p.y_mm = 80.0 - in + 100.0;
      p.length_mm = p.width_mm = 200.0;
      p.height_mm = 150.0;
      p.grey = 120.0 + 15.0 * static_cast<double>(i);
      s.parcels.push_back(p);
    }
    const sim::RenderResult r = sim::render_site_frame(
        s, sim::RenderCamera::from_ceiling(s.site.cameras[0]), sim::realistic_site_params(), 5);
    const TagDetector det;
    int read = 0;
    for (const sim::AgvTruth& t : r.agvs) {
      ASSERT_LT(t.tag_visible_fraction, 0.999);
      TagObservation o;
      if (det.detect_predicted(r.image, t.tag_corners_px, {t.tag_id, 0, 2, 3}, &o)) {
        ++read;
        EXPECT_EQ(o.id, t.tag_id);
        EXPECT_LT(std::sqrt(corner_err2(o.corners_px, t.tag_corners_px) / 4), 0.3) << t.tag_id;
      }
    }
    for (const TagObservation& o : det.detect(r.image, cv::Rect(0, 0, 1280, 720))) {
      for (const sim::AgvTruth& t : r.agvs) {
        if (t.tag_id != o.id) continue;
        ++read;
        EXPECT_LT(std::sqrt(corner_err2(o.corners_px, t.tag_corners_px) / 4), 0.3) << t.tag_id;
      }
    }
    std::printf("[ measured ] %.0f px tags with a hidden corner: %d readings kept\n", side, read);
  }
}

TEST(TagDetectBadInput, NoDetectionNoCrash) {
  const Frame& f = frame(40.0);
  const sim::AgvTruth& t = first_visible(f);
  const TagDetector det;
  const cv::Rect full(0, 0, 1280, 720);
  TagObservation o;
  const std::vector<std::uint32_t> area{t.tag_id};
  EXPECT_TRUE(det.detect(cv::Mat(), full).empty());
  EXPECT_FALSE(det.detect_predicted(cv::Mat(), t.tag_corners_px, area, &o));
  cv::Mat colour;
  cv::cvtColor(f.r.image, colour, cv::COLOR_GRAY2BGR);
  EXPECT_TRUE(det.detect(colour, full).empty());
  EXPECT_FALSE(det.detect_predicted(colour, t.tag_corners_px, area, &o));
  cv::Mat wide;
  f.r.image.convertTo(wide, CV_16U);
  EXPECT_TRUE(det.detect(wide, full).empty());
  EXPECT_FALSE(det.detect_predicted(wide, t.tag_corners_px, area, &o));
  EXPECT_TRUE(det.detect(f.r.image, cv::Rect(2000, 2000, 256, 256)).empty());
  EXPECT_TRUE(det.detect(f.r.image, cv::Rect(-300, -300, 256, 256)).empty());
  EXPECT_TRUE(det.detect(f.r.image, cv::Rect(100, 100, 8, 8)).empty());
  EXPECT_TRUE(det.detect(f.r.image, cv::Rect(100, 100, -50, 40)).empty());
  // Corners outside the image, NaN, degenerate, no ids, no output.
  EXPECT_FALSE(
      det.detect_predicted(f.r.image, shifted(t.tag_corners_px, 3000.0, 0.0, 0.0), area, &o));
  std::array<Vec2, 4> nan = t.tag_corners_px;
  nan[2].x = std::nan("");
  EXPECT_FALSE(det.detect_predicted(f.r.image, nan, area, &o));
  std::array<Vec2, 4> point{};
  point.fill(t.tag_corners_px[0]);
  EXPECT_FALSE(det.detect_predicted(f.r.image, point, area, &o));
  EXPECT_FALSE(det.detect_predicted(f.r.image, t.tag_corners_px, {}, &o));
  EXPECT_FALSE(det.detect_predicted(f.r.image, t.tag_corners_px, {99999}, &o));
  EXPECT_FALSE(det.detect_predicted(f.r.image, t.tag_corners_px, area, nullptr));
  // A blank and a noise image give nothing.
  const cv::Mat blank(720, 1280, CV_8UC1, cv::Scalar(128));
  EXPECT_TRUE(det.detect(blank, full).empty());
  EXPECT_FALSE(det.detect_predicted(blank, t.tag_corners_px, area, &o));
  cv::Mat noise(240, 320, CV_8UC1);
  cv::randu(noise, 0, 255);
  EXPECT_TRUE(det.detect(noise, cv::Rect(0, 0, 320, 240)).empty());
  // A non-contiguous view (a column range) is read in place like any image.
  const cv::Mat roi = f.r.image(cv::Rect(0, 0, 1280, 720));
  EXPECT_EQ(det.detect(roi, full).size(), det.detect(f.r.image, full).size());
}

INSTANTIATE_TEST_SUITE_P(Sides, TagDetectSizes, ::testing::Values(40.0, 60.0));

// Large tags (the 40 px scene on a sensor 3 times larger: 120 px) searched shrunk 3 times:
// every visible one found with its id from the whole-family decode (it may start a track), its
// corners refined at full resolution as close to the truth as the full-resolution search's.
TEST(TagDetectDecimated, LargeTagsFoundShrunkWithFullResolutionCorners) {
  Frame f;
  f.scene = test::tag_scene(40.0, 6, 5);
  test::scale_camera(&f.scene.site.cameras[0], 3);
  f.r = sim::render_site_frame(f.scene, sim::RenderCamera::from_ceiling(f.scene.site.cameras[0]),
                               sim::realistic_site_params(), 5);
  const TagDetector det;
  const cv::Rect full(0, 0, f.r.image.cols, f.r.image.rows);
  const std::vector<TagObservation> at1 = det.detect(f.r.image, full);
  const std::vector<TagObservation> shrunk = det.detect(f.r.image, full, 3);
  int visible = 0;
  double sum1 = 0.0, sum_s = 0.0;
  for (const sim::AgvTruth& t : f.r.agvs) {
    if (!inside(t, f.r.image, 20.0)) continue;
    ++visible;
    const TagObservation *a = nullptr, *b = nullptr;
    for (const TagObservation& o : at1) a = o.id == t.tag_id ? &o : a;
    for (const TagObservation& o : shrunk) b = o.id == t.tag_id ? &o : b;
    ASSERT_NE(a, nullptr) << "tag " << t.tag_id << " at full resolution";
    ASSERT_NE(b, nullptr) << "tag " << t.tag_id << " shrunk";
    EXPECT_FALSE(b->restricted);
    EXPECT_LE(b->hamming, 2);
    EXPECT_EQ(hamming36(b->code, tag36h11_code(t.tag_id)), b->hamming);
    EXPECT_GT(b->corner_sigma_px, 0.0);
    sum1 += corner_err2(a->corners_px, t.tag_corners_px);
    sum_s += corner_err2(b->corners_px, t.tag_corners_px);
  }
  EXPECT_EQ(shrunk.size(), static_cast<std::size_t>(visible));
  ASSERT_GE(visible, 2);
  const double rms1 = std::sqrt(sum1 / (4 * visible)), rms_s = std::sqrt(sum_s / (4 * visible));
  std::printf("[ measured ] 120 px tags: %d visible, corner RMS %.3f px full, %.3f px shrunk 3x\n",
              visible, rms1, rms_s);
  EXPECT_LT(rms_s, 0.3);
  EXPECT_LT(rms_s, rms1 + 0.05);
  // Too small a window to shrink: the full-resolution search.
  const cv::Rect small(0, 0, 60, 60);
  EXPECT_EQ(det.detect(f.r.image, small, 4).size(), det.detect(f.r.image, small).size());
}

}  // namespace
}  // namespace agv::overhead

// The printed landmark: geometry of the PNG raster and SVG as docs/design/landmark.md says, and the
// QR decodes to the payload at the documented version and ECC level.
#include <ZXing/ReadBarcode.h>
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "agv/sim/render.hpp"

using namespace agv;
using namespace agv::sim;

namespace {

const std::string kFull = "AGV1/00017/+001000.0/-002000.0/+090.00";
const std::string kIdOnly = "AGV1/00017/MAP";

ZXing::Result decode(const cv::Mat& img) {
  // Add a white quiet zone the way a real decoder would see the printed landmark's white area.
  return ZXing::ReadBarcode(
      ZXing::ImageView(img.data, img.cols, img.rows, ZXing::ImageFormat::Lum),
      ZXing::DecodeHints().setFormats(ZXing::BarcodeFormat::QRCode).setTryHarder(true));
}

// Edge position along one image row, found from the dark area between two white stretches:
// the left edge is where darkness starts, measured as white length * mm_per_px from a pixel
// boundary. Works for any anti-aliasing that preserves area.
double dark_start_mm(const cv::Mat& img, int row, int x_from, int x_to, double mm_per_px) {
  double white_px = 0.0;
  for (int x = x_from; x < x_to; ++x) white_px += img.at<std::uint8_t>(row, x) / 255.0;
  const double c0 = 0.5 * (img.cols - 1);
  return ((x_from - 0.5) - c0 + white_px) * mm_per_px;
}

}  // namespace

TEST(QrEncoding, VersionsAndEccLevelAsDocumented) {
  QrModules q;
  std::string err;
  ASSERT_TRUE(encode_qr(kFull, &q, &err)) << err;
  EXPECT_EQ(q.n, 25);  // version 2
  ASSERT_TRUE(encode_qr(kIdOnly, &q, &err)) << err;
  EXPECT_EQ(q.n, 21);  // version 1
  EXPECT_FALSE(encode_qr("", &q, &err));
  EXPECT_FALSE(err.empty());
  // Every full payload has the same width, so extreme values stay version 2.
  ASSERT_TRUE(encode_qr("AGV1/65535/-999999.9/-999999.9/-179.99", &q, &err));
  EXPECT_EQ(q.n, 25);
}

TEST(LandmarkPage, QrDecodesToPayloadAtEccM) {
  for (const std::string& payload : {kFull, kIdOnly}) {
    const cv::Mat img = render_landmark_page(LandmarkGeometry{}, payload, 0.25);
    ASSERT_FALSE(img.empty());
    const ZXing::Result r = decode(img);
    ASSERT_TRUE(r.isValid()) << payload;
    EXPECT_EQ(r.text(), payload);
    EXPECT_EQ(r.ecLevel(), "M");
  }
}

TEST(LandmarkPage, EdgesWhereDocsSayWithinTenthMm) {
  for (double size_mm : {60.0, 45.0}) {
    const LandmarkGeometry g{size_mm};
    const double mmpp = 0.1;
    const cv::Mat img = render_landmark_page(g, kFull, mmpp);
    ASSERT_FALSE(img.empty());
    const double margin = g.border_width_mm();
    EXPECT_EQ(img.cols, std::lround(2 * (g.outer_half_mm() + margin) / mmpp));
    const double c0 = 0.5 * (img.cols - 1);
    auto col_of = [&](double u_mm) { return static_cast<int>(std::lround(u_mm / mmpp + c0)); };
    // Row through the landmark centre; the left border starts at -30k and ends at -24k.
    // Row at v = 22k crosses the bottom part of the border band on the sides and the white area.
    for (double v : {0.0, 22.0 * g.k(), -22.0 * g.k()}) {
      const int row = col_of(v);
      const double outer_left = dark_start_mm(img, row, 0, col_of(-27.0 * g.k()), mmpp);
      EXPECT_NEAR(outer_left, -g.outer_half_mm(), 0.1) << size_mm << " v " << v;
      // Inner edge of the left border: white length measured leftwards from inside.
      double white_px = 0.0;
      const int x_end = col_of(-20.0 * g.k());
      const int x_start = col_of(-27.0 * g.k());
      for (int x = x_start; x < x_end; ++x) white_px += img.at<std::uint8_t>(row, x) / 255.0;
      const double inner_left = ((x_end - 0.5) - c0 - white_px) * mmpp;
      EXPECT_NEAR(inner_left, -g.inner_half_mm(), 0.1) << size_mm << " v " << v;
    }
    // Columns: the transposed image checks the top/bottom border edges the same way.
    cv::Mat t = img.t();
    for (double u : {0.0, 20.0 * g.k()}) {
      const int row = col_of(u);
      EXPECT_NEAR(dark_start_mm(t, row, 0, col_of(-27.0 * g.k()), mmpp), -g.outer_half_mm(), 0.1);
      cv::Mat flipped;
      cv::flip(t, flipped, 1);
      EXPECT_NEAR(-dark_start_mm(flipped, row, 0, col_of(-27.0 * g.k()), mmpp), g.outer_half_mm(),
                  0.1);
    }
    // The QR's first module row (finder pattern, dark from u0 for 7 modules) starts at qr_u0.
    const int qr_row = col_of(g.qr_v0_mm() + 0.5 * g.qr_side_mm() / 25.0);
    EXPECT_NEAR(dark_start_mm(img, qr_row, col_of(-20.0 * g.k()), col_of(-13.0 * g.k()), mmpp),
                g.qr_u0_mm(), 0.1);
    // Logo apex: the column through u = 0 turns dark at v = -21k (scan the transposed image).
    EXPECT_NEAR(dark_start_mm(t, col_of(0.0), col_of(-23.0 * g.k()), col_of(-17.0 * g.k()), mmpp),
                g.logo_apex_uv_mm().y, 0.1);
  }
}

TEST(LandmarkPage, RejectsBadInput) {
  EXPECT_TRUE(render_landmark_page(LandmarkGeometry{}, kFull, 0.0).empty());
  EXPECT_TRUE(render_landmark_page(LandmarkGeometry{}, kFull, -1.0).empty());
  EXPECT_TRUE(render_landmark_page(LandmarkGeometry{}, "", 0.2).empty());
  EXPECT_TRUE(render_landmark_page(LandmarkGeometry{-5.0}, kFull, 0.2).empty());
}

TEST(LandmarkSvg, PhysicalSizeAndElements) {
  const LandmarkGeometry g{};
  const std::string svg = landmark_svg(g, kFull);
  ASSERT_FALSE(svg.empty());
  EXPECT_NE(svg.find("width=\"72mm\" height=\"72mm\" viewBox=\"0 0 72 72\""), std::string::npos);
  // Outer border at 6..66, inner white at 12..60.
  EXPECT_NE(svg.find("<rect x=\"6\" y=\"6\" width=\"60\" height=\"60\" fill=\"#000\"/>"),
            std::string::npos);
  EXPECT_NE(svg.find("<rect x=\"12\" y=\"12\" width=\"48\" height=\"48\" fill=\"#fff\"/>"),
            std::string::npos);
  // Logo apex at (36, 36 - 21).
  EXPECT_NE(svg.find("<polygon points=\"36,15 31,23 41,23\""), std::string::npos);
  LandmarkMap map;
  std::string err;
  ASSERT_TRUE(parse_landmark_map("id,x_mm,y_mm,heading_deg\n1,0,0,0\n2,1000,0,90\n", &map, &err));
  const std::string sheet = landmark_sheet_svg(g, map, 3);
  EXPECT_NE(sheet.find("id 2  x 1000.0"), std::string::npos);
  EXPECT_TRUE(landmark_sheet_svg(g, LandmarkMap{}, 3).empty());
}

// The misprinted landmark stays at its map pose but its QR code claims the shifted one.
TEST(Scene, MisprintShiftsOnlyThePayload) {
  Scene scene;
  std::string err;
  ASSERT_TRUE(
      make_scene(default_landmark_grid(), LandmarkGeometry{}, PayloadMode::kFull, &scene, &err))
      << err;
  const SceneLandmark before = scene.landmarks[7];
  ASSERT_EQ(before.id, 8u);
  ASSERT_TRUE(misprint_landmark(&scene, 8, {300.0, -40.0}, &err)) << err;
  const SceneLandmark& after = scene.landmarks[7];
  EXPECT_EQ(after.world_pose.x_mm, before.world_pose.x_mm);
  EXPECT_EQ(after.world_pose.y_mm, before.world_pose.y_mm);
  LandmarkPayload claimed, truth;
  ASSERT_EQ(parse_payload(after.pattern.payload(), &claimed), PayloadError::kOk);
  ASSERT_EQ(parse_payload(before.pattern.payload(), &truth), PayloadError::kOk);
  EXPECT_EQ(claimed.id, 8u);
  EXPECT_NEAR(claimed.x_mm, truth.x_mm + 300.0, 1e-6);
  EXPECT_NEAR(claimed.y_mm, truth.y_mm - 40.0, 1e-6);
  EXPECT_EQ(claimed.heading_deg, truth.heading_deg);
  EXPECT_EQ(scene.landmarks[6].pattern.payload(), full_payload({7, scene.landmarks[6].world_pose}));
  EXPECT_FALSE(misprint_landmark(&scene, 99, {300.0, 0.0}, &err));
  EXPECT_NE(err.find("99"), std::string::npos);
}

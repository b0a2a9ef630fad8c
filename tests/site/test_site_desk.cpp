// The desk side of the site file: loading it from disk (site_io) and drawing it (site_svg).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <string>

#include "site_io.hpp"
#include "site_svg.hpp"

namespace agv::desk {
namespace {

const std::string kData = AGV_SOURCE_DIR "/tests/site/data/";

std::size_t count_of(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (auto p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

TEST(SiteDesk, LoadsTheFloorMapBesideTheSiteFile) {
  agv::site::Site site;
  std::string errors;
  ASSERT_TRUE(load_site(kData + "small_site.yaml", &site, &errors)) << errors;
  EXPECT_EQ(site.floor_map.entries.size(), 2u);
  EXPECT_EQ(site.floor_map_file, "small_grid.csv");
  ASSERT_TRUE(load_site(AGV_SOURCE_DIR "/tools/maps/example_site.yaml", &site, &errors)) << errors;
  EXPECT_EQ(site.floor_map.entries.size(), 25u);
}

TEST(SiteDesk, ErrorsComeOneLinePerProblemWithThePath) {
  agv::site::Site site;
  std::string errors;
  const std::string broken = kData + "broken_site.yaml";
  ASSERT_FALSE(load_site(broken, &site, &errors));
  EXPECT_EQ(count_of(errors, "\n"), 2u) << errors;
  EXPECT_EQ(count_of(errors, broken + ": "), 2u) << errors;
  EXPECT_NE(errors.find("obstacles[1].outline_mm (line 6)"), std::string::npos) << errors;

  ASSERT_FALSE(load_site(kData + "no_such_site.yaml", &site, &errors));
  EXPECT_NE(errors.find("no_such_site.yaml"), std::string::npos) << errors;
  // A directory is not a site file (and is not read).
  ASSERT_FALSE(load_site(kData, &site, &errors));
  EXPECT_NE(errors.find("regular file"), std::string::npos) << errors;

  // The floor map is missing: named with the key.
  const auto dir = std::filesystem::temp_directory_path() / "agv_site_desk_test";
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "site.yaml") << "name: x\noutline_mm: [[0, 0], [1, 0], [1, 1]]\n"
                                      "floor_map: {file: nowhere.csv}\n";
  ASSERT_FALSE(load_site((dir / "site.yaml").string(), &site, &errors));
  EXPECT_NE(errors.find("floor_map.file: "), std::string::npos) << errors;
  EXPECT_NE(errors.find("nowhere.csv"), std::string::npos) << errors;
  std::filesystem::remove_all(dir);
}

TEST(SiteDesk, SvgShowsEveryPartAndTheRoutes) {
  agv::site::Site site;
  std::string errors;
  ASSERT_TRUE(load_site(AGV_SOURCE_DIR "/tools/maps/example_site.yaml", &site, &errors)) << errors;
  const std::vector<std::vector<Vec2>> routes = {{{0, 0}, {5000, 2000}, {5000, 6000}},
                                                 {{-1000, 8000}, {3000, 8000}}};
  const std::vector<agv::site::Polygon> extra = {site.obstacles[0].outline};
  const std::string svg = site_svg(site, routes, extra);
  ASSERT_EQ(svg.rfind("<svg", 0), 0u);
  EXPECT_NE(svg.find("</svg>"), std::string::npos);
  // Outline (and its clip path) + 5 obstacles + 25 floor landmarks + 2 camera footprints +
  // 1 extra + 5 legend keys.
  EXPECT_EQ(count_of(svg, "<polygon"), 2u + 5 + 25 + 2 + 1 + 5);
  EXPECT_EQ(count_of(svg, "clip-path=\"url(#site-outline)\""), 2u);  // the camera views
  EXPECT_EQ(count_of(svg, "stroke=\"#ff7f0e\""), 1u);                // the extra polygon
  for (const auto& o : site.obstacles) EXPECT_NE(svg.find(">" + o.id + "<"), std::string::npos);
  for (const auto& a : site.fleet) EXPECT_NE(svg.find(">" + a.id + " tag36h11"), std::string::npos);
  EXPECT_NE(svg.find(">ceiling-west (6.0 m)<"), std::string::npos);
  EXPECT_NE(svg.find(">tag 101<"), std::string::npos);
  EXPECT_NE(svg.find(">qr 500<"), std::string::npos);
  // Routes: one polyline each (plus the wall landmarks' 2 x 7 and the scale bar).
  EXPECT_EQ(count_of(svg, "<polyline"), 2u + 14 + 1);
  // A name with markup is escaped.
  site.name = "a<b & \"c\"";
  EXPECT_NE(site_svg(site, {}, {}).find(">a&lt;b &amp; &quot;c&quot;<"), std::string::npos);
}

TEST(SiteDesk, PngIsTheSameDrawingAndBounded) {
  agv::site::Site site;
  std::string errors;
  ASSERT_TRUE(load_site(kData + "small_site.yaml", &site, &errors)) << errors;
  cv::Mat img;
  std::string error;
  ASSERT_TRUE(site_png(site, {}, {}, 50.0, &img, &error)) << error;
  EXPECT_EQ(img.type(), CV_8UC3);
  // 4 m at 50 px/m, two 40 px margins, the legend below.
  EXPECT_GT(img.rows, 4 * 50 + 80);
  // The rack (x 3..5 m, y 1..2 m) is filled with its kind's colour (#c89b5a, BGR below).
  const cv::Vec3b rack = img.at<cv::Vec3b>(40 + (4000 - 1200) * 50 / 1000, 40 + 4000 * 50 / 1000);
  EXPECT_EQ(rack, cv::Vec3b(0x5a, 0x9b, 0xc8));
  ASSERT_FALSE(site_png(site, {}, {}, 1e5, &img, &error));
  EXPECT_NE(error.find("lower --px-per-m"), std::string::npos);
}

}  // namespace
}  // namespace agv::desk

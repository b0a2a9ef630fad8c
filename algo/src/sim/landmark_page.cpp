// Printable landmarks: QR encoding, the landmark pattern, page rasters, SVG and sheets
// (docs/design/landmark.md). The floor and camera rendering is in render.cpp.
#include <ZXing/BitMatrix.h>
#include <ZXing/MultiFormatWriter.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "agv/sim/render.hpp"
#include "agv/vision/map_identity.hpp"
#include "svg_number.hpp"

namespace agv::sim {

namespace {

// zxing-cpp 1.4 maps setEccLevel(0..8) to QR levels L,L,L,M,M,Q,Q,H,H (level = (e-1)/2);
// 4 is M. Confirmed by decoding the generated codes in tests/sim.
constexpr int kZxingEccLevelM = 4;

double cross(Vec2 o, Vec2 a, Vec2 b) {
  return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
}

bool in_triangle(Vec2 p, Vec2 a, Vec2 b, Vec2 c) {
  const double d1 = cross(a, b, p), d2 = cross(b, c, p), d3 = cross(c, a, p);
  const bool has_neg = d1 < 0 || d2 < 0 || d3 < 0;
  const bool has_pos = d1 > 0 || d2 > 0 || d3 > 0;
  return !(has_neg && has_pos);
}

// SVG elements of one landmark whose page origin is at (cx, cy) in the SVG's mm coordinates.
void append_landmark_svg(std::ostringstream& os, const LandmarkPattern& pat, double cx, double cy) {
  const LandmarkGeometry& g = pat.geometry();
  const double oh = g.outer_half_mm(), ih = g.inner_half_mm();
  os << "  <rect x=\"" << svg_number(cx - oh) << "\" y=\"" << svg_number(cy - oh) << "\" width=\""
     << svg_number(2 * oh) << "\" height=\"" << svg_number(2 * oh) << "\" fill=\"#000\"/>\n";
  os << "  <rect x=\"" << svg_number(cx - ih) << "\" y=\"" << svg_number(cy - ih) << "\" width=\""
     << svg_number(2 * ih) << "\" height=\"" << svg_number(2 * ih) << "\" fill=\"#fff\"/>\n";
  const QrModules& q = pat.qr();
  const double m = pat.module_mm();
  os << "  <g fill=\"#000\">\n";
  for (int r = 0; r < q.n; ++r) {
    int c = 0;
    while (c < q.n) {
      if (!q.at(c, r)) {
        ++c;
        continue;
      }
      int e = c;
      while (e < q.n && q.at(e, r)) ++e;
      // Runs are merged per row; rows overlap by nothing, so printers show no hairlines between
      // modules of one row and exact module boundaries between rows.
      os << "    <rect x=\"" << svg_number(cx + g.qr_u0_mm() + c * m) << "\" y=\""
         << svg_number(cy + g.qr_v0_mm() + r * m) << "\" width=\"" << svg_number((e - c) * m)
         << "\" height=\"" << svg_number(m) << "\"/>\n";
      c = e;
    }
  }
  os << "  </g>\n";
  const Vec2 a = g.logo_apex_uv_mm(), b = g.logo_base_left_uv_mm(), c = g.logo_base_right_uv_mm();
  os << "  <polygon points=\"" << svg_number(cx + a.x) << "," << svg_number(cy + a.y) << " "
     << svg_number(cx + b.x) << "," << svg_number(cy + b.y) << " " << svg_number(cx + c.x) << ","
     << svg_number(cy + c.y) << "\" fill=\"#000\"/>\n";
}

}  // namespace

bool encode_qr(const std::string& payload, QrModules* out, std::string* error) {
  if (payload.empty()) {
    if (error) *error = "empty payload";
    return false;
  }
  try {
    const ZXing::BitMatrix bm = ZXing::MultiFormatWriter(ZXing::BarcodeFormat::QRCode)
                                    .setEccLevel(kZxingEccLevelM)
                                    .setMargin(0)
                                    .encode(payload, 0, 0);
    if (bm.width() <= 0 || bm.width() != bm.height()) {
      if (error) *error = "QR encoder returned an empty or non-square matrix";
      return false;
    }
    QrModules q;
    q.n = bm.width();
    q.dark.resize(static_cast<size_t>(q.n * q.n));
    for (int r = 0; r < q.n; ++r) {
      for (int c = 0; c < q.n; ++c) q.dark[static_cast<size_t>(r * q.n + c)] = bm.get(c, r) ? 1 : 0;
    }
    *out = std::move(q);
    return true;
  } catch (const std::exception& e) {
    if (error) *error = std::string("QR encoding failed: ") + e.what();
    return false;
  }
}

bool LandmarkPattern::make(const LandmarkGeometry& geometry, const std::string& payload,
                           LandmarkPattern* out, std::string* error) {
  if (!(geometry.size_mm > 0.0) || !std::isfinite(geometry.size_mm)) {
    if (error) *error = "landmark size must be a positive number of millimetres";
    return false;
  }
  LandmarkPattern p;
  if (!encode_qr(payload, &p.qr_, error)) return false;
  p.geometry_ = geometry;
  p.payload_ = payload;
  p.module_mm_ = geometry.qr_side_mm() / p.qr_.n;
  *out = std::move(p);
  return true;
}

PageInk LandmarkPattern::at(Vec2 uv) const {
  if (is_tag()) return tag_at(uv);
  const double au = std::abs(uv.x), av = std::abs(uv.y);
  const double oh = geometry_.outer_half_mm();
  // Half-open squares so that every point belongs to exactly one region.
  if (!(au < oh && av < oh)) return PageInk::kOutside;
  const double ih = geometry_.inner_half_mm();
  if (!(au < ih && av < ih)) return PageInk::kBlack;
  const double qu = (uv.x - geometry_.qr_u0_mm()) / module_mm_;
  const double qv = (uv.y - geometry_.qr_v0_mm()) / module_mm_;
  if (qu >= 0.0 && qv >= 0.0 && qu < qr_.n && qv < qr_.n) {
    return qr_.at(static_cast<int>(qu), static_cast<int>(qv)) ? PageInk::kBlack : PageInk::kWhite;
  }
  if (in_triangle(uv, geometry_.logo_apex_uv_mm(), geometry_.logo_base_left_uv_mm(),
                  geometry_.logo_base_right_uv_mm())) {
    return PageInk::kBlack;
  }
  return PageInk::kWhite;
}

cv::Mat render_landmark_page(const LandmarkGeometry& geometry, const std::string& payload,
                             double mm_per_px, double margin_mm) {
  LandmarkPattern pat;
  if (!(mm_per_px > 0.0) || !std::isfinite(mm_per_px) ||
      !LandmarkPattern::make(geometry, payload, &pat, nullptr)) {
    return {};
  }
  if (margin_mm < 0.0) margin_mm = geometry.border_width_mm();
  const double side_mm = 2.0 * (geometry.outer_half_mm() + margin_mm);
  const int n = static_cast<int>(std::lround(side_mm / mm_per_px));
  if (n <= 0 || n > 20000) return {};
  cv::Mat img(n, n, CV_8UC1);
  const double c0 = 0.5 * (n - 1);
  constexpr int kSub = 16;
  auto grey = [&](Vec2 uv) { return pat.at(uv) == PageInk::kBlack ? 0.0 : 1.0; };
  for (int y = 0; y < n; ++y) {
    auto* row = img.ptr<std::uint8_t>(y);
    for (int x = 0; x < n; ++x) {
      const double u = (x - c0) * mm_per_px, v = (y - c0) * mm_per_px, hp = 0.5 * mm_per_px;
      const PageInk k = pat.at({u, v});
      const bool uniform = pat.at({u - hp, v - hp}) == k && pat.at({u + hp, v - hp}) == k &&
                           pat.at({u - hp, v + hp}) == k && pat.at({u + hp, v + hp}) == k;
      double g = 0.0;
      if (uniform) {
        g = k == PageInk::kBlack ? 0.0 : 1.0;
      } else {
        for (int j = 0; j < kSub; ++j) {
          for (int i = 0; i < kSub; ++i) {
            g += grey({u + ((i + 0.5) / kSub - 0.5) * mm_per_px,
                       v + ((j + 0.5) / kSub - 0.5) * mm_per_px});
          }
        }
        g /= kSub * kSub;
      }
      row[x] = static_cast<std::uint8_t>(std::lround(255.0 * g));
    }
  }
  return img;
}

std::string landmark_svg(const LandmarkGeometry& geometry, const std::string& payload,
                         double margin_mm) {
  LandmarkPattern pat;
  if (!LandmarkPattern::make(geometry, payload, &pat, nullptr)) return {};
  if (margin_mm < 0.0) margin_mm = geometry.border_width_mm();
  const double side = 2.0 * (geometry.outer_half_mm() + margin_mm);
  std::ostringstream os;
  os << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
     << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << svg_number(side) << "mm\" height=\""
     << svg_number(side) << "mm\" viewBox=\"0 0 " << svg_number(side) << " " << svg_number(side)
     << "\" shape-rendering=\"crispEdges\">\n"
     << "  <!-- agvloc landmark, payload " << payload << ", size " << svg_number(geometry.size_mm)
     << " mm; print at 100% scale -->\n"
     << "  <rect x=\"0\" y=\"0\" width=\"" << svg_number(side) << "\" height=\"" << svg_number(side)
     << "\" fill=\"#fff\"/>\n";
  append_landmark_svg(os, pat, side / 2, side / 2);
  os << "</svg>\n";
  return os.str();
}

// The payload the map-guided identity expects to see printed (one definition for both).
std::string full_payload(const LandmarkMapEntry& e) { return vision::map_full_payload(e); }

std::string landmark_sheet_svg(const LandmarkGeometry& geometry, const LandmarkMap& map,
                               int columns) {
  if (columns < 1 || map.entries.empty()) return {};
  const SheetGrid g =
      sheet_grid(2.0 * geometry.outer_half_mm() + 2.0 * geometry.border_width_mm() + 10.0,
                 static_cast<int>(map.entries.size()), columns);
  std::ostringstream os;
  svg_sheet_open(os, g, "agvloc landmark sheet, size " + svg_number(geometry.size_mm));
  int i = 0;
  for (const auto& [id, e] : map.entries) {
    const std::string payload = full_payload(e);
    LandmarkPattern pat;
    if (payload.empty() || !LandmarkPattern::make(geometry, payload, &pat, nullptr)) return {};
    const double cx = g.cx(i), cy = g.cy(i);
    append_landmark_svg(os, pat, cx, cy);
    char cap[160];
    std::snprintf(cap, sizeof cap, "id %u  x %.1f  y %.1f  heading %.2f deg",
                  static_cast<unsigned>(id), e.pose.x_mm, e.pose.y_mm,
                  rad_to_deg(wrap_angle_rad(e.pose.theta_rad)));
    svg_caption(os, cx, cy + g.cell_w / 2 + 3.0, cap);
    ++i;
  }
  os << "</svg>\n";
  return os.str();
}

}  // namespace agv::sim

#include "agv/vision/landmark_localizer.hpp"

#define ZX_USE_UTF8 1
#include <ZXing/ReadBarcode.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "agv/vision/edges.hpp"
#include "agv/vision/qr_grid.hpp"

namespace agv::vision {

const char* to_string(FixStatus s) {
  switch (s) {
    case FixStatus::kOk:
      return "ok";
    case FixStatus::kBadInput:
      return "bad input image";
    case FixStatus::kNoLandmark:
      return "no landmark";
    case FixStatus::kPartlyOutside:
      return "landmark partly outside the image";
    case FixStatus::kQrUnreadable:
      return "QR code unreadable";
    case FixStatus::kPayloadInvalid:
      return "payload invalid";
    case FixStatus::kUnknownLandmark:
      return "landmark not in the map";
    case FixStatus::kDirectionAmbiguous:
      return "direction ambiguous";
    case FixStatus::kTooFewEdgePoints:
      return "too few edge points";
  }
  return "unknown status";
}

namespace {

constexpr int kNumLines = 8;       // line index = side * 2 + (inner ? 1 : 0)
constexpr int kMaxTemplates = 32;  // upper bound of VisionConfig::corner_rotations

struct CornerPeak {
  double x = 0, y = 0;  // coarse pixels (template centre)
  double score = 0;
  int rot = 0;
};

struct Hypothesis {
  double cx = 0, cy = 0;  // landmark centre, coarse pixels
  double up_angle = 0;    // image angle of one border normal (mod 90 deg)
  double score_sum = 0, score_max = 0;
  double sum_w = 0;
  double c4 = 0, s4 = 0;          // accumulated 4*angle vector
  std::array<int, 8> peak_idx{};  // supporting corner peaks
  int n_peaks = 0;
};

Vec2 rot(Vec2 v, double a) {
  const double c = std::cos(a), s = std::sin(a);
  return {c * v.x - s * v.y, s * v.x + c * v.y};
}

// Bilinear sample of an 8-bit image; false outside.
bool sample(const cv::Mat& img, double x, double y, double* v) {
  if (!(x >= 0.0 && y >= 0.0 && x <= img.cols - 1.0 && y <= img.rows - 1.0)) return false;
  const int x0 = std::min(static_cast<int>(x), img.cols - 2 < 0 ? 0 : img.cols - 2);
  const int y0 = std::min(static_cast<int>(y), img.rows - 2 < 0 ? 0 : img.rows - 2);
  const double fx = x - x0, fy = y - y0;
  const std::uint8_t* r0 = img.ptr<std::uint8_t>(y0);
  const std::uint8_t* r1 = img.ptr<std::uint8_t>(std::min(y0 + 1, img.rows - 1));
  const int x1 = std::min(x0 + 1, img.cols - 1);
  *v = (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x1]);
  return true;
}

double ncc(const std::vector<double>& a, const std::vector<double>& b) {
  const size_t n = std::min(a.size(), b.size());
  if (n < 2) return 0.0;
  double ma = 0, mb = 0;
  for (size_t i = 0; i < n; ++i) {
    ma += a[i];
    mb += b[i];
  }
  ma /= static_cast<double>(n);
  mb /= static_cast<double>(n);
  double sab = 0, saa = 0, sbb = 0;
  for (size_t i = 0; i < n; ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  return saa > 1e-9 && sbb > 1e-9 ? sab / std::sqrt(saa * sbb) : 0.0;
}

// Dot products of one coarse patch (row pointer, stride) with every corner template at once.
// Templates are stored pixel-major with `Lanes` slots per pixel, so one pixel value multiplies
// Lanes / 4 vectors of four templates (GCC/Clang vector extensions: SSE on x86-64, NEON on
// aarch64; the auto-vectoriser interleaved this loop badly at 16 lanes). 16 lanes hold the
// default 12 rotations, 32 the maximum.
template <int Lanes>
int best_template(const float* patch, size_t stride, int tsz, const float* tp, int n_t,
                  float* best_dot) {
  typedef float V4 __attribute__((vector_size(16)));
  constexpr int kV = Lanes / 4;
  V4 acc[kV];
  for (int k = 0; k < kV; ++k) acc[k] = V4{0, 0, 0, 0};
  for (int j = 0; j < tsz; ++j) {
    const float* row = patch + static_cast<size_t>(j) * stride;
    for (int i = 0; i < tsz; ++i) {
      const float v = row[i];
      const V4 vv{v, v, v, v};
      const float* tq = tp + static_cast<size_t>(j * tsz + i) * Lanes;
      for (int k = 0; k < kV; ++k) {
        V4 t;
        std::memcpy(&t, tq + 4 * k, sizeof t);
        acc[k] += t * vv;
      }
    }
  }
  float out[Lanes];
  std::memcpy(out, acc, sizeof out);
  int best_i = 0;
  for (int t = 1; t < n_t; ++t) {
    if (out[t] > out[best_i]) best_i = t;
  }
  *best_dot = out[best_i];
  return best_i;
}

// Mean of each f x f block (rounded), the coarse detection image: what cv::resize with INTER_AREA
// computes for an integer factor, without its generic machinery (f rows summed into one row of
// vectorised adds, then f columns at a time).
void box_downsample(const cv::Mat& img, int f, cv::Size cs, cv::Mat* out,
                    std::vector<std::uint32_t>* sums) {
  out->create(cs, CV_8UC1);
  const int w = cs.width * f;
  sums->resize(static_cast<size_t>(w));
  const std::uint32_t area = static_cast<std::uint32_t>(f * f);
  for (int y = 0; y < cs.height; ++y) {
    std::uint32_t* acc = sums->data();
    std::fill(acc, acc + w, 0u);
    for (int k = 0; k < f; ++k) {
      const std::uint8_t* src = img.ptr<std::uint8_t>(y * f + k);
      for (int x = 0; x < w; ++x) acc[x] += src[x];
    }
    std::uint8_t* dst = out->ptr<std::uint8_t>(y);
    for (int x = 0; x < cs.width; ++x) {
      std::uint32_t sum = 0;
      for (int k = 0; k < f; ++k) sum += acc[x * f + k];
      dst[x] = static_cast<std::uint8_t>((sum + area / 2) / area);
    }
  }
}

}  // namespace

struct LandmarkLocalizer::Impl {
  VisionConfig cfg;
  CameraModel cam;
  CameraModel cam_linear;  // same mount, one mm/px ratio, no distortion (paper 001)
  LandmarkGeometry geom;
  const LandmarkMap* map = nullptr;

  // Detection.
  int coarse_factor = 8;
  double coarse_w = 0, coarse_h = 0, coarse_anchor = 0;  // border width, outer half, anchor
  std::vector<cv::Mat> templates;                        // CV_32F corner templates
  std::vector<double> template_angles;
  cv::Mat coarse, binary, isum, isq, best_score, best_rot;
  std::vector<std::vector<float>> templates_zm;  // zero-mean, unit-norm
  std::vector<float> templates_t;
  int template_lanes = 16;
  cv::Mat coarse_f;  // CV_32F copy of `coarse` for the NCC kernel
  cv::Mat orient4;   // CV_32FC2 per coarse pixel: |g|^2-weighted (cos 4a, sin 4a) of the gradient
  std::vector<std::uint32_t> row_sums;
  std::vector<std::vector<float>> fine_templates;  // 1-degree steps
  std::vector<CornerPeak> peaks;
  std::vector<Hypothesis> hyps;

  // QR.
  cv::Mat qr_small, qr_blur, qr_sharp;
  QrSamples qr_samples;
  std::vector<float> qr_fill;
  QrGridScratch qr_scratch;
  std::string qr_text;

  // Pose.
  std::array<std::vector<Vec2>, kNumLines> pts_px, pts_mm;
  std::array<std::vector<double>, kNumLines> weights;
  std::vector<double> logo_template, logo_samples, residual_buf, scratch_buf;
  std::vector<Vec2> logo_page_pts;
  std::vector<int> strip_gx, strip_gy;
  std::vector<double> strip_along;

  // Kept for the overlay.
  bool have_overlay = false;
  std::array<bool, kNumLines> line_ok{};
  std::array<Vec2, 8> corners_px{};  // outer 0..3, inner 4..7
  Vec2 centre_px;
  int quadrant = 0;
  double up_angle_px = 0;

  double mm_per_px = 0.26;

  Impl(const VisionConfig& c, const CameraModel& m, const LandmarkGeometry& g,
       const LandmarkMap* mp)
      : cfg(c), cam(m), cam_linear(m), geom(g), map(mp) {
    mm_per_px = cam.mm_per_px();
    if (!(mm_per_px > 0.0) || !std::isfinite(mm_per_px)) mm_per_px = 0.26;
    auto& li = cam_linear.intrinsics;
    li.fx = li.fy = cam.mount.height_mm / mm_per_px;
    li.k1 = li.k2 = li.p1 = li.p2 = li.k3 = 0.0;
    const double border_px = geom.border_width_mm() / mm_per_px;
    coarse_factor = 1;
    while (border_px / (coarse_factor * 2) >= cfg.coarse_border_px) coarse_factor *= 2;
    coarse_w = border_px / coarse_factor;
    coarse_h = geom.outer_half_mm() / mm_per_px / coarse_factor;
    coarse_anchor = coarse_w / 2.0;
    build_templates();
    build_logo();
  }

  // Corner template: the top-left outer corner of the border (square towards +x, +y), rendered
  // by 8x8 supersampling and rotated about its anchor (middle of the corner's dark square).
  // Renders the corner template rotated by angle a (image angle) into t (CV_32F, (2r+1)^2).
  void render_corner(double a, int r, cv::Mat* t) const {
    t->create(2 * r + 1, 2 * r + 1, CV_32FC1);
    const double ca = std::cos(a), sa = std::sin(a);
    for (int y = -r; y <= r; ++y) {
      for (int x = -r; x <= r; ++x) {
        double acc = 0;
        for (int sy = 0; sy < 8; ++sy) {
          for (int sx = 0; sx < 8; ++sx) {
            const Vec2 q{x + (sx + 0.5) / 8.0 - 0.5, y + (sy + 0.5) / 8.0 - 0.5};
            const Vec2 u{ca * q.x + sa * q.y, -sa * q.x + ca * q.y};  // rotate by -a
            const double px = u.x + coarse_anchor, py = u.y + coarse_anchor;
            const bool inside = px >= 0 && py >= 0;
            const bool dark = inside && (px < coarse_w || py < coarse_w);
            acc += dark ? 0.0 : 1.0;
          }
        }
        t->at<float>(y + r, x + r) = static_cast<float>(acc / 64.0);
      }
    }
  }

  static std::vector<float> zero_mean_unit(const cv::Mat& t) {
    cv::Scalar mean = cv::mean(t);
    std::vector<float> zm(static_cast<size_t>(t.total()));
    double norm = 0;
    for (size_t q = 0; q < zm.size(); ++q) {
      zm[q] = static_cast<float>(static_cast<double>(t.at<float>(static_cast<int>(q))) - mean[0]);
      norm += static_cast<double>(zm[q]) * static_cast<double>(zm[q]);
    }
    for (float& v : zm) v = static_cast<float>(static_cast<double>(v) / std::sqrt(norm));
    return zm;
  }

  // Corner template: the top-left outer corner of the border (square towards +x, +y), rendered
  // by 8x8 supersampling and rotated about its anchor (middle of the corner's dark square).
  void build_templates() {
    const int r = static_cast<int>(std::ceil(1.5 * coarse_w));
    const int n_rot = std::clamp(cfg.corner_rotations, 1, kMaxTemplates);
    templates.clear();
    templates_zm.clear();
    template_angles.clear();
    for (int i = 0; i < n_rot; ++i) {
      const double a = 2.0 * kPi * i / n_rot;
      cv::Mat t;
      render_corner(a, r, &t);
      templates_zm.push_back(zero_mean_unit(t));
      templates.push_back(t);
      template_angles.push_back(a);
    }
    // Transposed, padded to a fixed number of lanes (zeros) so the NCC inner loop has a fixed
    // trip count and vectorises.
    const size_t n_pix = templates_zm[0].size(), n_t = templates_zm.size();
    template_lanes = n_t <= 16 ? 16 : kMaxTemplates;
    const size_t lanes = static_cast<size_t>(template_lanes);
    templates_t.assign(n_pix * lanes, 0.0f);
    for (size_t t = 0; t < n_t; ++t) {
      for (size_t q = 0; q < n_pix; ++q) templates_t[q * lanes + t] = templates_zm[t][q];
    }
    // Zero-mean templates at every whole degree, for the local re-match.
    fine_templates.clear();
    for (int deg = 0; deg < 360; ++deg) {
      cv::Mat t;
      render_corner(deg_to_rad(deg), r, &t);
      fine_templates.push_back(zero_mean_unit(t));
    }
  }

  // NCC of a zero-mean unit template at coarse position (x, y) (top-left of the window); -1 when
  // the window leaves the image or has no contrast. Window sums come from the integral images.
  double ncc_at(const std::vector<float>& tz, int tsz, int x, int y) const {
    if (x < 0 || y < 0 || x + tsz > coarse.cols || y + tsz > coarse.rows) return -1.0;
    const double sum = isum.at<int>(y + tsz, x + tsz) - isum.at<int>(y, x + tsz) -
                       isum.at<int>(y + tsz, x) + isum.at<int>(y, x);
    const double sq = isq.at<double>(y + tsz, x + tsz) - isq.at<double>(y, x + tsz) -
                      isq.at<double>(y + tsz, x) + isq.at<double>(y, x);
    const double n = tsz * tsz;
    const double var = sq / n - (sum / n) * (sum / n);
    if (!(var > 1.0)) return -1.0;
    float dot = 0.0f;
    const float* t = tz.data();
    for (int j = 0; j < tsz; ++j) {
      const float* row = coarse_f.ptr<float>(y + j) + x;
      for (int i = 0; i < tsz; ++i) dot += t[j * tsz + i] * row[i];
    }
    return static_cast<double>(dot) / std::sqrt(var * n);
  }

  // Logo template: samples on the page around the triangle, 1 = white, 0 = inside the triangle.
  void build_logo() {
    const double k = geom.k();
    const Vec2 apex = geom.logo_apex_uv_mm(), bl = geom.logo_base_left_uv_mm(),
               br = geom.logo_base_right_uv_mm();
    auto inside = [&](Vec2 p) {
      auto cross = [](Vec2 a, Vec2 b, Vec2 c) {
        return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
      };
      const double d1 = cross(apex, bl, p), d2 = cross(bl, br, p), d3 = cross(br, apex, p);
      const bool neg = d1 < 0 || d2 < 0 || d3<0, pos = d1> 0 || d2 > 0 || d3 > 0;
      return !(neg && pos);
    };
    logo_page_pts.clear();
    logo_template.clear();
    const int nu = 20, nv = 16;
    for (int j = 0; j < nv; ++j) {
      for (int i = 0; i < nu; ++i) {
        const Vec2 p{(-8.0 + 16.0 * (i + 0.5) / nu) * k, (-23.0 + 12.0 * (j + 0.5) / nv) * k};
        logo_page_pts.push_back(p);
        logo_template.push_back(inside(p) ? 0.0 : 1.0);
      }
    }
  }

  double now_ms() const { return cfg.now_ns ? static_cast<double>(cfg.now_ns()) * 1e-6 : 0.0; }

  Vec2 coarse_to_full(Vec2 c) const {
    const double f = coarse_factor;
    return {(c.x + 0.5) * f - 0.5, (c.y + 0.5) * f - 0.5};
  }

  bool detect(const cv::Mat& img, Hypothesis* best, bool* found_corner, double* corner_score);
  bool ring_check(const Hypothesis& h, double* dark_level, double* white_level, int* n_dark);
  void refine_coarse_angle(Hypothesis* h) const;
  void compute_orient4();
  bool read_qr_search(const cv::Mat& img, Vec2 centre_px, double up_angle, std::string* text,
                      double* qr_up_angle, bool* qr_ok);
  bool sample_qr(const cv::Mat& img, Vec2 c_mm, double fwd, int n, QrSamples* s);
  FixStatus check_payload(const std::string& text, LandmarkFix* out, Pose2* world_landmark);
  FixStatus pose(const cv::Mat& img, Vec2 centre_px, double up_angle, double contrast,
                 LandmarkFix* out, Vec2* c_mm, double* beta, Eigen::Matrix3d* cov);
  int collect(const cv::Mat& img, Vec2 centre_px, double up_angle, double band_px, double thr);
  FixStatus run(const cv::Mat& img, LandmarkFix* out);
  const CameraModel& metric_cam() const {
    return cfg.metric == MetricMode::kCameraModel ? cam : cam_linear;
  }
};

bool LandmarkLocalizer::Impl::detect(const cv::Mat& img, Hypothesis* best, bool* found_corner,
                                     double* corner_score) {
  *found_corner = false;
  *corner_score = 0.0;
  const int f = coarse_factor;
  const cv::Size cs(img.cols / f, img.rows / f);
  if (cs.width < templates[0].cols + 2 || cs.height < templates[0].rows + 2) return false;
  box_downsample(img, f, cs, &coarse, &row_sums);
  int block = static_cast<int>(std::lround(cfg.adaptive_block_mm / (mm_per_px * f)));
  block = std::max(3, block | 1);
  cv::adaptiveThreshold(coarse, binary, 255, cv::ADAPTIVE_THRESH_MEAN_C, cv::THRESH_BINARY_INV,
                        block, cfg.adaptive_offset);
  // NCC of every rotated corner template at the candidate positions: the template's anchor (the
  // middle of the corner's dark square) must be dark in the binary image and the patch must have
  // contrast. Keeps the best score and rotation per position.
  cv::integral(coarse, isum, isq, CV_32S, CV_64F);
  const int tsz = templates[0].cols, r = tsz / 2, n_pix = tsz * tsz;
  best_score.create(coarse.rows - tsz + 1, coarse.cols - tsz + 1, CV_32FC1);
  best_score.setTo(-1.0f);
  best_rot.create(best_score.size(), CV_8UC1);
  coarse.convertTo(coarse_f, CV_32F);
  const size_t fstride = coarse_f.step1();
  const int n_t = static_cast<int>(templates_zm.size());
  const double min_var = 12.0 * 12.0;
  for (int y = 0; y < best_score.rows; ++y) {
    const std::uint8_t* brow = binary.ptr<std::uint8_t>(y + r);
    float* out_row = best_score.ptr<float>(y);
    for (int x = 0; x < best_score.cols; ++x) {
      if (!brow[x + r]) continue;
      const double sum = isum.at<int>(y + tsz, x + tsz) - isum.at<int>(y, x + tsz) -
                         isum.at<int>(y + tsz, x) + isum.at<int>(y, x);
      const double sq = isq.at<double>(y + tsz, x + tsz) - isq.at<double>(y, x + tsz) -
                        isq.at<double>(y + tsz, x) + isq.at<double>(y, x);
      const double var = sq / n_pix - (sum / n_pix) * (sum / n_pix);
      if (var < min_var) continue;  // NCC ignores contrast; faint texture is not a corner
      const float* patch = coarse_f.ptr<float>(y) + x;
      float best_dot = 0.0f;
      const int best_i =
          template_lanes == 16
              ? best_template<16>(patch, fstride, tsz, templates_t.data(), n_t, &best_dot)
              : best_template<kMaxTemplates>(patch, fstride, tsz, templates_t.data(), n_t,
                                             &best_dot);
      out_row[x] = static_cast<float>(static_cast<double>(best_dot) / std::sqrt(var * n_pix));
      best_rot.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(best_i);
    }
  }
  // Local maxima above threshold.
  peaks.clear();
  const float thr = static_cast<float>(cfg.corner_threshold);
  const int tr = templates[0].cols / 2;
  for (int y = 1; y + 1 < best_score.rows; ++y) {
    const float* sm = best_score.ptr<float>(y - 1);
    const float* s0 = best_score.ptr<float>(y);
    const float* sp = best_score.ptr<float>(y + 1);
    for (int x = 1; x + 1 < best_score.cols; ++x) {
      const float v = s0[x];
      if (v < thr) continue;
      if (v < s0[x - 1] || v <= s0[x + 1] || v < sm[x - 1] || v < sm[x] || v < sm[x + 1] ||
          v <= sp[x - 1] || v <= sp[x] || v <= sp[x + 1]) {
        continue;
      }
      // Subpixel peak by parabolas in x and y.
      const double vl = s0[x - 1], vr = s0[x + 1], vu = sm[x], vd = sp[x], vc = v;
      const double dxd = vl - 2.0 * vc + vr;
      const double dyd = vu - 2.0 * vc + vd;
      const double ox = dxd < 0 ? std::clamp(0.5 * (vl - vr) / dxd, -0.5, 0.5) : 0;
      const double oy = dyd < 0 ? std::clamp(0.5 * (vu - vd) / dyd, -0.5, 0.5) : 0;
      CornerPeak p;
      p.x = x + tr + ox;
      p.y = y + tr + oy;
      p.score = v;
      p.rot = best_rot.at<std::uint8_t>(y, x);
      peaks.push_back(p);
    }
  }
  if (peaks.empty()) return false;
  *found_corner = true;
  std::sort(peaks.begin(), peaks.end(),
            [](const CornerPeak& a, const CornerPeak& b) { return a.score > b.score; });
  if (static_cast<int>(peaks.size()) > cfg.max_corner_peaks) {
    peaks.resize(static_cast<size_t>(cfg.max_corner_peaks));
  }
  *corner_score = peaks[0].score;
  // Each corner predicts the landmark centre; corners that agree are merged.
  hyps.clear();
  for (const CornerPeak& p : peaks) {
    const double a = template_angles[static_cast<size_t>(p.rot)];
    const Vec2 d = rot({coarse_h - coarse_anchor, coarse_h - coarse_anchor}, a);
    const Vec2 c{p.x + d.x, p.y + d.y};
    // Normal of the template's top side points to image angle a - 90 deg.
    const double up = a - kPi / 2.0;
    Hypothesis* hit = nullptr;
    for (Hypothesis& h : hyps) {
      const double da = std::abs(reduce_angle_90(up, h.up_angle) - h.up_angle);
      if (std::hypot(h.cx - c.x, h.cy - c.y) < 1.5 * coarse_w && da < deg_to_rad(25.0)) {
        hit = &h;
        break;
      }
    }
    if (!hit) {
      hyps.push_back({});
      hit = &hyps.back();
    }
    const double w = p.score;
    hit->cx = (hit->cx * hit->sum_w + c.x * w) / (hit->sum_w + w);
    hit->cy = (hit->cy * hit->sum_w + c.y * w) / (hit->sum_w + w);
    hit->sum_w += w;
    hit->c4 += w * std::cos(4.0 * up);
    hit->s4 += w * std::sin(4.0 * up);
    hit->up_angle = std::atan2(hit->s4, hit->c4) / 4.0;
    hit->score_sum += p.score;
    hit->score_max = std::max(hit->score_max, p.score);
    if (hit->n_peaks < static_cast<int>(hit->peak_idx.size())) {
      hit->peak_idx[static_cast<size_t>(hit->n_peaks++)] = static_cast<int>(&p - peaks.data());
    }
  }
  std::sort(hyps.begin(), hyps.end(),
            [](const Hypothesis& a, const Hypothesis& b) { return a.score_sum > b.score_sum; });
  int best_dark_count = 0;
  compute_orient4();
  for (Hypothesis& h : hyps) {
    // The templates are 30 degrees apart: refine the angle from the gradients, then the centre
    // from the supporting corners with the refined angle; twice.
    int prev_deg = -1;
    for (int it = 0; it < 2; ++it) {
      refine_coarse_angle(&h);
      // The re-match below depends on the angle only through its whole degree (mod 90): when
      // that did not change, a second pass would repeat the first.
      const int deg90 = static_cast<int>(std::lround(rad_to_deg(h.up_angle))) % 90;
      const int key = deg90 < 0 ? deg90 + 90 : deg90;
      if (key == prev_deg) break;
      prev_deg = key;
      double sx = 0, sy = 0, sw = 0;
      for (int i = 0; i < h.n_peaks; ++i) {
        const CornerPeak& p = peaks[static_cast<size_t>(h.peak_idx[static_cast<size_t>(i)])];
        const double a_tmpl = template_angles[static_cast<size_t>(p.rot)];
        // The corner's true rotation: the template's, snapped to the refined square angle.
        const double a = reduce_angle_90(h.up_angle + kPi / 2.0, a_tmpl);
        // Re-match a template at that rotation around the peak (the 30-degree templates shift
        // the peak), with a parabolic subpixel maximum.
        const int deg = static_cast<int>(std::lround(rad_to_deg(a))) % 360;
        const std::vector<float>& tz =
            fine_templates[static_cast<size_t>(deg < 0 ? deg + 360 : deg)];
        const int px0 = static_cast<int>(std::lround(p.x)),
                  py0 = static_cast<int>(std::lround(p.y));
        double sc[7][7];
        for (auto& row : sc) std::fill(std::begin(row), std::end(row), -1.0);
        int bx = 3, by = 3;
        for (int dy = -2; dy <= 2; ++dy) {
          for (int dx = -2; dx <= 2; ++dx) {
            sc[dy + 3][dx + 3] = ncc_at(tz, tsz, px0 + dx - r, py0 + dy - r);
            if (sc[dy + 3][dx + 3] > sc[by][bx]) {
              bx = dx + 3;
              by = dy + 3;
            }
          }
        }
        double qx = px0 + bx - 3, qy = py0 + by - 3;
        if (bx > 0 && bx < 6) {
          const double d2 = sc[by][bx - 1] - 2 * sc[by][bx] + sc[by][bx + 1];
          if (d2 < 0) qx += std::clamp(0.5 * (sc[by][bx - 1] - sc[by][bx + 1]) / d2, -0.5, 0.5);
        }
        if (by > 0 && by < 6) {
          const double d2 = sc[by - 1][bx] - 2 * sc[by][bx] + sc[by + 1][bx];
          if (d2 < 0) qy += std::clamp(0.5 * (sc[by - 1][bx] - sc[by + 1][bx]) / d2, -0.5, 0.5);
        }
        const double w = std::max(0.05, sc[by][bx]);
        const Vec2 d = rot({coarse_h - coarse_anchor, coarse_h - coarse_anchor}, a);
        sx += w * (qx + d.x);
        sy += w * (qy + d.y);
        sw += w;
      }
      if (sw > 0) {
        h.cx = sx / sw;
        h.cy = sy / sw;
      }
    }
    double dark = 0, white = 0;
    int n_dark = 0;
    if (ring_check(h, &dark, &white, &n_dark) && n_dark > best_dark_count) {
      // The hypothesis with the most dark ring samples wins (a false corner predicting a
      // landmark mostly outside the image has few).
      best_dark_count = n_dark;
      *best = h;
      best->score_max = dark;   // reuse: dark level
      best->score_sum = white;  // white level
      *corner_score = h.score_max;
    }
  }
  return best_dark_count > 0;
}

// The corner templates come in 30-degree steps; the dominant gradient orientation (modulo 90
// degrees, from the 4x angle weighted by |g|^2) inside the predicted square refines the angle.
// The per-pixel 4x-angle vectors are computed once per frame (orient4), not per hypothesis.
void LandmarkLocalizer::Impl::compute_orient4() {
  orient4.create(coarse.size(), CV_32FC2);
  orient4.setTo(cv::Scalar::all(0));
  for (int y = 1; y + 1 < coarse.rows; ++y) {
    cv::Vec2f* o = orient4.ptr<cv::Vec2f>(y);
    for (int x = 1; x + 1 < coarse.cols; ++x) {
      int gxi, gyi;
      prewitt_at(coarse.ptr<std::uint8_t>(y) + x, static_cast<std::ptrdiff_t>(coarse.step[0]), &gxi,
                 &gyi);
      const double ex = gxi, ey = gyi, m2 = ex * ex + ey * ey;
      if (m2 < 1.0) continue;
      const double a = ex * ex - ey * ey, b = 2 * ex * ey;
      o[x] =
          cv::Vec2f(static_cast<float>((a * a - b * b) / m2), static_cast<float>(2 * a * b / m2));
    }
  }
}

void LandmarkLocalizer::Impl::refine_coarse_angle(Hypothesis* h) const {
  const double reach = coarse_h + 1.0;
  const int x0 = std::max(1, static_cast<int>(h->cx - reach));
  const int x1 = std::min(coarse.cols - 2, static_cast<int>(h->cx + reach) + 1);
  const int y0 = std::max(1, static_cast<int>(h->cy - reach));
  const int y1 = std::min(coarse.rows - 2, static_cast<int>(h->cy + reach) + 1);
  const Vec2 n0{std::cos(h->up_angle), std::sin(h->up_angle)};
  double c4 = 0, s4 = 0;
  for (int y = y0; y <= y1; ++y) {
    const cv::Vec2f* o = orient4.ptr<cv::Vec2f>(y);
    for (int x = x0; x <= x1; ++x) {
      const double dx = x - h->cx, dy = y - h->cy;
      if (std::abs(dx * n0.x + dy * n0.y) > reach || std::abs(-dx * n0.y + dy * n0.x) > reach) {
        continue;
      }
      c4 += static_cast<double>(o[x][0]);
      s4 += static_cast<double>(o[x][1]);
    }
  }
  if (c4 != 0 || s4 != 0) h->up_angle = reduce_angle_90(std::atan2(s4, c4) / 4.0, h->up_angle);
}

bool LandmarkLocalizer::Impl::ring_check(const Hypothesis& h, double* dark_level,
                                         double* white_level, int* n_dark) {
  int ring_in = 0, ring_dark = 0, out_in = 0, out_dark = 0, total = 0;
  double dark_sum = 0, white_sum = 0;
  const double len = coarse_h - coarse_w;
  const int n = std::max(4, static_cast<int>(2.0 * len));
  for (int k = 0; k < 4; ++k) {
    const double a = h.up_angle + k * kPi / 2.0;
    const Vec2 nrm{std::cos(a), std::sin(a)}, tan{-nrm.y, nrm.x};
    for (int i = 0; i <= n; ++i) {
      const double t = -len + 2.0 * len * i / n;
      ++total;
      const double rx = h.cx + nrm.x * (coarse_h - coarse_w / 2) + tan.x * t;
      const double ry = h.cy + nrm.y * (coarse_h - coarse_w / 2) + tan.y * t;
      const int ix = static_cast<int>(std::lround(rx)), iy = static_cast<int>(std::lround(ry));
      if (ix >= 0 && iy >= 0 && ix < binary.cols && iy < binary.rows) {
        ++ring_in;
        if (binary.at<std::uint8_t>(iy, ix)) {
          ++ring_dark;
          dark_sum += coarse.at<std::uint8_t>(iy, ix);
        }
      }
      const double ox = h.cx + nrm.x * (coarse_h + 0.9 * coarse_w) + tan.x * t;
      const double oy = h.cy + nrm.y * (coarse_h + 0.9 * coarse_w) + tan.y * t;
      const int jx = static_cast<int>(std::lround(ox)), jy = static_cast<int>(std::lround(oy));
      if (jx >= 0 && jy >= 0 && jx < binary.cols && jy < binary.rows) {
        ++out_in;
        if (binary.at<std::uint8_t>(jy, jx)) {
          ++out_dark;
        } else {
          white_sum += coarse.at<std::uint8_t>(jy, jx);
        }
      }
    }
  }
  if (ring_in < total / 4 || ring_dark == 0) return false;
  if (static_cast<double>(ring_dark) < cfg.ring_dark_fraction * ring_in) return false;
  if (out_in > 0 && out_dark > out_in / 2) return false;
  *dark_level = dark_sum / ring_dark;
  *n_dark = ring_dark;
  *white_level = out_in > out_dark ? white_sum / (out_in - out_dark) : 255.0;
  return true;
}

bool LandmarkLocalizer::Impl::read_qr_search(const cv::Mat& img, Vec2 c, double up_angle,
                                             std::string* text, double* qr_up_angle, bool* qr_ok) {
  *qr_ok = false;
  const double module_px = geom.qr_side_mm() / 25.0 / mm_per_px;
  int d = 1;
  if (cfg.qr_target_module_px > 0) {
    d = std::max(1, static_cast<int>(std::floor(module_px / cfg.qr_target_module_px + 0.25)));
  }
  ZXing::DecodeHints hints;
  hints.setFormats(ZXing::BarcodeFormat::QRCode)
      .setTryHarder(cfg.qr_try_harder)
      .setTryRotate(cfg.qr_try_harder)
      .setTryDownscale(false)
      .setMaxNumberOfSymbols(1);
  ZXing::Result res;
  cv::Rect r;
  // Attempts: (0) the inner white square's bounding box; only when that fails: (1) the same crop
  // slightly blurred, which removes thin scratches that break zxing's local binarizer; (2) a
  // larger crop (zxing's block binarizer is sensitive to where blocks fall on a blurred code);
  // (3) zxing's global-histogram binarizer; (4, 5) an unsharp-masked crop (sigma 2.5 px, amount
  // 1) with either binarizer, which recovers codes smeared by defocus plus motion blur.
  const int attempts = cfg.qr_retries ? 6 : 1;
  for (int attempt = 0; attempt < attempts; ++attempt) {
    const double half = (attempt == 2 ? geom.outer_half_mm() : geom.inner_half_mm()) / mm_per_px *
                            (std::abs(std::cos(up_angle)) + std::abs(std::sin(up_angle))) +
                        4.0;
    r = cv::Rect(static_cast<int>(std::floor(c.x - half)), static_cast<int>(std::floor(c.y - half)),
                 static_cast<int>(std::ceil(2 * half)) + 1,
                 static_cast<int>(std::ceil(2 * half)) + 1);
    r &= cv::Rect(0, 0, img.cols, img.rows);
    if (r.width < 16 || r.height < 16) return false;
    cv::Mat roi = img(r);
    const cv::Mat* src = &roi;
    if (d > 1) {
      cv::resize(roi, qr_small, cv::Size(r.width / d, r.height / d), 0, 0, cv::INTER_AREA);
      src = &qr_small;
    }
    if (attempt == 1) {
      cv::GaussianBlur(*src, qr_blur, cv::Size(0, 0), 1.0);
      src = &qr_blur;
    } else if (attempt >= 4) {
      cv::GaussianBlur(*src, qr_blur, cv::Size(0, 0), 2.5);
      cv::addWeighted(*src, 2.0, qr_blur, -1.0, 0.0, qr_sharp);
      src = &qr_sharp;
    }
    hints.setBinarizer(attempt == 3 || attempt == 5 ? ZXing::Binarizer::GlobalHistogram
                                                    : ZXing::Binarizer::LocalAverage);
    ZXing::ImageView iv(src->data, src->cols, src->rows, ZXing::ImageFormat::Lum,
                        static_cast<int>(src->step[0]));
    res = ZXing::ReadBarcode(iv, hints);
    if (res.isValid()) break;
  }
  if (!res.isValid()) return false;
  *text = res.text();
  const auto& pos = res.position();
  auto to_full = [&](ZXing::PointI p) {
    return Vec2{r.x + (p.x + 0.5) * d - 0.5, r.y + (p.y + 0.5) * d - 0.5};
  };
  const Vec2 tl = to_full(pos.topLeft()), tr = to_full(pos.topRight()),
             br = to_full(pos.bottomRight()), bl = to_full(pos.bottomLeft());
  *qr_up_angle = std::atan2((tl.y + tr.y) - (bl.y + br.y), (tl.x + tr.x) - (bl.x + br.x));
  *qr_ok = !res.isMirrored();
  return true;
}

bool LandmarkLocalizer::Impl::sample_qr(const cv::Mat& img, Vec2 c_mm, double fwd, int n,
                                        QrSamples* s) {
  const CameraModel& mc = metric_cam();
  const Pose2 l_in_v{c_mm.x, c_mm.y, fwd};
  const double m = geom.qr_side_mm() / n;
  auto to_px = [&](Vec2 uv, Vec2* px) {
    return mc.vehicle_to_pixel(transform(l_in_v, page_to_landmark(uv)), px);
  };
  // Four extra samples per module at a quarter module along the page axes (pixel offsets from
  // the code's centre; distortion changes them by far less than a pixel over the code).
  const Vec2 mid{geom.qr_u0_mm() + 0.5 * geom.qr_side_mm(),
                 geom.qr_v0_mm() + 0.5 * geom.qr_side_mm()};
  Vec2 p0, pu, pv;
  if (!to_px(mid, &p0) || !to_px({mid.x + 0.25 * m, mid.y}, &pu) ||
      !to_px({mid.x, mid.y + 0.25 * m}, &pv)) {
    return false;
  }
  const Vec2 du{pu.x - p0.x, pu.y - p0.y}, dv{pv.x - p0.x, pv.y - p0.y};
  s->n = n;
  s->ring = 2;
  const int side = s->side();
  s->v.resize(static_cast<size_t>(side * side));
  // Modules whose samples leave the image (a landmark cut by the image border) are filled in:
  // quiet-zone modules with the quiet zone's median, fixed modules with their known value, and up
  // to max_missing_data data modules with the code's mean (left to Reed-Solomon to correct).
  constexpr float kMissing = -1.0f;
  int missing_data = 0, missing = 0;
  const int max_missing_data = cfg.qr_max_missing_modules;
  for (int r = 0; r < side; ++r) {
    for (int c = 0; c < side; ++c) {
      const Vec2 uv{geom.qr_u0_mm() + (c - s->ring + 0.5) * m,
                    geom.qr_v0_mm() + (r - s->ring + 0.5) * m};
      Vec2 px;
      double acc = 0, v = 0;
      bool inside = to_px(uv, &px);
      const double ou[5] = {0, 1, -1, 0, 0}, ov[5] = {0, 0, 0, 1, -1};
      for (int k = 0; k < 5 && inside; ++k) {
        inside =
            sample(img, px.x + ou[k] * du.x + ov[k] * dv.x, px.y + ou[k] * du.y + ov[k] * dv.y, &v);
        acc += v;
      }
      if (!inside) {
        ++missing;
        const int rr = r - s->ring, cc = c - s->ring;
        const bool in_code = rr >= 0 && cc >= 0 && rr < n && cc < n;
        if (in_code && qr_fixed_module(n, rr, cc) < 0 && ++missing_data > max_missing_data) {
          return false;
        }
      }
      s->v[static_cast<size_t>(r * side + c)] = inside ? static_cast<float>(acc / 5.0) : kMissing;
    }
  }
  if (missing == 0) return true;
  // Levels for the fill-in, from the samples that were inside.
  qr_fill.clear();
  double code_sum = 0;
  int code_n = 0;
  for (int r = 0; r < side; ++r) {
    for (int c = 0; c < side; ++c) {
      const float v = s->v[static_cast<size_t>(r * side + c)];
      if (v == kMissing) continue;
      const int rr = r - s->ring, cc = c - s->ring;
      if (rr >= 0 && cc >= 0 && rr < n && cc < n) {
        code_sum += static_cast<double>(v);
        ++code_n;
      } else {
        qr_fill.push_back(v);
      }
    }
  }
  if (qr_fill.empty() || code_n == 0) return false;
  std::nth_element(qr_fill.begin(),
                   qr_fill.begin() + static_cast<std::ptrdiff_t>(qr_fill.size() / 2),
                   qr_fill.end());
  const float light = qr_fill[qr_fill.size() / 2];
  const float mean = static_cast<float>(code_sum / code_n);
  const float dark = std::max(0.0f, 2.0f * mean - light);
  for (int r = 0; r < side; ++r) {
    for (int c = 0; c < side; ++c) {
      float& v = s->v[static_cast<size_t>(r * side + c)];
      if (v != kMissing) continue;
      const int rr = r - s->ring, cc = c - s->ring;
      const int f = (rr >= 0 && cc >= 0 && rr < n && cc < n) ? qr_fixed_module(n, rr, cc) : 0;
      const bool in_code = rr >= 0 && cc >= 0 && rr < n && cc < n;
      v = !in_code ? light : f == 1 ? dark : f == 0 ? light : mean;
    }
  }
  return true;
}

FixStatus LandmarkLocalizer::Impl::check_payload(const std::string& text, LandmarkFix* out,
                                                 Pose2* world_landmark) {
  std::snprintf(out->payload, sizeof out->payload, "%s", text.c_str());
  LandmarkPayload p;
  if (parse_payload(text, &p) != PayloadError::kOk) return FixStatus::kPayloadInvalid;
  out->landmark_id = p.id;
  const LandmarkMapEntry* e = map ? map->find(p.id) : nullptr;
  if (!p.has_pose) {
    if (!e) return FixStatus::kUnknownLandmark;
    *world_landmark = e->pose;
  } else {
    const Pose2 pp = payload_pose(p);
    if (map) {
      if (!e) return FixStatus::kUnknownLandmark;
      const double dpos = std::hypot(pp.x_mm - e->pose.x_mm, pp.y_mm - e->pose.y_mm);
      const double dang = std::abs(rad_to_deg(wrap_angle_rad(pp.theta_rad - e->pose.theta_rad)));
      if (!(dpos <= cfg.map_tolerance_mm) || !(dang <= cfg.map_tolerance_deg)) {
        return FixStatus::kPayloadInvalid;
      }
    }
    *world_landmark = pp;
  }
  out->map_verified = map != nullptr;
  return FixStatus::kOk;
}

// Collects classified, non-maximum-suppressed, optionally subpixel edge points of the 8 border
// lines (outer and inner edge of each side). Only pixels inside a band of +-band px around each
// predicted line are visited (rasterised strip), and a pixel is kept for a line only when its
// gradient class (paper 001 fig. 7: direction within the tolerance of the line's normal, outward
// on outer edges, inward on inner edges) is that line's class.
int LandmarkLocalizer::Impl::collect(const cv::Mat& img, Vec2 c, double up, double band,
                                     double thr) {
  const double h_out = geom.outer_half_mm() / mm_per_px;
  const double h_in = geom.inner_half_mm() / mm_per_px;
  const double tan_tol = std::tan(deg_to_rad(cfg.edge_direction_tol_deg));
  // Squared-magnitude threshold in integers (Prewitt sums are exact): a pixel passes when
  // gx^2 + gy^2 >= thr^2.
  const int thr2_int = static_cast<int>(std::ceil(std::min(thr * thr, 4.0e6)));
  const std::uint8_t* base = img.data;
  const std::ptrdiff_t step = static_cast<std::ptrdiff_t>(img.step[0]);
  const int x_lo = 2, y_lo = 2, x_hi = img.cols - 3, y_hi = img.rows - 3;
  int total = 0;
  for (auto& v : pts_px) v.clear();
  for (int k = 0; k < 4; ++k) {
    const double na = up + k * kPi / 2;
    const Vec2 nk{std::cos(na), std::sin(na)}, tk{-nk.y, nk.x};
    for (int e = 0; e < 2; ++e) {
      const double h = e == 0 ? h_out : h_in;
      // Expected gradient direction: outward on the outer edge, inward on the inner edge.
      const Vec2 g_dir = e == 0 ? nk : Vec2{-nk.x, -nk.y};
      const double t_max = h - band;  // stay away from the corners
      if (t_max <= 0) continue;
      auto& dst = pts_px[static_cast<size_t>(k * 2 + e)];
      const Vec2 m{c.x + nk.x * h, c.y + nk.y * h};  // foot of the line
      // Iterate along the pixel axis closest to the line direction.
      const bool by_rows = std::abs(tk.y) >= std::abs(tk.x);
      const double ta = by_rows ? tk.y : tk.x;        // line direction, major component
      const double na_major = by_rows ? nk.x : nk.y;  // normal, across component
      const double m_major = by_rows ? m.y : m.x;
      const double m_minor = by_rows ? m.x : m.y;
      const double t_minor = by_rows ? tk.x : tk.y;
      const double q0 = m_major - std::abs(ta) * t_max, q1 = m_major + std::abs(ta) * t_max;
      const int i0 = std::max(static_cast<int>(std::ceil(q0)), by_rows ? y_lo : x_lo);
      const int i1 = std::min(static_cast<int>(std::floor(q1)), by_rows ? y_hi : x_hi);
      const double half_w = band / std::max(std::abs(na_major), 1e-6);
      const int sx = by_rows ? 1 : 0, sy = by_rows ? 0 : 1;  // step across the line
      for (int i = i0; i <= i1; ++i) {
        const double tau = (i - m_major) / ta;
        const double centre_minor = m_minor + tau * t_minor;
        const int j0 =
            std::max(static_cast<int>(std::ceil(centre_minor - half_w)), by_rows ? x_lo : y_lo);
        const int j1 =
            std::min(static_cast<int>(std::floor(centre_minor + half_w)), by_rows ? x_hi : y_hi);
        if (j1 < j0) continue;
        // Gradients of the strip's pixels and of one more on each side (the non-maximum
        // suppression compares each pixel with its two neighbours along j, which is the pixel
        // axis closest to the line's normal).
        const int n = j1 - j0 + 3;
        strip_gx.resize(static_cast<size_t>(n));
        strip_gy.resize(static_cast<size_t>(n));
        strip_along.resize(static_cast<size_t>(n));
        for (int q = 0; q < n; ++q) {
          const int j = j0 - 1 + q;
          const int x = by_rows ? j : i, y = by_rows ? i : j;
          int gxi, gyi;
          prewitt_at(base + static_cast<std::ptrdiff_t>(y) * step + x, step, &gxi, &gyi);
          strip_gx[static_cast<size_t>(q)] = gxi;
          strip_gy[static_cast<size_t>(q)] = gyi;
          strip_along[static_cast<size_t>(q)] = gxi * g_dir.x + gyi * g_dir.y;
        }
        for (int q = 1; q + 1 < n; ++q) {
          const int gxi = strip_gx[static_cast<size_t>(q)], gyi = strip_gy[static_cast<size_t>(q)];
          if (gxi * gxi + gyi * gyi < thr2_int) continue;
          if (!gradient_within(gxi, gyi, g_dir, tan_tol)) continue;
          const double along = strip_along[static_cast<size_t>(q)];
          const double em = strip_along[static_cast<size_t>(q - 1)];
          const double ep = strip_along[static_cast<size_t>(q + 1)];
          if (!(along >= em && along > ep)) continue;
          double off = 0;
          if (cfg.subpixel) {
            const double den = em - 2 * along + ep;
            if (den < 0) off = std::clamp(0.5 * (em - ep) / den, -0.5, 0.5);
          }
          const int j = j0 - 1 + q;
          const int x = by_rows ? j : i, y = by_rows ? i : j;
          dst.push_back({x + off * sx, y + off * sy});
        }
      }
      total += static_cast<int>(dst.size());
    }
  }
  return total;
}

namespace {

// Joint model: outward normal of side k in the metric frame is at beta - k * 90 deg (the image
// shows the floor from above, and image y points down, so the clockwise order flips).
Vec2 side_normal_mm(double beta, int k) {
  const double a = beta - k * kPi / 2.0;
  return {std::cos(a), std::sin(a)};
}

Vec2 intersect(const Line2& a, const Line2& b, bool* ok) {
  const double det = a.nx * b.ny - a.ny * b.nx;
  *ok = std::abs(det) > 1e-9;
  if (!*ok) return {};
  return {(a.d * b.ny - a.ny * b.d) / det, (a.nx * b.d - a.d * b.nx) / det};
}

}  // namespace

FixStatus LandmarkLocalizer::Impl::pose(const cv::Mat& img, Vec2 c_px, double up, double contrast,
                                        LandmarkFix* out, Vec2* c_mm, double* beta_out,
                                        Eigen::Matrix3d* cov) {
  const double w_px = geom.border_width_mm() / mm_per_px;
  const double thr = cfg.edge_threshold_rel * 3.0 * contrast;
  const int total = collect(img, c_px, up, cfg.band_rel * w_px, thr);
  up_angle_px = up;
  if (total < cfg.min_points_total) return FixStatus::kTooFewEdgePoints;

  // Metric conversion of every point.
  const CameraModel& mc = metric_cam();
  std::array<LineFit, kNumLines> fits;
  line_ok.fill(false);
  int used = 0;
  for (int l = 0; l < kNumLines; ++l) {
    auto& src = pts_px[static_cast<size_t>(l)];
    auto& dst = pts_mm[static_cast<size_t>(l)];
    dst.clear();
    size_t keep = 0;
    for (size_t i = 0; i < src.size(); ++i) {
      Vec2 q;
      if (mc.pixel_to_vehicle(src[i], &q)) {
        src[keep++] = src[i];
        dst.push_back(q);
      }
    }
    src.resize(keep);
    auto& w = weights[static_cast<size_t>(l)];
    w.assign(dst.size(), 1.0);
    if (static_cast<int>(dst.size()) < cfg.min_points_per_line) continue;
    bool ok;
    if (cfg.robust) {
      ok = fit_line_robust(dst, cfg.tukey_c, 0.02, 4, w, &fits[static_cast<size_t>(l)],
                           cfg.ransac_iterations, 0.5 * mm_per_px);
    } else {
      ok = fit_line_tls(dst, {}, &fits[static_cast<size_t>(l)]);
    }
    // A line must be long enough to carry an angle (half the inner side).
    if (ok && fits[static_cast<size_t>(l)].extent >= geom.inner_half_mm()) {
      line_ok[static_cast<size_t>(l)] = true;
      used += fits[static_cast<size_t>(l)].n;
    }
  }
  std::array<bool, 4> side_ok{};
  for (int k = 0; k < 4; ++k) side_ok[k] = line_ok[k * 2] && line_ok[k * 2 + 1];
  out->sides_used = side_ok[0] + side_ok[1] + side_ok[2] + side_ok[3];
  const bool axis0 = side_ok[0] || side_ok[2], axis1 = side_ok[1] || side_ok[3];
  if (!axis0 || !axis1 || used < cfg.min_points_total) return FixStatus::kTooFewEdgePoints;
  out->edge_points_used = used;

  // Initial metric angle of side 0's normal from the pixel angle.
  Vec2 a0, a1;
  mc.pixel_to_vehicle(c_px, &a0);
  mc.pixel_to_vehicle({c_px.x + 20 * std::cos(up), c_px.y + 20 * std::sin(up)}, &a1);
  const double beta0 = std::atan2(a1.y - a0.y, a1.x - a0.x);

  // Per-line angles reduced to side 0's normal direction (line direction +90 deg).
  std::vector<double>& angles = logo_samples;  // scratch (reused below for the logo)
  angles.clear();
  std::array<double, kNumLines> ang{}, var_ang{}, k000{};
  for (int l = 0; l < kNumLines; ++l) {
    if (!line_ok[static_cast<size_t>(l)]) continue;
    const LineFit& f = fits[static_cast<size_t>(l)];
    const double nrm_angle = std::atan2(f.line.ny, f.line.nx);
    ang[static_cast<size_t>(l)] = reduce_angle_90(nrm_angle, beta0);
    var_ang[static_cast<size_t>(l)] = std::max(f.var_angle, 1e-14);
    // Paper 000 eq. 11 with raw coordinates across the line.
    double sy2 = 0;
    for (const Vec2& p : pts_mm[static_cast<size_t>(l)]) {
      const double y = f.line.nx * p.x + f.line.ny * p.y;
      sy2 += y * y;
    }
    k000[static_cast<size_t>(l)] = weight_000(sy2, f.rms * f.rms * f.sum_w);
  }
  auto heading = [&]() {
    double s = 0, sw = 0;
    for (int l = 0; l < kNumLines; ++l) {
      if (!line_ok[static_cast<size_t>(l)]) continue;
      double w = 1.0;
      if (cfg.heading_method == HeadingMethod::kWeighted000) w = k000[static_cast<size_t>(l)];
      if (cfg.heading_method == HeadingMethod::kInverseVariance) {
        w = 1.0 / var_ang[static_cast<size_t>(l)];
      }
      s += w * (ang[static_cast<size_t>(l)] - beta0);
      sw += w;
    }
    return beta0 + (sw > 0 ? s / sw : 0.0);
  };

  double beta = heading();
  Vec2 c{a0.x, a0.y};
  const bool all_sides = out->sides_used == 4;
  PoseMethod method = cfg.pose_method;
  if (!all_sides) method = PoseMethod::kJointSquareFit;

  if (method == PoseMethod::kPaperCornerA) {
    // Paper 001 eq. 8-11 in the frame aligned with the fine heading: corner A of the border's
    // midline square from the extreme edge points of the left (side 3) and top (side 0) sides.
    const double cb = std::cos(beta), sb = std::sin(beta);
    auto to_al = [&](Vec2 p) { return Vec2{cb * p.x + sb * p.y, -sb * p.x + cb * p.y}; };
    // Aligned frame: side 0 normal = +x, side 3 normal = beta + 90 deg = +y.
    auto extreme = [&](int line, bool along_y, double* coord) {
      const auto& v = pts_mm[static_cast<size_t>(line)];
      double best = -1e300;
      for (const Vec2& p : v) {
        const Vec2 q = to_al(p);
        const double t = along_y ? q.y : q.x;
        if (t > best) {
          best = t;
          *coord = along_y ? q.x : q.y;
        }
      }
    };
    double x1 = 0, x2 = 0, y3 = 0, y4 = 0;
    extreme(0, true, &x1);                                // side 0 outer, point with max y -> its x
    extreme(1, true, &x2);                                // side 0 inner
    extreme(6, false, &y3);                               // side 3 outer, point with max x -> its y
    extreme(7, false, &y4);                               // side 3 inner
    const double xa = (x1 + x2) / 2, ya = (y3 + y4) / 2;  // eq. 8-9
    const double half_d = 0.5 * (geom.outer_half_mm() + geom.inner_half_mm());
    const Vec2 o_al{xa - half_d, ya - half_d};  // eq. 10-11 (rotation already removed)
    c = {cb * o_al.x - sb * o_al.y, sb * o_al.x + cb * o_al.y};
  } else if (method == PoseMethod::kLineIntersections) {
    Vec2 sum{0, 0};
    int n = 0;
    for (int e = 0; e < 2; ++e) {
      for (int k = 0; k < 4; ++k) {
        bool ok;
        const Vec2 p = intersect(fits[static_cast<size_t>(k * 2 + e)].line,
                                 fits[static_cast<size_t>(((k + 1) % 4) * 2 + e)].line, &ok);
        if (ok) {
          sum.x += p.x;
          sum.y += p.y;
          ++n;
        }
      }
    }
    if (n == 0) return FixStatus::kTooFewEdgePoints;
    c = {sum.x / n, sum.y / n};
  }

  // Joint fit (also used for the covariance of every method). Parameters: c_x, c_y, beta and,
  // when an axis has both sides, shared outer/inner half sizes.
  const bool free_size = (side_ok[0] && side_ok[2]) || (side_ok[1] && side_ok[3]);
  double h_out = geom.outer_half_mm(), h_in = geom.inner_half_mm();
  const int np = free_size ? 5 : 3;
  if (method == PoseMethod::kJointSquareFit) {
    // Start: the centre's coordinate along each axis from the line centroids, n_k . c =
    // n_k . centroid - h (side k's normal is +-n_(k%2)).
    double num[2] = {0, 0};
    int cnt[2] = {0, 0};
    for (int k = 0; k < 4; ++k) {
      const Vec2 n = side_normal_mm(beta, k);
      const double sgn = k < 2 ? 1.0 : -1.0;
      for (int e = 0; e < 2; ++e) {
        const int l = k * 2 + e;
        if (!line_ok[static_cast<size_t>(l)]) continue;
        const Vec2 m = fits[static_cast<size_t>(l)].centroid;
        num[k % 2] += sgn * (m.x * n.x + m.y * n.y - (e == 0 ? h_out : h_in));
        ++cnt[k % 2];
      }
    }
    const Vec2 n0 = side_normal_mm(beta, 0), n1 = side_normal_mm(beta, 1);
    const double t0 = cnt[0] ? num[0] / cnt[0] : (c.x * n0.x + c.y * n0.y);
    const double t1 = cnt[1] ? num[1] / cnt[1] : (c.x * n1.x + c.y * n1.y);
    c = {t0 * n0.x + t1 * n1.x, t0 * n0.y + t1 * n1.y};
  }
  // Normal equations of all five parameters; the size terms are left out (np == 3) when no axis
  // has both sides. Fixed size: no heap, and the per-point work is six sums per line (the
  // Jacobian row is constant along a line except for its angle term).
  Eigen::Matrix<double, 5, 5> jtj;
  Eigen::Matrix<double, 5, 1> jtr;
  double ssr = 0, sw_all = 0;
  const bool joint = method == PoseMethod::kJointSquareFit;
  // Joint robust rounds: after the first round, every point of every fitted line (also those the
  // per-line fit rejected) is re-weighted (Tukey) by its residual to the joint model with one
  // global scale, so an occluder edge that won a single line's vote is rejected by the square.
  const int rounds = joint && cfg.robust ? 3 : 1;
  const int iters = joint ? 5 * rounds : 1;
  for (int it = 0; it < iters; ++it) {
    if (joint && cfg.robust && it > 0 && it % 5 == 0) {
      residual_buf.clear();
      for (int k = 0; k < 4; ++k) {
        const Vec2 n = side_normal_mm(beta, k);
        for (int e = 0; e < 2; ++e) {
          const int l = k * 2 + e;
          if (!line_ok[static_cast<size_t>(l)]) continue;
          for (const Vec2& p : pts_mm[static_cast<size_t>(l)]) {
            residual_buf.push_back(
                std::abs(n.x * (p.x - c.x) + n.y * (p.y - c.y) - (e == 0 ? h_out : h_in)));
          }
        }
      }
      scratch_buf = residual_buf;
      const auto mid = scratch_buf.size() / 2;
      std::nth_element(scratch_buf.begin(), scratch_buf.begin() + static_cast<std::ptrdiff_t>(mid),
                       scratch_buf.end());
      const double sigma = std::max(0.005, 1.4826 * scratch_buf[mid]);
      const double cut = cfg.tukey_c * sigma;
      size_t idx = 0;
      for (int l = 0; l < kNumLines; ++l) {
        if (!line_ok[static_cast<size_t>(l)]) continue;
        for (double& wi : weights[static_cast<size_t>(l)]) {
          const double u = residual_buf[idx++] / cut;
          wi = u < 1.0 ? (1.0 - u * u) * (1.0 - u * u) : 0.0;
        }
      }
    }
    jtj.setZero();
    jtr.setZero();
    ssr = 0;
    sw_all = 0;
    for (int k = 0; k < 4; ++k) {
      const Vec2 n = side_normal_mm(beta, k);
      const Vec2 dn{-n.y, n.x};  // d n / d beta
      for (int e = 0; e < 2; ++e) {
        const int l = k * 2 + e;
        if (!line_ok[static_cast<size_t>(l)]) continue;
        const auto& v = pts_mm[static_cast<size_t>(l)];
        const auto& w = weights[static_cast<size_t>(l)];
        const double h = e == 0 ? h_out : h_in;
        // Row of point i: (-n.x, -n.y, a_i, -[outer], -[inner]) with a_i = dn . (p_i - c).
        double s_w = 0, s_a = 0, s_aa = 0, s_r = 0, s_ar = 0, s_rr = 0;
        for (size_t i = 0; i < v.size(); ++i) {
          const double wi = w[i];
          if (!(wi > 0)) continue;
          const double dx = v[i].x - c.x, dy = v[i].y - c.y;
          const double r = n.x * dx + n.y * dy - h;
          const double a = dn.x * dx + dn.y * dy;
          s_w += wi;
          s_a += wi * a;
          s_aa += wi * a * a;
          s_r += wi * r;
          s_ar += wi * a * r;
          s_rr += wi * r * r;
        }
        Eigen::Matrix<double, 5, 1> u;
        u << -n.x, -n.y, 0.0, e == 0 ? -1.0 : 0.0, e == 1 ? -1.0 : 0.0;
        jtj.noalias() += s_w * u * u.transpose();
        for (int q = 0; q < 5; ++q) {
          jtj(q, 2) += u(q) * s_a;
          jtj(2, q) += u(q) * s_a;
        }
        jtj(2, 2) += s_aa;
        jtr += s_r * u;
        jtr(2) += s_ar;
        ssr += s_rr;
        sw_all += s_w;
      }
    }
    if (method != PoseMethod::kJointSquareFit) break;
    Eigen::Matrix<double, 5, 1> delta = Eigen::Matrix<double, 5, 1>::Zero();
    if (np == 5) {
      delta = jtj.ldlt().solve(-jtr);
    } else {
      delta.head<3>() = jtj.topLeftCorner<3, 3>().ldlt().solve(-jtr.head<3>());
    }
    if (!delta.allFinite()) return FixStatus::kTooFewEdgePoints;
    c.x += delta(0);
    c.y += delta(1);
    beta += delta(2);
    if (free_size) {
      h_out += delta(3);
      h_in += delta(4);
    }
    if (delta.head(3).norm() < 1e-9 && (it + 1) % 5 != 0) it += 4 - it % 5;  // next round
  }
  const double dof = std::max(1.0, sw_all - np);
  const double s2 = ssr / dof;
  Eigen::Matrix3d cv3;
  if (np == 5) {
    const Eigen::Matrix<double, 5, 5> inv =
        jtj.ldlt().solve(Eigen::Matrix<double, 5, 5>::Identity());
    cv3 = inv.topLeftCorner<3, 3>() * s2 * cfg.cov_inflation;
  } else {
    cv3 = jtj.topLeftCorner<3, 3>().ldlt().solve(Eigen::Matrix3d::Identity()) * s2 *
          cfg.cov_inflation;
  }
  cv3(0, 0) += cfg.sigma_floor_mm * cfg.sigma_floor_mm;
  cv3(1, 1) += cfg.sigma_floor_mm * cfg.sigma_floor_mm;
  cv3(2, 2) += deg_to_rad(cfg.sigma_floor_deg) * deg_to_rad(cfg.sigma_floor_deg);
  *cov = cv3;
  out->residual_rms_mm = sw_all > 0 ? std::sqrt(ssr / sw_all) : 0.0;
  *c_mm = c;
  *beta_out = beta;

  // Overlay geometry in pixels.
  for (int e = 0; e < 2; ++e) {
    const double h = e == 0 ? h_out : h_in;
    for (int k = 0; k < 4; ++k) {
      const Vec2 n = side_normal_mm(beta, k), m = side_normal_mm(beta, k + 1);
      Vec2 px;
      mc.vehicle_to_pixel({c.x + h * (n.x + m.x), c.y + h * (n.y + m.y)}, &px);
      corners_px[static_cast<size_t>(e * 4 + k)] = px;
    }
  }
  mc.vehicle_to_pixel(c, &centre_px);
  return FixStatus::kOk;
}

FixStatus LandmarkLocalizer::Impl::run(const cv::Mat& img, LandmarkFix* out) {
  have_overlay = false;
  const double t0 = now_ms();
  auto finish = [&](FixStatus s) {
    out->status = s;
    if (cfg.now_ns) out->timings.total_ms = now_ms() - t0;
    return s;
  };
  if (img.empty() || img.type() != CV_8UC1 || img.dims != 2 ||
      img.cols != cam.intrinsics.width_px || img.rows != cam.intrinsics.height_px) {
    return finish(FixStatus::kBadInput);
  }
  // 1-2. Detection.
  Hypothesis h;
  bool found_corner = false;
  double corner_score = 0;
  const bool found = detect(img, &h, &found_corner, &corner_score);
  out->corner_score = corner_score;
  const double t1 = now_ms();
  if (cfg.now_ns) out->timings.detect_ms = t1 - t0;
  if (!found) return finish(FixStatus::kNoLandmark);
  const double dark = h.score_max, white = h.score_sum;
  const double contrast = white - dark;
  if (contrast < 15.0) return finish(FixStatus::kNoLandmark);
  Vec2 c_px = coarse_to_full({h.cx, h.cy});
  const double up = h.up_angle;
  out->detect_x_px = c_px.x;
  out->detect_y_px = c_px.y;
  out->detect_angle_deg = rad_to_deg(up);

  // Partly outside: any predicted outer corner beyond the image (plus margin).
  {
    const double margin_px = cfg.outside_margin_mm / mm_per_px;
    const double ho = geom.outer_half_mm() / mm_per_px;
    for (int k = 0; k < 4; ++k) {
      const Vec2 d = rot({ho, ho}, up + k * kPi / 2);
      const double x = c_px.x + d.x, y = c_px.y + d.y;
      if (x < -0.5 - margin_px || y < -0.5 - margin_px || x > img.cols - 0.5 + margin_px ||
          y > img.rows - 0.5 + margin_px) {
        out->partly_outside = true;
      }
    }
    if (out->partly_outside && !cfg.allow_partly_outside) return finish(FixStatus::kPartlyOutside);
  }

  // 5. Pose first: the guided QR reading and the logo are sampled where the fitted pose puts them.
  Vec2 c_mm;
  double beta = 0;
  Eigen::Matrix3d cov;
  FixStatus st = pose(img, c_px, up, contrast, out, &c_mm, &beta, &cov);
  const double t2 = now_ms();
  if (cfg.now_ns) out->timings.pose_ms = t2 - t1;
  if (st == FixStatus::kTooFewEdgePoints && out->partly_outside) st = FixStatus::kPartlyOutside;
  if (st != FixStatus::kOk) return finish(st);
  have_overlay = true;

  // 4. Direction: logo NCC at the four turns; the true forward axis is side q's normal.
  const CameraModel& mc = metric_cam();
  std::array<double, 4> sc{};
  for (int q = 0; q < 4; ++q) {
    const double fwd = beta - q * kPi / 2.0;
    logo_samples.clear();
    bool all_in = true;
    for (const Vec2& uv : logo_page_pts) {
      const Vec2 l = page_to_landmark(uv);
      const Vec2 v = transform({c_mm.x, c_mm.y, fwd}, l);
      Vec2 px;
      double val = 0;
      if (!mc.vehicle_to_pixel(v, &px) || !sample(img, px.x, px.y, &val)) {
        all_in = false;
        break;
      }
      logo_samples.push_back(val);
    }
    sc[static_cast<size_t>(q)] = all_in ? ncc(logo_samples, logo_template) : -1.0;
  }
  int best_q = 0;
  for (int q = 1; q < 4; ++q) {
    if (sc[static_cast<size_t>(q)] > sc[static_cast<size_t>(best_q)]) best_q = q;
  }
  double second = -1.0;
  for (int q = 0; q < 4; ++q) {
    if (q != best_q) second = std::max(second, sc[static_cast<size_t>(q)]);
  }
  out->logo_score = sc[static_cast<size_t>(best_q)];
  out->logo_margin = out->logo_score - second;
  const bool logo_clear =
      out->logo_score >= cfg.logo_threshold && out->logo_margin >= cfg.logo_margin;
  const double t3 = now_ms();

  // 3. QR: guided module sampling at the logo's turn (all four when the logo is unclear; the
  // code sits off-centre, so a wrong turn samples the wrong place and cannot decode), then
  // zxing's search on the crop. qr_q: the turn the code's own orientation points to.
  int qr_q = -1;
  qr_text.clear();
  if (cfg.qr_guided) {
    std::array<int, 4> order{best_q, -1, -1, -1};
    if (!logo_clear) {
      order = {0, 1, 2, 3};
      std::sort(order.begin(), order.end(), [&](int x, int y) {
        return sc[static_cast<size_t>(x)] > sc[static_cast<size_t>(y)];
      });
    }
    // Order measured (qr_grid.hpp, docs/accuracy.md): strong sharpening reads the most codes;
    // the others rescue a few more at no cost to frames that already decode.
    constexpr QrThreshold kThresholds[] = {QrThreshold::kStronglySharpenedLocalMean,
                                           QrThreshold::kSharpenedLocalMean,
                                           QrThreshold::kLocalMean, QrThreshold::kMidpoint};
    for (int q : order) {
      if (q < 0 || qr_q >= 0) break;
      for (int n : {25, 21}) {
        if (qr_q >= 0) break;
        if (!sample_qr(img, c_mm, beta - q * kPi / 2.0, n, &qr_samples)) continue;
        for (QrThreshold t : kThresholds) {
          if (decode_qr_grid(qr_samples, t, &qr_text, &qr_scratch)) {
            qr_q = q;
            out->qr_method = 1;
            break;
          }
        }
      }
    }
  }
  if (qr_q < 0) {
    double qr_up = 0;
    bool qr_ok = false;
    if (read_qr_search(img, c_px, up, &qr_text, &qr_up, &qr_ok)) {
      out->qr_method = 2;
      // The code's orientation in the metric frame: which turn does it point to?
      Vec2 a0, a1;
      if (qr_ok && mc.pixel_to_vehicle(c_px, &a0) &&
          mc.pixel_to_vehicle({c_px.x + 20 * std::cos(qr_up), c_px.y + 20 * std::sin(qr_up)},
                              &a1)) {
        const double b_qr = std::atan2(a1.y - a0.y, a1.x - a0.x);
        for (int q = 0; q < 4; ++q) {
          if (std::abs(wrap_angle_rad(b_qr - (beta - q * kPi / 2.0))) < deg_to_rad(30.0)) qr_q = q;
        }
      }
    }
  }
  Pose2 world_landmark;
  if (out->qr_method == 0) {
    st = FixStatus::kQrUnreadable;
  } else {
    st = check_payload(qr_text, out, &world_landmark);
  }
  const double t4 = now_ms();
  if (cfg.now_ns) out->timings.decode_ms = t4 - t3;
  if (st == FixStatus::kQrUnreadable && out->partly_outside) st = FixStatus::kPartlyOutside;
  if (st != FixStatus::kOk) return finish(st);

  int q_final = -1;
  if (logo_clear) {
    if (qr_q >= 0 && qr_q != best_q) {
      if (cfg.now_ns) out->timings.direction_ms = (t3 - t2) + (now_ms() - t4);
      return finish(FixStatus::kDirectionAmbiguous);
    }
    q_final = best_q;
  } else if (cfg.direction_from_qr_when_logo_weak && qr_q >= 0 &&
             out->logo_score < cfg.logo_threshold) {
    q_final = qr_q;
  }
  if (cfg.now_ns) out->timings.direction_ms = (t3 - t2) + (now_ms() - t4);
  if (q_final < 0) return finish(FixStatus::kDirectionAmbiguous);
  quadrant = q_final;

  // Result.
  const double fwd = wrap_angle_rad(beta - q_final * kPi / 2.0);
  out->landmark_in_vehicle = {c_mm.x, c_mm.y, fwd};
  const Pose2 v_in_l = inverse(out->landmark_in_vehicle);
  out->e_x_mm = v_in_l.x_mm;
  out->e_y_mm = v_in_l.y_mm;
  out->e_phi_deg = rad_to_deg(v_in_l.theta_rad);
  out->cov_landmark_in_vehicle = cov;
  out->vehicle_in_world = compose(world_landmark, v_in_l);
  // Covariance through W<-V = (W<-L) (+) inverse(V<-L), Jacobian by central differences.
  Eigen::Matrix3d jac;
  const double eps[3] = {1e-4, 1e-4, 1e-7};
  for (int j = 0; j < 3; ++j) {
    Pose2 a = out->landmark_in_vehicle, b = out->landmark_in_vehicle;
    double* pa = j == 0 ? &a.x_mm : j == 1 ? &a.y_mm : &a.theta_rad;
    double* pb = j == 0 ? &b.x_mm : j == 1 ? &b.y_mm : &b.theta_rad;
    *pa += eps[j];
    *pb -= eps[j];
    const Pose2 wa = compose(world_landmark, inverse(a)), wb = compose(world_landmark, inverse(b));
    jac(0, j) = (wa.x_mm - wb.x_mm) / (2 * eps[j]);
    jac(1, j) = (wa.y_mm - wb.y_mm) / (2 * eps[j]);
    jac(2, j) = wrap_angle_rad(wa.theta_rad - wb.theta_rad) / (2 * eps[j]);
  }
  out->cov_world = jac * cov * jac.transpose();
  return finish(FixStatus::kOk);
}

LandmarkLocalizer::LandmarkLocalizer(const VisionConfig& config, const CameraModel& camera,
                                     const LandmarkGeometry& geometry, const LandmarkMap* map)
    : impl_(std::make_unique<Impl>(config, camera, geometry, map)) {}

LandmarkLocalizer::~LandmarkLocalizer() = default;

const VisionConfig& LandmarkLocalizer::config() const { return impl_->cfg; }

const std::vector<Vec2>& LandmarkLocalizer::edge_points_px(int line) const {
  static const std::vector<Vec2> kNone;
  if (line < 0 || line >= kNumLines) return kNone;
  return impl_->pts_px[static_cast<size_t>(line)];
}

FixStatus LandmarkLocalizer::process(const cv::Mat& gray8, LandmarkFix* out) {
  if (!out) return FixStatus::kBadInput;
  *out = LandmarkFix{};
  try {
    return impl_->run(gray8, out);
  } catch (...) {
    // OpenCV and zxing report some malformed input by exceptions; never let them escape.
    impl_->have_overlay = false;
    out->status = FixStatus::kBadInput;
    return out->status;
  }
}

void LandmarkLocalizer::draw_overlay(const cv::Mat& gray8, const LandmarkFix& fix,
                                     cv::Mat* bgr_out) const {
  if (!bgr_out) return;
  if (gray8.empty() || gray8.type() != CV_8UC1) {
    *bgr_out = cv::Mat();
    return;
  }
  cv::cvtColor(gray8, *bgr_out, cv::COLOR_GRAY2BGR);
  const Impl& m = *impl_;
  char text[160];
  if (m.have_overlay) {
    // Colours by class relative to the landmark's forward direction (page up/right/down/left).
    const cv::Scalar colours[4] = {{0, 255, 0}, {0, 0, 255}, {255, 0, 0}, {0, 255, 255}};
    for (int l = 0; l < kNumLines; ++l) {
      const int side = l / 2;
      const int cls_img = (l % 2 == 0) ? side : (side + 2) % 4;  // gradient class
      const int cls = ((cls_img - m.quadrant) % 4 + 4) % 4;
      for (const Vec2& p : m.pts_px[static_cast<size_t>(l)]) {
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
        const Vec2 a = m.corners_px[static_cast<size_t>(e * 4 + k)];
        const Vec2 b = m.corners_px[static_cast<size_t>(e * 4 + (k + 1) % 4)];
        cv::line(*bgr_out, cv::Point2d(a.x, a.y), cv::Point2d(b.x, b.y), {0, 0, 255}, 1,
                 cv::LINE_AA);
      }
    }
    for (const Vec2& c : m.corners_px) {
      cv::circle(*bgr_out, cv::Point2d(c.x, c.y), 3, {0, 0, 255}, -1, cv::LINE_AA);
    }
    cv::circle(*bgr_out, cv::Point2d(m.centre_px.x, m.centre_px.y), 4, {255, 0, 255}, -1,
               cv::LINE_AA);
    // Forward arrow.
    const double fwd_img = m.up_angle_px + m.quadrant * kPi / 2.0;
    const double len = 0.6 * m.geom.outer_half_mm() / m.mm_per_px;
    cv::arrowedLine(*bgr_out, cv::Point2d(m.centre_px.x, m.centre_px.y),
                    cv::Point2d(m.centre_px.x + len * std::cos(fwd_img),
                                m.centre_px.y + len * std::sin(fwd_img)),
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

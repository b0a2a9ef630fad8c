// Stage 5 of the pipeline (docs/design/vision.md), QR decode: model-guided module sampling where
// the fitted pose puts the code (qr_grid), zxing's own search on the image crop as the fallback,
// then the payload parser and the map check. Also gives the QR code's orientation for the direction
// cross-check.
#define ZX_USE_UTF8 1
#include <ZXing/ReadBarcode.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>

#include "agv/vision/map_identity.hpp"
#include "code_reader.hpp"

namespace agv::vision {

namespace {

// zxing search attempts: the first only, or all six with VisionConfig::qr_retries (see
// read_qr_search for what each does).
constexpr int kQrSearchAttempts = 6;
// Downscale factor = floor(module_px / target + 0.25): rounds up from 0.75 of a step, so a code
// slightly above the target size is still reduced (zxing reads 3-5 px per module equally well).
constexpr double kDownscaleRoundUp = 0.25;
// The crop reaches this many pixels beyond the rotated square's bounding box: the detection
// centre can be a few pixels off, and zxing needs a little quiet zone.
constexpr double kQrCropMarginPx = 4.0;
// Below this crop size (pixels) there is no readable code (a version-2 code needs >= 25 px).
constexpr int kMinQrCropPx = 16;
// Attempt 1: a light Gaussian blur (sigma in px after downscaling) erases thin bright scratches.
constexpr double kScratchBlurSigmaPx = 1.0;
// Attempts 4 and 5: unsharp masking, sigma about one module after downscaling, amount 1.
constexpr double kUnsharpSigmaPx = 2.5;
constexpr double kUnsharpAmount = 1.0;
// Guided sampling: besides each module's centre, four samples a quarter module away along the
// page axes (averaging them tolerates a pose error of a quarter module), and two modules of quiet
// zone around the code (the local-mean thresholds need light surroundings).
constexpr double kSampleOffsetModules = 0.25;
constexpr int kSamplesPerModule = 5;
// The cheap first read (decode_guided) binarizes this way only: the order below reads the most
// codes with it.
constexpr QrThreshold kCentreOnlyThreshold = QrThreshold::kStronglySharpenedLocalMean;
constexpr int kQuietRingModules = 2;
constexpr float kMissing = -1.0f;  // marks a module whose samples left the image
// The QR orientation selects the turn whose forward axis lies within this angle: turns are 90
// degrees apart, and a misread orientation is off by a multiple of 90.
constexpr double kQrTurnTolDeg = 30.0;
// The tracked landmark is the mapped one predicted nearest the fitted centre, within this many
// outer half sizes: neighbouring landmarks are far further apart than the trusted prediction's
// few-sigma error, and a wrong pick costs only the zxing decode the expected code would have saved.
constexpr double kTrackedCodeReachRel = 1.0;

}  // namespace

// Reads the code (read_code) expecting the tracked landmark's codes when there is a trusted
// prediction, and records on the fix how often zxing ran.
int CodeReader::decode_qr(const cv::Mat& img, const Prediction& pred,
                          const std::vector<SearchWindow>& windows, Vec2 c_px, double up, Vec2 c_mm,
                          double beta, const LogoScores& logo, QrRead* rd, LandmarkFix* out) {
  rd->text.clear();
  expect_tracked_code(pred, windows, c_mm, beta, rd);
  qr_scratch.zxing_runs = 0;
  rd->search_attempts = 0;
  const int q = read_code(img, c_px, up, c_mm, beta, logo, rd, out);
  out->qr_grid_decodes = qr_scratch.zxing_runs;
  out->qr_search_attempts = rd->search_attempts;
  return q;
}

// Tracking's first read (TrackingConfig::logo_at_code_turn): the module centres at the predicted
// turn, verified as decode_guided's centre-only read is (and, as that one, only with
// qr_centre_first). The turn, or -1 with out's QR fields untouched when there is no predicted
// turn, no expected code or no verified read.
int CodeReader::read_at_predicted_turn(const cv::Mat& img, const Prediction& pred,
                                       const std::vector<SearchWindow>& windows, Vec2 c_mm,
                                       double beta, QrRead* rd, LandmarkFix* out) {
  rd->text.clear();
  expect_tracked_code(pred, windows, c_mm, beta, rd);
  if (!setup.cfg.qr_guided || !setup.cfg.qr_centre_first || rd->predicted_turn < 0 ||
      rd->expected.empty()) {
    return -1;
  }
  if (!read_centres(img, c_mm, beta, rd->predicted_turn, cache.code_book(), rd)) {
    rd->text.clear();
    return -1;
  }
  out->qr_method = 1;
  out->qr_verified = qr_scratch.verified;
  out->qr_centre_only = true;
  out->qr_grid_decodes = 0;
  out->qr_search_attempts = 0;
  return rd->predicted_turn;
}

// The centre-only read at turn q: the module centres of either grid size, verified against the
// expected codes and the book (never zxing). Sets rd->text on success.
bool CodeReader::read_centres(const cv::Mat& img, Vec2 c_mm, double beta, int q, QrCodeBook* book,
                              QrRead* rd) {
  for (int n : {kQrModulesV2, kQrModulesV1}) {
    if (sample_qr(img, c_mm, beta - q * kPi / 2.0, n, &qr_samples, true) &&
        verify_qr_grid(qr_samples, kCentreOnlyThreshold, &rd->text, &qr_scratch, rd->expected,
                       book)) {
      return true;
    }
  }
  return false;
}

// Guided module sampling at the logo's turn (all four when the logo is unclear; the code sits
// off-centre, so a wrong turn samples the wrong place and cannot decode), then zxing's search on
// the crop. Returns the turn the code's own orientation points to (-1 when unknown) and sets
// out->qr_method (0 = unread), out->qr_verified and rd->text.
int CodeReader::read_code(const cv::Mat& img, Vec2 c_px, double up, Vec2 c_mm, double beta,
                          const LogoScores& logo, QrRead* rd, LandmarkFix* out) {
  if (setup.cfg.qr_guided) {
    const int q = decode_guided(img, c_mm, beta, logo, rd);
    if (q >= 0) {
      out->qr_method = 1;
      out->qr_verified = qr_scratch.verified;
      out->qr_centre_only = rd->centre_only;
      return q;
    }
  }
  // zxing reads only a code that lies wholly in the image (it samples every module). On a
  // landmark cut by the image border this saves its six attempts, the worst case of a
  // landmark-free frame (about 12 M aarch64 instructions, docs/design/tracking.md).
  if (out->partly_outside && code_cut_at_every_turn(img, c_mm, beta, logo)) return -1;
  double qr_up = 0;
  bool qr_ok = false;
  if (!read_qr_search(img, c_px, up, &rd->text, &qr_up, &qr_ok, &rd->search_attempts)) return -1;
  out->qr_method = 2;
  // The code's orientation in the metric frame: which turn does it point to?
  const FloorProjector& mc = setup.metric_floor;
  Vec2 a0, a1;
  int qr_q = -1;
  if (qr_ok && mc.pixel_to_vehicle(c_px, &a0) &&
      mc.pixel_to_vehicle(
          {c_px.x + kAngleProbePx * std::cos(qr_up), c_px.y + kAngleProbePx * std::sin(qr_up)},
          &a1)) {
    const double b_qr = std::atan2(a1.y - a0.y, a1.x - a0.x);
    for (int q = 0; q < 4; ++q) {
      if (std::abs(wrap_angle_rad(b_qr - (beta - q * kPi / 2.0))) < deg_to_rad(kQrTurnTolDeg)) {
        qr_q = q;
      }
    }
  }
  return qr_q;
}

// With a trusted prediction (the tracking windows are planned), the mapped landmark predicted
// within kTrackedCodeReachRel outer half sizes of the fitted centre gives the codes the guided
// reader expects (rd->expected) and, when the predicted heading is within kQrTurnTolDeg of a turn,
// the turn to read first (rd->predicted_turn). Neither can change what is read: an expected code
// is taken only where zxing would decode it too (qr_grid.hpp), and a wrong turn decodes nothing.
void CodeReader::expect_tracked_code(const Prediction& pred,
                                     const std::vector<SearchWindow>& windows, Vec2 c_mm,
                                     double beta, QrRead* rd) {
  rd->expected.clear();
  rd->predicted_turn = -1;
  if (windows.empty() || !setup.map || !pred.valid) return;
  const LandmarkMapEntry* best = nullptr;
  Pose2 best_p;
  double best_d = kTrackedCodeReachRel * setup.geom.outer_half_mm();
  for (const SearchWindow& w : windows) {
    const LandmarkMapEntry* e = setup.map->find(w.landmark_id);
    if (!e) continue;
    const Pose2 p = predicted_landmark_in_vehicle(pred, e->pose, nullptr);
    const double d = std::hypot(p.x_mm - c_mm.x, p.y_mm - c_mm.y);
    if (d < best_d) {
      best_d = d;
      best = e;
      best_p = p;
    }
  }
  CodeCache::MapCodes* codes = best ? cache.codes_of(best->id) : nullptr;
  if (!codes) return;
  for (size_t form = 0; form < 2; ++form) {
    int& back = codes->reads_back[form];
    if (back == 0) {
      back = qr_bits_decode_to(codes->bits[form], codes->text[form], &qr_scratch) ? 1 : -1;
    }
    if (back == 1) rd->expected.push_back({&codes->bits[form], &codes->text[form]});
  }
  for (int q = 0; q < 4; ++q) {
    if (std::abs(wrap_angle_rad(best_p.theta_rad - (beta - q * kPi / 2.0))) <
        deg_to_rad(kQrTurnTolDeg)) {
      rd->predicted_turn = q;
    }
  }
}

// The turn at which the guided reader decoded, or -1. Turns in the logo's order (only its best
// when it is clear); an unclear logo's order starts at the predicted turn when there is one.
int CodeReader::decode_guided(const cv::Mat& img, Vec2 c_mm, double beta, const LogoScores& logo,
                              QrRead* rd) {
  const int predicted_turn = rd->predicted_turn;
  const std::vector<QrExpected>& expected = rd->expected;
  std::array<int, 4> order{logo.best_q, -1, -1, -1};
  if (!logo.clear) {
    order = {0, 1, 2, 3};
    std::sort(order.begin(), order.end(), [&](int x, int y) {
      if ((x == predicted_turn) != (y == predicted_turn)) return x == predicted_turn;
      return logo.ncc[static_cast<size_t>(x)] > logo.ncc[static_cast<size_t>(y)];
    });
  }
  // Order measured (qr_grid.hpp, docs/design/accuracy.md): strong sharpening reads the most codes;
  // the others rescue a few more at no cost to frames that already decode.
  constexpr QrThreshold kThresholds[] = {QrThreshold::kStronglySharpenedLocalMean,
                                         QrThreshold::kSharpenedLocalMean, QrThreshold::kLocalMean,
                                         QrThreshold::kMidpoint};
  QrCodeBook* book = cache.code_book();
  rd->centre_only = false;
  // A cheap first read when a verified read is possible (an expected code or the map's book):
  // the module centres only, and no zxing. Its answer is, as every verified read's, the code
  // zxing would decode from that grid; when it finds none, the full read below runs unchanged, so
  // it can cost a frame a fifth of the sampling but never a read. Whole codes only (sample_qr).
  // Measured in docs/design/tracking.md ("Centre-only first read").
  if (setup.cfg.qr_centre_first && (!expected.empty() || (book && book->size() > 0))) {
    for (int q : order) {
      if (q < 0) break;
      if (read_centres(img, c_mm, beta, q, book, rd)) {
        rd->centre_only = true;
        return q;
      }
    }
  }
  // At most qr_max_grid_decodes zxing reads; past them, verified reads only. That bounds a frame's
  // zxing cost: an unclear logo on a cut code took up to 24 reads (4.6 M aarch64 instructions).
  const bool verifiable = !expected.empty() || (book && book->size() > 0);
  const auto read = [&](const QrSamples& g, QrThreshold t) {
    return qr_scratch.zxing_runs < setup.cfg.qr_max_grid_decodes
               ? decode_qr_grid(g, t, &rd->text, &qr_scratch, expected, book)
               : verifiable && verify_qr_grid(g, t, &rd->text, &qr_scratch, expected, book);
  };
  if (logo.clear) {
    // One turn: each grid's thresholds in order, the verified read before zxing's at each.
    for (int n : {kQrModulesV2, kQrModulesV1}) {
      if (!sample_qr(img, c_mm, beta - logo.best_q * kPi / 2.0, n, &qr_samples)) continue;
      for (QrThreshold t : kThresholds) {
        if (read(qr_samples, t)) return logo.best_q;
      }
    }
    return -1;
  }
  // Four turns: every grid's verified reads (no zxing) come first, so the wrong turns cost no
  // zxing reads when a later one is verified; then zxing. Measured in docs/design/tracking.md
  // ("zxing budget").
  int n_grids = 0;
  for (int q : order) {
    for (int n : {kQrModulesV2, kQrModulesV1}) {
      QrSamples& g = qr_grids[static_cast<size_t>(n_grids)];
      if (!sample_qr(img, c_mm, beta - q * kPi / 2.0, n, &g)) continue;
      qr_grid_turns[static_cast<size_t>(n_grids++)] = q;
      for (QrThreshold t : kThresholds) {
        if (verifiable && verify_qr_grid(g, t, &rd->text, &qr_scratch, expected, book)) return q;
      }
    }
  }
  // zxing on the grids within the budget. No expected codes or book: their verified reads just
  // failed on these grids.
  const auto read_zxing = [&](int i, QrThreshold t) {
    return qr_scratch.zxing_runs < setup.cfg.qr_max_grid_decodes &&
           decode_qr_grid(qr_grids[static_cast<size_t>(i)], t, &rd->text, &qr_scratch);
  };
  // The predicted turn's grids (tracking) get every threshold first ...
  for (int i = 0; i < n_grids; ++i) {
    if (qr_grid_turns[static_cast<size_t>(i)] != predicted_turn) continue;
    for (QrThreshold t : kThresholds) {
      if (read_zxing(i, t)) return predicted_turn;
    }
  }
  // ... the others go threshold by threshold (the first reads the most), so the budget reaches
  // every turn.
  for (QrThreshold t : kThresholds) {
    for (int i = 0; i < n_grids; ++i) {
      const int q = qr_grid_turns[static_cast<size_t>(i)];
      if (q != predicted_turn && read_zxing(i, t)) return q;
    }
  }
  return -1;
}

// zxing's own search on a crop around the detected centre. Attempts: (0) the inner white square's
// bounding box; only when that fails: (1) the same crop slightly blurred, which removes thin
// scratches that break zxing's local binarizer; (2) a larger crop (zxing's block binarizer is
// sensitive to where blocks fall on a blurred code); (3) zxing's global-histogram binarizer;
// (4, 5) an unsharp-masked crop with either binarizer, which recovers codes smeared by defocus
// plus motion blur. qr_up_angle: image angle of the code's "up"; qr_ok: not mirrored;
// attempts_made: counts the attempts zxing ran.
bool CodeReader::read_qr_search(const cv::Mat& img, Vec2 c, double up_angle, std::string* text,
                                double* qr_up_angle, bool* qr_ok, int* attempts_made) {
  *qr_ok = false;
  const double module_px = setup.geom.qr_side_mm() / kQrModulesV2 / setup.mm_per_px;
  int d = 1;
  if (setup.cfg.qr_target_module_px > 0) {
    d = std::max(1, static_cast<int>(
                        std::floor(module_px / setup.cfg.qr_target_module_px + kDownscaleRoundUp)));
  }
  ZXing::DecodeHints hints;
  hints.setFormats(ZXing::BarcodeFormat::QRCode)
      .setTryHarder(setup.cfg.qr_try_harder)
      .setTryRotate(setup.cfg.qr_try_harder)
      .setTryDownscale(false)
      .setMaxNumberOfSymbols(1);
  ZXing::Result res;
  cv::Rect r;
  const int attempts = setup.cfg.qr_retries ? kQrSearchAttempts : 1;
  for (int attempt = 0; attempt < attempts; ++attempt) {
    const double half = (attempt == 2 ? setup.geom.outer_half_mm() : setup.geom.inner_half_mm()) /
                            setup.mm_per_px *
                            (std::abs(std::cos(up_angle)) + std::abs(std::sin(up_angle))) +
                        kQrCropMarginPx;
    r = cv::Rect(static_cast<int>(std::floor(c.x - half)), static_cast<int>(std::floor(c.y - half)),
                 static_cast<int>(std::ceil(2 * half)) + 1,
                 static_cast<int>(std::ceil(2 * half)) + 1);
    r &= cv::Rect(0, 0, img.cols, img.rows);
    if (r.width < kMinQrCropPx || r.height < kMinQrCropPx) return false;
    cv::Mat roi = img(r);
    const cv::Mat* src = &roi;
    if (d > 1) {
      cv::resize(roi, qr_small, cv::Size(r.width / d, r.height / d), 0, 0, cv::INTER_AREA);
      src = &qr_small;
    }
    if (attempt == 1) {
      cv::GaussianBlur(*src, qr_blur, cv::Size(0, 0), kScratchBlurSigmaPx);
      src = &qr_blur;
    } else if (attempt >= 4) {
      cv::GaussianBlur(*src, qr_blur, cv::Size(0, 0), kUnsharpSigmaPx);
      cv::addWeighted(*src, 1.0 + kUnsharpAmount, qr_blur, -kUnsharpAmount, 0.0, qr_sharp);
      src = &qr_sharp;
    }
    hints.setBinarizer(attempt == 3 || attempt == 5 ? ZXing::Binarizer::GlobalHistogram
                                                    : ZXing::Binarizer::LocalAverage);
    ZXing::ImageView iv(src->data, src->cols, src->rows, ZXing::ImageFormat::Lum,
                        static_cast<int>(src->step[0]));
    ++*attempts_made;
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

// True when, at each turn a fix could come from, a corner of the code square lies more than one
// module beyond the image (pixel centres span -0.5 .. size - 0.5): no such turn leaves zxing a
// whole code. A clear logo admits only its own turn (decide_direction refuses a code read at
// another), an unclear one all four.
bool CodeReader::code_cut_at_every_turn(const cv::Mat& img, Vec2 c_mm, double beta,
                                        const LogoScores& logo) const {
  const double side = setup.geom.qr_side_mm();
  const double module_px = side / kQrModulesV2 / setup.mm_per_px;
  const double lo = -0.5 - module_px;
  const double hi_x = img.cols - 0.5 + module_px, hi_y = img.rows - 0.5 + module_px;
  for (int q = 0; q < 4; ++q) {
    if (logo.clear && q != logo.best_q) continue;
    const PlaneProjector page = setup.page_projector(c_mm, beta - q * kPi / 2.0);
    bool cut = false;
    for (int k = 0; k < 4 && !cut; ++k) {
      const Vec2 uv{setup.geom.qr_u0_mm() + (k & 1) * side,
                    setup.geom.qr_v0_mm() + (k >> 1) * side};
      Vec2 px;
      cut = !page.to_pixel(uv, &px) || px.x < lo || px.y < lo || px.x > hi_x || px.y > hi_y;
    }
    if (!cut) return false;
  }
  return true;
}

// Samples every module of an n x n code (plus the quiet-zone ring) where the pose (c_mm, forward
// angle fwd) puts it: the mean of kSamplesPerModule samples, or the centre alone (centre_only).
// False when the code cannot be sampled (too much of it outside the image; for centre_only, any
// module outside: a cut code goes to the five-sample read and its fill-in directly).
bool CodeReader::sample_qr(const cv::Mat& img, Vec2 c_mm, double fwd, int n, QrSamples* s,
                           bool centre_only) {
  const PlaneProjector page = setup.page_projector(c_mm, fwd);
  const double m = setup.geom.qr_side_mm() / n;
  auto to_px = [&](Vec2 uv, Vec2* px) { return page.to_pixel(uv, px); };
  // The extra samples' pixel offsets are taken at the code's centre; distortion changes them by
  // far less than a pixel over the code.
  const Vec2 mid{setup.geom.qr_u0_mm() + 0.5 * setup.geom.qr_side_mm(),
                 setup.geom.qr_v0_mm() + 0.5 * setup.geom.qr_side_mm()};
  Vec2 p0, pu, pv;
  if (!to_px(mid, &p0) || !to_px({mid.x + kSampleOffsetModules * m, mid.y}, &pu) ||
      !to_px({mid.x, mid.y + kSampleOffsetModules * m}, &pv)) {
    return false;
  }
  const Vec2 du{pu.x - p0.x, pu.y - p0.y}, dv{pv.x - p0.x, pv.y - p0.y};
  s->n = n;
  s->ring = kQuietRingModules;
  const int side = s->side();
  s->v.resize(static_cast<size_t>(side * side));
  // Modules whose samples leave the image (a landmark cut by the image border) are filled in
  // (fill_missing_modules); at most qr_max_missing_modules of them may be data modules.
  int missing_data = 0, missing = 0;
  const int max_missing_data = setup.cfg.qr_max_missing_modules;
  const double ou[kSamplesPerModule] = {0, 1, -1, 0, 0}, ov[kSamplesPerModule] = {0, 0, 0, 1, -1};
  const int samples = centre_only ? 1 : kSamplesPerModule;
  const GreySampler grey(img);
  for (int r = 0; r < side; ++r) {
    for (int c = 0; c < side; ++c) {
      const Vec2 uv{setup.geom.qr_u0_mm() + (c - s->ring + 0.5) * m,
                    setup.geom.qr_v0_mm() + (r - s->ring + 0.5) * m};
      Vec2 px;
      double acc = 0, v = 0;
      bool inside = to_px(uv, &px);
      for (int k = 0; k < samples && inside; ++k) {
        inside = grey(px.x + ou[k] * du.x + ov[k] * dv.x, px.y + ou[k] * du.y + ov[k] * dv.y, &v);
        acc += v;
      }
      if (!inside) {
        if (centre_only) return false;
        ++missing;
        const int rr = r - s->ring, cc = c - s->ring;
        const bool in_code = rr >= 0 && cc >= 0 && rr < n && cc < n;
        if (in_code && qr_fixed_module(n, rr, cc) < 0 && ++missing_data > max_missing_data) {
          return false;
        }
      }
      s->v[static_cast<size_t>(r * side + c)] =
          inside ? static_cast<float>(acc / samples) : kMissing;
    }
  }
  return missing == 0 || fill_missing_modules(s);
}

// Fill-in of the modules outside the image: quiet-zone modules with the quiet zone's median,
// fixed modules with their known value, and data modules with the code's mean (left to
// Reed-Solomon to correct). Levels from the samples that were inside.
bool CodeReader::fill_missing_modules(QrSamples* s) {
  const int n = s->n, side = s->side();
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
  // Dark level mirrored about the mean: modules are about half dark, half light.
  const float dark = std::max(0.0f, 2.0f * mean - light);
  for (int r = 0; r < side; ++r) {
    for (int c = 0; c < side; ++c) {
      float& v = s->v[static_cast<size_t>(r * side + c)];
      if (v != kMissing) continue;
      const int rr = r - s->ring, cc = c - s->ring;
      const bool in_code = rr >= 0 && cc >= 0 && rr < n && cc < n;
      const int f = in_code ? qr_fixed_module(n, rr, cc) : 0;
      v = !in_code ? light : f == 1 ? dark : f == 0 ? light : mean;
    }
  }
  return true;
}

// The payload must parse; its landmark must be in the map (an id-only payload takes its pose
// from there) and a full payload must agree with the map entry within the tolerances.
FixStatus CodeReader::check_payload(const std::string& text, LandmarkFix* out,
                                    Pose2* world_landmark) {
  std::snprintf(out->payload, sizeof out->payload, "%s", text.c_str());
  LandmarkPayload p;
  if (parse_payload(text, &p) != PayloadError::kOk) return FixStatus::kPayloadInvalid;
  out->landmark_id = p.id;
  const LandmarkMapEntry* e = setup.map ? setup.map->find(p.id) : nullptr;
  if (!p.has_pose) {
    if (!e) return FixStatus::kUnknownLandmark;
    *world_landmark = e->pose;
  } else {
    const Pose2 pp = payload_pose(p);
    if (setup.map) {
      if (!e) return FixStatus::kUnknownLandmark;
      const double dpos = std::hypot(pp.x_mm - e->pose.x_mm, pp.y_mm - e->pose.y_mm);
      const double dang = std::abs(rad_to_deg(wrap_angle_rad(pp.theta_rad - e->pose.theta_rad)));
      if (!(dpos <= setup.cfg.map_tolerance_mm) || !(dang <= setup.cfg.map_tolerance_deg)) {
        return FixStatus::kPayloadInvalid;
      }
    }
    *world_landmark = pp;
  }
  out->map_verified = setup.map != nullptr;
  return FixStatus::kOk;
}

}  // namespace agv::vision

// LandmarkLocalizer: the stages of one frame in order (run, locate, identify), the public class and
// VisionSetup, the configuration the stages share. The stages themselves: localizer_impl.hpp.
#include "agv/vision/landmark_localizer.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <opencv2/core.hpp>

#include "agv/vision/pose_covariance.hpp"
#include "localizer_impl.hpp"

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
const char* to_string(FixIdentity i) {
  switch (i) {
    case FixIdentity::kNone:
      return "none";
    case FixIdentity::kQrCode:
      return "qr";
    case FixIdentity::kMapGuided:
      return "map";
    case FixIdentity::kAprilTag:
      return "tag";
  }
  return "unknown";
}

const char* to_string(SearchMode m) {
  switch (m) {
    case SearchMode::kFull:
      return "full";
    case SearchMode::kWindow:
      return "window";
    case SearchMode::kWindowThenFull:
      return "window+full";
  }
  return "unknown";
}

VisionSetup::VisionSetup(const VisionConfig& c, const CameraModel& m, const LandmarkGeometry& g,
                         const LandmarkMap* mp)
    : cfg(c), cam(m), cam_linear(m), geom(g), map(mp) {
  // 0.26 mm/px is the default camera's scale: a fallback for a degenerate model, which then
  // fails every frame's size check rather than dividing by zero here.
  mm_per_px = cam.mm_per_px();
  if (!(mm_per_px > 0.0) || !std::isfinite(mm_per_px)) mm_per_px = 0.26;
  auto& li = cam_linear.intrinsics;
  li.fx = li.fy = cam.mount.height_mm / mm_per_px;
  li.k1 = li.k2 = li.p1 = li.p2 = li.k3 = 0.0;
  metric_floor = FloorProjector(metric_cam());
  // Coarse level: the largest power-of-two reduction that keeps coarse_border_px per border.
  const double border_px = geom.border_width_mm() / mm_per_px;
  coarse_factor = 1;
  while (border_px / (coarse_factor * 2) >= cfg.coarse_border_px) coarse_factor *= 2;
  coarse_w = border_px / coarse_factor;
  coarse_h = geom.outer_half_mm() / mm_per_px / coarse_factor;
  coarse_anchor = coarse_w / 2.0;
  outer_only = cfg.family == LandmarkFamily::kTag36h11;
}

LandmarkLocalizer::Impl::Impl(const VisionConfig& c, const CameraModel& m,
                              const LandmarkGeometry& g, const LandmarkMap* mp)
    : VisionSetup(c, m, g, mp), planner(c, m, g, mp) {
  // A small map's codes are encoded now, at start-up, rather than on the first landmark frame,
  // which would be late by the encoding (1000 landmarks, 2000 codes, take 0.23 s on x86-64); a
  // large map's book follows the prediction (code_cache.cpp, docs/design/large_maps.md).
  // A tag floor has no QR codes to encode; its start-up work is libapriltag's tables (TagReader).
  if (cfg.family != LandmarkFamily::kTag36h11) codes.update_code_book(Prediction{});
}

// The stages in the order they run, numbered as in docs/design/vision.md "Pipeline". The pose comes
// before the direction and the QR code: the guided QR reading and the logo are sampled where the
// fitted pose puts them.
FixStatus LandmarkLocalizer::Impl::run(const cv::Mat& img, const Prediction& pred,
                                       LandmarkFix* out) {
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
  Frame frame{img, pred, t0, window_storage};
  if (cfg.family == LandmarkFamily::kTag36h11) return finish(run_tag(frame, out));
  // The book and the expected codes point into the cache: both go when it is emptied.
  if (codes.prune()) code_reader.read().expected.clear();
  codes.update_code_book(pred);
  planner.plan(pred, &frame.windows);
  Detection det;
  Vec2 c_mm;
  double beta = 0;
  Eigen::Matrix3d cov;
  const FixStatus st = locate(frame, out, &det, &c_mm, &beta, &cov);
  if (st != FixStatus::kOk) return finish(st);
  return finish(identify(frame, det, c_mm, beta, cov, out));
}

// 1-3. Binarization, detection and pose: no detection when the prediction is precise enough to
// place the pose stage's edge bands itself and the fit then lands where it said; otherwise from
// the prediction when it is trusted (tracked, then the windows), the whole frame when there is
// none or they find nothing (docs/design/tracking.md).
FixStatus LandmarkLocalizer::Impl::locate(const Frame& f, LandmarkFix* out, Detection* det,
                                          Vec2* c_mm, double* beta, Eigen::Matrix3d* cov) {
  const cv::Mat& img = f.img;
  const std::vector<SearchWindow>& windows = f.windows;
  Vec2 predicted_px;
  bool probed = false;
  if (cfg.tracking.detect_from_prediction && !windows.empty() &&
      predicted.detect_predicted(img, windows, det, &predicted_px, &probed)) {
    const LandmarkFix before = *out;
    out->search = SearchMode::kWindow;
    out->detection_predicted = true;
    out->detection_probed = probed;
    const FixStatus st = measure(img, *det, 0.0, f.t0_ms, out, c_mm, beta, cov);
    if (st == FixStatus::kOk && predicted.fit_agrees_with_prediction(predicted_px)) return st;
    *out = before;
  }
  bool found_corner = false;
  double corner_score = 0;
  bool found = false;
  bool searched_all = false;
  *det = Detection{};
  if (!windows.empty()) {
    // The prediction replaces the search (tracked detection); when it finds nothing trusted,
    // the corner search over the windows.
    found = corners.detect_tracked(img, windows, det, &corner_score) &&
            det->white_grey - det->dark_grey >= kMinContrastGrey;
    if (!found) {
      *det = Detection{};
      found = corners.detect_in_windows(img, windows, det, &found_corner, &corner_score,
                                        &searched_all) &&
              det->white_grey - det->dark_grey >= kMinContrastGrey;
    }
    out->search = found ? SearchMode::kWindow : SearchMode::kWindowThenFull;
  }
  // Windows that cover the whole frame were the full search: not repeated.
  if (!found && !searched_all) {
    *det = Detection{};
    found = corners.detect(img, det, &found_corner, &corner_score);
  }
  if (!found) {
    out->corner_score = corner_score;
    if (cfg.now_ns) out->timings.detect_ms = now_ms() - f.t0_ms;
    return FixStatus::kNoLandmark;
  }
  return measure(img, *det, corner_score, f.t0_ms, out, c_mm, beta, cov);
}

// 4-6. Logo, code, identity and direction of the measured square (det; c_mm, beta and cov from
// the pose stage), and the result.
FixStatus LandmarkLocalizer::Impl::identify(const Frame& f, const Detection& det, Vec2 c_mm,
                                            double beta, const Eigen::Matrix3d& cov,
                                            LandmarkFix* out) {
  const Vec2 c_px = coarse_to_full({det.h.cx, det.h.cy});
  const double up = det.h.up_angle;
  const double t2 = now_ms();
  have_overlay = true;

  // 4-5a. Logo (NCC at the turns of the fitted square) and QR decode, then payload and map
  // check. Tracking reads the code first and scores the logo at its turn only (logo_and_code).
  LogoScores logo;
  double logo_ms = 0.0;
  QrRead* const rd = &code_reader.read();
  const int qr_q = logo_and_code(f, c_px, up, c_mm, beta, &logo, &logo_ms, rd, out);
  out->logo_score = logo.best;
  out->logo_margin = logo.margin;
  Pose2 world_landmark;
  FixStatus st = out->qr_method == 0 ? FixStatus::kQrUnreadable
                                     : code_reader.check_payload(rd->text, out, &world_landmark);
  const double t4 = now_ms();
  if (cfg.now_ns) out->timings.decode_ms = t4 - t2 - logo_ms;
  // 5c. Map-guided identity of an unread code (docs/design/map_identity.md): whole border only, and
  // never a filter (re)initialisation (map_verified stays false).
  if (st == FixStatus::kQrUnreadable && !out->partly_outside && out->sides_used == 4) {
    int turn = 0;
    std::uint32_t id = 0;
    if (identity.map_identity(f.img, f.pred, c_mm, beta, cov, logo, &world_landmark, &turn, &id)) {
      quadrant = turn;
      out->landmark_id = id;
      fill_result(world_landmark, c_mm, beta, turn, cov, out);
      out->identity = FixIdentity::kMapGuided;
      if (cfg.now_ns) out->timings.decode_ms = now_ms() - t2 - logo_ms;
      return FixStatus::kOk;
    }
  }
  if (st == FixStatus::kQrUnreadable && out->partly_outside) st = FixStatus::kPartlyOutside;
  if (st != FixStatus::kOk) return st;

  // 5b. Direction: the logo against the QR code's orientation.
  const int q_final = direction.decide_direction(logo, qr_q);
  if (cfg.now_ns) out->timings.direction_ms = logo_ms + (now_ms() - t4);
  if (q_final < 0) return FixStatus::kDirectionAmbiguous;
  quadrant = q_final;

  // 6. Result and its covariance.
  fill_result(world_landmark, c_mm, beta, q_final, cov, out);
  out->identity = FixIdentity::kQrCode;
  return FixStatus::kOk;
}

// Stages 4 and 5a: the logo and the code, returning the code's turn (-1 unknown). With a trusted
// prediction the code is read first at the predicted turn (TrackingConfig::logo_at_code_turn);
// a verified read there fixes the direction by the code's own orientation (its finder patterns
// verify at one turn only), and the logo need only confirm it: at least logo_threshold at that
// turn. The margin over the other turns matters when the logo alone chooses the turn to read,
// which it does not here. Otherwise the logo at four turns and the full read, whose decision
// (decide_direction) refuses a clear logo at another turn than the code's; so does this path,
// because that logo scores below the threshold at the code's turn and the frame falls back.
// logo_ms: the logo's share of the time (timings.direction_ms).
int LandmarkLocalizer::Impl::logo_and_code(const Frame& f, Vec2 c_px, double up, Vec2 c_mm,
                                           double beta, LogoScores* logo, double* logo_ms,
                                           QrRead* rd, LandmarkFix* out) {
  const cv::Mat& img = f.img;
  const Prediction& pred = f.pred;
  const std::vector<SearchWindow>& windows = f.windows;
  *logo_ms = 0.0;
  if (cfg.tracking.logo_at_code_turn && pred.valid && !windows.empty()) {
    const int q = code_reader.read_at_predicted_turn(img, pred, windows, c_mm, beta, rd, out);
    if (q >= 0) {
      const double t = now_ms();
      const double s = direction.logo_ncc(img, c_mm, beta, q);
      *logo_ms = now_ms() - t;
      if (s >= cfg.logo_threshold) {
        *logo = LogoScores{};
        logo->ncc.fill(-1.0);
        logo->ncc[static_cast<size_t>(q)] = s;
        logo->best_q = q;
        logo->best = s;
        logo->clear = true;
        out->logo_one_turn = true;
        return q;
      }
      out->qr_method = 0;
      out->qr_verified = false;
      out->qr_centre_only = false;
    }
  }
  const double t = now_ms();
  *logo = direction.logo_scores(img, c_mm, beta);
  *logo_ms += now_ms() - t;
  return code_reader.decode_qr(img, pred, windows, c_px, up, c_mm, beta, *logo, rd, out);
}

// Stage 3 from an accepted detection: its diagnostics, the image-border check and the pose. t0 is
// the frame's start (the detection's time is up to now).
FixStatus LandmarkLocalizer::Impl::measure(const cv::Mat& img, const Detection& det,
                                           double corner_score, double t0, LandmarkFix* out,
                                           Vec2* c_mm, double* beta, Eigen::Matrix3d* cov) {
  out->corner_score = corner_score;
  const double t1 = now_ms();
  if (cfg.now_ns) out->timings.detect_ms = t1 - t0;
  const double contrast = det.white_grey - det.dark_grey;
  if (contrast < kMinContrastGrey) return FixStatus::kNoLandmark;
  const Vec2 c_px = coarse_to_full({det.h.cx, det.h.cy});
  const double up = det.h.up_angle;
  out->detect_x_px = c_px.x;
  out->detect_y_px = c_px.y;
  out->detect_angle_deg = rad_to_deg(up);
  out->partly_outside = partly_outside(img, c_px, up);
  if (out->partly_outside && !cfg.allow_partly_outside) return FixStatus::kPartlyOutside;
  FixStatus st = square.pose(img, c_px, up, contrast, &square.edge_points(), out, c_mm, beta, cov);
  if (cfg.now_ns) out->timings.pose_ms = now_ms() - t1;
  if (st == FixStatus::kTooFewEdgePoints && out->partly_outside) st = FixStatus::kPartlyOutside;
  return st;
}

// Any predicted outer corner beyond the image (plus VisionConfig::outside_margin_mm).
bool VisionSetup::partly_outside(const cv::Mat& img, Vec2 c_px, double up) const {
  const double margin_px = cfg.outside_margin_mm / mm_per_px;
  const double ho = geom.outer_half_mm() / mm_per_px;
  bool outside = false;
  for (int k = 0; k < 4; ++k) {
    const Vec2 d = rot({ho, ho}, up + k * kPi / 2);
    const double x = c_px.x + d.x, y = c_px.y + d.y;
    if (x < -kHalfPixel - margin_px || y < -kHalfPixel - margin_px ||
        x > img.cols - kHalfPixel + margin_px || y > img.rows - kHalfPixel + margin_px) {
      outside = true;
    }
  }
  return outside;
}

void LandmarkLocalizer::Impl::fill_result(const Pose2& world_landmark, Vec2 c_mm, double beta,
                                          int q_final, const Eigen::Matrix3d& cov,
                                          LandmarkFix* out) const {
  const double fwd = wrap_angle_rad(beta - q_final * kPi / 2.0);
  out->landmark_in_vehicle = {c_mm.x, c_mm.y, fwd};
  const Pose2 v_in_l = inverse(out->landmark_in_vehicle);
  out->e_x_mm = v_in_l.x_mm;
  out->e_y_mm = v_in_l.y_mm;
  out->e_phi_deg = rad_to_deg(v_in_l.theta_rad);
  out->cov_landmark_in_vehicle = cov;
  out->vehicle_in_world = compose(world_landmark, v_in_l);
  out->cov_world = vehicle_in_world_covariance(world_landmark, out->landmark_in_vehicle, cov);
}

LandmarkLocalizer::LandmarkLocalizer(const VisionConfig& config, const CameraModel& camera,
                                     const LandmarkGeometry& geometry, const LandmarkMap* map)
    : impl_(std::make_unique<Impl>(config, camera, geometry, map)) {}

LandmarkLocalizer::~LandmarkLocalizer() = default;

const VisionConfig& LandmarkLocalizer::config() const { return impl_->cfg; }

const std::vector<Vec2>& LandmarkLocalizer::edge_points_px(int line) const {
  static const std::vector<Vec2> kNone;
  if (line < 0 || line >= kNumLines) return kNone;
  return impl_->square.edge_points().px[static_cast<size_t>(line)];
}

FixStatus LandmarkLocalizer::process(const cv::Mat& gray8, LandmarkFix* out) {
  return process(gray8, Prediction{}, out);
}

FixStatus LandmarkLocalizer::process(const cv::Mat& gray8, const Prediction& prediction,
                                     LandmarkFix* out) {
  if (!out) return FixStatus::kBadInput;
  *out = LandmarkFix{};
  try {
    return impl_->run(gray8, prediction, out);
  } catch (...) {
    // OpenCV and zxing report some malformed input by exceptions; never let them escape.
    impl_->have_overlay = false;
    out->status = FixStatus::kBadInput;
    return out->status;
  }
}

}  // namespace agv::vision

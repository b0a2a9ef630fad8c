// Tag family (VisionConfig::family = kTag36h11), the stages composed: libapriltag finds and
// decodes the tag (Debian's libapriltag 3.3, not rewritten; tag_reader.cpp), its homography gives
// the start of this project's pose stage (pose.cpp, outer edge of the black square only: the inner
// edge is broken by the data cells), the decoded rotation gives the heading quadrant and the map
// gives the id's world pose.
#include <array>
#include <cmath>
#include <cstdio>

#include "localizer_impl.hpp"

namespace agv::vision {

namespace {

// The fitted centre must lie within this share of the pose stage's band of where the square was
// placed: a fit further away found other edges.
constexpr double kPlacedCentreBandShare = 1.0;

}  // namespace

// libapriltag first; when it finds no tag, or its quad gives no fix, the prediction and the map
// place the predicted tag's square as the QR family's tracking does, and the tag's code is read
// at the fitted square (docs/design/landmark.md "AprilTag landmark"). libapriltag needs the whole
// quad with white around it: an occluder over the border, or floor dirt joining it, breaks it.
FixStatus LandmarkLocalizer::Impl::run_tag(Frame& f, LandmarkFix* out) {
  const cv::Mat& img = f.img;
  const double t0 = now_ms();
  const FixStatus st = tag_from_detector(img, out);
  if (st == FixStatus::kOk || !map) return st;
  if (cfg.tracking.detect_from_prediction) {
    planner.plan(f.pred, &f.windows);
    LandmarkFix tried;
    if (!f.windows.empty() && tag_from_prediction(f, &tried) == FixStatus::kOk) {
      tried.timings = out->timings;
      *out = tried;
      return FixStatus::kOk;
    }
  }
  if (st != FixStatus::kNoLandmark || !cfg.tag_corner_search) return st;
  LandmarkFix found;
  found.timings = out->timings;
  const FixStatus cs = tag_from_corners(img, t0, &found);
  if (cs == FixStatus::kNoLandmark) return st;
  *out = found;
  return cs;
}

FixStatus LandmarkLocalizer::Impl::tag_from_detector(const cv::Mat& img, LandmarkFix* out) {
  const double t0 = now_ms();
  TagQuad quad;
  if (!tags.strongest_quad(img, &quad)) {
    if (cfg.now_ns) out->timings.detect_ms = now_ms() - t0;
    return FixStatus::kNoLandmark;
  }
  const std::uint32_t id = quad.id;
  const Vec2 c_px = quad.c_px;
  const Vec2 fwd_px = quad.fwd_px;
  const double up = quad.up;
  const double t1 = now_ms();
  if (cfg.now_ns) out->timings.detect_ms = t1 - t0;
  if (!quad.sampled) return FixStatus::kNoLandmark;
  const double contrast = quad.contrast;
  if (contrast < kMinContrastGrey) return FixStatus::kNoLandmark;
  out->corner_score = contrast;
  out->detect_x_px = c_px.x;
  out->detect_y_px = c_px.y;
  out->detect_angle_deg = rad_to_deg(up);
  out->partly_outside = partly_outside(img, c_px, up);
  if (out->partly_outside && !cfg.allow_partly_outside) return FixStatus::kPartlyOutside;
  out->landmark_id = id;
  std::snprintf(out->payload, sizeof out->payload, "tag36h11/%u", static_cast<unsigned>(id));

  Vec2 c_mm;
  double beta = 0;
  Eigen::Matrix3d cov;
  FixStatus st =
      square.pose(img, c_px, up, contrast, &square.edge_points(), out, &c_mm, &beta, &cov);
  if (cfg.now_ns) out->timings.pose_ms = now_ms() - t1;
  if (st == FixStatus::kTooFewEdgePoints && out->partly_outside) st = FixStatus::kPartlyOutside;
  if (st != FixStatus::kOk) return st;
  have_overlay = true;

  st = tags.consistent_square(&square.edge_points(), &c_mm, &beta, &cov, out);
  if (st != FixStatus::kOk) return st;

  // Heading quadrant from the decoded rotation: the fitted border normal beta is only known modulo
  // 90 degrees, the detector's homography says which side is the tag's top.
  const FloorProjector& mc = metric_floor;
  Vec2 a0, a1;
  if (!mc.pixel_to_vehicle(c_px, &a0) || !mc.pixel_to_vehicle(fwd_px, &a1)) {
    return FixStatus::kDirectionAmbiguous;
  }
  const double fwd0 = std::atan2(a1.y - a0.y, a1.x - a0.x);
  const int q = static_cast<int>(std::lround(wrap_angle_rad(beta - fwd0) / (kPi / 2.0)) + 4) % 4;
  quadrant = q;

  const LandmarkMapEntry* e = map ? map->find(id) : nullptr;
  if (!e) return FixStatus::kUnknownLandmark;
  out->map_verified = true;
  fill_result(e->pose, c_mm, beta, q, cov, out);
  out->identity = FixIdentity::kAprilTag;
  return FixStatus::kOk;
}

// No quad from libapriltag and none placed by the prediction (none trusted: the first fix, or
// after a long leg): the QR family's full search (detect.cpp) finds the black square from its
// outer corners, which a border broken on one side keeps three of, the pose stage fits the outer
// square, and the code read at the fitted square is looked up among all tag36h11 codes at the
// four turns, accepted within TagReader::kBitsCorrected cells as libapriltag's decode. Only the
// full search costs anything on a frame without a tag (the QR family's every frame does the same).
FixStatus LandmarkLocalizer::Impl::tag_from_corners(const cv::Mat& img, double t0_ms,
                                                    LandmarkFix* out) {
  Detection det;
  bool found_corner = false;
  double corner_score = 0;
  if (!corners.detect(img, &det, &found_corner, &corner_score)) return FixStatus::kNoLandmark;
  Vec2 c_mm;
  double beta = 0;
  Eigen::Matrix3d cov;
  FixStatus st = measure(img, det, corner_score, t0_ms, out, &c_mm, &beta, &cov);
  if (st == FixStatus::kOk)
    st = tags.consistent_square(&square.edge_points(), &c_mm, &beta, &cov, out);
  if (st != FixStatus::kOk) return st;
  have_overlay = true;
  const double half = out->outer_half_mm > 0.0 ? out->outer_half_mm : geom.outer_half_mm();
  std::array<TagReader::Cells, 4> read{};
  bool readable[4] = {};
  for (int q = 0; q < 4; ++q) readable[q] = tags.read_tag_cells(img, c_mm, beta, q, half, &read[q]);
  int best_q = -1, best_d = TagReader::kDataCells * TagReader::kDataCells + 1;
  std::uint32_t best_id = 0;
  tags.nearest_code(read, readable, &best_q, &best_d, &best_id);
  // A dark square without a tag's code (a floor feature, another print) is not a tag.
  if (best_q < 0 || best_d > TagReader::kBitsCorrected) return FixStatus::kNoLandmark;
  quadrant = best_q;
  out->landmark_id = best_id;
  std::snprintf(out->payload, sizeof out->payload, "tag36h11/%u", static_cast<unsigned>(best_id));
  out->search = SearchMode::kFull;
  const LandmarkMapEntry* e = map->find(best_id);
  if (!e) return FixStatus::kUnknownLandmark;
  out->map_verified = true;
  fill_result(e->pose, c_mm, beta, best_q, cov, out);
  out->identity = FixIdentity::kAprilTag;
  return FixStatus::kOk;
}

// The QR family's tracking for a tag (landmark_localizer.cpp, predicted_detect.cpp,
// edge_probe.cpp): each predicted mapped tag in view is placed by the prediction itself when it is
// precise enough, else by the edge probes (outer edge only; one side may be lost to an occluder),
// its outer square fitted by the pose stage, and accepted when its code, read at the fitted
// square, is the predicted tag's at one of the four turns. The id is read, not assumed: the fix
// is the detector's (identity tag, map-verified), found where libapriltag's quad search was not.
FixStatus LandmarkLocalizer::Impl::tag_from_prediction(const Frame& frame, LandmarkFix* out) {
  const cv::Mat& img = frame.img;
  FixStatus best_st = FixStatus::kNoLandmark;
  for (const SearchWindow& w : frame.windows) {
    const LandmarkMapEntry* e = map->find(w.landmark_id);
    if (!e || w.landmark_id > kTag36h11MaxId) continue;
    Vec2 c_px;
    double up = 0, dark = 0, white = 0;
    bool placed = false, probed = false;
    if (predicted.prediction_places_bands(w)) {
      int n_dark = 0, n_samples = 0;
      placed = predicted.ring_check_full(img, w.centre_px, w.up_angle_rad, &dark, &white, &n_dark,
                                         &n_samples);
      c_px = w.centre_px;
      up = w.up_angle_rad;
    }
    if (!placed && cfg.tracking.probe_edges) {
      ProbedSquare sq;
      placed = probed = predicted.probe_prediction(img, w, &sq);
      c_px = sq.centre_px;
      up = sq.up_rad;
      dark = sq.dark_grey;
      white = sq.white_grey;
    }
    if (!placed) continue;
    const double contrast = white - dark;
    if (contrast < kMinContrastGrey) continue;
    LandmarkFix f;
    f.corner_score = contrast;
    f.detect_x_px = c_px.x;
    f.detect_y_px = c_px.y;
    f.detect_angle_deg = rad_to_deg(up);
    f.search = SearchMode::kWindow;
    f.detection_predicted = true;
    f.detection_probed = probed;
    f.partly_outside = partly_outside(img, c_px, up);
    if (f.partly_outside && !cfg.allow_partly_outside) continue;
    Vec2 c_mm;
    double beta = 0;
    Eigen::Matrix3d cov;
    FixStatus st =
        square.pose(img, c_px, up, contrast, &square.edge_points(), &f, &c_mm, &beta, &cov);
    const double band_px = cfg.band_rel * geom.border_width_mm() / mm_per_px;
    if (st == FixStatus::kOk &&
        std::hypot(square.pixels().centre_px.x - c_px.x, square.pixels().centre_px.y - c_px.y) >
            kPlacedCentreBandShare * band_px) {
      st = FixStatus::kNoLandmark;
    }
    if (st == FixStatus::kOk)
      st = tags.consistent_square(&square.edge_points(), &c_mm, &beta, &cov, &f);
    if (st != FixStatus::kOk) {
      best_st = st;
      continue;
    }
    const double half = f.outer_half_mm > 0.0 ? f.outer_half_mm : geom.outer_half_mm();
    int best_q = -1, best_d = TagReader::kDataCells * TagReader::kDataCells + 1;
    for (int q = 0; q < 4; ++q) {
      const int d = tags.tag_code_distance(img, c_mm, beta, q, half, w.landmark_id);
      if (d >= 0 && d < best_d) best_d = d, best_q = q;
    }
    if (best_q < 0 || best_d > TagReader::kBitsCorrected) {
      best_st = FixStatus::kUnknownLandmark;
      continue;
    }
    have_overlay = true;
    quadrant = best_q;
    f.landmark_id = w.landmark_id;
    std::snprintf(f.payload, sizeof f.payload, "tag36h11/%u", static_cast<unsigned>(w.landmark_id));
    f.map_verified = true;
    fill_result(e->pose, c_mm, beta, best_q, cov, &f);
    f.identity = FixIdentity::kAprilTag;
    f.status = FixStatus::kOk;
    *out = f;
    return FixStatus::kOk;
  }
  return best_st;
}

}  // namespace agv::vision

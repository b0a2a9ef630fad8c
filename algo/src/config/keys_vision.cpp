// Key table rows of the vision section: the fields of agv::vision::VisionConfig
// (algo/include/agv/vision/landmark_localizer.hpp), same names and defaults, in pipeline order.
// The texts condense the header comments and docs/design/vision.md; measurements:
// docs/design/accuracy.md.
#include "key_builders.hpp"

namespace agv::config::detail {

namespace {

void add_detection(std::vector<Key>* k) {
  k->push_back(number("vision.adaptive_block_mm", AGV_AT(vision.adaptive_block_mm), 2.0, 200.0,
                      24.0,
                      {"mm",
                       "local-mean window of the binarization (default about 4 border "
                       "widths). Larger ignores more texture but follows illumination "
                       "gradients less"}));
  k->push_back(number("vision.adaptive_offset", AGV_AT(vision.adaptive_offset), 0.0, 100.0, 6.0,
                      {"grey levels",
                       "below the local mean to count as dark. Higher: fewer "
                       "texture pixels reach the NCC (faster, fewer false "
                       "hypotheses), weak-contrast borders may be missed"}));
  // At 0 the pyramid-level search would not terminate: the lower bound is a guard.
  k->push_back(number("vision.coarse_border_px", AGV_AT(vision.coarse_border_px), 0.5, 20.0, 2.5,
                      {"px",
                       "minimum border width at the detection level; sets the pyramid "
                       "factor (8 at 0.26 mm/px). Smaller = faster full-frame search, "
                       "weaker corner templates"}));
  k->push_back(integer("vision.corner_rotations", AGV_AT(vision.corner_rotations), 1, 32, 12,
                       {"",
                        "rotations of the corner template (12 = 30° steps, at most 15° "
                        "off). More = higher NCC peaks at arbitrary headings, linear cost "
                        "in the search"}));
  k->push_back(number("vision.corner_threshold", AGV_AT(vision.corner_threshold), 0.1, 0.99, 0.55,
                      {"",
                       "NCC a corner must reach for a landmark to count as present. Lower "
                       "finds more blurred or occluded landmarks, sends more floor texture "
                       "to the (strict) ring and QR checks"}));
  k->push_back(number("vision.ring_dark_fraction", AGV_AT(vision.ring_dark_fraction), 0.0, 1.0,
                      0.55,
                      {"",
                       "part of the predicted border ring (inside the image) that must be "
                       "dark. Lower tolerates occluders and scratches, admits more false "
                       "hypotheses (which the QR check still rejects)"}));
  // 0 would leave no peak to examine after one was found.
  k->push_back(integer("vision.max_corner_peaks", AGV_AT(vision.max_corner_peaks), 1, 1000, 16,
                       {"",
                        "corner peaks examined per frame; bounds the worst-case time on "
                        "busy floors, fewer may miss a landmark among texture peaks"}));
}

void add_qr(std::vector<Key>* k) {
  k->push_back(boolean("vision.qr_guided", AGV_AT(vision.qr_guided), true,
                       "model-guided QR reading at the fitted pose before zxing's own search. "
                       "Off = the zxing search only (combined degradations 100 % → 91.3 % "
                       "read, twice the decode time: docs/design/accuracy.md)"));
  k->push_back(boolean("vision.qr_centre_first", AGV_AT(vision.qr_centre_first), true,
                       "a first guided read from each module's centre alone, taken only when "
                       "it is within the Reed-Solomon bound of a mapped code; otherwise the "
                       "five-sample read runs as before. No read lost, a fifth of the "
                       "sampling on most frames (docs/design/tracking.md)"));
  k->push_back(integer(
      "vision.qr_max_missing_modules", AGV_AT(vision.qr_max_missing_modules), 0, 625, 80,
      {"modules",
       "data modules of a code cut by the image border that may be missing (filled "
       "with the code's mean grey and left to the Reed-Solomon correction; a wrong "
       "read is still excluded by the RS and payload/map checks). Cut-landmark fixes "
       "56 % (0) → 72 % (80), no gain above 80 (docs/design/accuracy.md). 0 = the code must "
       "be whole"}));
  k->push_back(
      integer("vision.qr_max_grid_decodes", AGV_AT(vision.qr_max_grid_decodes), 0, 32, 4,
              {"reads",
               "zxing reads of the guided QR grids per frame, once every grid's verified read "
               "has failed (about 0.19 M aarch64 instructions each): the bound on a frame's "
               "zxing cost. Fewer loses codes the map's code book does not hold byte for byte "
               "(docs/design/tracking.md \"zxing budget\")"}));
  k->push_back(boolean("vision.qr_try_harder", AGV_AT(vision.qr_try_harder), false,
                       "zxing TryHarder for the zxing search fallback: slower, reads a few more "
                       "damaged codes; no measurable effect since the guided reader reads every "
                       "evaluation frame"));
  k->push_back(boolean("vision.qr_retries", AGV_AT(vision.qr_retries), true,
                       "zxing search fallback: blurred, larger and unsharp-masked crops and the "
                       "global binarizer after a failed decode (up to 6 zxing calls); costs "
                       "time only on frames that would otherwise be lost"));
  k->push_back(number("vision.qr_target_module_px", AGV_AT(vision.qr_target_module_px), 0.0, 50.0,
                      4.0,
                      {"px",
                       "the zxing search crop is downscaled by an integer factor so a "
                       "module is about this size (zxing is fastest at 3–5 px). 0 = never "
                       "downscale"}));
  k->push_back(number("vision.map_tolerance_mm", AGV_AT(vision.map_tolerance_mm), 0.0, 1000.0, 1.0,
                      {"mm",
                       "allowed disagreement between a full payload and the map (payload "
                       "stores 0.1 mm: more means a wrong map or label)"}));
  k->push_back(number("vision.map_tolerance_deg", AGV_AT(vision.map_tolerance_deg), 0.0, 180.0, 0.1,
                      {"deg", "the same for the heading (payload stores 0.01°)"}));
}

void add_direction(std::vector<Key>* k) {
  k->push_back(number("vision.logo_threshold", AGV_AT(vision.logo_threshold), 0.0, 1.0, 0.5,
                      {"",
                       "logo NCC the best 90° turn must reach. Higher = fewer wrong "
                       "directions, more `kDirectionAmbiguous` on dirty logos"}));
  k->push_back(number("vision.logo_margin", AGV_AT(vision.logo_margin), 0.0, 1.0, 0.2,
                      {"", "lead of the best turn over the second; same trade-off"}));
  k->push_back(boolean("vision.direction_from_qr_when_logo_weak",
                       AGV_AT(vision.direction_from_qr_when_logo_weak), true,
                       "when the logo is unreadable (dirt, occluder) but the QR was decoded, "
                       "take the direction from the QR orientation alone (reliable: it comes "
                       "with Reed-Solomon-checked content). false = such frames are "
                       "`kDirectionAmbiguous`"));
}

void add_pose(std::vector<Key>* k) {
  using vision::HeadingMethod;
  using vision::MetricMode;
  using vision::PoseMethod;
  k->push_back(number("vision.edge_threshold_rel", AGV_AT(vision.edge_threshold_rel), 0.01, 1.0,
                      0.25,
                      {"",
                       "gradient threshold relative to the measured border contrast. "
                       "Lower keeps more (noisier) points on blurred edges"}));
  k->push_back(number("vision.edge_direction_tol_deg", AGV_AT(vision.edge_direction_tol_deg), 1.0,
                      45.0, 20.0,
                      {"deg",
                       "gradient-direction class tolerance. Smaller rejects more dirt "
                       "and scratch points, larger keeps more points near blurred "
                       "corners"}));
  // Above 0.6 (3.6 mm) the band would reach the QR code's quiet zone.
  k->push_back(number("vision.band_rel", AGV_AT(vision.band_rel), 0.05, 0.6, 0.4,
                      {"border widths",
                       "half-width of the search band around each predicted "
                       "edge (0.4 = 2.4 mm). Wider tolerates a worse "
                       "detection estimate and costs time"}));
  k->push_back(
      integer("vision.edge_row_step", AGV_AT(vision.edge_row_step), 1, 8, 3,
              {"pixel rows",
               "edge points on every N-th pixel row along each border line. Larger "
               "costs less (pose stage about 1/N; tracked frame 3.09 → 1.72 M aarch64 "
               "instructions at 3) and is a little noisier (realistic frames p95 "
               "0.0028 → 0.0033 mm at 3; docs/design/vision.md). The point minimums and the "
               "covariance count rows covered, so N does not change which views have "
               "enough edge"}));
  k->push_back(boolean("vision.subpixel", AGV_AT(vision.subpixel), true,
                       "parabolic subpixel edge positions across the edge"));
  k->push_back(boolean("vision.robust", AGV_AT(vision.robust), true,
                       "Tukey biweight IRLS (scale from the MAD) per line and on the joint "
                       "square, against scratches, dirt and occluders"));
  k->push_back(number("vision.tukey_c", AGV_AT(vision.tukey_c), 1.0, 20.0, 4.685,
                      {"robust σ",
                       "Tukey cut-off. Smaller rejects more outliers and more good "
                       "points; 4.685 = 95 % efficiency on clean edges"}));
  k->push_back(integer("vision.ransac_iterations", AGV_AT(vision.ransac_iterations), 0, 1000, 24,
                       {"",
                        "RANSAC start of each robust line fit, needed when an occluder edge "
                        "covers much of a side. More = safer, slower. 0 = off"}));
  k->push_back(enumeration(
      "vision.metric", AGV_AT(vision.metric),
      std::vector<std::pair<std::string, MetricMode>>{{"camera_model", MetricMode::kCameraModel},
                                                      {"linear_ratio", MetricMode::kLinearRatio}},
      "camera_model",
      "edge points to mm: through the camera model (undistorts) or Li et al.'s single mm/px "
      "ratio (wrong under distortion, see the ablation in docs/design/accuracy.md)"));
  k->push_back(enumeration(
      "vision.pose_method", AGV_AT(vision.pose_method),
      std::vector<std::pair<std::string, PoseMethod>>{
          {"joint_square_fit", PoseMethod::kJointSquareFit},
          {"line_intersections", PoseMethod::kLineIntersections},
          {"paper_corner_a", PoseMethod::kPaperCornerA}},
      "joint_square_fit",
      "one fit of the known square to all points (shared angle), 8 independent line fits, or "
      "Li et al. eq. 8-11 (centre from corner A). Partial views always use the joint fit"));
  k->push_back(enumeration(
      "vision.heading_method", AGV_AT(vision.heading_method),
      std::vector<std::pair<std::string, HeadingMethod>>{
          {"inverse_variance", HeadingMethod::kInverseVariance},
          {"mean", HeadingMethod::kMean},
          {"weighted_000", HeadingMethod::kWeighted000}},
      "inverse_variance",
      "line angles to one heading, for the non-joint pose methods: 1/variance weights, plain "
      "mean (Li et al. eq. 7) or Yang et al. eq. 10-11 weights"));
  k->push_back(
      integer("vision.min_points_per_line", AGV_AT(vision.min_points_per_line), 3, 10000, 20,
              {"",
               "edge points a fitted line needs, counted at row step 1 (`vision.edge_row_step`); "
               "fewer give `kTooFewEdgePoints`"}));
  k->push_back(integer("vision.min_points_total", AGV_AT(vision.min_points_total), 8, 100000, 200,
                       {"", "edge points the landmark needs in total; same"}));
  k->push_back(number("vision.outside_margin_mm", AGV_AT(vision.outside_margin_mm), 0.0, 100.0, 0.0,
                      {"mm",
                       "a predicted corner further than this outside the image makes the "
                       "landmark \"partly outside\"; 0 = any cut counts"}));
  k->push_back(boolean("vision.allow_partly_outside", AGV_AT(vision.allow_partly_outside), true,
                       "measure a cut landmark when each axis keeps one complete side and the "
                       "QR is readable; false = `kPartlyOutside`"));
}

void add_covariance(std::vector<Key>* k) {
  k->push_back(number("vision.cov_inflation", AGV_AT(vision.cov_inflation), 0.1, 1000.0, 4.0,
                      {"",
                       "scales the fit covariance (neighbouring edge points share blur and "
                       "noise, so they are not independent)"}));
  k->push_back(number("vision.sigma_floor_mm", AGV_AT(vision.sigma_floor_mm), 0.0, 100.0, 0.05,
                      {"mm", "floor of the position σ (calibration, print)"}));
  k->push_back(number("vision.sigma_floor_deg", AGV_AT(vision.sigma_floor_deg), 0.0, 10.0, 0.01,
                      {"deg", "floor of the heading σ"}));
}

void add_tracking(std::vector<Key>* k) {
  k->push_back(
      boolean("vision.tracking.enabled", AGV_AT(vision.tracking.enabled), true,
              "search only the windows around the mapped landmarks the fused pose "
              "predicts in view (full frame when they find nothing, docs/design/tracking.md). "
              "landmark.family tag36h11: a predicted tag libapriltag does not find (an "
              "occluder broke its quad) is placed there and its code read "
              "(docs/design/landmark.md). false: every frame searched in full, tags by "
              "libapriltag and landmark.tag_corner_search only"));
  k->push_back(number("vision.tracking.max_position_sigma_mm",
                      AGV_AT(vision.tracking.max_position_sigma_mm), 0.0, 1000.0, 10.0,
                      {"mm",
                       "largest position σ of the prediction for windows to be used. Larger "
                       "trusts looser poses: bigger windows, less saved, more misses that pay "
                       "window + full search"}));
  k->push_back(number("vision.tracking.max_heading_sigma_deg",
                      AGV_AT(vision.tracking.max_heading_sigma_deg), 0.0, 90.0, 2.0,
                      {"deg", "largest heading σ of the prediction for windows to be used"}));
  k->push_back(number("vision.tracking.window_sigmas", AGV_AT(vision.tracking.window_sigmas), 0.0,
                      20.0, 4.0,
                      {"σ",
                       "window growth around each predicted corner, in σ of its position. "
                       "Smaller = cheaper windows, more misses (a miss costs the window and "
                       "the full search)"}));
  k->push_back(
      boolean("vision.tracking.detect_from_prediction",
              AGV_AT(vision.tracking.detect_from_prediction), true,
              "skip detection when the prediction places every corner within half the "
              "pose stage's edge band (at window_sigmas σ) and the fit lands where "
              "predicted; otherwise the tracked detection (docs/design/tracking.md). false: "
              "detection on every frame"));
  k->push_back(boolean("vision.tracking.probe_edges", AGV_AT(vision.tracking.probe_edges), true,
                       "when the prediction is too loose to place the bands itself, find the "
                       "border's outer edge with 8 one-dimensional probes across each predicted "
                       "side and place them from the lines through those (docs/design/tracking.md "
                       "\"Edge probes\"); otherwise the tracked detection. Needs "
                       "detect_from_prediction. false: the tracked detection"));
  k->push_back(
      boolean("vision.tracking.logo_at_code_turn", AGV_AT(vision.tracking.logo_at_code_turn), true,
              "read the code first at the predicted turn; when its module centres match "
              "a mapped code, score the logo at that turn only (it must reach "
              "logo_threshold there) instead of at all four turns (docs/design/tracking.md "
              "\"Logo at the code's turn\"). Needs qr_guided and qr_centre_first. "
              "Otherwise, or false: four turns and the full read"));
}

// vision::MapIdentityConfig (map_identity_config.hpp; docs/design/map_identity.md has the
// measurements).
void add_identity(std::vector<Key>* k) {
  k->push_back(number("vision.identity.gate_chi2", AGV_AT(vision.identity.gate_chi2), 1.0, 100.0,
                      16.27,
                      {"",
                       "squared Mahalanobis distance (x, y, heading) within which a mapped "
                       "landmark is a candidate for an unread code. 16.27 = chi2(3) at 0.999: a "
                       "right landmark is refused once in a thousand frames (one fix lost, never "
                       "a wrong one). Must be below clear_chi2"}));
  k->push_back(number("vision.identity.clear_chi2", AGV_AT(vision.identity.clear_chi2), 1.0, 1000.0,
                      60.0,
                      {"",
                       "the runner-up must lie beyond this distance, or the identity is refused "
                       "as two plausible. Lower gives identities on a looser prediction, and "
                       "trusts the covariance more (60 tolerates a sigma ~2x too small)"}));
  k->push_back(number("vision.identity.min_agreement", AGV_AT(vision.identity.min_agreement), 0.5,
                      1.0, 0.70,
                      {"",
                       "share of the visible code modules that must agree with the candidate's "
                       "code (right code >= 0.82 with a third covered). Rejects a landmark not in "
                       "the map, not a neighbour"}));
  k->push_back(number("vision.identity.min_pair_agreement",
                      AGV_AT(vision.identity.min_pair_agreement), 0.5, 1.0, 0.55,
                      {"",
                       "on the modules where another mapped code differs, the share that must "
                       "side with the candidate (right >= 0.67, wrong <= 0.22 measured). Higher "
                       "refuses more covered codes"}));
  k->push_back(integer(
      "vision.identity.min_pair_modules", AGV_AT(vision.identity.min_pair_modules), 1, 1000, 24,
      {"",
       "visible differing modules needed for a pairwise verdict; fewer and the "
       "identity is refused (payloads differing in the id alone differ on ~100)"}));
  k->push_back(integer("vision.identity.pair_neighbours", AGV_AT(vision.identity.pair_neighbours),
                       1, 1000, 24,
                       {"",
                        "mapped landmarks nearest the candidate whose codes the module check "
                        "compares with; bounds its cost on large maps (24: every landmark within "
                        "2.5 m on a 1 m grid)"}));
}

}  // namespace

void add_vision_keys(std::vector<Key>* keys) {
  add_detection(keys);
  add_qr(keys);
  add_direction(keys);
  add_pose(keys);
  add_covariance(keys);
  add_tracking(keys);
  add_identity(keys);
}

}  // namespace agv::config::detail

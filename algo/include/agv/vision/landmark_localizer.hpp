// Landmark pose from one floor image: Li et al.'s pipeline (adaptive threshold, NCC corner
// templates, QR decode, logo direction, Prewitt edge classes, least-squares edge lines) plus the
// improvements measured in docs/design/accuracy.md. Tunables and their trade-offs:
// docs/design/vision.md. Frames: docs/design/frames.md. Pure: no I/O, no threads, no clocks (time
// comes from an injected function only to fill the per-stage timings).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/geometry.hpp"
#include "agv/common/landmark.hpp"
#include "agv/vision/map_identity_config.hpp"

namespace cv {
class Mat;
}

namespace agv::vision {

// How edge-point coordinates become millimetres.
enum class MetricMode {
  kLinearRatio,  // Li et al.: one mm-per-pixel ratio about the image centre (ignores distortion)
  kCameraModel,  // every edge point through CameraModel::pixel_to_vehicle (undistorts)
};

// How the landmark centre and heading are computed from the classified edge points.
enum class PoseMethod {
  kPaperCornerA,       // Li et al. eq. 7-11: heading from the line angles, centre from corner A
  kLineIntersections,  // 8 independent line fits; centre = mean of the outer+inner corners
  kJointSquareFit,     // one Gauss-Newton fit of the known square to all points (shared angle)
};

// How the four (eight) line angles are averaged into one heading (kPaperCornerA and
// kLineIntersections; the joint fit estimates one shared angle directly).
enum class HeadingMethod {
  kMean,             // Li et al. eq. 7
  kWeighted000,      // Yang et al. eq. 10-11 (weights k_i from the fit residuals)
  kInverseVariance,  // each line angle weighted by 1/var from its own residuals
};

// Search windows from the filter's prediction (docs/design/tracking.md).
struct TrackingConfig {
  // Search only the windows around the predicted landmarks when the prediction is trusted (full
  // frame when they find nothing). false = every frame is searched in full, as before tracking.
  bool enabled = true;
  // Trust limits: the largest position standard deviation (sqrt of the largest eigenvalue of the
  // x-y covariance) and the heading standard deviation. Larger trusts a looser pose: bigger
  // windows, less saved, more window misses that pay window + full search. Defaults 10 mm, 2 deg
  // (a window then stays under about half the 640x480 frame).
  double max_position_sigma_mm = 10.0;
  double max_heading_sigma_deg = 2.0;
  // Window half growth in standard deviations of each corner's position. Smaller = cheaper windows
  // and more misses (a miss costs the window plus the full search). Default 4 (a 2-D miss
  // probability of at most exp(-8) ~ 3e-4 for a Gaussian error).
  double window_sigmas = 4.0;
  // Skip detection when the prediction alone places the pose stage's edge bands: every predicted
  // outer corner within half the band (window_sigmas sigma), the landmark wholly in the image, the
  // border ring dark on light paper in the full image; the fit must then land where predicted,
  // otherwise the frame takes the tracked detection as before (docs/design/tracking.md "Detection
  // from the prediction"). Saves the detection, a third of a tracked frame, on the frames that
  // follow a fix closely. false = the tracked detection on every windowed frame. Default true.
  bool detect_from_prediction = true;
  // With detect_from_prediction: a prediction too loose for that (but trusted) is made precise by
  // 1-D searches for the border's outer edge, 8 across each predicted side, and robust lines
  // through them (docs/design/tracking.md "Edge probes"); the fit must then land where the lines
  // put the landmark. Replaces the tracked detection's coarse level and corner templates over the
  // window, about 0.06 ms of a 0.2 ms tracked frame on x86-64. A side that is covered, cut by the
  // image border or too blurred declines, and the frame takes the tracked detection. false = the
  // tracked detection whenever the prediction alone does not place the bands. Default true.
  bool probe_edges = true;
  // Read the code first at the predicted turn (the module centres, verified against the mapped
  // codes); when that succeeds the logo is scored at that turn only and must reach logo_threshold
  // there, instead of at all four turns with logo_margin over the second best
  // (docs/design/tracking.md "Logo at the code's turn"). The direction is then the code's own
  // orientation, confirmed by the prediction and the logo; a logo below the threshold there, or no
  // such read, takes the four turns and the full read as before, so a logo that contradicts the
  // code is still refused. Saves three quarters of the logo stage, about 0.009 ms of a 0.15 ms
  // tracked frame on x86-64; logo_margin is then not measured (LandmarkFix::logo_one_turn). Needs
  // qr_guided and qr_centre_first (that read is theirs). false = four turns on every frame. Default
  // true.
  bool logo_at_code_turn = true;
};

struct VisionConfig {
  // Which printed landmark the frames show (one family per floor). kTag36h11: libapriltag finds
  // and decodes the tag, this pipeline's edge fits on the tag's outer black square give the pose
  // and the map gives the world pose of the id (apriltag.cpp, docs/design/landmark.md). Default
  // kQr.
  agv::LandmarkFamily family = agv::LandmarkFamily::kQr;
  // kTag36h11 only: when libapriltag finds no quad and no trusted prediction places a tag, search
  // the frame for the black square's outer corners as the QR family does and read the tag's code
  // at the fitted square. An occluder that joins the border to the floor breaks libapriltag's
  // quad but leaves three corners. Costs the corner search on every tag-floor frame without a
  // tag (what the QR family pays on every frame). Default true.
  bool tag_corner_search = true;

  // --- 1. binarization -------------------------------------------------------------------
  // Adaptive threshold on the coarse detection image: a pixel is dark when it is below the local
  // mean (box of adaptive_block_mm on the floor) minus adaptive_offset grey levels. A larger block
  // tolerates stronger illumination gradients less well but ignores small texture; the offset
  // trades sensitivity on low-contrast frames against false dark pixels on floor texture.
  // Defaults 24 mm (about 4 border widths) and 6 grey levels.
  double adaptive_block_mm = 24.0;
  double adaptive_offset = 6.0;

  // --- 2. detection ------------------------------------------------------------------------
  // The coarse level is chosen so the 6 mm border is at least this many coarse pixels wide.
  // Smaller = faster full-frame search but weaker corner templates. Default 2.5 (a factor 8
  // pyramid at 0.26 mm/px).
  double coarse_border_px = 2.5;
  // Number of rotations of the corner template (one corner type; the other three corners are
  // its 90-degree turns). More rotations = higher NCC peaks for arbitrary headings and slower
  // search. Default 12 (30-degree steps, at most 15 degrees off); at most 32.
  int corner_rotations = 12;
  // NCC score a corner must reach for the landmark to count as present (paper: "as long as one
  // of the four templates has a matching score greater than a threshold"). Lower finds more
  // blurred / occluded landmarks and lets more floor texture through to the (strict) ring and
  // QR checks. Default 0.55.
  double corner_threshold = 0.55;
  // Fraction of the predicted border ring (where it is inside the image) that must be dark in
  // the binary image for a hypothesis to be accepted. Guards against texture that happens to
  // look like a corner. Default 0.55 (occluders and scratches lower it).
  double ring_dark_fraction = 0.55;
  // Maximal number of corner peaks examined per frame. Default 16.
  int max_corner_peaks = 16;

  // --- 3. QR decode ------------------------------------------------------------------------
  // Model-guided reading (qr_grid.hpp): after the border fit, sample every module where the pose
  // puts it, binarize against the local mean of the modules around it and decode a re-rendered
  // code with zxing's pure-code reader (Reed-Solomon checked, so a wrong grid cannot give a
  // payload). zxing's own search on the image crop remains as the fallback. Reads codes zxing's
  // binarizer loses under blur and scratches (combined degradations 91.3 -> 100 %) in half the
  // decode time (0.155 -> 0.079 ms, docs/design/accuracy.md). Default true.
  bool qr_guided = true;
  // When a verified read is possible (a mapped landmark's code is expected, or the map's code
  // book), first sample only each module's centre and take the grid only if it is within the
  // Reed-Solomon bound of a mapped code (the answer zxing would give); otherwise the five-sample
  // read runs as without it, so no read is lost (one stress frame gained one), at a fifth of the
  // sampling on most frames and without zxing on unclear logos (docs/design/tracking.md
  // "Centre-only first read"); a frame whose centre grid is not verified pays its cost on top.
  // Default true.
  bool qr_centre_first = true;
  // Guided reading of a code cut by the image border: at most this many data modules may lie
  // outside the image (they are filled with the code's mean grey and left to the Reed-Solomon
  // correction of ECC level M; quiet-zone and fixed modules outside are filled with their known
  // values). 0 = the whole code must be inside. Larger reads more cut codes and costs nothing on
  // whole ones; a wrong read is still excluded by the Reed-Solomon check (estimated, not
  // measured: a random word lands within the 8 correctable symbols of a version-2-M codeword
  // with probability ~1e-11) and the payload/map check. Measured on 300 cut frames
  // (docs/design/accuracy.md): fixes 52 % (before fill-in) -> 56 % (quiet zone only, 0) -> 63 %
  // (20) -> 68 % (40) -> 72 % (80, no gain above). Default 80.
  int qr_max_missing_modules = 80;
  // zxing reads of the guided grids per frame, after every grid's verified read (no zxing) has
  // failed. Each costs about 0.19 M aarch64 instructions; an unclear logo on a cut code could
  // take 32 (4 turns, 2 sizes, 4 thresholds). They read codes the map's code book does not hold
  // byte for byte, and codes beyond the verified read's bounds. Fewer bounds the frame's worst
  // case more tightly and loses such reads (measured in docs/design/tracking.md "zxing budget").
  // Default 4.
  int qr_max_grid_decodes = 4;
  // zxing-cpp TryHarder: slower, reads a few more damaged codes. Default false (measured in
  // docs/design/accuracy.md).
  bool qr_try_harder = false;
  // When the first zxing attempt fails, retry on a slightly blurred crop (thin bright scratches
  // break zxing's local binarizer), a larger crop, zxing's global-histogram binarizer and an
  // unsharp-masked crop (defocus plus motion blur). Costs time only on frames that would
  // otherwise be lost (up to 6 decodes). Default true.
  bool qr_retries = true;
  // The QR crop is downscaled by an integer factor so a module is about this many pixels (zxing
  // is fastest at 3-5 px per module). 0 disables downscaling. Default 4.
  double qr_target_module_px = 4.0;
  // A full payload must agree with the map entry (if a map is given) within these tolerances.
  // The payload stores 0.1 mm and 0.01 deg, so anything above rounding means a wrong map or a
  // wrong label. Defaults 1.0 mm and 0.1 deg.
  double map_tolerance_mm = 1.0;
  double map_tolerance_deg = 0.1;

  // --- 4. direction -----------------------------------------------------------------------
  // NCC of the logo template at the four 90-degree turns: the best must reach logo_threshold and
  // beat the second best by logo_margin, and must agree with the QR code's own orientation (the
  // turn the guided reader decoded at, or zxing's finder-pattern corners) (else
  // kDirectionAmbiguous). Defaults 0.5 and 0.2.
  double logo_threshold = 0.5;
  double logo_margin = 0.2;
  // When the logo is unreadable (below threshold: dirt, occluder) but the QR was decoded, take
  // the direction from the QR code's orientation alone. Default true (the QR orientation comes with
  // Reed-Solomon-checked content, so it is reliable).
  bool direction_from_qr_when_logo_weak = true;

  // --- 5./6. pose --------------------------------------------------------------------------
  // Gradient magnitude threshold relative to the landmark's measured contrast (dark border vs
  // white). The paper uses an absolute threshold; relative keeps working under illumination
  // changes. Lower keeps more (noisier) points on blurred edges. Default 0.25.
  double edge_threshold_rel = 0.25;
  // Maximal angle between a point's gradient and the expected normal of its side (the
  // gradient-direction classification). Smaller rejects more points from dirt and scratches,
  // larger keeps more points on blurred corners. Default 20 deg.
  double edge_direction_tol_deg = 20.0;
  // Half-width of the band around each predicted edge line in which pixels are examined, as a
  // fraction of the border width (6 mm). Wider tolerates a worse detection estimate and costs
  // time; it must stay below half the distance to the QR code (4 mm). Default 0.4 (2.4 mm).
  double band_rel = 0.4;
  // Edge points are taken on every edge_row_step-th pixel row (or column, for lines closer to
  // horizontal) along each border line, on rows that are multiples of the step. The pose stage's
  // cost (collection, undistortion, line and joint fits) falls about as 1/step; the error grows
  // far less than sqrt(step), as neighbouring rows share blur (measured at 3: realistic frames'
  // p95 0.0028 -> 0.0033 mm, every detection rate unchanged; docs/design/vision.md "Row step"),
  // which is micrometres against the millimetres a vehicle needs. min_points_per_line,
  // min_points_total and the fit covariance count rows covered (each point stands for step rows):
  // the step does not change which views have enough edge, and the covariance keeps the scale
  // cov_inflation was measured at (mean NEES on motion blur 2.4 at step 1, 2.5 at 3). Default 3.
  int edge_row_step = 3;
  // Subpixel edge positions: parabola through the gradient magnitude across the edge. Default on.
  bool subpixel = true;
  // Robust fitting (Tukey biweight IRLS, scale from the MAD) against scratches, dirt and
  // occluders. Default on; tukey_c in units of the robust sigma, default 4.685.
  bool robust = true;
  double tukey_c = 4.685;
  // RANSAC start of the robust fit (two-point lines, inliers within 0.5 px): needed when an
  // occluder or dirt puts a parallel edge into the band over a large part of a side, which pulls
  // a plain least-squares start too far for IRLS to recover. More iterations = safer, slower.
  // 0 disables. Default 24.
  int ransac_iterations = 24;
  MetricMode metric = MetricMode::kCameraModel;
  PoseMethod pose_method = PoseMethod::kJointSquareFit;
  HeadingMethod heading_method = HeadingMethod::kInverseVariance;
  // Minimal number of edge points on a fitted line, and minimal total, counted at row step 1
  // (edge_row_step); fewer gives kTooFewEdgePoints. Defaults 20 and 200.
  int min_points_per_line = 20;
  int min_points_total = 200;
  // A landmark with a predicted corner more than this far (mm) outside the image is "partly
  // outside". It is still measured when each axis keeps at least one complete side (outer and
  // inner edge) and the QR is readable; otherwise kPartlyOutside. Default 0 (any cut counts).
  double outside_margin_mm = 0.0;
  bool allow_partly_outside = true;

  // --- covariance -------------------------------------------------------------------------
  // The fit covariance assumes independent edge points; neighbouring points share blur and
  // noise, so it is scaled by cov_inflation and floored by sigma_floor_mm / sigma_floor_deg
  // (model errors: calibration, print). Defaults 4, 0.05 mm, 0.01 deg.
  double cov_inflation = 4.0;
  double sigma_floor_mm = 0.05;
  double sigma_floor_deg = 0.01;

  TrackingConfig tracking;
  // Map-guided identity of a landmark whose code cannot be read (keys vision.identity.*).
  MapIdentityConfig identity;

  // --- timings -----------------------------------------------------------------------------
  // Optional monotonic clock supplied by the caller (algo/ never reads a clock). When empty,
  // StageTimings stay 0.
  std::function<std::int64_t()> now_ns;
};

enum class FixStatus {
  kOk,
  kBadInput,            // empty image, not 8-bit single channel, or size unlike the camera model
  kNoLandmark,          // no corner template above threshold / no border ring
  kPartlyOutside,       // the landmark is cut by the image border too much for a safe pose
  kQrUnreadable,        // landmark found but neither the guided reader nor zxing's search read it
  kPayloadInvalid,      // payload text fails the strict parser or disagrees with the map
  kUnknownLandmark,     // id-only payload (or full payload) whose id is not in the map
  kDirectionAmbiguous,  // logo and QR orientation disagree, or the logo has no clear winner
  kTooFewEdgePoints,    // not enough classified edge points for the line fits
};

const char* to_string(FixStatus s);

// How a landmark's identity (and so its world pose) was established.
enum class FixIdentity : std::uint8_t {
  kNone,       // no identity (the fix failed)
  kQrCode,     // the QR payload (Reed-Solomon checked, map-checked when a map is given)
  kMapGuided,  // QR unreadable; the one mapped landmark the prediction allows
               // (docs/design/tracking.md)
  kAprilTag,   // a tag36h11 id through the map
};
const char* to_string(FixIdentity i);

// Where the detection stage looked for the landmark.
enum class SearchMode : std::uint8_t {
  kFull,            // the whole frame (no trusted prediction)
  kWindow,          // only the windows around the predicted landmarks, and found it there
  kWindowThenFull,  // the windows found nothing, the whole frame was searched after them
};
const char* to_string(SearchMode m);

// What the fused pose predicts for the frame being processed: the vehicle's pose in the world at
// the frame's exposure and its covariance. It gives the search windows and the map-guided
// identity of a landmark whose QR code cannot be read (docs/design/tracking.md). valid = false (the
// default): full-frame search, identity from the code only.
struct Prediction {
  bool valid = false;
  Pose2 vehicle_in_world;                         // W<-V at the exposure
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();  // of (x_mm, y_mm, theta_rad)
};

// Milliseconds per stage, filled only when VisionConfig::now_ns is set.
struct StageTimings {
  double detect_ms = 0.0;     // pyramid + binarization + corner templates + ring check
  double decode_ms = 0.0;     // QR (guided sampling, then zxing search) + payload + map check
  double direction_ms = 0.0;  // logo template at four turns + QR orientation cross-check
  double pose_ms = 0.0;       // Prewitt, classification, line fits, centre, covariance
  double total_ms = 0.0;
};

// What fusion takes from a frame: the outcome, the landmark's identity and the vehicle's world
// pose with its covariance. The exposure time travels beside it (the localizer has no clock): the
// real-time hand-off from the vision worker to the output thread carries only this.
struct LandmarkMeasurement {
  FixStatus status = FixStatus::kNoLandmark;
  std::uint32_t landmark_id = 0;
  FixIdentity identity = FixIdentity::kNone;
  // The landmark's world pose came from the survey map or was checked against it (a map was
  // given): a misprinted code cannot have produced this fix.
  bool map_verified = false;
  Pose2 vehicle_in_world;  // W<-V, valid only when status == kOk
  // Covariance of (x_mm, y_mm, theta_rad) of vehicle_in_world, from the fit residuals.
  Eigen::Matrix3d cov_world = Eigen::Matrix3d::Zero();
};

// How the frame was measured, for the logs, the desk tools and the tests: nothing fusion reads.
struct FixDiagnostics {
  char payload[48] = {};  // NUL-terminated QR text (truncated if longer; valid payloads are 38)
  // Pose of the vehicle in the landmark frame (docs/design/frames.md "Vision output").
  double e_x_mm = 0.0, e_y_mm = 0.0, e_phi_deg = 0.0;
  Pose2 landmark_in_vehicle;  // V<-L
  // Covariance of (x_mm, y_mm, theta_rad) of landmark_in_vehicle.
  Eigen::Matrix3d cov_landmark_in_vehicle = Eigen::Matrix3d::Zero();
  StageTimings timings;
  int edge_points_used = 0;
  double corner_score = 0.0;  // best corner-template NCC
  double logo_score = 0.0;    // best logo NCC
  double logo_margin = 0.0;   // best minus second-best logo NCC (0 when logo_one_turn)
  // The logo was scored only at the verified code's turn (TrackingConfig::logo_at_code_turn).
  bool logo_one_turn = false;
  int sides_used = 0;           // border sides with both edges fitted (4 when fully visible)
  bool partly_outside = false;  // some of the border is outside the image (pose still valid)
  double residual_rms_mm = 0.0;
  // Measured half sides (mm, vehicle frame) of the outer and inner border squares from the joint
  // square fit, when it could estimate them (some axis with both sides fitted); 0 otherwise. Their
  // ratio to LandmarkGeometry's values is the image scale error (camera height, fx, or a print
  // not at 100 %): agvloc-desk calibrate check. Tag family: outer only (inner_half_mm stays 0).
  double outer_half_mm = 0.0, inner_half_mm = 0.0;
  // How the QR code was read: 1 = model-guided module sampling, 2 = zxing's search on the crop.
  int qr_method = 0;
  // The guided read matched the tracked landmark's expected code within what Reed-Solomon
  // corrects, so zxing did not run (the text is the one zxing would have returned).
  bool qr_verified = false;
  // That verified read came from the module centres alone (the cheap first read, one sample per
  // module instead of five; docs/design/tracking.md "Centre-only first read").
  bool qr_centre_only = false;
  // zxing runs this frame, the QR stage's cost driver (diagnostics, cost tests): pure-code reads
  // of sampled grids (about 0.1 M instructions each on x86-64) and search attempts on the crop
  // (about 2 M aarch64 instructions each).
  int qr_grid_decodes = 0;
  int qr_search_attempts = 0;
  SearchMode search = SearchMode::kFull;
  // The prediction placed the edge bands; no detection ran
  // (TrackingConfig::detect_from_prediction). detect_x_px / detect_y_px / detect_angle_deg are then
  // the prediction's, corner_score 0.
  bool detection_predicted = false;
  // Of those, the edge probes placed the bands (TrackingConfig::probe_edges); detect_x_px etc. are
  // then the probes' estimate.
  bool detection_probed = false;
  // Detection estimate (before the edge fit), for diagnostics: landmark centre in pixels and the
  // image angle of one border normal (modulo 90 deg).
  double detect_x_px = 0.0, detect_y_px = 0.0, detect_angle_deg = 0.0;
};

// One frame's full result: the measurement fusion takes and the frame's diagnostics. Code that
// feeds fusion takes a LandmarkMeasurement (a LandmarkFix converts to it).
struct LandmarkFix : LandmarkMeasurement, FixDiagnostics {
  const LandmarkMeasurement& measurement() const { return *this; }
  const FixDiagnostics& diagnostics() const { return *this; }
};

class LandmarkLocalizer {
 public:
  // `map` may be null: then only full payloads can give a world pose. The map must outlive the
  // localizer.
  LandmarkLocalizer(const VisionConfig& config, const agv::CameraModel& camera,
                    const agv::LandmarkGeometry& geometry, const agv::LandmarkMap* map);
  ~LandmarkLocalizer();
  LandmarkLocalizer(const LandmarkLocalizer&) = delete;
  LandmarkLocalizer& operator=(const LandmarkLocalizer&) = delete;

  // gray8: CV_8UC1 image of the camera model's size. Never throws; the reason is in the status
  // (also written to out->status). Buffers are reused between calls.
  FixStatus process(const cv::Mat& gray8, LandmarkFix* out);
  // The same with the filter's prediction for this frame (search windows, map-guided identity).
  FixStatus process(const cv::Mat& gray8, const Prediction& prediction, LandmarkFix* out);

  // Debug overlay like Li et al. figures 5-9: edge points coloured by class, fitted lines,
  // corners, centre, the numbers. Uses the edge points kept from the last process() call, so
  // pass the same image and the fix that call returned.
  void draw_overlay(const cv::Mat& gray8, const LandmarkFix& fix, cv::Mat* bgr_out) const;

  const VisionConfig& config() const;

  // Raw border edge points (distorted pixels) found by the last process() call, per edge line
  // 0..7 (outer and inner edge of each of the four border sides), before the pose fit: the
  // per-frame observation for the vehicle calibration (agvloc-desk calibrate vehicle), which
  // must not inherit the configured mounting. Empty for an out-of-range line.
  static constexpr int kEdgeLines = 8;
  const std::vector<agv::Vec2>& edge_points_px(int line) const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace agv::vision

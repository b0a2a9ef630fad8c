// Vehicle calibration (commissioning): camera mounting (offset, yaw, height, roll, pitch), odometry
// (speed scale, yaw-rate scale, yaw-rate bias, yaw per metre) and the camera-odometry time
// offset, estimated jointly by nonlinear least squares (Ceres) from a calibration drive over
// mapped landmarks.
//
// Model (all in the world frame W of the map, docs/design/frames.md):
//  - Odometry. Sample k, stamped T_k on the odometry clock, reports (v_k, omega_k) as the mean
//    over (T_{k-1}, T_k]. The true rates are  v = speed_scale * v_k,
//    v = speed_scale * v_k + yaw_per_metre * track^2 / 4 * omega_k,
//    omega = yaw_rate_scale * omega_k + yaw_rate_bias + yaw_per_metre * v_k  (piecewise
//    constant). The yaw_per_metre terms are unequal wheels (UMBmark's type A error): a right
//    wheel that reads a fraction a more than the left adds a * v / track to the reported yaw
//    rate, so a straight run curves by a / track radians per metre (0.46 deg/m for 0.4 % on a
//    0.5 m track), and a * track / 4 * omega to the reported speed, so a turn on the spot
//    creeps (0.5 mm per radian). Both come from the one wheel ratio: inverting the wheels'
//    equations gives the speed term as exactly track^2 / 4 times the yaw term (track:
//    Options::track_width_mm). Without the yaw term the straight passes put the curvature
//    into the camera yaw (0.11 deg on a clean 60 s simulated drive, 6 sigma); without the
//    speed term the creep of the turns on the spot, which has exactly the form of a lever arm,
//    goes into the lateral offset (0.53 mm, 12 sigma). An instant at
//    camera time t is stamped t + time_offset on the odometry clock (odometry clock = camera
//    clock + time_offset; time_offset > 0: odometry stamps are late). The relative motion
//    from camera time a to b is the unicycle integral of those rates over
//    [a + time_offset, b + time_offset] (midpoint heading per piece).
//  - Anchors. The drive is cut into landmark passes (consecutive frames seeing one landmark);
//    each pass is cut into sub-passes of at most `max_subpass_s` (default: one frame each).
//    Sub-pass j has a free vehicle pose A_j (x, y, theta) at the time of its first frame.
//  - Frames. The vehicle pose at a frame of sub-pass j is A_j (+) odometry(t_j -> t). Each
//    mapped landmark corner (outer and inner border corners, landmark frame (+-h, +-h)) is
//    projected through the mounting (CameraMount, tilt included) to undistorted normalised image
//    coordinates; residual = (predicted - observed) * fx / pixel_sigma_px.
//  - Odometry links. Consecutive sub-passes j, j+1: residual = A_{j+1} (-) (A_j (+) odometry(
//    t_j -> t_{j+1})), weighted by the odometry noise accumulated over the interval (white
//    noise per sample in v and omega; the heading noise adds dist * sigma_theta / sqrt(3)
//    across track).
// The map fixes the gauge: absolute heading comes from driving along the vehicle's x axis
// between landmarks, the camera yaw from the landmark's orientation in the image, the offset
// from rotations (turns), height from the landmark size, tilt from the perspective across the
// image, scales and bias from odometry vs vision over turns and straights, the time offset from
// speed changes with a landmark in view.
//
// Worn landmarks: scratches, dirt and faded ink move a landmark's corners by an amount
// that is the same in every frame of that landmark, so more frames do not average it out and a
// covariance that assumes independent pixel noise is far too optimistic. Two measures:
//  - the corners come from robust line fits (corners_from_edges: the vision stage's RANSAC +
//    Tukey fit), so a scratch or a smudge on part of an edge does not move the line;
//  - what remains is modelled: after a first solve with the printed geometry, each landmark gets
//    its own corner noise sigma_L (the RMS of its residuals about their per-corner means, at
//    least pixel_sigma_px) and its own print deviation tau_L (the RMS of those means, mapped to
//    the landmark plane, mm); the second solve weights the landmark's frames by 1/sigma_L and
//    gives each of its corners a free offset in the landmark frame with a N(0, tau_L^2) prior.
//    The offsets are shared by all frames of the landmark, so the covariance carries the
//    systematic part exactly where it acts, and a worn landmark counts less than a clean one.
//    Per landmark, not one global factor: wear is a property of one print; a global reduced
//    chi-square would weight the clean landmarks down with the worn ones, and, applied to
//    independent-noise sigmas, still shrink as 1/sqrt(frames) an error that does not. The
//    global reduced chi-square of the second solve still scales the covariance when it
//    exceeds 1 (what the per-landmark model leaves); it never shrinks it.
// Observability: the standard deviation of every global parameter comes from Ceres' covariance
// (anchors and corner offsets marginalised). A parameter whose sigma exceeds its limit, or that
// lies in a (near-)null space of the problem, is reported as not determined, with the parameters it
// trades off against, and is never written to the configuration snippet.
#pragma once

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/landmark.hpp"
#include "agv/common/track_width.hpp"

namespace agv::desk::vcal {

struct OdomSample {
  std::int64_t t_ns = 0;  // odometry clock
  double v_mps = 0.0, omega_radps = 0.0;
};

// One frame's raw landmark observation: undistorted normalised image coordinates (x/z, y/z in
// the OpenCV camera frame) of the border corners: outer 0..3 at landmark (h_out, h_out),
// (-h_out, h_out), (-h_out, -h_out), (h_out, -h_out), inner 4..7 the same with h_in.
struct CornerObservation {
  std::int64_t t_ns = 0;  // camera clock (exposure mid-time)
  std::uint32_t landmark_id = 0;
  std::array<Vec2, 8> xn{};
  std::array<bool, 8> valid{};
};

// The estimated quantities. time_offset_s: odometry clock = camera clock + time_offset_s. The
// configuration keys `odometry.*` and localizer::OdometryCorrection apply exactly this model.
struct VehicleParams {
  CameraMount mount;
  double speed_scale = 1.0;
  double yaw_rate_scale = 1.0;
  double yaw_rate_bias_radps = 0.0;
  double yaw_per_metre_rad = 0.0;  // rad of heading per metre of reported travel
  double time_offset_s = 0.0;
};

struct Options {
  double fx_px = 769.0;         // to express residuals in pixels
  double pixel_sigma_px = 0.1;  // corner noise
  // Huber loss per frame beyond this many sigmas (RMS over the frame's corners); 0 = plain
  // least squares.
  double robust_sigmas = 3.0;
  double odom_v_sigma_mps = 0.002;       // per odometry sample (white)
  double odom_omega_sigma_radps = 0.01;  // per odometry sample (white)
  // Frames of one pass closer than this share one free pose (exact odometry in between).
  // 0 = every frame has its own pose, linked by odometry: the odometry noise is then modelled
  // correctly (a shared pose treats noisy odometry as exact and biases the speed scale low).
  double max_subpass_s = 0.0;
  double pass_gap_s = 0.2;  // a longer gap without observation ends a pass
  int min_passes = 4;
  int min_frames_per_pass = 3;
  // A parameter is determined (and written) when its standard deviation is at most this:
  // offset/height mm, angles deg, scales relative, bias deg/s, time offset ms.
  double max_sigma_mm = 0.25, max_sigma_yaw_deg = 0.05, max_sigma_tilt_deg = 0.05;
  double max_sigma_scale = 0.001, max_sigma_bias_degps = 0.02, max_sigma_time_ms = 1.0;
  // The wheels' track (`can.odometry.track_width_mm`, also in v_omega mode): the lever of the
  // unequal wheels' speed term. 10 % off moves the lateral offset by 20 % of that term (0.1 mm
  // for 0.4 % unequal wheels on a 0.5 m track).
  double track_width_mm = kDefaultTrackWidthMm;
  // deg/m. 0.05 deg/m is 0.25 deg of heading over a 5 m leg between landmarks; at a steady
  // speed the filter's yaw-rate bias state takes up what is left. The simulated drives of
  // tests/calib_vehicle determine it to 0.04 deg/m (the odometry's yaw-rate noise over the
  // straight passes limits it).
  double max_sigma_yaw_per_metre_deg = 0.05;
  int max_iterations = 200;
  // Per-landmark noise and print deviation (top of this file); false = one solve with
  // pixel_sigma_px for every corner and the printed geometry taken as exact (clean floor).
  bool model_wear = true;
  // Floor of tau_L, mm: a clean print still deviates by a few micrometres, and a zero prior
  // would make the offsets' information matrix singular.
  double min_print_offset_mm = 0.002;
  // A landmark's residual stands out (warning) above residual_warn_ratio times the median of
  // the other landmarks' and above residual_warn_floor_px, or above residual_warn_px in any
  // case (reported worn prints: 0.59-0.92 px with a plain line fit, clean 0.09-0.14).
  double residual_warn_ratio = 2.5, residual_warn_floor_px = 0.1, residual_warn_px = 0.5;
};

// One frame's border edge points in undistorted normalised coordinates, per edge: [0] outer,
// [1] inner; side 0 is x = +h, 1 y = +h, 2 x = -h, 3 y = -h in the landmark frame.
struct BorderEdges {
  std::array<std::array<std::vector<Vec2>, 4>, 2> xn;
};

// The border corners of one frame (CornerObservation::xn, t_ns and landmark_id left as they are)
// from its edge points: one robust line per edge (vision::fit_line_robust with the vision
// stage's constants: RANSAC start, Tukey IRLS, scale floor), intersected. A scratch, a smudge or
// an occluder on part of an edge then gets weight 0 instead of pulling the line. fx_px turns the
// pixel-sized constants into normalised units. False when fewer than 3 corners result.
bool corners_from_edges(const BorderEdges& edges, double fx_px, CornerObservation* out);

struct ParamReport {
  std::string name;  // configuration-style name
  std::string unit;
  double initial = 0.0, value = 0.0, sigma = 0.0;  // in `unit`
  bool determined = false;
  std::string why;  // when not determined
};

struct PassReport {
  int index = 0;
  std::uint32_t landmark_id = 0;
  double t_start_s = 0.0, t_end_s = 0.0;  // relative to the first frame
  int frames = 0;
  double rms_before_px = 0.0, rms_after_px = 0.0;
};

// Per landmark: the corner residual after calibration with the printed geometry, the noise and
// print deviation the second solve modelled (see the top of this file).
struct LandmarkReport {
  std::uint32_t landmark_id = 0;
  int passes = 0, frames = 0;
  double rms_before_px = 0.0, rms_after_px = 0.0;
  double sigma_px = 0.0;         // corner noise used for its frames
  double print_offset_mm = 0.0;  // tau_L: RMS deviation of its corners from the printed square
  bool stands_out = false;       // named in a warning
};

struct Result {
  VehicleParams estimate;
  std::vector<ParamReport> params;  // ordered: mounting (6), odometry (4), time offset
  std::vector<PassReport> passes;
  std::vector<LandmarkReport> landmarks;  // by id
  std::vector<std::string> warnings;
  int frames_used = 0, subpasses = 0, iterations = 0;
  double rms_before_px = 0.0, rms_after_px = 0.0;
  bool turns_seen = false;

  // The report of the parameter named `name` (a key of docs/guide/config.md); throws
  // std::out_of_range for a name the calibration does not estimate.
  const ParamReport& param(const std::string& name) const {
    for (const ParamReport& p : params)
      if (p.name == name) return p;
    throw std::out_of_range("calibrate vehicle: no parameter " + name);
  }
};

// Least-squares rigid 2D fit V<-L of landmark-frame points `l` to their vehicle-frame images `v`
// (the same count); false with fewer than two.
bool fit_rigid(const std::vector<Vec2>& l, const std::vector<Vec2>& v, Pose2* v_from_l);

// False with *error naming what is missing (no odometry, no observation of a mapped landmark,
// too few passes, no frame inside the odometry span, solver failure).
bool calibrate_vehicle(const std::vector<OdomSample>& odom,
                       const std::vector<CornerObservation>& obs, const LandmarkMap& map,
                       double outer_half_mm, double inner_half_mm, const VehicleParams& initial,
                       const Options& opt, Result* out, std::string* error);

// Marks the landmarks whose rms_after_px stands out (Options::residual_warn_*: against the
// median of the other landmarks, or the absolute limit) and adds a warning naming each.
void flag_standing_out(const Options& opt, std::vector<LandmarkReport>* landmarks,
                       std::vector<std::string>* warnings);

// The filter's prior for one odometry calibration state after commissioning (a fusion.init_*
// key and its value in the key's unit).
struct FilterPrior {
  std::string key;
  double value = 0.0;
};
// Minimum prior per state: what can change between commissioning and a later start (tyre wear
// and load change a wheel's rolling radius by tenths of a percent; the yaw-rate bias and the
// per-metre term by a few hundredths of a degree). Below these the filter would refuse the
// fixes that show such a change.
inline constexpr double kMinPriorScale = 0.002;
inline constexpr double kMinPriorDegps = 0.05;
inline constexpr double kMinPriorDegpm = 0.05;
// fusion.init_{v_scale,omega_scale,omega_bias,omega_per_v}_sigma* for the odometry parameters
// the drive determined: `sigma_factor` times the calibration's sigma, at least the minimum
// above. Their defaults (3 %, 3 %, 1.5 deg/s, 1.5 deg/m) describe a vehicle nobody measured: on
// a commissioned one they make the heading sigma outgrow the error on the first leg after every
// start (lost while good, docs/guide/commissioning.md).
std::vector<FilterPrior> odometry_priors(const Result& r, double sigma_factor = 3.0);

// The per-landmark table of report.txt (Result::landmarks).
std::string landmark_table(const Result& r);

// Corners of the landmark in its own frame (the order of CornerObservation::xn).
std::array<Vec2, 8> landmark_corners(double outer_half_mm, double inner_half_mm);

}  // namespace agv::desk::vcal

// Vehicle pose from landmarks seen at a distance, without a prior: two landmarks by intersecting
// two range circles (the solution chosen by the image left/right order or by the bearing
// difference), three or more by linear trilateration (Cramer's rule on the differenced circle
// equations), then a Gauss-Newton weighted least squares over ranges and bearings that gives the
// covariance and a chi-square consistency check. Derivations and measured figures:
// docs/design/ranging.md.
#pragma once

#include <Eigen/Dense>
#include <limits>
#include <span>

#include "agv/common/geometry.hpp"

namespace agv::ranging {

// One landmark seen from the vehicle: its surveyed floor position in W, and the measured
// horizontal range and bearing from the vehicle reference point in V (RangeBearing), with their
// 2x2 covariance over (range_mm, bearing_rad). Optionally the landmark's face yaw: the direction
// in V of its face normal (RangeBearing::relative_yaw_rad, from a full tag pose) and its surveyed
// facing in W, which together say the heading (facing minus face yaw) and make a third residual.
// With two landmarks it is what checks the map: a wrong position of one landmark along the circle
// around the other turns the pose about that other landmark, which the ranges and bearings cannot
// see but the face yaws do.
struct Observation {
  Vec2 landmark_mm;
  double range_mm = 0.0;
  double bearing_rad = 0.0;
  Eigen::Matrix2d cov = Eigen::Matrix2d::Identity();
  bool has_face_yaw = false;
  double face_yaw_rad = 0.0;
  double face_yaw_var_rad2 = 0.0;
  // Covariance of the face yaw with (range_mm, bearing_rad): a tag pose's rotation and translation
  // share the corners' noise.
  Eigen::Vector2d face_yaw_cov = Eigen::Vector2d::Zero();
  double landmark_facing_rad = 0.0;
  // The share of the covariance over (range_mm, bearing_rad, face yaw) that every frame of this
  // landmark seen from the same place repeats (RangeBearing::systematic_cov): what averaging
  // frames cannot shrink. Zero where nothing is known of it.
  Eigen::Matrix3d systematic_cov = Eigen::Matrix3d::Zero();
  // How one error that every landmark of the frame shares moves this one's (range, bearing, face
  // yaw), 1 sigma per column: the lens's focal lengths, fx and fy (ranging::lens_response). cov
  // and systematic_cov hold lens_response lens_response^T, as if each landmark had its own error;
  // lens_cov_change makes it the one error it is. The face yaw's row is zero without one.
  Eigen::Matrix<double, 3, 2> lens_response = Eigen::Matrix<double, 3, 2>::Zero();
};

enum class FixStatus {
  kOk,
  kTooFew,           // fewer than two landmarks: one never fixes a pose
  kNoIntersection,   // two range circles miss each other by more than the noise allows
  kShallowGeometry,  // the circles cross (or the rays meet) at too small an angle
  kCollinear,        // three or more landmarks on (nearly) one line: the linear system is singular
  kAmbiguous,        // the two circle solutions cannot be told apart
  kInconsistent,     // the measurements do not fit any pose (chi-square over the gate): a wrong
                     // map entry or a misidentified landmark
  kUnverifiable,     // consistent, but a wrong map entry could hide in it: one landmark's map
                     // error that keeps chi-square under the gate could move the pose further
                     // than max_hidden_map_shift_sigma of its own covariance
};
const char* fix_status_name(FixStatus status);

struct FixOptions {
  // Smallest angle between the two range circles at the solution (equal to the angle the two
  // landmarks subtend there, or its supplement). The position error across the bisector grows as
  // 1 / sin(angle): 15 degrees amplifies the range noise about 3.9 times.
  double min_crossing_angle_rad = deg_to_rad(15.0);
  // Two landmarks both read with their face yaw (the tag's full pose) whose circles cross below
  // min_crossing_angle_rad: true seeds the least squares from the two single-landmark poses
  // instead of refusing, and leaves the geometry to the refinement's rank and max_position_sd_mm
  // checks (the face yaws constrain what the shallow circles do not). The position along the
  // bisector then rests on the face yaws, so their sigma must carry the lens's scale doubt
  // (ObserveOptions::focal_sigma_rel), which turns a face yaw alike in every frame; with it, on
  // rendered frames, shallow pairs initialise within 3 sigma (docs/design/ranging.md, "Switched
  // on"). false: refused as kShallowGeometry.
  bool face_yaw_pairs_below_crossing = true;
  // Circles that miss each other by less than this many standard deviations of the range sum
  // (or difference) are taken as touching: their one solution is the closest point.
  double intersection_gate_sigma = 3.0;
  // Landmarks are collinear when the normalised trilateration determinant (the sine of the angle
  // between the baselines, for three) is below this.
  double min_baseline_sine = 0.05;
  // A bearing-difference choice needs the runner-up to be this many sigma worse than the winner.
  double ambiguity_gate_sigma = 3.0;
  // Consistency gate: chi-square above its (Wilson-Hilferty) quantile for the standard normal
  // quantile chi2_gate_z (3.09: probability 0.999) refuses the fix.
  double chi2_gate_z = 3.09;
  int max_iterations = 20;
  // Covariance-size check after the refinement: a fix whose position standard deviation along
  // its worst axis exceeds this is refused as kShallowGeometry (the crossing angle alone does not
  // see range noise growing with the square of the distance). Off by default.
  double max_position_sd_mm = std::numeric_limits<double>::infinity();
  // Map check (refine_fix): the largest pose shift, in sigmas of the fix's own covariance, that a
  // wrong map position of any one landmark could cause while chi-square stays under its gate.
  // Fixes above it are kUnverifiable. Off by default: two landmarks without face yaws (one degree
  // of freedom) can never check the map (the figure is then 1e4 and more), with face yaws they
  // give hundreds to thousands, three or more give 10 to 200 on ordinary geometry; a finite value
  // such as 1000 therefore means "never from two landmarks without face yaws".
  double max_hidden_map_shift_sigma = std::numeric_limits<double>::infinity();
  // Landmarks that carry a lens response (Observation::lens_response, held in their cov): true
  // weighs them as a generalised least squares with the focal lengths' error as one error of the
  // frame, estimated with the pose under its unit prior and marginalised out of cov
  // (FixResult::lens_estimated); false weighs each landmark's share as its own, as if independent,
  // and leaves the common error to lens_cov_change.
  bool lens_in_weights = true;
};

struct FixResult {
  FixStatus status = FixStatus::kTooFew;
  Pose2 pose;                                     // V in W
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();  // over (x_mm, y_mm, theta_rad)
  double chi2 = 0.0;                              // weighted squared residuals at pose
  int dof = 0;                                    // 2 * landmarks + face yaws - 3
  int iterations = 0;                             // Gauss-Newton iterations taken
  bool touching = false;                          // two circles taken as touching
  double hidden_map_shift_sigma = 0.0;            // see FixOptions::max_hidden_map_shift_sigma
  // FixOptions::lens_in_weights took effect: cov holds the common lens error once, and
  // lens_error_sigma is its estimate, in sigmas of (fx, fy) (prior 0 +- 1).
  bool lens_estimated = false;
  Eigen::Vector2d lens_error_sigma = Eigen::Vector2d::Zero();
};

// Two circles: the solutions (up to two) of |p - c0| = r0, |p - c1| = r1. solutions[0] lies to
// the left of the directed line c0 -> c1, solutions[1] to its right. Circles missing each other
// by at most tolerance_mm are taken as touching (count 1, the closest point, touching true).
struct CircleCrossing {
  int count = 0;
  Vec2 solutions[2];
  bool touching = false;
};
CircleCrossing intersect_circles(Vec2 c0, double r0_mm, Vec2 c1, double r1_mm, double tolerance_mm);

// The image left/right rule for two landmarks seen in one forward image: if the landmark with the
// smaller x appears left of the other, the vehicle is at the lower (smaller y) solution, else the
// upper; for landmarks with equal x, the landmark with the larger y appearing on the left puts the
// vehicle at the left (smaller x) solution. Returns the index into crossing.solutions, or -1
// when the crossing has fewer than two solutions or the two are at the same height and column.
int choose_by_left_right(Vec2 l0, Vec2 l1, bool l0_left_of_l1, const CircleCrossing& crossing);

// The bearing-difference rule: each solution predicts the bearing difference bearing1 - bearing0
// (the mirror solution predicts its negative); the one nearer the observed difference wins if the
// other is ambiguity_gate_sigma sigmas worse. Bearings in V are comparable across cameras, which
// image columns are not. Returns the index, or -1 (ambiguous).
int choose_by_bearing_difference(Vec2 l0, Vec2 l1, double bearing_difference_rad,
                                 double sigma_difference_rad, const CircleCrossing& crossing,
                                 double gate_sigma);

// Heading from the bearing to one landmark seen from a known position: the direction to the
// landmark in W minus the bearing in V.
double heading_from_bearing_rad(Vec2 position_mm, Vec2 landmark_mm, double bearing_rad);
// From all: circular mean of the per-landmark headings, each weighted by the inverse of its
// variance (bearing variance plus the position uncertainty across the line of sight,
// position_sigma_mm / range).
double heading_from_bearings_rad(Vec2 position_mm, std::span<const Observation> obs,
                                 double position_sigma_mm);

// Linear trilateration from three or more ranges: subtract the first circle equation from the
// others and solve the 2x2 normal equations by determinants (exactly the three-landmark formula
// for three). kCollinear when the normalised determinant is below min_baseline_sine.
FixStatus trilaterate(std::span<const Observation> obs, const FixOptions& opt, Vec2* position_mm);

// Gauss-Newton weighted least squares over all ranges, bearings and face yaws from init (and the
// common lens error, FixOptions::lens_in_weights); fills pose, the covariance (J^T W J)^-1 of the
// pose, chi2, dof and iterations, and checks the chi-square gate.
FixResult refine_fix(std::span<const Observation> obs, const Pose2& init, const FixOptions& opt);

// The map check's figure for a pose with information matrix J^T W J and chi-square gate: the
// largest sqrt(pose NEES) over single-landmark map errors whose chi-square rise is the gate
// (Baarda's external reliability, per landmark, worst direction). A landmark's map error is its
// position, and its facing too where it has a face yaw. Infinite when some map error raises
// chi-square not at all.
double hidden_map_shift_sigma(std::span<const Observation> obs, const Pose2& pose,
                              const Eigen::Matrix3d& information, double gate);

// Chi-square at a given pose and its gate for dof degrees of freedom.
double fix_chi2(std::span<const Observation> obs, const Pose2& pose);
double chi2_gate(int dof, double z);

enum class TwoLandmarkRule { kLeftRight, kBearingDifference };

// Two landmarks without refinement: circle intersection, the rule's choice, heading from both
// bearings; cov by first-order propagation of the measurement covariance through that
// computation. l0_left_of_l1 is used by kLeftRight only.
FixResult fix_two_circles(const Observation& o0, const Observation& o1, TwoLandmarkRule rule,
                          bool l0_left_of_l1, const FixOptions& opt);

// The three-or-more-landmark fix without refinement: trilateration, heading from all bearings,
// cov by first-order propagation.
FixResult fix_trilateration(std::span<const Observation> obs, const FixOptions& opt);

// The fix to initialise from: one landmark: kTooFew; two: circles with the bearing-difference
// rule; three or more: trilateration, or for landmarks on (nearly) one line, such as one rack
// face, the widest pair's circles with the bearing-difference rule; then refine_fix. Geometry and
// consistency refusals keep the status and leave the pose unset.
FixResult fix_from_landmarks(std::span<const Observation> obs, const FixOptions& opt);

// A fix's covariance grown by an error that every bearing and face yaw of its landmarks shares
// (the camera's yaw calibration, the principal point's column): the fix's first-order response
// to one such offset, times sigma_common_rad, added as a rank-one term. obs are the fix's own
// inputs; nothing is added for a sigma of 0.
void add_mount_yaw_uncertainty(std::span<const Observation> obs, double sigma_common_rad,
                               FixResult* fix);

// The share of an OK fix's covariance that its observations' systematic_cov make: the weighted
// least squares' first-order response to them (cov J^T W per landmark). A fix of the same
// landmarks from the same place in another frame repeats it; the rest of cov is that frame's own.
// obs are the fix's own inputs and fix as fix_from_landmarks returned it (before
// add_mount_yaw_uncertainty); zero when none carries a systematic share.
Eigen::Matrix3d fix_systematic_cov(std::span<const Observation> obs, const FixResult& fix);

// What an OK fix's covariance (and its systematic share alike) must change by when the lens's
// error (Observation::lens_response) is one error shared by all landmarks and the fix weighed it
// per landmark (zero for a fix with lens_estimated, whose cov holds it already): per column the
// fix's first-order response to it as a rank-one term, less the per-landmark shares the least
// squares averaged down as if independent. A focal length off scales the whole view: landmarks on
// one side of the vehicle (a forward camera) then leave it almost whole in the position, along
// their mean direction; where the bearings fix the position and the ranges disagree with them, it
// is mostly residual and the change is negative. Symmetric, not always PSD; fix.cov plus it is. obs
// and fix as for fix_systematic_cov; zero when no observation carries a lens response.
Eigen::Matrix3d lens_cov_change(std::span<const Observation> obs, const FixResult& fix);

}  // namespace agv::ranging

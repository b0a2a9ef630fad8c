// Pose of a ceiling camera in the site frame from tag36h11 tags lying at surveyed positions
// (docs/guide/site.md, "Calibrating the ceiling cameras"). The intrinsics are known and held
// fixed; the six pose parameters are solved by PnP on every tag corner, then refined by robust
// least squares (Ceres) with a covariance per parameter.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <opencv2/core.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/geometry.hpp"
#include "agv/common/landmark.hpp"
#include "agv/site/site.hpp"

namespace agv::desk::ccal {

// A tag lying flat (page facing up) at a surveyed position: centre of its black square at
// (x, y, z) in the site frame, its page "up" along yaw_rad (counter-clockwise from site +x),
// size_mm the black square's side. A fleet tray tag is one: the vehicle's pose, tray height,
// yaw = the vehicle's heading.
struct SurveyedTag {
  std::uint32_t id = 0;
  double x_mm = 0.0, y_mm = 0.0, z_mm = 0.0;
  double yaw_rad = 0.0;
  double size_mm = 160.0;
};

// The black square's corners in the site frame, page order: top-left, top-right, bottom-right,
// bottom-left (seen from above, page right is yaw - 90 degrees).
std::array<std::array<double, 3>, 4> tag_corners_site(const SurveyedTag& t);

// Survey CSV: header "id,x_mm,y_mm,z_mm,yaw_deg,size_mm", one tag per line, '#' comments and
// blank lines ignored. False with *error ("line N: reason") on a bad header, field, range
// (id 0..586, size 10..5000 mm, finite coordinates within 10 km, yaw -360..360) or duplicate id.
bool parse_survey_csv(std::string_view text, std::map<std::uint32_t, SurveyedTag>* out,
                      std::string* error);
// The site's floor-landmark map read as tag36h11 tags of one size lying on the floor (z = 0),
// their heading the page's "up".
std::map<std::uint32_t, SurveyedTag> survey_from_floor_map(const LandmarkMap& map, double size_mm);

// One tag seen in one frame: corners in page order (as tag_corners_site), distorted pixels.
struct TagSighting {
  int frame = 0;
  std::uint32_t id = 0;
  std::array<Vec2, 4> corners_px{};
  double decision_margin = 0.0;
};

// tag36h11 tags of a gray frame: libapriltag at full resolution with its edge refinement (a line
// fitted along each side of the quad, the corners their intersections), at most 1 corrected bit,
// shifted to pixel centres at integers. Tags whose black square is under 12 px a side are not
// used (their corners are not reliable). On rendered 1280x720 frames with 50 px tags these corners
// were 0.075 px RMS from the truth; cv::cornerSubPix on top made them worse (0.2 px: the window
// of a convex corner of a blurred square sees the rounded corner and the data cells).
std::vector<TagSighting> detect_tags(const cv::Mat& gray, int frame);

// Camera pose as the site file's angles (agv/site/site_geometry.hpp): optical centre and
// yaw, pitch, roll of R_site_cam = Rz(yaw) * diag(1, -1, -1) * Rx(pitch) * Ry(roll).
struct CameraPose {
  double x_mm = 0.0, y_mm = 0.0, z_mm = 0.0;
  double yaw_rad = 0.0, pitch_rad = 0.0, roll_rad = 0.0;
};
CameraPose pose_of(const site::CeilingCamera& cam);
void set_pose(const CameraPose& p, site::CeilingCamera* cam);

// Site point -> distorted pixel through the intrinsics and pose. False behind the camera.
bool project(const CameraIntrinsics& k, const CameraPose& pose, const std::array<double, 3>& p,
             Vec2* px);

// Residuals of one tag under a pose: reprojection of its corners and where its observed centre
// (the intersection of the observed, undistorted diagonals, averaged over its sightings) meets
// the tag's plane z = z_mm, against the surveyed centre.
struct TagResidual {
  std::uint32_t id = 0;
  int sightings = 0;
  double rms_px = 0.0;       // corner reprojection RMS (pixel distance)
  double floor_dx_mm = 0.0;  // seen - surveyed
  double floor_dy_mm = 0.0;
  double floor_mm = 0.0;  // hypot of the two; NaN when the centre ray misses the plane
};
struct Evaluation {
  int corners = 0;
  double rms_px = 0.0;  // over every corner of every surveyed sighting
  double max_px = 0.0;
  double max_floor_mm = 0.0;  // NaN when a tag's centre ray misses its plane
  // Per axis, the tags' floor residuals' RMS over their degrees of freedom (2 per tag less the
  // pose's 6): what a point between the tags is off beyond the pose's sigma (the lens's residual
  // error, the survey's); written as pose_sigma.floor_mm. 0 with 3 tags or fewer.
  double floor_sigma_mm = 0.0;
  std::vector<TagResidual> tags;  // by id
};
Evaluation evaluate(const CameraIntrinsics& k, const std::map<std::uint32_t, SurveyedTag>& survey,
                    const std::vector<TagSighting>& sightings, const CameraPose& pose);

// Named failures of the pose solve.
enum class Error : std::uint8_t {
  kNone,
  kTooFewTags,   // fewer than min_tags surveyed tags seen
  kDegenerate,   // the tags' centres lie (nearly) on one line
  kSolveFailed,  // PnP or the refinement did not converge, or the build has no Ceres
};
const char* to_string(Error e);  // "too-few-tags", ...

struct Options {
  // Huber loss scale on the corner residual (px): corners further off count linearly.
  double robust_px = 1.0;
  // Two tags always lie on a line, so three is the least that fixes the pose well.
  int min_tags = 3;
  // Degenerate when the centres' spread across their main line (RMS) is under this share of the
  // spread along it, or under one tag side.
  double min_cross_spread = 0.05;
  // A tag whose corner RMS exceeds both reject_min_px and reject_ratio times the median tag's
  // is left out and the pose solved again (one at a time, while at least min_tags not on one
  // line remain): surveyed wrong, or moved since.
  double reject_min_px = 1.0;
  double reject_ratio = 5.0;
  // Start of the refinement; null: PnP on every corner (SQPnP).
  const CameraPose* initial = nullptr;
};

struct Result {
  Error error = Error::kNone;
  std::string message;  // why, for a failure
  CameraPose pose;
  // 1-sigma of x, y, z (mm) and roll, pitch, yaw (rad): the Ceres covariance scaled by the
  // corner residuals' variance, or from the residuals' spread between tags where that is larger
  // (a survey error is common to a tag's corners). NaN when the covariance is singular.
  std::array<double, 6> sigma{};
  // Their correlation coefficients in site::CeilingCamera::pose_correlation's order.
  std::array<double, 15> correlation{};
  double residual_sigma_px = 0.0;  // per coordinate, from the residuals
  int tags_used = 0;
  int corners_used = 0;
  std::vector<std::uint32_t> unsurveyed_ids;  // seen but not in the survey (ignored)
  std::vector<std::uint32_t> rejected_ids;    // surveyed, seen, left out (Options::reject_*)
  // At the solved pose: corners, rms_px, max_px and max_floor_mm over the tags used; tags lists
  // every surveyed tag seen, the rejected ones too.
  Evaluation eval;
};
Result solve_camera_pose(const CameraIntrinsics& k,
                         const std::map<std::uint32_t, SurveyedTag>& survey,
                         const std::vector<TagSighting>& sightings, const Options& opt = {});

}  // namespace agv::desk::ccal

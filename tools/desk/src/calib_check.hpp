// agvloc-desk calibrate check: the parked-vehicle check of the camera calibration with one printed
// landmark at a taped pose (docs/guide/commissioning.md, docs/guide/camera.md). Pure: frames, taped
// poses and the configuration in, deviations and findings out (file handling:
// cmd_calibrate_check.cpp).
//
// Model (docs/design/frames.md): with the configured mounting (offset o_c, yaw psi_c, height h_c)
// and the true one (o_t, psi_t, h_t), the vision stage measures a floor point p of the vehicle
// frame at
//   p' = o_c + s R(dpsi) (p - o_t),   s = h_c / h_t,   dpsi = psi_c - psi_t,
// and the landmark's heading dpsi too large and its size s times the printed size. So the heading
// difference gives the yaw, the measured size the height (or fx, or a print not at 100 %), and
// what is left of the position difference the offset. Anything else (the implied offset or scale
// changing with the landmark's place in the image, edges that are not straight) points to the
// intrinsics/distortion; a spread over frames of one placement to focus, blur or vibration.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/landmark.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace cv {
class Mat;
}

namespace agv::desk::calib {

// Acceptance limits. Defaults: docs/guide/camera.md's "agreement within ~1 mm and ~0.2 deg" for the
// taped pose (a tape gives about +-1 mm / +-0.5 deg, so tighter limits test the tape), the
// others from simulated frames of a correct calibration (docs/guide/commissioning.md).
struct Tolerances {
  double position_mm = 1.0;   // measured vs taped landmark position, and the implied offset
  double heading_deg = 0.2;   // measured vs taped landmark heading (= mounting yaw error)
  double height_mm = 0.5;     // height implied by the measured landmark size vs configured
  double spread_mm = 0.05;    // standard deviation of the position over frames of one placement
  double residual_mm = 0.05;  // rms distance of the edge points from the fitted square
};

// A frame in memory (image), or one read when the check reaches it (load; the image is dropped
// after its fix, so a check over thousands of frames holds one decoded frame at a time).
struct FrameInput {
  std::string name;  // for messages (file name)
  const cv::Mat* image = nullptr;
  std::function<bool(cv::Mat*, std::string*)> load = nullptr;  // used when image is null
};

// One placement of the landmark: its taped pose and the frames taken of it. The taped pose is
// either the landmark in the vehicle frame (V<-L), or the vehicle in the world (W<-V), in which
// case the landmark's world pose comes from the map entry of the id the fix reads.
struct PlacementInput {
  bool taped_is_vehicle_in_world = false;
  Pose2 taped;
  std::vector<FrameInput> frames;
};

struct FrameResult {
  std::string name;
  vision::LandmarkFix fix;
};

struct PlacementResult {
  Pose2 taped_landmark_in_vehicle;
  Pose2 measured_landmark_in_vehicle;  // mean over the frames with a fix
  std::uint32_t landmark_id = 0;
  int frames_total = 0, frames_ok = 0;
  double dx_mm = 0, dy_mm = 0, dheading_deg = 0;  // measured - taped (vehicle frame)
  double spread_mm = 0, spread_deg = 0;           // std over frames (0 with one frame)
  double outer_side_mm = 0, border_width_mm = 0;  // measured (0 when the fix had no size)
  double scale = 0;                               // measured / printed (midline square); 0 unknown
  double residual_rms_mm = 0;                     // mean of the fixes'
  Vec2 implied_offset_mm{};                       // o_t from this placement
  double implied_height_mm = 0;                   // h_c / scale (0 unknown)
  std::vector<FrameResult> frames;
};

enum class Cause { kPose, kYaw, kHeight, kOffset, kDistortion, kFocus };
const char* to_string(Cause c);

struct Finding {
  Cause cause;
  bool ok = true;
  double value = 0;      // the measured deviation in the unit of the message
  double tolerance = 0;  // its limit
  std::string message;   // one line: what was measured, what it points to, the corrected value
};

struct CheckResult {
  std::vector<PlacementResult> placements;
  // Recovered mounting (from all placements): what the configuration should say.
  double yaw_deg = 0, height_mm = 0, offset_x_mm = 0, offset_y_mm = 0;
  bool height_known = false;
  // The placements disagree (position-dependent error): the recovered mounting assumes a correct
  // lens model and is not to be trusted until the intrinsics are recalibrated.
  bool lens_suspect = false;
  std::vector<Finding> findings;
  bool within_tolerance() const;
};

// Runs the vision stage on every frame and evaluates. False with *error on bad input: no frames,
// a frame of the wrong size or type, a frame without a landmark fix (with the vision status), a
// placement whose frames show different landmarks, a world-taped placement whose landmark is not
// in the map (or no map). printed_size_mm is the outer side of the print as measured with
// calipers (the configuration's landmark.size_mm when the print is exact).
bool run_check(const CameraModel& camera, const vision::VisionConfig& vision_config,
               double printed_size_mm, const LandmarkMap* map,
               const std::vector<PlacementInput>& placements, const Tolerances& tol,
               CheckResult* out, std::string* error);

// A taped pose as written on the command line or in a placements CSV: X_MM,Y_MM,HEADING_DEG,
// finite. False on anything else (a trailing character, a missing field).
bool parse_pose(const std::string& text, Pose2* out);

// The placements of a --placements CSV: one per distinct pose text, in order of first appearance,
// with the frame paths as written (a relative path is relative to the CSV: the caller resolves
// it).
struct PlacementRows {
  Pose2 taped;
  std::vector<std::string> frames;
};
// Parses a --placements CSV text: the header `frame,x_mm,y_mm,heading_deg` first, then one
// `FRAME,X,Y,DEG` row per frame; blank and '#' lines skipped, CRLF accepted. False with *error
// "name:line: what" on a bad header or row, a NUL byte, a control character in a frame path,
// or no row. Pure (text in): the fuzzed
// surface (fuzz/fuzz_placements.cpp).
bool parse_placements_csv(const std::string& text, const std::string& name,
                          std::vector<PlacementRows>* out, std::string* error);

// Human-readable report (deviations per placement, findings, the suggested mounting lines).
std::string format_report(const CameraModel& camera, const CheckResult& r);

}  // namespace agv::desk::calib

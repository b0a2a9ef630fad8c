// Checks of the tray fit's inputs and its error text (tray_fit_input.hpp).
#include "tray_fit_input.hpp"

#include <cmath>
#include <cstdio>

namespace agv::overhead {

const char* to_string(TrayRefusal r) {
  switch (r) {
    case TrayRefusal::kNone:
      return "none";
    case TrayRefusal::kBadInput:
      return "bad_input";
    case TrayRefusal::kUncertain:
      return "uncertain_prediction";
    case TrayRefusal::kOutOfView:
      return "out_of_view";
    case TrayRefusal::kNoOutline:
      return "no_outline";
    case TrayRefusal::kSidesHidden:
      return "sides_hidden";
    case TrayRefusal::kSizeMismatch:
      return "size_mismatch";
    case TrayRefusal::kAmbiguous:
      return "ambiguous_heading";
  }
  return "unknown";
}

}  // namespace agv::overhead

namespace agv::overhead::tray_fit_detail {

bool fail(std::string* why, const std::string& msg) {
  if (why) *why = msg;
  return false;
}

std::string fmt(const char* f, double a, double b) {
  char buf[160];
  std::snprintf(buf, sizeof buf, f, a, b);
  return buf;
}

bool check_input(const cv::Mat& gray, const site::CeilingCamera& cam, const site::FleetAgv& agv,
                 const Pose2& predicted, const std::array<double, 9>& cov, const TrayFitParams& p,
                 std::string* why) {
  if (const std::string e = validate(p); !e.empty()) return fail(why, "tray fit parameters: " + e);
  if (gray.empty() || gray.type() != CV_8UC1 || gray.cols != cam.intrinsics.width_px ||
      gray.rows != cam.intrinsics.height_px || gray.cols < 3 || gray.rows < 3) {
    return fail(why, "image is not 8-bit gray of the camera's size");
  }
  const double sizes[3] = {agv.tray_length_mm, agv.tray_width_mm, agv.tray_height_mm};
  if (!(sizes[0] > 0.0 && sizes[1] > 0.0) || !std::isfinite(sizes[0]) || !std::isfinite(sizes[1]) ||
      !std::isfinite(sizes[2])) {
    return fail(why, "vehicle " + agv.id + ": tray size is not positive and finite");
  }
  if (!std::isfinite(predicted.x_mm) || !std::isfinite(predicted.y_mm) ||
      !std::isfinite(predicted.theta_rad)) {
    return fail(why, "predicted pose is not finite");
  }
  for (const double v : cov) {
    if (!std::isfinite(v)) return fail(why, "predicted covariance is not finite");
  }
  if (!(cov[0] > 0.0 && cov[4] > 0.0 && cov[8] > 0.0 && cov[0] * cov[4] > cov[1] * cov[3])) {
    return fail(why, "predicted covariance is not positive definite");
  }
  return true;
}

}  // namespace agv::overhead::tray_fit_detail

// Stages of the tray fit (tray_fit.hpp), shared by its two sources and reachable from tests.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/overhead/tray_fit.hpp"

namespace agv::overhead::tray_fit_detail {

// An edge pixel carried onto the tray plane: position relative to the predicted centre (mm) and
// the direction of its gradient's axis on the plane, in [0, pi).
struct PlaneEdge {
  Vec2 q;
  double axis_rad = 0.0;
  Vec2 axis2;  // (cos, sin) of twice axis_rad: axes compared without wrapping angles
};

struct TrayWindow {
  cv::Rect roi;            // pixels searched, inside the image
  double mm_per_px = 0.0;  // the plane's scale at the prediction
  double reach_mm = 0.0;   // the centre is searched this far from the prediction along each axis
};

// The image window that holds the predicted tray in every pose within the prediction's
// sigma_window sigma; false with *why when it cannot be projected or misses the image.
bool tray_window(const site::CeilingCamera& cam, const site::FleetAgv& agv, const Pose2& predicted,
                 double sigma_pos_mm, double sigma_theta_rad, const TrayFitParams& p,
                 TrayWindow* out, std::string* why);

// Edge pixels of the window (gradient at least p.min_gradient, the local maximum along their
// gradient, placed to a sub-pixel by a parabola through the magnitudes) on the tray plane.
void plane_edges(const cv::Mat& gray, const site::CeilingCamera& cam, const site::FleetAgv& agv,
                 const Pose2& predicted, const TrayWindow& win, const TrayFitParams& p,
                 std::vector<PlaneEdge>* out);

}  // namespace agv::overhead::tray_fit_detail

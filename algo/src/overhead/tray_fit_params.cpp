// The tray fit's parameter check (tray_fit.hpp).
#include <cmath>
#include <string>

#include "agv/overhead/tray_fit.hpp"

namespace agv::overhead {

std::string validate(const TrayFitParams& p) {
  if (!(p.min_gradient > 0.0) || !std::isfinite(p.min_gradient)) return "min_gradient must be > 0";
  if (!(p.sigma_window >= 1.0) || !std::isfinite(p.sigma_window))
    return "sigma_window must be >= 1";
  if (!(p.margin_mm >= 0.0) || !std::isfinite(p.margin_mm)) return "margin_mm must be >= 0";
  if (!(p.max_position_sigma_mm > 0.0) || !std::isfinite(p.max_position_sigma_mm)) {
    return "max_position_sigma_mm must be > 0";
  }
  if (!(p.class_tol_rad > 0.0 && p.class_tol_rad < 0.25 * kPi)) {
    return "class_tol_rad must be in (0, pi/4)";
  }
  if (!(p.min_side_coverage > 0.0 && p.min_side_coverage <= 1.0)) {
    return "min_side_coverage must be in (0, 1]";
  }
  if (!(p.on_line_px > 0.0) || !std::isfinite(p.on_line_px)) return "on_line_px must be > 0";
  if (!(p.rim_depth_mm >= 0.0) || !std::isfinite(p.rim_depth_mm))
    return "rim_depth_mm must be >= 0";
  if (!(p.max_size_error_mm > 0.0) || !(p.max_size_error_px > 0.0) ||
      !std::isfinite(p.max_size_error_mm) || !std::isfinite(p.max_size_error_px)) {
    return "max_size_error_mm and max_size_error_px must be > 0";
  }
  if (!(p.edge_correlation >= 1.0) || !std::isfinite(p.edge_correlation)) {
    return "edge_correlation must be >= 1";
  }
  if (!(p.side_offset_sigma_px >= 0.0) || !std::isfinite(p.side_offset_sigma_px)) {
    return "side_offset_sigma_px must be >= 0";
  }
  if (!(p.side_offset_bias_share >= 0.0 && p.side_offset_bias_share <= 1.0)) {
    return "side_offset_bias_share must be in [0, 1]";
  }
  if (p.min_sides_seen < 2 || p.min_sides_seen > 4) return "min_sides_seen must be in 2..4";
  if (p.iterations < 1 || p.iterations > 100) return "iterations must be in 1..100";
  return "";
}

}  // namespace agv::overhead

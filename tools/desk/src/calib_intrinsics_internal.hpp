// Shared by the intrinsics calibration's files (calib_intrinsics.hpp): calib_intrinsics_board.cpp
// (the board), calib_intrinsics_detect.cpp (corners and blur), calib_intrinsics.cpp (the solve),
// calib_intrinsics_report.cpp (the texts and pictures).
#pragma once

#include <cstdio>
#include <string>

#if AGV_HAVE_ARUCO
#include <opencv2/aruco/charuco.hpp>
#endif

#include "calib_intrinsics.hpp"

namespace agv::desk::calib::detail {

inline std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

#if AGV_HAVE_ARUCO
// The OpenCV board of the spec: null with *error for an unknown dictionary or one with fewer
// markers than the board needs.
cv::Ptr<cv::aruco::CharucoBoard> charuco_board(const BoardSpec& s, std::string* error);
#endif

inline constexpr const char* kNoAruco =
    "this build has no OpenCV aruco module (Debian libopencv-contrib-dev), so no ChArUco "
    "boards: use --board chessboard or rebuild with libopencv-contrib-dev";

}  // namespace agv::desk::calib::detail

// The tray fit's input checks and error text, shared by its sources.
#pragma once

#include <array>
#include <opencv2/core.hpp>
#include <string>

#include "agv/overhead/tray_fit.hpp"

namespace agv::overhead::tray_fit_detail {

// Sets *why (when given) to msg; returns false.
bool fail(std::string* why, const std::string& msg);

// printf-style text with up to two numbers.
std::string fmt(const char* f, double a, double b = 0.0);

// false with *why when the parameters, the image, the vehicle's tray or the prediction are unfit.
bool check_input(const cv::Mat& gray, const site::CeilingCamera& cam, const site::FleetAgv& agv,
                 const Pose2& predicted, const std::array<double, 9>& cov, const TrayFitParams& p,
                 std::string* why);

}  // namespace agv::overhead::tray_fit_detail

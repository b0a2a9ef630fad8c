// Private to algo/src/vision: LandmarkLocalizer's composition of the stages (numbers:
// docs/design/vision.md "Pipeline"). Each stage is an object that owns its scratch storage and
// reads the configuration through a const VisionSetup (stage_common.hpp), so what a stage takes
// from another shows in its arguments:
//   CornerDetector     1-2  corner_detector.hpp: detect.cpp (full search), track_detect.cpp
//   PredictedDetector  1-2  predicted_detector.hpp: predicted_detect.cpp, edge_probe.cpp
//   SquareFit          3, 6 square_fit.hpp: pose.cpp, covariance.cpp
//   DirectionStage     4-5  direction_stage.hpp: direction.cpp
//   CodeReader         5    code_reader.hpp: qr_decode.cpp
//   CodeCache               code_cache.hpp: code_cache.cpp (mapped codes, verified read's book)
//   MapIdentityStage   5c   map_identity_stage.hpp: map_identity_stage.cpp
//   TagReader          tag  tag_reader.hpp: tag_reader.cpp (libapriltag, cells, side checks)
// The composition itself: landmark_localizer.cpp (run, locate, identify, the public class),
// apriltag.cpp (the tag family) and overlay.cpp. Impl keeps, besides the stages, only what spans
// them: the window planner and the storage of a frame's windows, and the overlay's turn.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/geometry.hpp"
#include "agv/common/landmark.hpp"
#include "agv/vision/bilinear.hpp"
#include "agv/vision/edges.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "agv/vision/map_identity.hpp"
#include "agv/vision/qr_grid.hpp"
#include "agv/vision/tracking.hpp"
#include "code_cache.hpp"
#include "code_reader.hpp"
#include "corner_detector.hpp"
#include "direction_stage.hpp"
#include "map_identity_stage.hpp"
#include "predicted_detector.hpp"
#include "square_fit.hpp"
#include "stage_common.hpp"
#include "tag_reader.hpp"

namespace agv::vision {

// One frame's inputs, passed explicitly through the composition: the image, the filter's
// prediction, the frame's start (timings) and the tracking windows planned from the prediction
// (storage kept by the localizer, so that a frame allocates nothing).
struct Frame {
  const cv::Mat& img;
  const Prediction& pred;
  double t0_ms = 0.0;
  std::vector<SearchWindow>& windows;
};

struct LandmarkLocalizer::Impl : VisionSetup {
  // Kept for the overlay: the fitted square's pixels are SquareFit's.
  bool have_overlay = false;
  int quadrant = 0;

  // Tracking (docs/design/tracking.md): the planner, and the storage of a frame's windows.
  WindowPlanner planner;
  std::vector<SearchWindow> window_storage;

  Impl(const VisionConfig& c, const CameraModel& m, const LandmarkGeometry& g,
       const LandmarkMap* mp);

  // run(): the stages in order (landmark_localizer.cpp): locate (detection and pose), then
  // identify (logo, code, identity, direction and result).
  FixStatus run(const cv::Mat& img, const Prediction& pred, LandmarkFix* out);
  FixStatus locate(const Frame& f, LandmarkFix* out, Detection* det, Vec2* c_mm, double* beta,
                   Eigen::Matrix3d* cov);
  FixStatus identify(const Frame& f, const Detection& det, Vec2 c_mm, double beta,
                     const Eigen::Matrix3d& cov, LandmarkFix* out);
  FixStatus measure(const cv::Mat& img, const Detection& det, double corner_score, double t0,
                    LandmarkFix* out, Vec2* c_mm, double* beta, Eigen::Matrix3d* cov);
  void fill_result(const Pose2& world_landmark, Vec2 c_mm, double beta, int q_final,
                   const Eigen::Matrix3d& cov, LandmarkFix* out) const;

  // Tag family: detection and id by libapriltag, pose by SquareFit (apriltag.cpp).
  FixStatus run_tag(Frame& f, LandmarkFix* out);
  FixStatus tag_from_detector(const cv::Mat& img, LandmarkFix* out);
  FixStatus tag_from_prediction(const Frame& f, LandmarkFix* out);
  FixStatus tag_from_corners(const cv::Mat& img, double t0_ms, LandmarkFix* out);

  // Stages 4 and 5a: the logo and the code read, composed (landmark_localizer.cpp).
  int logo_and_code(const Frame& f, Vec2 c_px, double up, Vec2 c_mm, double beta, LogoScores* logo,
                    double* logo_ms, QrRead* rd, LandmarkFix* out);

  // The stages that own their state (built after the members they reference).
  CornerDetector corners{*this};
  SquareFit square{*this};
  PredictedDetector predicted{*this, square};
  TagReader tags{*this, square};
  DirectionStage direction{*this};
  CodeCache codes{*this, planner.index()};
  CodeReader code_reader{*this, codes};
  MapIdentityStage identity{*this, planner.index(), codes, code_reader};
};

}  // namespace agv::vision

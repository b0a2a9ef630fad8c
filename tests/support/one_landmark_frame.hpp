// A rendered frame of the default 640x480 camera over landmark 17 alone: the map holding it at
// `landmark` (world) and the vehicle at `e` in the landmark's frame, rendered with `o` and
// seed 5. For the vision tests that check one fix against the truth.
#pragma once

#include <opencv2/core.hpp>
#include <random>
#include <string>

#include "agv/common/camera_model.hpp"
#include "agv/common/landmark.hpp"
#include "agv/sim/render.hpp"

namespace agv::testsupport {

struct OneLandmarkFrame {
  LandmarkMap map;
  CameraModel cam = CameraModel::default_640x480();
  cv::Mat img;
};

// False with *error when the scene cannot be made.
inline bool render_one_landmark(const Pose2& landmark, const Pose2& e, const sim::RenderOptions& o,
                                OneLandmarkFrame* out, std::string* error) {
  out->map.entries[17] = {17, landmark};
  sim::Scene scene;
  if (!sim::make_scene(out->map, LandmarkGeometry{}, sim::PayloadMode::kFull, &scene, error)) {
    return false;
  }
  std::mt19937_64 rng(5);
  out->img = sim::render_frame(scene, out->cam, compose(landmark, e), o, rng);
  return true;
}

}  // namespace agv::testsupport

// eval_vision internals shared by its files: frames with ground truth, statistics, the table
// rows, and the parts of the run that live in eval_vision_extra.cpp.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <opencv2/core.hpp>
#include <random>
#include <string>
#include <vector>

#include "agv/sim/render.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace eval_vision {

using namespace agv;
using namespace agv::vision;

std::int64_t now_ns();
double pct(std::vector<double> v, double p);

struct Frame {
  cv::Mat img;
  Pose2 e_true;  // vehicle in landmark frame
  Pose2 vehicle_world;
};

// Landmark at a fixed world pose; the vehicle pose is sampled in the landmark frame.
inline const Pose2 kLandmarkWorld{1000.0, -2000.0, deg_to_rad(90.0)};
inline constexpr std::uint32_t kId = 17;

struct Condition {
  std::string name;
  std::function<void(std::mt19937_64&, sim::RenderOptions*)> options;
  bool distorted_camera = false;
  bool want_full = true;
};

struct Stats {
  int n = 0, ok = 0, wrong_direction = 0;
  int qr_guided = 0, qr_search = 0;  // frames whose QR was read by each method
  std::map<FixStatus, int> status;
  std::vector<double> pos_err, head_err, world_err;
  std::vector<double> t_detect, t_decode, t_direction, t_pose, t_total;
  std::vector<double> nees;
};

extern std::string g_dump_dir;  // --dump: failed frames are written here

void evaluate(LandmarkLocalizer& loc, const std::vector<Frame>& frames, Stats* s,
              const std::string& tag = "");
void print_header();
void print_row(const std::string& name, const Stats& s);
std::vector<Frame> render_set(const sim::Scene& scene, const CameraModel& cam, const Condition& c,
                              int n, std::uint64_t seed);

// What every part of one run shares.
struct Setup {
  CameraModel cam, cam_dist;  // the profile's camera, and the same through a distorted lens
  LandmarkGeometry geom;
  LandmarkMap map;
  sim::Scene scene;
  VisionConfig cfg;
};

// AprilTag 3 on the clean frames with a tag painted in, against this pipeline (best of 3 each);
// nothing without AGV_HAVE_APRILTAG.
void run_apriltag(const Setup& su, const std::vector<Frame>& clean_frames, LandmarkLocalizer& loc,
                  const Stats& s, double ours_ms, std::uint64_t seed);
// Each row adds one change to the paper baseline, on the clean and the combined frames.
void run_ablation(const Setup& su, const std::vector<Frame>& clean_frames,
                  const std::vector<Frame>& combined_frames);

// The speed target: ours (QR, full search) at least 5x faster than AprilTag d2 on the same
// frames (eval_vision_tag.cpp, docs/design/performance.md).
void run_speed_compare(const Setup& su, const std::vector<Frame>& qr_frames,
                       const sim::Scene& tag_scene);

}  // namespace eval_vision

// A short rendered tag36h11 recording for the tests of the no-fix diagnosis (agvloc replay and
// agvloc-desk calibrate vehicle): the vehicle standing over tag 7 (world (2000, 1000), -90 deg)
// for kTagFrames frames 100 ms apart, taken by `truth_camera` (another camera height than the
// meta's: a mis-measured mount), standing odometry at 100 Hz, and map.csv holding `map_csv`.
// Header-only: the test programs that use it link agv_sim and agv_replay already.
#pragma once

#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "agv/recording/recording.hpp"
#include "agv/sim/render.hpp"

namespace agv::testsupport {

inline constexpr int kTagFrames = 5;
inline const Pose2 kTagWorld{2000.0, 1000.0, deg_to_rad(-90.0)};
// Where the vehicle stands in every frame.
inline Pose2 tag_recording_vehicle() { return compose(kTagWorld, {5.0, -3.0, deg_to_rad(30.0)}); }

inline bool write_tag_recording(const std::filesystem::path& d, const recording::Meta& m,
                                const CameraModel& truth_camera, const std::string& map_csv,
                                std::string* err) {
  if (!recording::write_meta(d.string(), m, err)) return false;
  LandmarkMap map;
  map.entries[7] = {7, kTagWorld};
  std::ofstream(d / "map.csv", std::ios::trunc) << map_csv;
  sim::Scene scene;
  if (!sim::make_tag_scene(map, AprilTagGeometry{}, &scene, err)) return false;
  std::mt19937_64 rng(5);
  const sim::FrameRenderer r(scene, truth_camera);
  const Pose2 vehicle = tag_recording_vehicle();
  std::vector<recording::FrameRow> frames;
  for (int i = 0; i < kTagFrames; ++i) {
    const std::string f = "frames/" + std::to_string(i) + ".png";
    if (!recording::write_frame_png(d.string(), f, r.render(vehicle, sim::realistic_options(), rng),
                                    err)) {
      return false;
    }
    frames.push_back({1'000'000'000LL + i * 100'000'000LL, f});
  }
  if (!recording::write_frames_csv(d.string(), frames, err)) return false;
  std::vector<recording::OdomRow> odom;
  for (int i = 0; i <= kTagFrames * 10; ++i)
    odom.push_back({1'000'000'000LL + i * 10'000'000LL, 0, 0});
  return recording::write_odom_csv(d.string(), odom, err);
}

}  // namespace agv::testsupport

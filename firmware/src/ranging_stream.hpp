// The second camera (ranging_camera.*, docs/design/ranging.md): the site's landmarks on racks read
// in each of its frames (ranging::LandmarkObserver, in windows from the core's pose when it
// tracks), each landmark turned into the core's input (localizer::RackObservation), handed to the
// output step through a fixed ring like the floor fixes; and the recording's `ranging/` stream
// (docs/guide/recording.md).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "agv/localizer/localizer.hpp"
#include "agv/ranging/observe.hpp"
#include "agv/recording/recording.hpp"
#include "agv/site/site.hpp"
#include "config.hpp"
#include "output_loop.hpp"

namespace agv::app {

// A second camera silent this long is stalled: counted and logged (the vehicle runs on its other
// aids meanwhile).
constexpr std::int64_t kRangingStallNs = 1'000'000'000;

// What the second camera's frames gave (summary line).
struct RangingCounts {
  std::uint64_t frames = 0;         // read and searched
  std::uint64_t frame_errors = 0;   // could not be read (skipped)
  std::uint64_t windowed = 0;       // searched in windows from the pose
  std::uint64_t landmarks = 0;      // measured
  std::uint64_t refused = 0;        // decoded but refused (unknown id, mirrored, ...)
  std::uint64_t dropped_queue = 0;  // ring full
  // The threaded loop: spans of more than kRangingStallNs without a frame from a started camera.
  std::uint64_t stalls = 0;
  // The threaded loop's worker: its thread CPU time per frame read (0: not measured, --fast).
  std::int64_t cpu_ns = 0, cpu_max_ns = 0;
  std::string last_error;
};

// What the second camera needs of the site: the wall landmarks it reads and the obstacles that
// hide them.
struct RackSite {
  std::vector<site::WallLandmark> walls;
  std::vector<site::Obstacle> obstacles;
};

// The site file's wall landmarks and obstacles (its floor map read too when it names one). False
// with *error naming the file and every problem.
bool load_rack_site(const std::string& site_file, RackSite* out, std::string* error);

// The observer of the configured second camera.
class RackObserver {
 public:
  RackObserver(const config::RangingCameraSection& cfg, const RackSite& site);
  // False with *error when the landmark table or the calibration cannot be used.
  bool ok(std::string* error) const;
  // Whether a frame of this size is the configured camera's (ranging_camera.camera).
  bool frame_size_ok(int width_px, int height_px) const {
    return width_px == width_px_ && height_px == height_px_;
  }
  // Reads one gray frame; prior null: a full sweep. Fills rec's observations (not its times).
  void observe(const cv::Mat& gray, const ranging::PosePrior* prior, RangingRecord* rec,
               RangingCounts* counts);

 private:
  ranging::LandmarkObserver observer_;
  int width_px_ = 0, height_px_ = 0;
  double mount_sigma_rad_ = 0.0, mount_sigma_mm_ = 0.0;  // the EKF aid's share of the mount's doubt
  std::uint64_t frame_index_ = 0;
  ranging::WindowOptions windows_;
};

// The core's pose at t_ns (vehicle clock) as the observer's prior; false when the core does not
// track (uninitialised or lost): the frame is then searched whole.
bool pose_prior(const localizer::Localizer& core, std::int64_t t_ns, ranging::PosePrior* prior);

// The recording's second stream: DIR/ranging/frames.csv (the frames.csv format, paths relative to
// DIR/ranging), its images of the configured size. A cut last line is dropped with a warning in
// *warnings; a missing or malformed file is an error naming it. Images are checked when read.
bool read_ranging_stream(const std::string& rec_dir, const config::RangingCameraSection& cfg,
                         recording::Recording* out, std::vector<std::string>* warnings,
                         std::string* error);

// The summary's line for the second camera.
std::string ranging_summary(const RangingCounts& c, const localizer::OutputStats& o);

}  // namespace agv::app

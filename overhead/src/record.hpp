// agvloc-overhead record: every configured ceiling camera's frames written as one recording
// folder per camera, in the format `replay` reads (the one `agvloc-desk render-site` writes,
// docs/guide/recording.md): meta.yaml with the camera's intrinsics from the site, camera.yaml
// with its id and pose, frames/*.png, frames.csv with the exposure stamps, an empty odom.csv.
//
// A frame is written to a temporary name and renamed, and its frames.csv row follows the rename,
// so a recording killed at any moment holds only whole frames and a frames.csv ending on a row
// boundary (or cut in its last row, which the reader drops with a warning). A camera whose writer
// falls behind loses frames (counted), never the pace of the others.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "agv/site/site.hpp"
#include "live_feed.hpp"

namespace agv::overhead_app {

struct RecordArgs {
  std::string config_path;  // required: the cameras' devices are configured there
  std::string site_path;
  std::string out_dir;      // one folder per camera under it
  double duration_s = 0.0;  // 0: until SIGINT / SIGTERM
};

struct CameraRecordCounters {
  std::string dir;
  std::uint64_t frames_written = 0;
  std::uint64_t frames_dropped = 0;       // the writer was behind
  std::uint64_t frames_out_of_order = 0;  // stamp not after the previous one (the reader's rule)
  std::uint64_t write_errors = 0;         // PNG, rename or frames.csv failures
};

// Creates out_dir/<camera id>/ with meta.yaml, camera.yaml, frames/, frames.csv and odom.csv
// (headers only) for one site camera. False with *error when the folder exists and is not empty
// (a recording is never overwritten) or cannot be written.
bool start_recording_folder(const std::string& dir, const site::CeilingCamera& cam,
                            const site::Site& site, const std::string& source, std::string* error);

// Records every camera into out_dir/<its id>/ until `stop` is set, duration_ns has passed (0: no
// limit) or every camera has ended. False with *error when a folder cannot be started (nothing
// is recorded then); *cams_health and *counters as the cameras were given.
bool record_cameras(std::vector<LiveCamera>* cams, const site::Site& site,
                    const std::string& out_dir, const std::string& source,
                    const std::atomic<bool>& stop, std::int64_t duration_ns,
                    std::vector<CameraRecordCounters>* counters,
                    std::vector<CameraHealth>* cams_health, std::string* error);

// Exit code: 0 stopped, 2 bad input (configuration, site, no camera, --out not empty), 1 an I/O
// failure while recording.
int run_record_command(const RecordArgs& args);

}  // namespace agv::overhead_app

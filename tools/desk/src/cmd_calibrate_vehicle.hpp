// agvloc-desk calibrate vehicle, shared by its two files: cmd_calibrate_vehicle.cpp (inputs,
// corner observations, the solves) and cmd_calibrate_vehicle_report.cpp (report.txt, the
// configuration snippet, residuals.svg).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/landmark.hpp"
#include "agv/config/config.hpp"
#include "agv/localizer/no_fix_diagnosis.hpp"
#include "agv/recording/recording.hpp"
#include "calib_gyro.hpp"
#include "calib_vehicle.hpp"

namespace agv::desk::vehicle_cmd {

// What the command reads.
struct Inputs {
  std::string rec_dir, map_path, config_path, out_dir;
  recording::Recording rec;
  config::Config cfg;
  CameraModel cam;       // the nominal camera: --config's, else the recording's
  LandmarkGeometry geom;
  std::string family_source;  // "--config", "meta.yaml" or empty (the default)
  LandmarkMap map;
};

// What the frames gave.
struct Observed {
  std::vector<vcal::CornerObservation> obs;
  int fixes = 0;
  std::string failures;          // frames with a landmark but no fix, by reason
  std::string misprint_warning;  // empty: none
  localizer::NoFixDiagnosis diagnosis;
  std::uint64_t no_fix_frames = 0;
};

struct GyroOutcome {
  bool have = false;  // the recording has imu.csv
  bool ok = false;    // calibrated
  vcal::GyroResult result;
  std::string error;
  double offset_ms = 0.0;  // imu.time_offset_ms
  // outside_key_range of imu.scale, imu.bias_degps, imu.time_offset_ms, each only when determined
  std::vector<std::string> out_of_range;
};

struct Outcome {
  vcal::Result r;
  GyroOutcome gyro;
  bool wheels = false;  // can.odometry.mode wheels: the yaw-rate scale is a track width
  // Per parameter of r (then the gyro's): why the key table refuses it, empty when it takes it.
  std::vector<std::string> out_of_range;
  bool any_out_of_range = false;
  std::vector<vcal::FilterPrior> wheel_priors;
};

std::string fmt(const char* f, double v);
std::string report_text(const Inputs& in, const Observed& seen, const Outcome& o);
std::string snippet_text(const Inputs& in, const Outcome& o);
// Bar chart of the per-pass RMS before/after (log scale), SVG.
std::string residual_svg(const vcal::Result& r);

}  // namespace agv::desk::vehicle_cmd

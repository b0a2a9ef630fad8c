// replay --out: tracks.csv (every vehicle's published state at every tick) and detections.csv
// (every tag seen), documented column by column in docs/guide/overhead.md "Outputs".
#pragma once

#include <cstdio>
#include <string>
#include <vector>

#include "agv/overhead/camera_frame.hpp"
#include "agv/site/site.hpp"

namespace agv::overhead_app {

inline constexpr const char* kTracksHeader =
    "t_ns,agv,x_mm,y_mm,theta_rad,v_mps,omega_radps,sigma_xy_mm,sigma_theta_rad,state";
inline constexpr const char* kDetectionsHeader =
    "camera,t_ns,tag_id,agv,x_mm,y_mm,theta_rad,c0_x,c0_y,c1_x,c1_y,c2_x,c2_y,c3_x,c3_y,"
    "hamming,margin,restricted,level,result";

const char* level_name(overhead::SearchLevel l);
// What became of a detection: the tracker's FixResult name, or unknown_id (a tag not in the
// fleet) or no_fix (the tray-plane fit failed).
std::string detection_result(const overhead::Detection& d);

std::string track_row(const std::string& agv_id, const overhead::TrackOutput& t);
std::string detection_row(const site::Site& site, const overhead::Detection& d);

class CsvOut {
 public:
  CsvOut() = default;
  ~CsvOut();
  CsvOut(const CsvOut&) = delete;
  CsvOut& operator=(const CsvOut&) = delete;
  // Creates DIR and both files with their headers; false with *error.
  bool open(const std::string& dir, std::string* error);
  bool is_open() const { return tracks_ != nullptr; }
  void track(const std::string& row) { write(tracks_, row); }
  void detection(const std::string& row) { write(detections_, row); }
  // Closes both; false with *error when a write failed (disk full).
  bool close(std::string* error);

 private:
  void write(std::FILE* f, const std::string& row);
  std::string dir_;
  std::FILE* tracks_ = nullptr;
  std::FILE* detections_ = nullptr;
  bool failed_ = false;
};

}  // namespace agv::overhead_app

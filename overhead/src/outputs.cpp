#include "outputs.hpp"

#include <cerrno>
#include <cstring>
#include <filesystem>

namespace agv::overhead_app {

namespace {

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

}  // namespace

const char* level_name(overhead::SearchLevel l) {
  switch (l) {
    case overhead::SearchLevel::kTrack:
      return "track";
    case overhead::SearchLevel::kArea:
      return "area";
    case overhead::SearchLevel::kFull:
      return "full";
  }
  return "unknown";
}

std::string detection_result(const overhead::Detection& d) {
  if (!d.in_fleet) return "unknown_id";
  if (!d.has_fix) return "no_fix";
  return overhead::to_string(d.result);
}

std::string track_row(const std::string& agv_id, const overhead::TrackOutput& t) {
  return std::to_string(t.t_ns) + "," + agv_id + "," + fmt("%.3f", t.pose.x_mm) + "," +
         fmt("%.3f", t.pose.y_mm) + "," + fmt("%.6f", t.pose.theta_rad) + "," +
         fmt("%.4f", t.v_mps) + "," + fmt("%.5f", t.omega_radps) + "," +
         fmt("%.3f", t.sigma_xy_mm) + "," + fmt("%.6f", t.sigma_theta_rad) + "," +
         overhead::to_string(t.state);
}

std::string detection_row(const site::Site& site, const overhead::Detection& d) {
  std::string r = (d.camera < site.cameras.size() ? site.cameras[d.camera].id : "?") + "," +
                  std::to_string(d.t_ns) + "," + std::to_string(d.tag.id) + "," +
                  (d.in_fleet && d.agv < site.fleet.size() ? site.fleet[d.agv].id : "");
  if (d.has_fix) {
    r += "," + fmt("%.3f", d.fix.pose.x_mm) + "," + fmt("%.3f", d.fix.pose.y_mm) + "," +
         fmt("%.6f", d.fix.pose.theta_rad);
  } else {
    r += ",,,";
  }
  for (const Vec2& c : d.tag.corners_px) r += "," + fmt("%.3f", c.x) + "," + fmt("%.3f", c.y);
  r += "," + std::to_string(d.tag.hamming) + "," + std::to_string(d.tag.margin) + "," +
       (d.tag.restricted ? "1" : "0") + "," + level_name(d.level) + "," + detection_result(d);
  return r;
}

CsvOut::~CsvOut() {
  std::string ignored;
  close(&ignored);
}

bool CsvOut::open(const std::string& dir, std::string* error) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return (*error = "--out " + dir + ": " + ec.message(), false);
  dir_ = dir;
  const std::string tp = (std::filesystem::path(dir) / "tracks.csv").string();
  const std::string dp = (std::filesystem::path(dir) / "detections.csv").string();
  tracks_ = std::fopen(tp.c_str(), "w");
  if (!tracks_) return (*error = tp + ": " + std::strerror(errno), false);
  detections_ = std::fopen(dp.c_str(), "w");
  if (!detections_) return (*error = dp + ": " + std::strerror(errno), false);
  track(kTracksHeader);
  detection(kDetectionsHeader);
  return true;
}

void CsvOut::write(std::FILE* f, const std::string& row) {
  if (!f) return;
  if (std::fputs(row.c_str(), f) < 0 || std::fputc('\n', f) == EOF) failed_ = true;
}

bool CsvOut::close(std::string* error) {
  for (std::FILE** f : {&tracks_, &detections_}) {
    if (*f && std::fclose(*f) != 0) failed_ = true;
    *f = nullptr;
  }
  if (failed_) *error = "--out " + dir_ + ": writing failed (" + std::strerror(errno) + ")";
  return !failed_;
}

}  // namespace agv::overhead_app

#include "ranging_stream.hpp"

#include <cstdio>
#include <filesystem>

#include "agv/recording/site_file.hpp"

namespace agv::app {

namespace fs = std::filesystem;

bool load_rack_site(const std::string& site_file, RackSite* out, std::string* error) {
  site::Site s;
  std::vector<std::string> found;
  if (!recording::read_site_file(site_file, &s, &found)) {
    *error = "ranging_camera.site:";
    for (const std::string& e : found) *error += (found.size() == 1 ? " " : "\n  ") + e;
    return false;
  }
  if (s.wall_landmarks.empty()) {
    *error = "ranging_camera.site: " + site_file +
             ": wall_landmarks: none (the second camera has nothing to read)";
    return false;
  }
  out->walls = std::move(s.wall_landmarks);
  out->obstacles = std::move(s.obstacles);
  return true;
}

namespace {

ranging::ObserveOptions observe_options(const config::RangingCameraSection& cfg) {
  ranging::ObserveOptions o;
  o.mount_sigma_rad = cfg.mount_sigma_rad;
  o.mount_sigma_mm = cfg.mount_sigma_mm;
  o.calibration_sigma_px = cfg.calibration_sigma_px;
  o.focal_sigma_rel = cfg.focal_sigma_rel;
  o.interval_sweep_decimate = cfg.interval_sweep_decimate;
  return o;
}

}  // namespace

RackObserver::RackObserver(const config::RangingCameraSection& cfg, const RackSite& site)
    : observer_(cfg.intrinsics, cfg.mount, site.walls, observe_options(cfg)),
      width_px_(cfg.intrinsics.width_px),
      height_px_(cfg.intrinsics.height_px),
      mount_sigma_rad_(cfg.mount_sigma_rad),
      mount_sigma_mm_(cfg.mount_sigma_mm) {
  observer_.set_obstacles(site.obstacles);
  windows_.predicted_first = cfg.predicted_first;
  windows_.full_sweep_interval_frames = static_cast<std::uint64_t>(cfg.sweep_interval_frames);
}

bool RackObserver::ok(std::string* error) const {
  if (observer_.status() == ranging::TableStatus::kOk) return true;
  *error = std::string("ranging_camera: ") + ranging::table_status_name(observer_.status()) + ": " +
           observer_.status_detail();
  return false;
}

void RackObserver::observe(const cv::Mat& gray, const ranging::PosePrior* prior, RangingRecord* rec,
                           RangingCounts* counts) {
  const ranging::ObserveResult res = observer_.observe(gray, prior, frame_index_++, windows_);
  ++counts->frames;
  if (!res.full_sweep) ++counts->windowed;
  counts->refused += res.refused.size();
  rec->n = 0;
  const ranging::RangingMount& mount = observer_.mount();
  for (const ranging::LandmarkObservation& o : res.seen) {
    if (rec->n >= rec->obs.size()) break;
    localizer::RackObservation& r = rec->obs[rec->n++];
    r.vehicle = ranging::fix_observation(o);
    const ranging::SensorRangeBearing s =
        ranging::sensor_range_bearing(mount, o, mount_sigma_rad_, mount_sigma_mm_);
    r.sensor.landmark_xy_mm = s.landmark_xy_mm;
    r.sensor.sensor_xy_mm = s.sensor_xy_mm;
    r.sensor.sensor_yaw_rad = s.sensor_yaw_rad;
    r.sensor.range_mm = s.range_mm;
    r.sensor.bearing_rad = s.bearing_rad;
    r.sensor.R = s.R;
    r.sensor.R_systematic = s.R_systematic;
  }
  counts->landmarks += rec->n;
}

bool pose_prior(const localizer::Localizer& core, std::int64_t t_ns, ranging::PosePrior* prior) {
  const fusion::PoseEstimate e = core.ekf().estimate_at(t_ns);
  if (!e.valid || e.health == fusion::HealthState::kLost) return false;
  prior->pose = e.pose;
  prior->cov = e.cov.topLeftCorner<3, 3>();
  return true;
}

bool read_ranging_stream(const std::string& rec_dir, const config::RangingCameraSection& cfg,
                         recording::Recording* out, std::vector<std::string>* warnings,
                         std::string* error) {
  const fs::path dir = fs::path(rec_dir) / "ranging";
  const std::string name = "ranging/frames.csv";
  // The same bound as the floor stream's frames.csv.
  constexpr std::uintmax_t kMaxBytes = 8u << 20;
  std::string text, err;
  if (!recording::read_file_bounded((dir / "frames.csv").string(), kMaxBytes, &text, &err)) {
    *error = name + ": " + err + " (ranging_camera.enabled needs the recording's second stream)";
    return false;
  }
  // A cut last line (interrupted recorder) is dropped as read_recording does for frames.csv.
  if (!text.empty() && text.back() != '\n') {
    const std::size_t nl = text.rfind('\n');
    if (nl != std::string::npos) {
      warnings->push_back(name + ": last line cut (no newline: interrupted write), ignored");
      text.resize(nl + 1);
    }
  }
  recording::Recording r;
  if (!recording::parse_frames_csv(text, &r.frames, &err, name)) {
    *error = err;
    return false;
  }
  r.dir = dir.string();
  r.meta.camera.intrinsics = cfg.intrinsics;
  *out = std::move(r);
  return true;
}

std::string ranging_summary(const RangingCounts& c, const localizer::OutputStats& o) {
  char buf[400];
  std::snprintf(
      buf, sizeof buf,
      "ranging camera: %llu frames (%llu in windows), %llu unreadable, %llu landmarks, "
      "%llu refused, %llu dropped, %llu stalls; core: %llu fused, %llu gated, %llu fixes, %llu "
      "initialisations\n",
      static_cast<unsigned long long>(c.frames), static_cast<unsigned long long>(c.windowed),
      static_cast<unsigned long long>(c.frame_errors), static_cast<unsigned long long>(c.landmarks),
      static_cast<unsigned long long>(c.refused), static_cast<unsigned long long>(c.dropped_queue),
      static_cast<unsigned long long>(c.stalls), static_cast<unsigned long long>(o.ranging_fused),
      static_cast<unsigned long long>(o.ranging_rejected_gate),
      static_cast<unsigned long long>(o.ranging_fixes),
      static_cast<unsigned long long>(o.ranging_initialisations));
  std::string s = buf;
  if (o.ranging_floor_conflicts > 0) {
    std::snprintf(buf, sizeof buf,
                  "ranging camera: floor fixes overruled the rack landmarks %llu times (the "
                  "filter took over its floor-only twin), %llu suspensions, %llu frames unused "
                  "while suspended: check the mount calibration and the rack landmarks' survey\n",
                  static_cast<unsigned long long>(o.ranging_floor_conflicts),
                  static_cast<unsigned long long>(o.ranging_suspensions),
                  static_cast<unsigned long long>(o.ranging_suspended_frames));
    s += buf;
  }
  if (o.ranging_floor_disputes > 0) {
    std::snprintf(buf, sizeof buf,
                  "ranging camera: %llu floor fixes disagreed with the rack landmarks, not enough "
                  "in a row to overrule them\n",
                  static_cast<unsigned long long>(o.ranging_floor_disputes));
    s += buf;
  }
  if (o.ranging_floor_twin_resyncs > 0) {
    std::snprintf(buf, sizeof buf,
                  "ranging camera: the floor-only twin refused %llu floor fixes that floor and "
                  "rack landmarks agreed on (it held an older, misread one) and was reset\n",
                  static_cast<unsigned long long>(o.ranging_floor_twin_resyncs));
    s += buf;
  }
  if (c.cpu_ns > 0 && c.frames > 0) {
    std::snprintf(buf, sizeof buf, "ranging camera: CPU per frame mean %.2f ms, max %.2f ms\n",
                  static_cast<double>(c.cpu_ns) / 1e6 / static_cast<double>(c.frames),
                  static_cast<double>(c.cpu_max_ns) / 1e6);
    s += buf;
  }
  if (!c.last_error.empty()) s += "ranging camera: last unreadable frame: " + c.last_error + "\n";
  return s;
}

}  // namespace agv::app

// Key table rows of the second camera (ranging_camera.*): landmarks on racks seen at a distance
// (docs/design/ranging.md). Off by default; when on, its calibration and the site file are
// required (check_ranging_camera_values).
#include "key_builders.hpp"

namespace agv::config::detail {

namespace {

void add_ranging_stream(std::vector<Key>* k) {
  k->push_back(boolean("ranging_camera.enabled", AGV_AT(ranging_camera.enabled), false,
                       "a second camera looking forward or sideways at tag36h11 landmarks on "
                       "racks and walls (the site file's `wall_landmarks`): their range and "
                       "bearing initialise a lost vehicle from two landmarks and aid the filter "
                       "between floor landmarks. `agvloc replay` reads the recording's "
                       "`ranging/` stream (docs/guide/recording.md). Needs `site` and "
                       "`intrinsics`"));
  k->push_back(enumeration("ranging_camera.driver", AGV_AT(ranging_camera.driver),
                           named(kCameraDriverNames), "libcamera",
                           "live backend, as `camera.driver`"));
  k->push_back(text("ranging_camera.id", AGV_AT(ranging_camera.camera.id), "",
                    "libcamera camera id, or the V4L2 device node (as `camera.id`); must name "
                    "another camera than the floor camera's"));
  k->push_back(text("ranging_camera.model", AGV_AT(ranging_camera.camera.model), "",
                    "libcamera: first camera whose model matches, when `id` is empty"));
  k->push_back(integer("ranging_camera.width", AGV_AT(ranging_camera.camera.width_px), 16, 8192,
                       1280, {"px", "stream width; the calibration's"}));
  k->push_back(integer("ranging_camera.height", AGV_AT(ranging_camera.camera.height_px), 16, 8192,
                       800, {"px", "stream height; the calibration's"}));
  k->push_back(number("ranging_camera.fps", AGV_AT(ranging_camera.camera.fps), 1.0, 60.0, 15.0,
                      {"Hz",
                       "a rack landmark is seen for seconds, so a low rate suffices; each frame "
                       "costs a landmark search (windows from the pose when tracking)"}));
  k->push_back(integer("ranging_camera.exposure_us", AGV_AT(ranging_camera.camera.exposure_us), 10,
                       100000, 2000,
                       {"µs",
                        "landmarks metres away blur less per mm of travel than the floor's; "
                        "2 ms at 1 m/s is 2 mm"}));
  k->push_back(number("ranging_camera.time_offset_ms", AGV_AT(ranging_camera.time_offset_ms),
                      -500.0, 500.0, 0.0,
                      {"ms",
                       "vehicle clock = this camera's clock + offset, as `camera.time_offset_ms` "
                       "for the floor camera"}));
  k->push_back(text("ranging_camera.site", AGV_AT(ranging_camera.site_file), "",
                    "site file (docs/guide/site.md) whose `wall_landmarks` are the landmarks "
                    "this camera reads, relative to the configuration file; required when "
                    "enabled"));
}

void add_ranging_intrinsics(std::vector<Key>* k) {
  k->push_back(number("ranging_camera.intrinsics.fx", AGV_AT(ranging_camera.intrinsics.fx), 0.0,
                      1e6, 0.0, {"px", "focal length x, from calibration; required when enabled"}));
  k->push_back(number("ranging_camera.intrinsics.fy", AGV_AT(ranging_camera.intrinsics.fy), 0.0,
                      1e6, 0.0, {"px", "focal length y; required when enabled"}));
  k->push_back(number("ranging_camera.intrinsics.cx", AGV_AT(ranging_camera.intrinsics.cx), -1e5,
                      1e5, 0.0, {"px", "principal point x (pixel centres at integers)"}));
  k->push_back(number("ranging_camera.intrinsics.cy", AGV_AT(ranging_camera.intrinsics.cy), -1e5,
                      1e5, 0.0, {"px", "principal point y"}));
  k->push_back(number("ranging_camera.intrinsics.k1", AGV_AT(ranging_camera.intrinsics.k1), -10.0,
                      10.0, 0.0, {"", "radial distortion (OpenCV model)"}));
  k->push_back(number("ranging_camera.intrinsics.k2", AGV_AT(ranging_camera.intrinsics.k2), -10.0,
                      10.0, 0.0, {"", "radial distortion"}));
  k->push_back(number("ranging_camera.intrinsics.p1", AGV_AT(ranging_camera.intrinsics.p1), -1.0,
                      1.0, 0.0, {"", "tangential distortion"}));
  k->push_back(number("ranging_camera.intrinsics.p2", AGV_AT(ranging_camera.intrinsics.p2), -1.0,
                      1.0, 0.0, {"", "tangential distortion"}));
  k->push_back(number("ranging_camera.intrinsics.k3", AGV_AT(ranging_camera.intrinsics.k3), -10.0,
                      10.0, 0.0, {"", "radial distortion"}));
}

void add_ranging_mount(std::vector<Key>* k) {
  k->push_back(number("ranging_camera.mount.x_mm", AGV_AT(ranging_camera.mount.x_mm), -10000.0,
                      10000.0, 0.0, {"mm", "optical centre in the vehicle frame, x forward"}));
  k->push_back(number("ranging_camera.mount.y_mm", AGV_AT(ranging_camera.mount.y_mm), -10000.0,
                      10000.0, 0.0, {"mm", "optical centre in the vehicle frame, y left"}));
  k->push_back(number("ranging_camera.mount.z_mm", AGV_AT(ranging_camera.mount.z_mm), 0.0, 10000.0,
                      0.0, {"mm", "optical centre above the floor"}));
  k->push_back(deg_as_rad("ranging_camera.mount.roll_deg", AGV_AT(ranging_camera.mount.roll_rad),
                          -180.0, 180.0, 0.0,
                          {"deg", "about the optical axis; + lowers the image's right side"}));
  k->push_back(deg_as_rad("ranging_camera.mount.pitch_deg", AGV_AT(ranging_camera.mount.pitch_rad),
                          -90.0, 90.0, 0.0, {"deg", "+ tilts the optical axis down"}));
  k->push_back(deg_as_rad("ranging_camera.mount.yaw_deg", AGV_AT(ranging_camera.mount.yaw_rad),
                          -180.0, 180.0, 0.0,
                          {"deg",
                           "optical axis counter-clockwise from vehicle +x (0 forward, 90 left); "
                           "the order is yaw, then pitch, then roll (docs/design/ranging.md)"}));
}

void add_ranging_calibration_doubt(std::vector<Key>* k) {
  k->push_back(deg_as_rad(
      "ranging_camera.mount.sigma_deg", AGV_AT(ranging_camera.mount_sigma_rad), 0.0, 10.0, 0.0,
      {"deg",
       "1 sigma of each mount angle as calibrated. Roll and pitch widen each landmark's range and "
       "bearing; the yaw turns every bearing alike, so it widens a prior-free fix's covariance "
       "instead (its heading cannot be surer than the mount), and the heading sigma of the "
       "filter's range-bearing updates stays at least at it. Errors the same in every frame: "
       "frames averaged never shrink them. 0: the mount is taken as exact"}));
  k->push_back(number("ranging_camera.mount.sigma_mm", AGV_AT(ranging_camera.mount_sigma_mm), 0.0,
                      100.0, 0.0, {"mm", "1 sigma of each mount offset as measured"}));
  k->push_back(number("ranging_camera.calibration_sigma_px",
                      AGV_AT(ranging_camera.calibration_sigma_px), 0.0, 20.0, 0.0,
                      {"px",
                       "systematic error of an undistorted point left by the lens calibration "
                       "(its reprojection RMS is a fair start): widens each bearing by sigma / "
                       "fx, and, through the principal point, every bearing alike as the mount's "
                       "yaw does"}));
  k->push_back(number("ranging_camera.focal_sigma_rel", AGV_AT(ranging_camera.focal_sigma_rel), 0.0,
                      0.1, 0.0,
                      {"",
                       "relative error of the focal length, fx and fy apart (0.002 = 0.2 %): "
                       "scales the whole view, each range and bearing, and turns each tag's face "
                       "yaw; one error for all landmarks of a frame"}));
  k->push_back(boolean("ranging_camera.shallow_pairs_from_face_yaws",
                       AGV_AT(ranging_camera.shallow_pairs_from_face_yaws), true,
                       "two landmarks seen under 15 deg of each other (their range circles cross "
                       "shallowly) fix a pose from their face yaws (the tags' turn) instead of "
                       "being refused; their sigma carries focal_sigma_rel, so state it "
                       "(docs/design/ranging.md, \"Switched on\"). false: refused"));
  k->push_back(boolean("ranging_camera.predicted_first", AGV_AT(ranging_camera.predicted_first),
                       true,
                       "a landmark the pose predicts in view is read first from edge lines "
                       "within 8 px of its predicted square, decoded against its own id; its "
                       "window is searched only when that fails (about half the CPU per frame "
                       "once localized, docs/design/ranging.md). false: every window searched"));
  k->push_back(integer("ranging_camera.sweep_interval_frames",
                       AGV_AT(ranging_camera.sweep_interval_frames), 0, 100000, 150,
                       {"frames",
                        "every this many frames the whole frame is searched as well, for "
                        "landmarks the pose does not expect in view (a pose wrong beyond its "
                        "sigma); without a usable pose every frame is. 0: never"}));
  k->push_back(number("ranging_camera.interval_sweep_decimate",
                      AGV_AT(ranging_camera.interval_sweep_decimate), 1.0, 4.0, 2.0,
                      {"",
                       "libapriltag's quad decimation for that search: 2 adds the tags the "
                       "windows did not read at a third of a full sweep's CPU, missing some of "
                       "the smallest (150 mm beyond about 7 m at 1000 px focal length). 1: a "
                       "full-resolution sweep in place of the windows"}));
}

}  // namespace

void add_ranging_camera_keys(std::vector<Key>* keys) {
  add_ranging_stream(keys);
  add_ranging_intrinsics(keys);
  add_ranging_mount(keys);
  add_ranging_calibration_doubt(keys);
}

void check_ranging_camera_values(const Config& cfg, const KeyError& error) {
  const RangingCameraSection& r = cfg.ranging_camera;
  if (!r.enabled) return;
  const char* why = "required with ranging_camera.enabled (the second camera's calibration)";
  if (!(r.intrinsics.fx > 0.0))
    error("ranging_camera.intrinsics.fx", std::string("missing: ") + why);
  if (!(r.intrinsics.fy > 0.0))
    error("ranging_camera.intrinsics.fy", std::string("missing: ") + why);
  if (r.site_file.empty()) {
    error("ranging_camera.site",
          "missing: required with ranging_camera.enabled (the site file naming the landmarks on "
          "racks)");
  }
}

}  // namespace agv::config::detail

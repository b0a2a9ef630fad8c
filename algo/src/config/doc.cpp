// docs/guide/config.md, generated from the key table. The prose here (header, section
// introductions) is emitted verbatim; everything about a single key comes from its record.
#include <string>

#include "agv/config/keys.hpp"

namespace agv::config {

namespace {

const char* const kHeader = R"(# Configuration

<!-- Generated from the key table (algo/src/config/keys_*.cpp, prose in algo/src/config/doc.cpp)
     by `agvloc-config-doc > docs/guide/config.md`; test_config fails when this file differs. -->

One YAML file, validated completely at start (`agvloc run --config FILE --check-config` checks
without starting). Every error names the key path and the accepted range, e.g.
`can.base_id: value 4096 outside the accepted range [0, 2047]`; unknown keys are errors (a typo
must not silently fall back to a default), and so are keys given twice (`loop.output_rate_hz:
duplicate key at line 4 (first at line 3)`, sections too), keys that are not plain names
(`[a]: 1`) and removed keys (named with their replacement, end of this page). Missing keys take
the defaults below, except the camera calibration: `intrinsics` with `fx`, `fy`, `cx`, `cy` is
required (below). The file must be a regular file of at most 1 MiB (`/dev/zero` or a FIFO is
refused, docs/design/security.md); configuration errors exit with code 2. The shipped example,
`firmware/config/agvloc.yaml` (installed as `/etc/agvloc/agvloc.yaml`), lists the camera,
landmark, CAN and loop sections; vision, fusion and replay take the defaults below. Relative
paths are relative to the configuration file.

`agvloc replay` takes the camera model and landmark size from the recording's `meta.yaml`;
`--config` then only supplies the other sections.

Every key below is read by the localizer and every key it reads is below: the checker, the
built-in defaults and this page come from one table.
)";

std::string escape_cell(const std::string& s) {
  std::string out;
  for (char ch : s) {
    if (ch == '|') out += '\\';
    out += ch;
  }
  return out;
}

}  // namespace

const std::vector<Section>& config_sections() {
  static const std::vector<Section> sections = {
      {"camera", "", "", ""},
      {"intrinsics", "(from calibration, docs/guide/camera.md) — required",
       "The OpenCV model, pixel centres at integer coordinates. `fx`, `fy`, `cx` and `cy` have no\n"
       "default: `agvloc run`, `agvloc record` and `--check-config` reject a configuration\n"
       "without them (`intrinsics: missing section (fx, fy, cx, cy are required: the camera\n"
       "calibration, docs/guide/camera.md)`, or `intrinsics.fy: missing (required: ...)` for one "
       "key),\n"
       "because a guessed focal length silently scales every fix. The shipped example carries the\n"
       "simulator's camera: fx = fy = 769.23 (0.26 mm/px at 200 mm), cx = 319.5, cy = 239.5.\n"
       "`agvloc replay --config` takes the camera from the recording's `meta.yaml` and does not\n"
       "need this section (if present it is still checked).\n",
       "the camera calibration, docs/guide/camera.md"},
      {"mounting", "(docs/design/frames.md)", "", ""},
      {"landmark", "", "", ""},
      {"can", "(docs/guide/can.md)", "", ""},
      {"can.odometry", "", "", ""},
      {"can.gyro", "(`AGV_Gyro`, docs/guide/can.md)", "", ""},
      {"odometry", "(from `agvloc-desk calibrate vehicle`)",
       "Correction of every odometry sample before fusion, the equations of the calibration's\n"
       "model (tools/desk/src/calib_vehicle.hpp): v' = `speed_scale` · v,\n"
       "ω' = `yaw_rate_scale` · ω + `yaw_rate_bias_degps`; stamps unchanged (odometry is the\n"
       "vehicle's clock; the camera's offset is `camera.time_offset_ms`). Applied to\n"
       "both odometry modes, after `can.odometry.wheel_speed_scale` / `track_width_mm` (which a\n"
       "wheels-mode calibration folds its yaw-rate scale into). With\n"
       "`fusion.estimate_odometry_calibration` the filter's own scale and bias states still start\n"
       "at 1 and 0 and learn only what this correction leaves. The defaults change nothing.\n",
       ""},
      {"imu", "",
       "Correction of every gyro sample before fusion (`agv::localizer::GyroCorrection`):\n"
       "rate' = `scale` · rate + `bias_degps`, t' = t − `time_offset_ms`. The filter's own gyro\n"
       "states learn only what this correction leaves. The defaults change nothing.\n",
       ""},
      {"loop", "",
       "The built-in defaults below need no privileges. The shipped example sets the real-time\n"
       "keys for the vehicle (`realtime_priority: 50`, `vision_priority: 40`, `lock_memory: "
       "true`;\n"
       "the service unit's `LimitRTPRIO=80` / `LimitMEMLOCK=infinity` permit them): on a shared\n"
       "2-core machine they took the output jitter p99 from 0.8–2.4 ms to 0.06–0.15 ms and, with\n"
       "`pose_on_fix`, the end to end p99 from 3.7–4.2 ms to 1.5–2.6 ms "
       "(docs/design/performance.md,\n"
       "second-session runs). When not permitted, the loop prints which capability or limit is\n"
       "missing and runs without them.\n",
       ""},
      {"vision", "(docs/design/vision.md has the pipeline)",
       "The fields of `agv::vision::VisionConfig` "
       "(algo/include/agv/vision/landmark_localizer.hpp)\n"
       "with the same names and defaults, in pipeline order; measurements behind the defaults:\n"
       "docs/design/accuracy.md.\n",
       ""},
      {"vision.tracking", "(docs/design/tracking.md)",
       "Search windows from the fused pose (`agv::vision::TrackingConfig`): used when the\n"
       "prediction is valid and within both σ limits; the windows are the mapped landmarks'\n"
       "outer squares grown by `window_sigmas` σ plus a fixed detection margin.\n",
       ""},
      {"vision.identity", "(docs/design/map_identity.md)",
       "Map-guided identity of a landmark whose code cannot be read "
       "(`agv::vision::MapIdentityConfig`):\n"
       "the fused pose's covariance must single out one mapped landmark (the gate), and the "
       "code's\nvisible modules must agree with that landmark's code (the module check).\n",
       ""},
      {"fusion", "(docs/design/fusion.md has the model)",
       "Fields of `agv::fusion::EkfConfig` (algo/include/agv/fusion/ekf_config.hpp) with the same\n"
       "defaults, in the order of its parts: odometry, core (process noise, history), gyro, wheel\n"
       "slip, landmark fixes, range-bearing observations, recovery, health; angles in degrees and\n"
       "times in milliseconds here. The combination is checked by\n"
       "`fusion::validate` at start (e.g. `odom_gap_ms` ≥ `odom_period_ms`). With\n"
       "`estimate_odometry_calibration: false` the defaults of\n"
       "`along_track_sigma_mm_per_sqrt_m`, `cross_track_sigma_mm_per_sqrt_m`,\n"
       "`heading_sigma_deg_per_sqrt_m` and `heading_drift_sigma_deg_per_sqrt_s` become 5, 2, 0.1\n"
       "and 0.3 (the process noise must then cover the uncalibrated odometry; "
       "docs/design/fusion.md);\n"
       "keys given in the file still win. The odometry timeout is `can.odometry.timeout_ms`.\n",
       ""},
      {"replay", "", "", ""},
      {"vda5050", "(VDA 5050 position over MQTT, docs/guide/vda5050.md)",
       "The position provider for a fleet control: `visualization` at `rate_hz`, `connection`\n"
       "with a last will, `initPosition` accepted. Off by default; MQTT runs in its own thread\n"
       "and never delays the output loop. `agvloc replay` publishes too (recording time).\n",
       ""},
      {"diag", "(live diagnostics page and /metrics, docs/guide/diagnostics.md)",
       "A read-only web page (pose, health, faults, the camera frame with the detection overlay,\n"
       "the map and trajectory) and Prometheus metrics, served by `agvloc run` when `enabled` and\n"
       "by `agvloc replay --serve`. Its threads are not real-time and never hold up the loop.\n",
       ""},
      {"ranging_camera", "(second camera, landmarks on racks, docs/design/ranging.md)",
       "A forward or side camera reading the tag36h11 landmarks the site file places on racks,\n"
       "pillars and walls (`wall_landmarks`, docs/guide/site.md). Off by default: nothing changes\n"
       "for a vehicle without one. While the filter is uninitialised or lost, two landmarks in\n"
       "view give a fix; consecutive agreeing fixes are stacked (the calibration's doubt below\n"
       "is the same in every frame, so stacking never shrinks it) and initialise it once two\n"
       "agree and the stack is within 20 mm; while it tracks, each landmark is a range-bearing\n"
       "update (`fusion.range_bearing_*`). `agvloc replay` reads the recording's `ranging/`\n"
       "stream (docs/guide/recording.md) with this section enabled.\n",
       ""},
      {"ranging_camera.intrinsics", "(the second camera's calibration, OpenCV model)", "", ""},
      {"ranging_camera.mount", "(6-DoF, vehicle frame)", "", ""},
  };
  return sections;
}

std::string config_doc() {
  std::string out = kHeader;
  for (const Section& s : config_sections()) {
    out += "\n## " + s.path + (s.title.empty() ? "" : " " + s.title) + "\n";
    if (!s.intro.empty()) out += "\n" + s.intro;
    out += "\n| key | default | range | unit | meaning / trade-off |\n|---|---|---|---|---|\n";
    for (const Key& k : config_keys()) {
      if (k.section() != s.path) continue;
      const std::string def = k.required_live ? "required" : format_value(k, k.def);
      out += "| `" + k.name + "` | " + escape_cell(def) + " | " + escape_cell(format_range(k)) +
             " | " + escape_cell(k.unit) + " | " + escape_cell(k.doc) + " |\n";
    }
  }
  out +=
      "\n## Removed keys\n\nA configuration that still has one of these fails, naming the "
      "replacement.\n\n| key | use instead |\n|---|---|\n";
  for (const RemovedKey& r : removed_keys()) {
    out += "| `" + r.name + "` | `" + r.replacement + "` |\n";
  }
  return out;
}

}  // namespace agv::config

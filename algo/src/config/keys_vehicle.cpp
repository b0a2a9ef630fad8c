// Key table rows of the vehicle sections: camera, intrinsics, mounting, landmark, can, loop,
// replay. Trade-off texts are the documentation (docs/guide/config.md is generated from them).
#include "key_builders.hpp"

namespace agv::config::detail {

namespace {

void add_camera(std::vector<Key>* k) {
  using PF = hal::PixelFormatPreference;
  k->push_back(enumeration("camera.driver", AGV_AT(camera.driver), named(kCameraDriverNames),
                           "libcamera", "live backend (replay is used by `agvloc replay`)"));
  k->push_back(text("camera.id", AGV_AT(camera.camera.id), "",
                    "libcamera camera id, or the V4L2 device node (`/dev/video0`, required for "
                    "v4l2)"));
  k->push_back(text("camera.model", AGV_AT(camera.camera.model), "",
                    "libcamera: first camera whose model matches, when `id` is empty"));
  // width and height also set the camera model's image size (parse.cpp, after the section).
  k->push_back(integer("camera.width", AGV_AT(camera.camera.width_px), 16, 8192, 640,
                       {"px", "stream width; must match `intrinsics`"}));
  k->push_back(integer("camera.height", AGV_AT(camera.camera.height_px), 16, 8192, 480,
                       {"px", "stream height; must match `intrinsics`"}));
  k->push_back(number("camera.fps", AGV_AT(camera.camera.fps), 1.0, 240.0, 30.0,
                      {"Hz",
                       "more frames = more chances to see a landmark, more CPU; the "
                       "exposure must fit into one frame period"}));
  k->push_back(integer("camera.exposure_us", AGV_AT(camera.camera.exposure_us), 10, 100000, 500,
                       {"µs",
                        "short exposure = less motion blur (blur_px = v·t_exp / mm_per_px, "
                        "docs/guide/camera.md) but a darker image; 500 µs = 1 mm blur at 2 m/s"}));
  k->push_back(number("camera.analogue_gain", AGV_AT(camera.camera.analogue_gain), 1.0, 64.0, 1.0,
                      {"", "brighter but noisier"}));
  k->push_back(enumeration("camera.pixel_format", AGV_AT(camera.camera.pixel_format),
                           std::vector<std::pair<std::string, PF>>{
                               {"auto", PF::kAuto}, {"gray", PF::kGray}, {"yuv", PF::kYuv}},
                           "auto", "auto: gray if offered, else planar YUV, else packed"));
  k->push_back(integer("camera.buffer_count", AGV_AT(camera.camera.buffer_count), 2, 16, 4,
                       {"",
                        "driver buffers in flight (the loop holds at most 2): more survive "
                        "longer processing hiccups, cost memory"}));
  k->push_back(integer("camera.readout_us", AGV_AT(camera.camera.readout_us), 0, 100000, 0,
                       {"µs",
                        "rolling-shutter readout (0 = global shutter); shifts the "
                        "timestamp to the centre row"}));
  k->push_back(number("camera.timeout_ms", AGV_AT(camera.timeout_ms), 10.0, 60000.0, 500.0,
                      {"ms",
                       "no frame this long → `CameraStalled` in the status frame; fusion "
                       "keeps dead-reckoning. Shorter reports a dead camera sooner, longer "
                       "tolerates exposure and scheduling hiccups"}));
  k->push_back(number("camera.time_offset_ms", AGV_AT(camera.time_offset_ms), -500.0, 500.0, 0.0,
                      {"ms",
                       "vehicle clock = camera clock + offset (the vehicle's clock stamps "
                       "odometry and CAN; + = the camera's stamps are early, − = late): every "
                       "exposure stamp is moved onto the vehicle's clock as t + offset, for the "
                       "fix and for the search windows' prediction, on every loop (`run`, "
                       "`replay --realtime`, `replay --fast`). At 1 m/s every ms is 1 mm along "
                       "track at each fix; the filter has no state for it. From `calibrate "
                       "vehicle`"}));
}

void add_intrinsics(std::vector<Key>* k) {
  auto required = [](Key key) {
    key.required_live = true;
    return key;
  };
  k->push_back(required(number("intrinsics.fx", AGV_AT(camera_model.intrinsics.fx), 1.0, 1e6, 0.0,
                               {"px", "focal length x, from calibration; scales every fix"})));
  k->push_back(required(number("intrinsics.fy", AGV_AT(camera_model.intrinsics.fy), 1.0, 1e6, 0.0,
                               {"px", "focal length y, from calibration"})));
  k->push_back(required(number("intrinsics.cx", AGV_AT(camera_model.intrinsics.cx), -1e5, 1e5, 0.0,
                               {"px", "principal point x (pixel centres at integers)"})));
  k->push_back(required(number("intrinsics.cy", AGV_AT(camera_model.intrinsics.cy), -1e5, 1e5, 0.0,
                               {"px", "principal point y"})));
  k->push_back(number("intrinsics.k1", AGV_AT(camera_model.intrinsics.k1), -10.0, 10.0, 0.0,
                      {"", "radial distortion (OpenCV model); 0 = none"}));
  k->push_back(number("intrinsics.k2", AGV_AT(camera_model.intrinsics.k2), -10.0, 10.0, 0.0,
                      {"", "radial distortion"}));
  k->push_back(number("intrinsics.p1", AGV_AT(camera_model.intrinsics.p1), -1.0, 1.0, 0.0,
                      {"", "tangential distortion"}));
  k->push_back(number("intrinsics.p2", AGV_AT(camera_model.intrinsics.p2), -1.0, 1.0, 0.0,
                      {"", "tangential distortion"}));
  k->push_back(number("intrinsics.k3", AGV_AT(camera_model.intrinsics.k3), -10.0, 10.0, 0.0,
                      {"", "radial distortion"}));
}

void add_mounting(std::vector<Key>* k) {
  k->push_back(number("mounting.offset_x_mm", AGV_AT(camera_model.mount.offset_x_mm), -5000.0,
                      5000.0, 0.0, {"mm", "optical centre in the vehicle frame, x forward"}));
  k->push_back(number("mounting.offset_y_mm", AGV_AT(camera_model.mount.offset_y_mm), -5000.0,
                      5000.0, 0.0, {"mm", "optical centre in the vehicle frame, y left"}));
  k->push_back(deg_as_rad("mounting.yaw_deg", AGV_AT(camera_model.mount.yaw_rad), -180.0, 180.0,
                          0.0, {"deg", "image axes relative to the vehicle, counter-clockwise"}));
  k->push_back(number("mounting.height_mm", AGV_AT(camera_model.mount.height_mm), 10.0, 5000.0,
                      200.0, {"mm", "optical centre above the floor; scales every measurement"}));
  k->push_back(deg_as_rad("mounting.roll_deg", AGV_AT(camera_model.mount.roll_rad), -45.0, 45.0,
                          0.0,
                          {"deg", "camera tilt about image up; + = optical axis to image left"}));
  k->push_back(deg_as_rad("mounting.pitch_deg", AGV_AT(camera_model.mount.pitch_rad), -45.0, 45.0,
                          0.0,
                          {"deg", "camera tilt about image left; + = optical axis to image down"}));
}

void add_landmark(std::vector<Key>* k) {
  k->push_back(number("landmark.size_mm", AGV_AT(landmark_size_mm), 10.0, 1000.0, 60.0,
                      {"mm",
                       "outer side of the dark square: the QR landmark's border, the "
                       "tag36h11 tag's black square (docs/design/landmark.md)"}));
  k->push_back(enumeration(
      "landmark.family", AGV_AT(vision.family), named(kLandmarkFamilyNames), "qr",
      "printed landmarks on this floor: the QR landmark (identity and pose in the code) or "
      "AprilTag tag36h11 (libapriltag detection, same edge-fit pose; the id needs the map, so "
      "without landmark.map every tag is \"not in the map\": `agvloc run` refuses tag36h11 "
      "without a map, and map ids above 586, the family's last). Tags: only the outer edge is "
      "fitted"));
  k->push_back(boolean(
      "landmark.tag_corner_search", AGV_AT(vision.tag_corner_search), true,
      "tag36h11: when libapriltag finds no quad and no trusted prediction places a tag, find the "
      "black square from its outer corners as the QR family does and read the tag's code there "
      "(an occluder joining the border to the floor breaks libapriltag's quad, not three "
      "corners; docs/design/landmark.md). Costs the corner search on frames without a tag. "
      "false: libapriltag and the prediction only"));
  k->push_back(text("landmark.map", AGV_AT(map_file), "",
                    "landmark map file, relative to the configuration file; empty = poses from "
                    "the QR payload only (id-only payloads are then rejected)"));
}

void add_can(std::vector<Key>* k) {
  k->push_back(text("can.interface", AGV_AT(can.interface), "can0",
                    "SocketCAN interface: a Linux interface name, 1..15 characters without '/', "
                    "':' or whitespace (checked: a name that can never open would be retried "
                    "forever)"));
  k->push_back(boolean("can.extended_ids", AGV_AT(can.extended_ids), false,
                       "29-bit IDs for all frames (widens the ID ranges below)"));
  k->push_back(can_id("can.base_id", AGV_AT(can.base_id), 0x300,
                      "ID of AGV_PoseXY; the other output frames follow"));
  k->push_back(enumeration("can.odometry.mode", AGV_AT(can.odometry_mode),
                           named(kOdometryModeNames), "v_omega",
                           "MC_OdomTwist (v, ω) or MC_OdomWheels (left/right wheel speed)"));
  k->push_back(can_id("can.odometry.id", AGV_AT(can.odometry_id), 0,
                      "0 = DBC default: base_id + 0x10 (wheels) / + 0x11 (v_omega)"));
  k->push_back(boolean("can.odometry.protected", AGV_AT(can.odometry_protected), true,
                       "check CRC and alive counter of odometry frames; false only for motor "
                       "controllers that cannot compute them (then only ID and length are "
                       "checked)"));
  // Stored once, where fusion reads it; the decoder and the odometry correction take it from
  // there (protocol_config, the firmware's localizer_config).
  k->push_back(number("can.odometry.track_width_mm", AGV_AT(fusion.slip.wheel_track_mm), 50.0,
                      5000.0, kDefaultTrackWidthMm,
                      {"mm",
                       "distance between the drive wheels, in both odometry modes. Wheels mode: "
                       "converts wheel speeds to v, ω. The lever of "
                       "`odometry.yaw_per_metre_deg`'s speed term (unequal wheels creep a turn "
                       "on the spot by yaw_per_metre · track² / 4 per radian) and of the "
                       "fusion's slip correction (a slip's yaw-rate error times half of it is "
                       "the slip's speed error, while a gyro is fitted)"}));
  k->push_back(number("can.odometry.wheel_speed_scale", AGV_AT(can.wheel_speed_scale), 0.5, 2.0,
                      1.0, {"", "wheels mode: calibrates wheel radius error"}));
  // Stored once, where it is used (the filter's flag and the core's pose validity both read
  // fusion.odom_timeout_ns); the key keeps its CAN name because the odometry comes over CAN.
  k->push_back(ms_as_ns(
      "can.odometry.timeout_ms", AGV_AT(fusion.health.odom_timeout_ns), 5.0, 10000.0, 100.0,
      "the one odometry timeout: no valid odometry this long → `OdomTimeout`, pose "
      "flagged invalid and the filter lost. Short reacts fast to a dead controller but "
      "trips on bus jitter; 100 ms = 10 missed frames at 100 Hz"));
  k->push_back(boolean(
      "can.gyro.enabled", AGV_AT(can.gyro_enabled), false,
      "receive the yaw rate from an IMU as `AGV_Gyro` (docs/guide/can.md): it carries the heading "
      "through wheel slip, which the wheels cannot see (1.7° in the demo's slipping turn). "
      "Costs one more receive filter and a second input that can fail: silent, saturated or "
      "rejected frames set `FaultImuTimeout` / `FaultImuE2E`, and the filter falls back to the "
      "wheels. false = no gyro, the frame is ignored like any other ID"));
  k->push_back(can_id("can.gyro.id", AGV_AT(can.gyro_id), 0,
                      "0 = DBC default: base_id + 0x12; same ID type as the odometry "
                      "(`can.extended_ids`); must not equal an output or the odometry ID"));
  k->push_back(boolean("can.gyro.protected", AGV_AT(can.gyro_protected), true,
                       "check CRC and alive counter of gyro frames; false only for a sender "
                       "that cannot compute them (then a corrupted or repeated rate reaches the "
                       "heading unnoticed; only ID and length are checked)"));
  k->push_back(number("can.gyro.timeout_ms", AGV_AT(can.gyro_timeout_ms), 5.0, 10000.0, 100.0,
                      {"ms",
                       "no usable gyro sample this long → `FaultImuTimeout` (with "
                       "`enabled` also when none arrived since the start); the filter uses "
                       "the wheels' yaw rate meanwhile. Short reports a dead IMU sooner but "
                       "trips on bus jitter; 100 ms = 10 missed frames at 100 Hz"}));
}

// The gyro correction (localizer::GyroCorrection), applied to every gyro sample before fusion.
void add_imu(std::vector<Key>* k) {
  k->push_back(number("imu.scale", AGV_AT(imu.scale), 0.5, 2.0, 1.0,
                      {"",
                       "rate' = scale · rate + bias. From the IMU's calibration (or a turn in "
                       "place between two fixes); the filter's gyro scale state learns the rest "
                       "but needs fixes. Heading error grows with every turn: 1 % of a 90° "
                       "turn is 0.9°. A sensor mounted upside down is corrected by the sender "
                       "(`GyroZ` is about the vehicle's z axis, up)"}));
  k->push_back(deg_as_rad("imu.bias_degps", AGV_AT(imu.bias_radps), -30.0, 30.0, 0.0,
                          {"deg/s",
                           "added after the scale (the correction: minus the measured bias at "
                           "standstill over the scale). A wrong value is heading drift the "
                           "filter's gyro bias state must first learn; 0.1 deg/s = 0.6° per "
                           "minute without fixes"}));
  k->push_back(number("imu.time_offset_ms", AGV_AT(imu.time_offset_ms), -500.0, 500.0, 0.0,
                      {"ms",
                       "gyro clock = vehicle clock + offset (+ = gyro stamps late); fusion uses "
                       "t − offset. CAN samples are stamped on receipt, so this is the sensor's "
                       "filter delay plus its transmit latency; at 1 rad/s every ms is 0.057° "
                       "of heading in a turn"}));
  k->push_back(enumeration(
      "imu.source", AGV_AT(imu.source), named(kImuSourceNames), "can",
      "where the yaw rate comes from. can: `AGV_Gyro` on the bus when `can.gyro.enabled` (the "
      "IMU's own controller stamps and protects it). iio: an IMU on the vehicle computer's own "
      "bus (I2C/SPI) through its Linux IIO driver (`imu.iio_*`, docs/design/fusion.md \"Gyro from "
      "a "
      "Linux IIO device\"): stamped by the kernel on the loop clock, no CAN latency, but no E2E "
      "protection and one more thread. none: wheels only. iio and none "
      "refuse `can.gyro.enabled: true` (one gyro source). With iio, `can.gyro.timeout_ms` is "
      "the IMU timeout"));
  k->push_back(text("imu.iio_device", AGV_AT(imu.iio_device), "",
                    "IIO device name as in /sys/bus/iio/devices/iio:deviceN/name (e.g. "
                    "`bmi160`, `mpu6050`), or `iio:deviceN` (changes with probe order: prefer "
                    "the name). Required with `source: iio`; must have a buffered `anglvel_z`"));
  k->push_back(text("imu.iio_trigger", AGV_AT(imu.iio_trigger), "",
                    "IIO trigger that clocks the samples (e.g. `bmi160-dev0`, the chip's "
                    "data-ready interrupt, or an hrtimer trigger's name). Empty = the trigger the "
                    "device already has; the chip's own data-ready trigger gives the steadiest "
                    "sample times, a software trigger adds scheduling jitter to every stamp"));
  k->push_back(number("imu.iio_rate_hz", AGV_AT(imu.iio_rate_hz), 0.0, 4000.0, 200.0,
                      {"Hz",
                       "`sampling_frequency` asked of the device (it rounds to what it supports; "
                       "the log names the result). Higher follows turns more closely and "
                       "averages noise if the chip filters, costs CPU (one wake-up per few "
                       "samples); 200 Hz is 2 samples per 100 Hz output period. 0 = leave the "
                       "device's rate (the trigger's frequency decides)"}));
}

// The odometry correction (localizer::OdometryCorrection), the calibration model's equations.
void add_odometry(std::vector<Key>* k) {
  k->push_back(number("odometry.speed_scale", AGV_AT(odometry.speed_scale), 0.5, 2.0, 1.0,
                      {"",
                       "v' = speed_scale · v. From `calibrate vehicle`; a 1 % error is 10 mm "
                       "per metre between landmarks. The filter's online scale state corrects "
                       "the rest but needs fixes to learn it (worst right after a start)"}));
  k->push_back(number("odometry.yaw_rate_scale", AGV_AT(odometry.yaw_rate_scale), 0.5, 2.0, 1.0,
                      {"",
                       "ω' = yaw_rate_scale · ω + bias. From `calibrate vehicle` (v_omega "
                       "mode; in wheels mode it is folded into `can.odometry.track_width_mm`). "
                       "Heading error grows with every turn: 1 % of a 90° turn is 0.9°"}));
  k->push_back(deg_as_rad("odometry.yaw_rate_bias_degps", AGV_AT(odometry.yaw_rate_bias_radps),
                          -30.0, 30.0, 0.0,
                          {"deg/s",
                           "added after the scale (the correction: minus the reported bias "
                           "over the scale). A wrong value turns into heading drift the "
                           "filter's bias state must first learn; 0.1 deg/s = 0.6° per "
                           "minute without fixes"}));
  k->push_back(deg_as_rad("odometry.yaw_per_metre_deg", AGV_AT(odometry.yaw_per_metre_rad), -10.0,
                          10.0, 0.0,
                          {"deg/m",
                           "unequal wheels: ω' += this · v and v' += this · track² / 4 · ω (v, "
                           "ω as read; track `can.odometry.track_width_mm`). A right wheel "
                           "reading 0.4 % more than the left on a 0.5 m track bends a straight "
                           "run 0.46° per metre to the left and creeps a turn on the spot 0.5 mm "
                           "per radian forward: c = −0.46. From `calibrate vehicle`, which "
                           "otherwise puts the curvature "
                           "into the camera yaw and the creep into the lateral offset; the "
                           "filter's bias state cannot follow it, since it changes with speed"}));
}

void add_loop(std::vector<Key>* k) {
  k->push_back(number("loop.output_rate_hz", AGV_AT(loop.output_rate_hz), 1.0, 1000.0, 100.0,
                      {"Hz", "pose, velocity, quality, status frames per second"}));
  k->push_back(number("loop.heartbeat_rate_hz", AGV_AT(loop.heartbeat_rate_hz), 0.1, 100.0, 1.0,
                      {"Hz", "heartbeat frames per second"}));
  k->push_back(integer("loop.realtime_priority", AGV_AT(loop.realtime_priority), 0, 99, 0,
                       {"", "SCHED_FIFO priority of the output thread; 0 = normal scheduling"}));
  k->push_back(integer(
      "loop.vision_priority", AGV_AT(loop.vision_priority), 0, 98, 0,
      {"",
       "SCHED_FIFO priority of the capture and vision threads; 0 = normal scheduling. Under "
       "CPU contention the worker no longer queues behind other processes, which shortens "
       "exposure → vision start and the vision time itself (the end-to-end tail with "
       "`pose_on_fix`). Cost: while a frame is processed, normal tasks on that core wait "
       "(vision p99 1.1–1.4 ms per frame; the whole process used 8 % of a core at 30 fps, "
       "docs/design/performance.md). Must be below `realtime_priority` so the output never waits "
       "for vision (rejected at start otherwise)"}));
  k->push_back(
      integer("loop.spin_before_deadline_us", AGV_AT(loop.spin_before_deadline_us), 0, 2000, 0,
              {"µs",
               "hybrid wait of the output thread: `clock_nanosleep(TIMER_ABSTIME)` to deadline − "
               "this, then busy-poll the clock to the deadline. Trade-off: CPU vs jitter — the "
               "kernel's wake-up latency up to this many µs no longer reaches the period, for up "
               "to this much busy CPU per period at the output thread's priority (100 µs at "
               "100 Hz = 1 % of a core); a wake-up later than the spin window is not hidden. At "
               "most half the output period (rejected otherwise). 0 = plain absolute sleep"}));
  k->push_back(text(
      "loop.realtime_cpus", AGV_AT(loop.realtime_cpus), "",
      "CPUs (kernel list syntax: \"3\", \"2-3\", \"0,2\") the output thread runs on; empty = "
      "any. With `loop.service_cpus` on other cores, the MQTT publisher and the diagnostics page "
      "(and the kernel work their sockets cause) no longer share a core with it. A CPU the kernel "
      "refuses is reported at start and left unpinned. Strongest with the core isolated from the "
      "scheduler as well (`isolcpus=`, docs/guide/deployment.md)"));
  k->push_back(text(
      "loop.vision_cpus", AGV_AT(loop.vision_cpus), "",
      "CPUs the capture and vision threads run on; empty = any. May overlap the other two "
      "lists: vision runs below the output thread's priority. Trade-off: on one CPU capture and "
      "vision, at the same priority, wait for each other (replay with both and the output "
      "thread on one CPU of the 2-core test machine: exposure → vision start p50 3.1 ms instead "
      "of 0.2 ms, the capture thread decoding the next PNG)"));
  k->push_back(text("loop.service_cpus", AGV_AT(loop.service_cpus), "",
                    "CPUs the network services run on: the MQTT publisher and the diagnostics "
                    "page's listener and workers; empty = any. Must not overlap "
                    "`loop.realtime_cpus` (rejected at start)"));
  k->push_back(boolean("loop.lock_memory", AGV_AT(loop.lock_memory), false,
                       "mlockall at start (needs CAP_IPC_LOCK or LimitMEMLOCK); also applied by "
                       "`replay --realtime`. Pages are locked as they are first touched "
                       "(`MCL_ONFAULT`), so the resident set does not grow (prefaulting "
                       "everything mapped took the benchmark from 25 to 90 MB)"));
  k->push_back(number("loop.log_period_s", AGV_AT(loop.log_period_s), 0.0, 3600.0, 10.0,
                      {"s", "periodic statistics line on stderr; 0 = off"}));
  k->push_back(boolean(
      "loop.pose_on_fix", AGV_AT(loop.pose_on_fix), true,
      "also send the pose pair right after each fused fix: the correction reaches the bus one "
      "vision time after exposure instead of up to one period later (with the shipped real-time "
      "settings end to end p99 1.5–2.6 ms instead of 12–14 ms, docs/design/performance.md); the "
      "extra "
      "pose pairs make pose frames irregularly spaced (receivers must not derive speed from "
      "pose-frame intervals). The fixed-rate stream (pose, velocity, quality, status every "
      "period) runs either way. false = fixed-rate stream only"));
}

}  // namespace

void add_vehicle_keys(std::vector<Key>* keys) {
  add_camera(keys);
  add_intrinsics(keys);
  add_mounting(keys);
  add_landmark(keys);
  add_can(keys);
  add_odometry(keys);
  add_imu(keys);
  add_loop(keys);
}

void add_replay_keys(std::vector<Key>* keys) {
  keys->push_back(number("replay.fix_delay_ms", AGV_AT(replay_fix_delay_ms), 0.0, 1000.0, 30.0,
                         {"ms",
                          "`--fast` only: time from exposure to the fix reaching fusion "
                          "(live, it is whatever the vision worker takes); at most "
                          "`fusion.max_fix_delay_ms`, or every fix is dropped as too old"}));
}

}  // namespace agv::config::detail

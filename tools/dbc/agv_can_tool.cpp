// agv_can_tool: renders the CAN contract and writes the interop test data.
//   agv_can_tool dbc [base_id [ext]]        DBC for a base ID (default 0x300, 11-bit) to stdout
//   agv_can_tool doc-table                  Markdown frame table of docs/guide/can.md to stdout
//   agv_can_tool interop LOG EXPECTED       frames the codec wrote (candump -l) + the physical
//                                           values each must decode to (JSON lines), for
//                                           tools/dbc/check_candied.cjs
//   agv_can_tool same-frames LOG_A LOG_B    exit 0 when both candump -l logs hold the same
//                                           frames (ID, type, length, data) in the same order
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "agv/protocol/candump.hpp"
#include "agv/protocol/codec.hpp"
#include "agv/protocol/dbc.hpp"

namespace p = agv::protocol;

namespace {

struct Expect {
  std::string name;
  double value;
  double tol;
};

struct Item {
  agv::hal::CanFrame frame;
  std::vector<Expect> expect;
};

const p::SignalDef& sig(p::Msg m, const char* name) {
  return *p::find_signal(p::message_def(m), name);
}

// Expected decoded value of `phys` written into `s`: the value itself within half an LSB, or
// the range limit when it saturates.
Expect expect_phys(p::Msg m, const char* name, double phys) {
  const p::SignalDef& s = sig(m, name);
  if (phys >= s.max) return {name, s.max, 1e-9 * std::max(1.0, std::fabs(s.max))};
  if (phys <= s.min) return {name, s.min, 1e-9 * std::max(1.0, std::fabs(s.min))};
  return {name, phys, s.scale * 0.5 + 1e-9 * std::max(1.0, std::fabs(phys))};
}
Expect exact(const char* name, double v) { return {name, v, 1e-9}; }

std::string json_line(const agv::hal::CanFrame& f, const std::vector<Expect>& ex) {
  std::string s = "{\"id\":" + std::to_string(f.id) +
                  ",\"extended\":" + (f.extended ? "true" : "false") + ",\"signals\":{";
  char buf[128];
  for (std::size_t i = 0; i < ex.size(); ++i) {
    std::snprintf(buf, sizeof buf, "%s\"%s\":[%.17g,%.17g]", i ? "," : "", ex[i].name.c_str(),
                  ex[i].value, ex[i].tol);
    s += buf;
  }
  return s + "}}";
}

// The generator and ranges the random test values are drawn from.
struct Draws {
  std::mt19937 rng{20261121};
  std::uniform_real_distribution<double> pos{-900000.0, 900000.0}, ang{-3.14159, 3.14159},
      vel{-40.0, 40.0}, omg{-4.0, 4.0}, sig_mm{0.0, 7000.0}, sig_rad{0.0, 7.0}, lat{0.0, 7000.0};
};

// Pose frames (AGV_PoseXY and AGV_PoseHeading): range limits, then random poses.
void add_pose_items(p::Encoder* enc, Draws* d, std::vector<Item>* items) {
  std::vector<p::PoseOut> poses = {{0, 0, 0, 0, true},
                                   {838860.7, -838860.8, 3.1415, 6553.5, true},
                                   {-838860.8, 838860.7, -3.1415, 0.1, true},
                                   {1e9, -1e9, 1.0, 1e9, true},
                                   {12345.6, -0.1, 0.0001, 2.5, false}};
  for (int i = 0; i < 40; ++i)
    poses.push_back({d->pos(d->rng), d->pos(d->rng), d->ang(d->rng), d->lat(d->rng), true});
  for (const p::PoseOut& po : poses) {
    Item xy, hd;
    const std::uint8_t counter = enc->next_counter(p::Msg::kPoseXY);
    enc->encode_pose(po, &xy.frame, &hd.frame);
    xy.expect = {exact("AliveCounter", counter), exact("PoseValid", po.valid ? 1 : 0),
                 expect_phys(p::Msg::kPoseXY, "X", po.x_mm),
                 expect_phys(p::Msg::kPoseXY, "Y", po.y_mm)};
    hd.expect = {exact("AliveCounter", counter), exact("PoseValid", po.valid ? 1 : 0),
                 expect_phys(p::Msg::kPoseHeading, "Theta", po.theta_rad),
                 expect_phys(p::Msg::kPoseHeading, "Latency", po.latency_ms)};
    items->push_back(xy);
    items->push_back(hd);
  }
}

void add_velocity_items(p::Encoder* enc, Draws* d, std::vector<Item>* items) {
  for (int i = 0; i < 30; ++i) {
    Item it;
    const p::VelocityOut v{d->vel(d->rng), d->omg(d->rng), i % 7 != 0};
    enc->encode_velocity(v, &it.frame);
    it.expect = {exact("VelocityValid", v.valid ? 1 : 0),
                 expect_phys(p::Msg::kVelocity, "V", v.v_mps),
                 expect_phys(p::Msg::kVelocity, "Omega", v.omega_radps)};
    items->push_back(it);
  }
}

void add_quality_items(p::Encoder* enc, Draws* d, std::vector<Item>* items) {
  for (int i = 0; i < 30; ++i) {
    Item it;
    const p::QualityOut q{d->sig_mm(d->rng), d->sig_mm(d->rng), d->sig_rad(d->rng), true};
    enc->encode_quality(q, &it.frame);
    it.expect = {exact("QualityValid", 1), expect_phys(p::Msg::kQuality, "SigmaX", q.sigma_x_mm),
                 expect_phys(p::Msg::kQuality, "SigmaY", q.sigma_y_mm),
                 expect_phys(p::Msg::kQuality, "SigmaTheta", q.sigma_theta_rad)};
    items->push_back(it);
  }
}

// Status frames: every health, landmark ids with and without a fix, random fault and rejection
// bits.
void add_status_items(p::Encoder* enc, Draws* d, std::vector<Item>* items) {
  const char* fault_names[] = {"FaultCameraStalled", "FaultCameraError",     "FaultOdomTimeout",
                               "FaultOdomE2E",       "FaultCanErrorPassive", "FaultCanBusOff",
                               "FaultNoMap",         "FaultLoopOverrun",     "FaultImuTimeout",
                               "FaultImuE2E"};
  const char* reject_names[] = {"RejectGate", "RejectUnknownLandmark", "RejectDecodeFailed",
                                "RejectGeometry", "RejectFixTooOld"};
  for (int i = 0; i < 20; ++i) {
    Item it;
    p::StatusOut s;
    s.health = static_cast<p::Health>(i % 4);
    s.last_landmark_id = static_cast<std::uint16_t>(i * 3271);
    s.last_landmark_valid = i % 3 != 0;  // also id 0 (i == 0) both ways: none yet and tag 0
    s.time_since_fix_ms = i == 0 ? -1.0 : i * 997.0;
    s.faults = static_cast<std::uint16_t>(d->rng() & 0x3FF);
    s.rejections = static_cast<std::uint8_t>(d->rng() & 0x1F);
    enc->encode_status(s, &it.frame);
    it.expect = {exact("Health", i % 4), exact("LastLandmarkId", s.last_landmark_id),
                 exact("LastLandmarkValid", s.last_landmark_valid ? 1 : 0),
                 exact("TimeSinceFix", i == 0 ? 65535.0 : i * 997.0)};
    for (int b = 0; b < 10; ++b) it.expect.push_back(exact(fault_names[b], (s.faults >> b) & 1));
    for (int b = 0; b < 5; ++b) {
      it.expect.push_back(exact(reject_names[b], (s.rejections >> b) & 1));
    }
    items->push_back(it);
  }
}

void add_heartbeat_item(p::Encoder* enc, std::vector<Item>* items) {
  Item it;
  enc->encode_heartbeat({1, 22, 255, 3600.5}, &it.frame);
  it.expect = {exact("ProtocolVersion", p::kProtocolVersion), exact("SwMajor", 1),
               exact("SwMinor", 22), exact("SwPatch", 255), exact("Uptime", 3600)};
  items->push_back(it);
}

// Odometry input frames as a motor controller would send them.
void add_odometry_items(const p::ProtocolConfig& cfg, Draws* d, std::vector<Item>* items) {
  for (p::Msg m : {p::Msg::kOdomWheels, p::Msg::kOdomTwist}) {
    const p::MessageDef& def = p::message_def(m);
    for (int i = 0; i < 15; ++i) {
      Item it;
      it.frame.id = p::can_id_of(cfg, m);
      it.frame.len = 8;
      const double a = d->vel(d->rng),
                   b = m == p::Msg::kOdomWheels ? d->vel(d->rng) : d->omg(d->rng);
      p::put_phys(def.signals[2], a, it.frame.data);
      p::put_phys(def.signals[3], b, it.frame.data);
      p::e2e_protect(def.data_id, static_cast<std::uint8_t>(i % 15), it.frame.data);
      it.expect = {exact("AliveCounter", i % 15), expect_phys(m, def.signals[2].name, a),
                   expect_phys(m, def.signals[3].name, b)};
      items->push_back(it);
    }
  }
}

// Gyro input frames (AGV_Gyro) as an IMU would send them; yaw rates beyond the range saturate.
void add_gyro_items(const p::ProtocolConfig& cfg, Draws* d, std::vector<Item>* items) {
  std::uniform_real_distribution<double> yaw(-100.0, 100.0), tilt(-5.0, 5.0);
  for (int i = 0; i < 20; ++i) {
    Item it;
    p::GyroSample g;
    g.gyro_z_radps = i == 0 ? 0.001 * 3.14159265358979 / 180.0 : yaw(d->rng);
    g.gyro_x_radps = tilt(d->rng);
    g.gyro_y_radps = tilt(d->rng);
    g.saturated = (d->rng() & 3) == 0;
    p::encode_gyro(cfg, g, static_cast<std::uint8_t>(i % 15), &it.frame);
    it.expect = {exact("AliveCounter", i % 15), exact("Saturated", g.saturated ? 1 : 0),
                 expect_phys(p::Msg::kGyro, "GyroZ", g.gyro_z_radps),
                 expect_phys(p::Msg::kGyro, "GyroX", g.gyro_x_radps),
                 expect_phys(p::Msg::kGyro, "GyroY", g.gyro_y_radps)};
    items->push_back(it);
  }
}

// The frames to LOG (candump -l) and what each must decode to to EXPECTED (JSON lines).
int write_interop(const char* log_path, const char* expected_path, const std::vector<Item>& items) {
  std::FILE* log = std::fopen(log_path, "w");
  std::FILE* exp = std::fopen(expected_path, "w");
  if (!log || !exp) {
    std::fprintf(stderr, "cannot write %s / %s\n", log_path, expected_path);
    return 1;
  }
  std::int64_t t = 1'763'700'000'000'000'000;
  for (const Item& it : items) {
    p::CandumpRecord r;
    r.t_ns = t;
    t += 1'000'000;
    r.iface = "can0";
    r.frame = it.frame;
    std::fprintf(log, "%s\n", p::format_candump_line(r).c_str());
    std::fprintf(exp, "%s\n", json_line(it.frame, it.expect).c_str());
  }
  const bool ok = std::fclose(log) == 0 && std::fclose(exp) == 0;
  std::fprintf(stderr, "agv_can_tool: wrote %zu frames\n", items.size());
  return ok ? 0 : 1;
}

int interop(const char* log_path, const char* expected_path) {
  const p::ProtocolConfig cfg;
  p::Encoder enc(cfg);
  std::vector<Item> items;
  Draws d;
  add_pose_items(&enc, &d, &items);
  add_velocity_items(&enc, &d, &items);
  add_quality_items(&enc, &d, &items);
  add_status_items(&enc, &d, &items);
  add_heartbeat_item(&enc, &items);
  add_odometry_items(cfg, &d, &items);
  add_gyro_items(cfg, &d, &items);
  return write_interop(log_path, expected_path, items);
}

bool read_log(const char* path, std::vector<p::CandumpRecord>* out) {
  std::ifstream in(path);
  if (!in) {
    std::fprintf(stderr, "%s: cannot open\n", path);
    return false;
  }
  std::string line, err;
  int n = 0;
  while (std::getline(in, line)) {
    ++n;
    if (line.empty()) continue;
    p::CandumpRecord r;
    if (!p::parse_candump_line(line, &r, &err)) {
      std::fprintf(stderr, "%s:%d: %s\n", path, n, err.c_str());
      return false;
    }
    out->push_back(r);
  }
  return true;
}

int same_frames(const char* a_path, const char* b_path) {
  std::vector<p::CandumpRecord> a, b;
  if (!read_log(a_path, &a) || !read_log(b_path, &b)) return 1;
  if (a.size() != b.size() || a.empty()) {
    std::fprintf(stderr, "frame counts differ: %zu vs %zu\n", a.size(), b.size());
    return 1;
  }
  for (std::size_t i = 0; i < a.size(); ++i) {
    const agv::hal::CanFrame &x = a[i].frame, &y = b[i].frame;
    if (x.id != y.id || x.extended != y.extended || x.len != y.len ||
        std::memcmp(x.data, y.data, x.len) != 0 || a[i].rtr != b[i].rtr) {
      std::fprintf(stderr, "frame %zu differs\n", i + 1);
      return 1;
    }
  }
  std::printf("PASS: %zu frames identical\n", a.size());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string cmd = argc > 1 ? argv[1] : "";
  if (cmd == "dbc") {
    p::ProtocolConfig cfg;
    if (argc > 2) cfg.base_id = static_cast<std::uint32_t>(std::strtoul(argv[2], nullptr, 0));
    if (argc > 3) cfg.extended_ids = cfg.odometry.extended_id = std::strcmp(argv[3], "ext") == 0;
    const std::string err = p::validate(cfg);
    if (!err.empty()) {
      std::fprintf(stderr, "agv_can_tool: %s\n", err.c_str());
      return 1;
    }
    std::fputs(p::render_dbc(cfg).c_str(), stdout);
    return 0;
  }
  if (cmd == "doc-table") {
    std::fputs(p::render_markdown_table(p::ProtocolConfig{}).c_str(), stdout);
    return 0;
  }
  if (cmd == "interop" && argc == 4) return interop(argv[2], argv[3]);
  if (cmd == "same-frames" && argc == 4) return same_frames(argv[2], argv[3]);
  std::fprintf(stderr,
               "usage: agv_can_tool dbc [base_id [ext]] | doc-table | interop LOG EXPECTED |\n"
               "                    same-frames LOG_A LOG_B\n");
  return 2;
}

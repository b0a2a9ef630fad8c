// IIO gyro check for the VM (and for a real IMU on the vehicle), through drivers/iio:
//   imu_vm_check --device NAME [--trigger NAME] [--rate-hz R] [--samples N]
//                [--raw-z Z --raw-x X --raw-y Y --scale S] [--set-cmd CMD --raw-z2 Z2]
//                [--remove PATH=VALUE] [--timeout-ms T]
// Starts the driver and checks: the device reports the rate the driver set (--rate-hz; also read
// back from sysfs), N samples arrive, each rate equals raw x scale (the register values the
// guest wrote, the scale the kernel reports for the range, which must equal --scale), timestamps
// strictly increase and lie on CLOCK_MONOTONIC (between the start and the read, not on
// CLOCK_REALTIME). --set-cmd runs a command that writes new registers (raw z becomes --raw-z2)
// and every sample stamped after it returned must carry the new value. --remove writes VALUE to
// PATH (e.g. an i2c adapter's delete_device) and read() must then report kDisconnected, not crash
// or hang. Prints measured numbers; exits 0 when every check passed, 1 otherwise, 2 on bad usage.
#include <time.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include "agv/hal/imu.hpp"
#include "agv/iio/iio_imu.hpp"

namespace {

using agv::hal::ImuStatus;

int g_failures = 0;

void fail(const std::string& msg) {
  std::printf("FAIL: %s\n", msg.c_str());
  std::fflush(stdout);
  ++g_failures;
}

std::int64_t mono_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec * 1'000'000'000LL + ts.tv_nsec;
}

std::int64_t real_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return ts.tv_sec * 1'000'000'000LL + ts.tv_nsec;
}

struct Args {
  agv::hal::ImuConfig cfg;
  int samples = 40;
  bool have_raw = false;
  long raw_x = 0, raw_y = 0, raw_z = 0, raw_z2 = 0;
  double scale = 0.0;
  std::string set_cmd;
  std::string remove_path, remove_value;
  std::int64_t timeout_ns = 10'000'000'000;  // per read: TCG under load is slow
};

bool parse(int argc, char** argv, Args* a) {
  a->cfg.rate_hz = 0.0;
  a->cfg.buffer_samples = 4;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    if (i + 1 >= argc) return false;
    const std::string v = argv[++i];
    if (k == "--device")
      a->cfg.device = v;
    else if (k == "--trigger")
      a->cfg.trigger = v;
    else if (k == "--rate-hz")
      a->cfg.rate_hz = std::atof(v.c_str());
    else if (k == "--samples")
      a->samples = std::atoi(v.c_str());
    else if (k == "--raw-x")
      a->raw_x = std::atol(v.c_str());
    else if (k == "--raw-y")
      a->raw_y = std::atol(v.c_str());
    else if (k == "--raw-z")
      a->raw_z = std::atol(v.c_str()), a->have_raw = true;
    else if (k == "--raw-z2")
      a->raw_z2 = std::atol(v.c_str());
    else if (k == "--scale")
      a->scale = std::atof(v.c_str());
    else if (k == "--set-cmd")
      a->set_cmd = v;
    else if (k == "--timeout-ms")
      a->timeout_ns = std::atoll(v.c_str()) * 1'000'000LL;
    else if (k == "--remove") {
      const auto eq = v.find('=');
      if (eq == std::string::npos) return false;
      a->remove_path = v.substr(0, eq);
      a->remove_value = v.substr(eq + 1);
    } else {
      return false;
    }
  }
  return !a->cfg.device.empty() && a->samples > 1;
}

// One sample, waiting up to the timeout; false on a status other than kOk / kTimeout.
ImuStatus read_one(agv::iio::IioImu& imu, const Args& a, agv::hal::GyroSample* s) {
  const std::int64_t t_end = mono_ns() + a.timeout_ns;
  while (true) {
    std::size_t n = 0;
    const ImuStatus st = imu.read(s, 1, &n, 200'000'000);
    if (st == ImuStatus::kOk && n == 1) return st;
    if (st != ImuStatus::kTimeout && st != ImuStatus::kOk) return st;
    if (mono_ns() > t_end) return ImuStatus::kTimeout;
  }
}

void check_value(const char* axis, double got, long raw, double scale) {
  const double want = static_cast<double>(raw) * scale;
  if (std::fabs(got - want) > 1e-9) {
    fail(std::string(axis) + " = " + std::to_string(got) + " rad/s, expected " +
         std::to_string(want) + " (raw " + std::to_string(raw) + " x scale)");
  }
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  if (!parse(argc, argv, &a)) {
    std::fprintf(stderr, "usage: see the comment at the top of imu_vm_check.cpp\n");
    return 2;
  }
  agv::iio::IioImu imu(a.cfg);
  const std::int64_t t_start = mono_ns();
  const ImuStatus st = imu.start();
  if (st != ImuStatus::kOk) {
    fail(std::string("start: ") + agv::hal::to_string(st) + ": " + imu.last_error());
    return 1;
  }
  const agv::hal::ImuStats s0 = imu.stats();
  std::printf(
      "imu_vm_check: started %s, trigger %s, rate %.3f Hz (asked %.3f), z scale %.9f "
      "rad/s/LSB\n",
      a.cfg.device.c_str(), imu.trigger_name().c_str(), s0.rate_hz, a.cfg.rate_hz, imu.z_scale());
  if (a.cfg.rate_hz > 0.0 && std::fabs(s0.rate_hz - a.cfg.rate_hz) > 1e-6) {
    fail("device rate " + std::to_string(s0.rate_hz) + " Hz, driver asked " +
         std::to_string(a.cfg.rate_hz));
  }
  if (a.scale > 0.0 && std::fabs(imu.z_scale() - a.scale) > 1e-12) {
    fail("z scale " + std::to_string(imu.z_scale()) + ", expected " + std::to_string(a.scale));
  }
  const double scale = imu.z_scale();

  std::vector<agv::hal::GyroSample> got;
  std::int64_t last_t = INT64_MIN;
  auto take = [&](long want_z, std::int64_t new_after_ns) {
    agv::hal::GyroSample s;
    const ImuStatus r = read_one(imu, a, &s);
    if (r != ImuStatus::kOk) {
      fail(std::string("read: ") + agv::hal::to_string(r) + ": " + imu.last_error());
      return false;
    }
    const std::int64_t now = mono_ns();
    if (s.t_ns <= last_t) fail("timestamp not increasing: " + std::to_string(s.t_ns));
    if (s.t_ns < t_start - 1'000'000'000 || s.t_ns > now) {
      fail("timestamp " + std::to_string(s.t_ns) + " not on CLOCK_MONOTONIC (start " +
           std::to_string(t_start) + ", now " + std::to_string(now) + ", realtime " +
           std::to_string(real_ns()) + ")");
    }
    last_t = s.t_ns;
    if (a.have_raw && s.t_ns > new_after_ns) {
      check_value("z", s.gyro_z_radps, want_z, scale);
      if (!s.has_xy) fail("no x/y although the device has them");
      check_value("x", s.gyro_x_radps, a.raw_x, scale);
      check_value("y", s.gyro_y_radps, a.raw_y, scale);
    }
    got.push_back(s);
    return true;
  };
  for (int i = 0; i < a.samples && g_failures == 0; ++i) take(a.raw_z, INT64_MIN);
  if (!got.empty()) {
    const auto& f = got.front();
    std::printf(
        "imu_vm_check: first sample t %lld ns (monotonic now %lld), x %.9f y %.9f z %.9f "
        "rad/s; expected x %.9f y %.9f z %.9f\n",
        static_cast<long long>(f.t_ns), static_cast<long long>(mono_ns()), f.gyro_x_radps,
        f.gyro_y_radps, f.gyro_z_radps, a.raw_x * scale, a.raw_y * scale, a.raw_z * scale);
  }
  if (got.size() >= 2) {
    const double span_s = static_cast<double>(got.back().t_ns - got.front().t_ns) / 1e9;
    std::printf(
        "imu_vm_check: %zu samples over %.3f s of timestamps (%.1f samples/s from the "
        "trigger), all increasing\n",
        got.size(), span_s, static_cast<double>(got.size() - 1) / span_s);
  }
  if (!a.set_cmd.empty() && g_failures == 0) {
    const int rc = std::system(a.set_cmd.c_str());
    if (rc != 0) fail("--set-cmd exited with " + std::to_string(rc));
    const std::int64_t t_set = mono_ns();
    int changed = 0;
    for (int i = 0; i < a.samples && g_failures == 0; ++i) {
      if (!take(a.raw_z2, t_set)) break;
      if (got.back().t_ns > t_set) ++changed;
    }
    std::printf(
        "imu_vm_check: after --set-cmd: %d samples with raw z %ld, z %.9f rad/s "
        "(expected %.9f)\n",
        changed, a.raw_z2, got.empty() ? 0.0 : got.back().gyro_z_radps, a.raw_z2 * scale);
    if (changed == 0) fail("no sample after --set-cmd");
  }
  if (!a.remove_path.empty() && g_failures == 0) {
    std::ofstream(a.remove_path) << a.remove_value << "\n";
    const std::int64_t t_end = mono_ns() + a.timeout_ns;
    ImuStatus r = ImuStatus::kOk;
    std::uint64_t after = 0;
    while (mono_ns() < t_end) {
      agv::hal::GyroSample s;
      std::size_t n = 0;
      r = imu.read(&s, 1, &n, 200'000'000);
      if (r != ImuStatus::kOk && r != ImuStatus::kTimeout) break;
      after += n;
    }
    std::printf("imu_vm_check: device removed: read() -> %s (%s), %llu samples still drained\n",
                agv::hal::to_string(r), imu.last_error(), static_cast<unsigned long long>(after));
    if (r != ImuStatus::kDisconnected) fail("expected kDisconnected after removal");
  }
  imu.stop();
  const agv::hal::ImuStats s1 = imu.stats();
  std::printf("imu_vm_check: stats samples %llu short_reads %llu errors %llu\n",
              static_cast<unsigned long long>(s1.samples),
              static_cast<unsigned long long>(s1.short_reads),
              static_cast<unsigned long long>(s1.errors));
  std::printf("imu_vm_check: %s (%d failures)\n", g_failures ? "FAILED" : "PASSED", g_failures);
  return g_failures ? 1 : 0;
}

#include <time.h>

#include <cstdlib>

#include "agv/camera/common.hpp"

namespace agv::camera {

std::int64_t exposure_mid_ns(std::int64_t t_ns, TimestampRef ref, std::int64_t exposure_ns,
                             std::int64_t readout_ns) {
  const std::int64_t half = readout_ns / 2 + exposure_ns / 2;
  return ref == TimestampRef::kStartOfExposure ? t_ns + half : t_ns - half;
}

ClockDomain guess_clock_domain(std::int64_t t_ns, std::int64_t now_mono_ns,
                               std::int64_t now_boot_ns, std::int64_t equal_tolerance_ns) {
  const std::int64_t offset = now_boot_ns - now_mono_ns;  // >= 0: time spent suspended
  if (std::llabs(offset) < equal_tolerance_ns) return ClockDomain::kMonotonic;
  // Age of the frame if the timestamp were on each clock; a real timestamp is in the recent
  // past. A boottime stamp read as monotonic looks `offset` in the future.
  const std::int64_t age_mono = now_mono_ns - t_ns;
  const std::int64_t age_boot = now_boot_ns - t_ns;
  const bool mono_plausible = age_mono >= -equal_tolerance_ns;
  const bool boot_plausible = age_boot >= -equal_tolerance_ns;
  if (mono_plausible && !boot_plausible) return ClockDomain::kMonotonic;
  if (boot_plausible && !mono_plausible) return ClockDomain::kBoottime;
  return std::llabs(age_boot) < std::llabs(age_mono) ? ClockDomain::kBoottime
                                                     : ClockDomain::kMonotonic;
}

std::int64_t to_monotonic_ns(std::int64_t t_ns, ClockDomain domain, std::int64_t now_mono_ns,
                             std::int64_t now_boot_ns) {
  if (domain == ClockDomain::kMonotonic) return t_ns;
  return t_ns - (now_boot_ns - now_mono_ns);
}

static std::int64_t read_clock(clockid_t id) {
  timespec ts{};
  clock_gettime(id, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::int64_t monotonic_now_ns() { return read_clock(CLOCK_MONOTONIC); }
std::int64_t boottime_now_ns() { return read_clock(CLOCK_BOOTTIME); }

}  // namespace agv::camera

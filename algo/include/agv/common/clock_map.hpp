// Maps a device's clock (a GigE Vision / USB3 Vision camera's timestamp counter) onto the host
// clock from pairs (device stamp, host receive time). The receive latency is always positive and
// mostly near its floor, so the lower envelope of host - device over a window is the offset plus
// the smallest latency: the window is cut into bins along the device time, the minimum of each bin
// is kept, and a line through the minima gives offset and drift. A latency spike only lifts one
// sample above the envelope and changes nothing.
//
// The mapped time is late by the smallest transport latency (the frame's transfer over the link),
// which no receive stamp can separate from the offset; the latency calibration absorbs it as it
// absorbs every other fixed delay (docs/guide/camera.md).
//
// Jumps (the camera rebooted, its counter was reset, PTP stepped it): a sample that maps later
// than it was received, or whose latency is beyond what the link can explain, breaks the lock.
// It is refused; when `relock_samples` such samples in a row agree with each other on a new
// offset, the window restarts from them and the jump is reported. Samples that agree with neither
// (stamps out of order, random values) are refused and never move the mapping.
//
// Pure: times are arguments. Not thread-safe (one per camera, used by its consumer).
#pragma once

#include <cstdint>
#include <deque>
#include <string>
#include <vector>

namespace agv {

struct ClockMapConfig {
  // Samples in the fit window. At 30 fps, 300 samples span 10 s: long enough for the drift of a
  // 50 ppm oscillator to show (0.5 ms), short enough to follow temperature changes.
  int window_samples = 300;
  // Bins of the lower envelope. More bins follow curvature better; fewer have more samples each,
  // so each minimum lies closer to the true latency floor.
  int bins = 8;
  // The drift is estimated only when the window spans at least this much device time; a shorter
  // window gives the offset alone (drift 0).
  std::int64_t min_drift_span_ns = 1'000'000'000;
  // A sample mapped later than its receive time by more than this is impossible under a positive
  // latency: the device clock stepped forward.
  std::int64_t early_tolerance_ns = 1'000'000;
  // A sample received more than this after its mapped time is a latency spike or a backward step
  // of the device clock; held back until the next samples say which.
  std::int64_t late_threshold_ns = 50'000'000;
  // Consecutive held-back samples agreeing on a new offset needed to accept a jump. Until the
  // window holds this many samples, early samples are taken as a lower latency floor, not as a
  // jump.
  int relock_samples = 4;
  // How closely the held-back samples must agree (host - device spread). A genuine step keeps the
  // link's jitter; frames queued behind a host stall arrive together, their host - device falling
  // by one frame period each, and must not pass for a new offset.
  std::int64_t relock_tolerance_ns = 5'000'000;
  // Fits whose drift exceeds this are ignored (the offset alone is used): no crystal is that far
  // off, so such a slope comes from a window too short or too noisy.
  double max_drift_ppm = 500.0;
};

// Empty when usable; otherwise names the offending field.
std::string validate_clock_map_config(const ClockMapConfig& config);

enum class ClockSample {
  kAccepted = 0,  // used in the fit
  kJump = 1,      // completed a jump: the mapping restarted from the new offset
  kHeldBack = 2,  // inconsistent with the lock; a jump candidate, not used (yet)
  kRefused = 3,   // unusable: host time not increasing, or a time difference overflows
};

const char* to_string(ClockSample s);

class ClockMap {
 public:
  explicit ClockMap(ClockMapConfig config = {});

  // One frame: its device stamp and the host time it was received at (host clock, must not go
  // backwards between calls).
  ClockSample add(std::int64_t device_ns, std::int64_t host_rx_ns);

  // Host time of a device stamp; false before the first accepted sample.
  bool map(std::int64_t device_ns, std::int64_t* host_ns) const;

  bool has_offset() const { return !window_.empty(); }
  // The drift is estimated (the window spans min_drift_span_ns).
  bool drift_locked() const { return drift_locked_; }
  // host - device at the newest accepted sample, on the envelope (includes the smallest latency).
  std::int64_t offset_ns() const;
  // Device clock rate error as seen from the host: +50 means the host counts 50 ns more per
  // million device ns.
  double drift_ppm() const { return drift_ppm_; }
  std::uint64_t jumps() const { return jumps_; }
  std::uint64_t held_back() const { return held_back_; }
  std::uint64_t refused() const { return refused_; }
  int window_size() const { return static_cast<int>(window_.size()); }

  // Forgets everything (a new stream).
  void reset();

 private:
  struct Pair {
    std::int64_t device_ns;
    std::int64_t diff_ns;  // host - device
  };
  bool consistent_with_lock(const Pair& p, std::int64_t host_rx_ns) const;
  bool candidates_agree(const Pair& p) const;
  void refit();

  ClockMapConfig cfg_;
  std::deque<Pair> window_;
  std::vector<Pair> candidates_;
  std::int64_t last_host_ns_ = 0;
  bool have_host_ = false;
  // Fitted envelope: diff(device) = ref_diff_ns_ + drift * (device - ref_device_ns_).
  std::int64_t ref_device_ns_ = 0;
  std::int64_t ref_diff_ns_ = 0;
  double drift_ppm_ = 0.0;
  bool drift_locked_ = false;
  std::uint64_t jumps_ = 0;
  std::uint64_t held_back_ = 0;
  std::uint64_t refused_ = 0;
};

}  // namespace agv

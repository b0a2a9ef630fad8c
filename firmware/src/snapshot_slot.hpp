// The output thread's fused estimates for the vision worker of the threaded loop (search windows,
// docs/design/tracking.md): the worker must not call the core, so the output thread publishes a
// snapshot each period and the worker extrapolates one to each frame's exposure.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include "agv/common/geometry.hpp"
#include "agv/localizer/time_base.hpp"
#include "agv/vision/tracking.hpp"
#include "agv/http/latest_slot.hpp"

namespace agv::app {

// Growth of the snapshot's covariance while it is extrapolated to a frame's exposure (a few ms to
// one output period, more when the output thread skipped a publication): the velocity may change
// at up to ~1 m/s^2 and ~50 deg/s^2 in that span, i.e. 0.1 m/s and 5 deg/s over 100 ms, which
// these rates cover at 1 sigma.
constexpr double kSnapshotPosGrowthMmPerS = 100.0;
constexpr double kSnapshotHeadingGrowthRadPerS = 5.0 * kPi / 180.0;

// The output thread is SCHED_FIFO and must never wait: it publishes with try_write and skips a
// period when the worker is reading (the next period publishes). The worker holds the lock for a
// scan of the timestamps and a copy of ~140 bytes.
//
// A history, not only the latest: when the worker lags (a loaded CPU, a camera that delivers
// 150 ms after the exposure), the latest snapshot is that much newer than the frame, and the
// extrapolation over the lag grows the covariance past the tracking limits (10 mm at 100 mm/s
// over 100 ms): every frame fell back to the full search. The snapshot published nearest the
// exposure needs almost no extrapolation. 64 periods cover 640 ms at 100 Hz.
class SnapshotSlot {
 public:
  // time_base: the core's (Localizer::time_base()), so the worker predicts for the instant the
  // core would.
  explicit SnapshotSlot(const localizer::TimeBase& time_base) : time_base_(time_base) {}

  void publish(const vision::MotionSnapshot& s) {
    history_.try_write([&](History& h) {
      h.ring[h.next % kHistory] = s;
      ++h.next;
    });
  }
  // The prediction for a frame exposed at t_exposure_ns on the camera's clock: the pose at that
  // instant on the vehicle's clock, as the core's prediction_at gives it.
  vision::Prediction predict_exposure(std::int64_t t_exposure_ns) {
    return predict(time_base_.camera_to_vehicle_ns(t_exposure_ns), kSnapshotPosGrowthMmPerS,
                   kSnapshotHeadingGrowthRadPerS);
  }

  // The extrapolation to t_ns (vehicle clock) with the smaller position variance of the two
  // candidates: the snapshot nearest that time, and the latest (it may hold a fix fused after
  // it). No snapshot yet: an invalid prediction.
  vision::Prediction predict(std::int64_t t_ns, double pos_growth_mm_per_s,
                             double heading_growth_rad_per_s) {
    vision::MotionSnapshot nearest, latest;
    const bool any = history_.read([&](const History& h) {
      if (h.next == 0) return false;
      const std::size_t n = std::min<std::size_t>(h.next, kHistory);
      latest = h.ring[(h.next - 1) % kHistory];
      std::size_t best = (h.next - 1) % kHistory;
      for (std::size_t k = 0; k < n; ++k) {
        const std::size_t i = (h.next - 1 - k) % kHistory;
        if (std::llabs(h.ring[i].t_ns - t_ns) < std::llabs(h.ring[best].t_ns - t_ns)) best = i;
      }
      nearest = h.ring[best];
      return true;
    });
    if (!any) return {};
    const vision::Prediction a =
        vision::extrapolate(nearest, t_ns, pos_growth_mm_per_s, heading_growth_rad_per_s);
    const vision::Prediction b =
        vision::extrapolate(latest, t_ns, pos_growth_mm_per_s, heading_growth_rad_per_s);
    if (!a.valid) return b;
    if (!b.valid) return a;
    return a.cov(0, 0) + a.cov(1, 1) <= b.cov(0, 0) + b.cov(1, 1) ? a : b;
  }

 private:
  static constexpr std::size_t kHistory = 64;
  struct History {
    std::array<vision::MotionSnapshot, kHistory> ring{};
    std::size_t next = 0;
  };
  localizer::TimeBase time_base_;
  LatestSlot<History> history_;
};

}  // namespace agv::app

// The camera-to-vehicle time offset on both loops. `agvloc run` and `replay --realtime` (threaded:
// the vision worker extrapolates the output thread's snapshots) and `replay --fast` (the core's
// prediction_at) must predict a frame's search windows for the same instant.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>

#include "../support/good_fix.hpp"
#include "agv/config/config.hpp"
#include "agv/localizer/localizer.hpp"
#include "output_loop.hpp"
#include "snapshot_slot.hpp"

using namespace agv;

namespace {

constexpr std::int64_t kMs = 1'000'000;

// The largest position difference (mm) between the two paths' predictions for frames exposed
// 50..10 ms before the newest snapshot, with the camera offset configured. Before the one time
// base the threaded path extrapolated to the camera's stamp: 12.000 mm at +-12 ms.
double worst_difference_mm(double camera_offset_ms) {
  config::Config cfg;
  cfg.camera.time_offset_ms = camera_offset_ms;
  const auto offset_ns = static_cast<std::int64_t>(std::llround(camera_offset_ms * 1e6));
  localizer::Localizer core(app::localizer_config(cfg));
  app::SnapshotSlot slot(core.time_base());
  // 2 s straight along x at 1 m/s (x_mm = ms since start), odometry and snapshots every 10 ms as
  // the output thread publishes them; a fix every 200 ms, its camera stamp on the camera's clock.
  const std::int64_t t0 = 1000 * kMs;
  std::int64_t t_last = t0;
  for (int i = 0; i <= 200; ++i) {
    const std::int64_t t = t0 + i * 10 * kMs;
    core.on_odometry(t, 1.0, 0.0);
    if (i % 20 == 0) {
      core.on_fix(test::good_fix(static_cast<double>(t - t0) * 1e-6), t - offset_ns, t + 30 * kMs);
    }
    slot.publish(core.snapshot_at(t));
    t_last = t;
  }
  double worst_mm = 0.0;
  for (std::int64_t dt_ms = 0; dt_ms <= 40; dt_ms += 5) {
    // A frame exposed at this vehicle time, stamped on the camera's clock.
    const std::int64_t t_camera_ns = t_last - 50 * kMs + dt_ms * kMs - offset_ns;
    const vision::Prediction fast = core.prediction_at(t_camera_ns);
    const vision::Prediction threaded = slot.predict_exposure(t_camera_ns);
    EXPECT_TRUE(fast.valid);
    EXPECT_TRUE(threaded.valid);
    const double d = std::hypot(threaded.vehicle_in_world.x_mm - fast.vehicle_in_world.x_mm,
                                threaded.vehicle_in_world.y_mm - fast.vehicle_in_world.y_mm);
    worst_mm = std::max(worst_mm, d);
  }
  return worst_mm;
}

}  // namespace

TEST(ExposurePrediction, ThreadedAndFastPathsPredictTheSameExposureWithACameraOffset) {
  for (const double offset_ms : {12.0, -12.0, 0.0}) {
    const double d = worst_difference_mm(offset_ms);
    std::printf("camera offset %+.0f ms: threaded - fast prediction %.3f mm at 1 m/s\n", offset_ms,
                d);
    EXPECT_LT(d, 0.05) << "camera offset " << offset_ms << " ms";
  }
}

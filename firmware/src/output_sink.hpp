// Where the output loop's results go besides the CAN bus: the VDA 5050 publisher's and the
// diagnostics page's hand-offs and the fault journal. The loop hands each sink the same
// transport-neutral record (the fused tick, the statistics, the fixes as they are fused); each
// sink encodes it for its own consumer. Sinks run on the output thread: they never block.
#pragma once

#include <cstdint>

#include "agv/hal/can_bus.hpp"
#include "agv/localizer/localizer.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace agv::app {

// What the vision worker hands the output thread: the measurement fusion takes and its times,
// not the frame's diagnostics (FrameRecord), so the real-time ring copies only what it needs.
struct FixRecord {
  std::int64_t t_exposure_ns = 0;
  std::int64_t t_done_ns = 0;  // when the fix was handed to fusion (its arrival)
  vision::LandmarkMeasurement fix;
};

// One frame's full result with its times: what `replay` writes to fixes.csv and the run report.
struct FrameRecord {
  std::int64_t t_exposure_ns = 0;
  std::int64_t t_done_ns = 0;
  vision::LandmarkFix fix;

  FixRecord for_fusion() const { return {t_exposure_ns, t_done_ns, fix.measurement()}; }
};

// One output period's result, as every sink gets it.
struct TickOutput {
  const localizer::TickRecord& tick;
  const localizer::OutputStats& stats;
  const hal::CanBus* bus;  // null: no CAN
  std::uint64_t frames_dropped;
};

class OutputSink {
 public:
  virtual ~OutputSink() = default;
  // Before the core's tick at now_ns: a command for the core (VDA 5050 initPosition), if any.
  virtual void before_tick(std::int64_t /*now_ns*/, localizer::Localizer& /*core*/) {}
  // A fix, as it is handed to fusion.
  virtual void on_fix(const FixRecord& /*fix*/) {}
  // The tick, after its CAN frames went out.
  virtual void on_tick(const TickOutput& out) = 0;
  // The run is over (the loop has stopped): its final state; last: the last tick, null if none.
  virtual void finish(const localizer::TickRecord* /*last*/,
                      const localizer::OutputStats& /*stats*/, const hal::CanBus* /*bus*/,
                      std::uint64_t /*frames_dropped*/) {}
};

}  // namespace agv::app

// Per-tick and per-fix CSV traces of eval_overhead (--trace-prefix): the raw material for breaking
// an error down (turning or driving straight, just after a track start, the fix's own error
// against the filtered one) outside the program.
#pragma once

#include <cstdio>
#include <string>
#include <vector>

#include "agv/overhead/camera_frame.hpp"
#include "agv/overhead/tracker.hpp"
#include "agv/sim/site_render.hpp"

namespace agv::eval {

class Trace {
 public:
  Trace() = default;
  ~Trace();
  Trace(const Trace&) = delete;
  Trace& operator=(const Trace&) = delete;
  // Opens PREFIX_ticks.csv and PREFIX_fixes.csv; false with *error when either cannot be written.
  bool open(const std::string& prefix, std::string* error);
  bool active() const { return ticks_ != nullptr; }
  // Every vehicle's output at tick t_ns against its truth.
  void tick(std::int64_t t_ns, const std::vector<overhead::TrackOutput>& outs,
            const std::vector<sim::AgvState>& truth);
  // Every detection with a fix (the fix whole, as the tracker got it, and when it arrived)
  // against the truth at its exposure.
  void fixes(std::int64_t arrival_ns, const std::vector<overhead::Detection>& dets,
             const std::vector<sim::AgvState>& truth_at_exposure);

 private:
  std::FILE* ticks_ = nullptr;
  std::FILE* fixes_ = nullptr;
};

}  // namespace agv::eval

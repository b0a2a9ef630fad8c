// agv::protocol::CanFrameData (algo/, pure) <-> agv::hal::CanFrame (hal/): identical members,
// kept as two types so that algo/ and hal/ do not depend on each other.
#pragma once

#include <cstring>

#include "agv/hal/can_bus.hpp"
#include "agv/protocol/can_frame.hpp"

namespace agv::can {

inline hal::CanFrame to_hal(const protocol::CanFrameData& f) {
  hal::CanFrame h;
  h.id = f.id;
  h.extended = f.extended;
  h.len = f.len;
  std::memcpy(h.data, f.data, sizeof h.data);
  h.t_ns = f.t_ns;
  return h;
}

inline protocol::CanFrameData from_hal(const hal::CanFrame& h) {
  protocol::CanFrameData f;
  f.id = h.id;
  f.extended = h.extended;
  f.len = h.len;
  std::memcpy(f.data, h.data, sizeof f.data);
  f.t_ns = h.t_ns;
  return f;
}

}  // namespace agv::can

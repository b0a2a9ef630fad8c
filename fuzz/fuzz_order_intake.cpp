// The fleet manager's orders as routes (algo/src/overhead/order_intake.cpp): anyone with access
// to the broker can write on the vehicles' order topics. The input's first line is the topic,
// the rest the payload; a second message follows a NUL byte (updates, duplicates). Properties:
// never throws; a refusal is named and leaves the output as it was; an accepted route is of a
// fleet vehicle, finite, within kRouteMaxPoints, and the route prior's path accepts it unless it
// is one point (the vehicle is to stay at its node).
#include <cmath>
#include <cstring>
#include <string>
#include <string_view>

#include "agv/overhead/order_intake.hpp"
#include "agv/overhead/route_prior.hpp"
#include "fuzz_check.hpp"

namespace o = agv::overhead;

namespace {

void one(o::OrderIntake* in, std::string_view msg) {
  const std::size_t nl = msg.find('\n');
  const std::string_view topic = msg.substr(0, nl),
                         payload = nl == std::string_view::npos ? "" : msg.substr(nl + 1);
  o::OrderRoute r;
  r.agv = 7;
  std::string why;
  const o::OrderReason reason = in->take(topic, payload, &r, &why);
  if (reason != o::OrderReason::kNone) {
    FUZZ_CHECK(r.agv == 7 && r.waypoints_mm.empty(), "a refusal changed the output");
    FUZZ_CHECK(std::strcmp(o::order_reason_name(reason), "unknown") != 0, "unnamed reason");
    return;
  }
  FUZZ_CHECK(r.agv < 2 && !r.waypoints_mm.empty(), "not a fleet vehicle's route");
  FUZZ_CHECK(r.waypoints_mm.size() <= o::kRouteMaxPoints, "route too long");
  for (const agv::Vec2& p : r.waypoints_mm)
    FUZZ_CHECK(std::isfinite(p.x) && std::isfinite(p.y), "non-finite waypoint");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  o::OrderIntake in({"agv-1", "agv-2"}, "uagv");
  const std::string_view text = agv::fuzz::as_text(data, size);
  std::size_t from = 0;
  while (from <= text.size()) {
    const std::size_t end = std::min(text.find('\0', from), text.size());
    one(&in, text.substr(from, end - from));
    from = end + 1;
  }
  return 0;
}

// VDA 5050 instantActions from the broker (algo/src/vda5050/parse.cpp): anyone with access to
// the fleet broker can write there. Properties: never throws; a refused message accepts nothing;
// an accepted initPosition is finite, in range, on the configured map and carries bounded ids;
// every refusal has a named reason.
#include <cmath>
#include <cstring>
#include <string>

#include "agv/vda5050/vda5050.hpp"
#include "fuzz_check.hpp"

namespace v = agv::vda5050;

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  v::Identity id;
  // The first byte picks the version, so both action names are explored.
  id.version = size > 0 && (data[0] & 1) ? v::Version::k3_0_0 : v::Version::k2_1_0;
  id.manufacturer = "acme";
  id.serial_number = "agv-7";
  id.map_id = "hall-1";
  const std::string_view text = agv::fuzz::as_text(data, size);
  const v::ParsedActions p = v::parse_instant_actions(id, text);
  if (p.message_reason != v::Reason::kNone) {
    FUZZ_CHECK(p.accepted.empty() && p.refused.empty(), "a refused message accepted actions");
    FUZZ_CHECK(std::strcmp(v::reason_name(p.message_reason), "unknown") != 0, "unnamed reason");
    return 0;
  }
  FUZZ_CHECK(p.accepted.size() + p.refused.size() + p.not_ours <= v::kMaxActions, "action count");
  for (const v::InitPosition& a : p.accepted) {
    FUZZ_CHECK(std::isfinite(a.x_m) && std::isfinite(a.y_m) && std::isfinite(a.theta_rad),
               "non-finite pose accepted");
    FUZZ_CHECK(std::fabs(a.x_m) <= v::kMaxCoordinateM && std::fabs(a.y_m) <= v::kMaxCoordinateM &&
                   std::fabs(a.theta_rad) <= M_PI + 1e-9,
               "pose out of range accepted");
    FUZZ_CHECK(a.map_id == id.map_id, "other map accepted");
    FUZZ_CHECK(a.action_id.size() <= v::kMaxIdChars && a.last_node_id.size() <= v::kMaxIdChars,
               "id length");
  }
  for (const v::ActionResult& r : p.refused) {
    FUZZ_CHECK(r.status == v::ActionStatus::kFailed && !r.result_description.empty() &&
                   r.result_description != "unknown",
               "refusal without a reason");
  }
  return 0;
}

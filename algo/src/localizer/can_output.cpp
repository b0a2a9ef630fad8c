#include "agv/localizer/can_output.hpp"

#include <stdexcept>
#include <string>

namespace agv::localizer {

// The encoder takes the configuration as given; an invalid one (an ID beyond 11/29 bits, two
// messages on one ID) is refused here, as the Localizer refuses it.
CanOutput::CanOutput(const protocol::ProtocolConfig& cfg) : encoder_(cfg) {
  const std::string err = protocol::validate(cfg);
  if (!err.empty()) throw std::invalid_argument("protocol: " + err);
}

void CanOutput::encode_pose(const PoseOutput& pose, OutFrames* out) {
  encoder_.encode_pose(pose.pose, &out->frame[0], &out->frame[1]);
  out->n = 2;
  out->e2e_exposure_ns = pose.e2e_exposure_ns;
}

void CanOutput::encode(const TickRecord& tick, OutFrames* out) {
  encode_pose(tick.pose, out);
  encoder_.encode_velocity(tick.velocity, &out->frame[out->n++]);
  encoder_.encode_quality(tick.quality, &out->frame[out->n++]);
  encoder_.encode_status(tick.status, &out->frame[out->n++]);
  if (tick.heartbeat_due) encoder_.encode_heartbeat(tick.heartbeat, &out->frame[out->n++]);
}

void CanOutput::tick(Localizer& core, std::int64_t now_ns, OutFrames* out, TickRecord* rec) {
  const TickRecord r = core.tick(now_ns);
  encode(r, out);
  if (rec) *rec = r;
}

}  // namespace agv::localizer

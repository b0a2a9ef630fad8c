// The CAN output: the core's transport-neutral record (TickRecord, PoseOutput) encoded as the
// output frames of the signal table (can/agvloc.dbc, docs/guide/can.md). Owns the encoder, and so
// the alive counters and E2E protection of every output message: one CanOutput per bus, kept for
// the run. Pure: no bus, no clock; the caller sends the frames (firmware/src/output_loop.*).
#pragma once

#include <cstdint>

#include "agv/hal/can_frame.hpp"
#include "agv/localizer/localizer.hpp"
#include "agv/protocol/codec.hpp"

namespace agv::localizer {

// Frames to send, in order, in a fixed buffer. The pose pair (xy, heading) always comes first.
struct OutFrames {
  // One per transmitted message of the signal table (pose xy + heading, velocity, quality,
  // status, heartbeat); the localizer test checks it against the table.
  static constexpr int kMax = 6;
  hal::CanFrame frame[kMax];
  int n = 0;
  // Exposure of the newest fused fix this pose pair is the first to carry; INT64_MIN if none.
  // The sender records end-to-end latency = (time the pose pair left) - this.
  std::int64_t e2e_exposure_ns = INT64_MIN;
};

class CanOutput {
 public:
  // Throws std::invalid_argument on an invalid protocol configuration.
  explicit CanOutput(const protocol::ProtocolConfig& cfg);

  // A period's frames: pose pair, velocity, quality, status, heartbeat when due.
  void encode(const TickRecord& tick, OutFrames* out);
  // The pose pair alone (Localizer::pose_now).
  void encode_pose(const PoseOutput& pose, OutFrames* out);

  // The core's tick and its frames in one call, for callers that want both (tests, tools).
  // Fills *rec when not null.
  void tick(Localizer& core, std::int64_t now_ns, OutFrames* out, TickRecord* rec = nullptr);
  void pose_now(Localizer& core, std::int64_t now_ns, OutFrames* out) {
    encode_pose(core.pose_now(now_ns), out);
  }

  const protocol::Encoder& encoder() const { return encoder_; }

 private:
  protocol::Encoder encoder_;
};

}  // namespace agv::localizer

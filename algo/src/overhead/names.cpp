// Names of the tracker's enums, as written in tracks.csv, the logs and the diagnostics page.
#include "agv/overhead/tracker.hpp"

namespace agv::overhead {

const char* to_string(TrackState s) {
  switch (s) {
    case TrackState::kNone:
      return "none";
    case TrackState::kTentative:
      return "tentative";
    case TrackState::kConfirmed:
      return "confirmed";
    case TrackState::kCoasting:
      return "coasting";
    case TrackState::kLost:
      return "lost";
  }
  return "unknown";
}

const char* to_string(FixResult r) {
  switch (r) {
    case FixResult::kApplied:
      return "applied";
    case FixResult::kStarted:
      return "started";
    case FixResult::kGated:
      return "gated";
    case FixResult::kTooOld:
      return "too_old";
    case FixResult::kInvalid:
      return "invalid";
  }
  return "unknown";
}

}  // namespace agv::overhead

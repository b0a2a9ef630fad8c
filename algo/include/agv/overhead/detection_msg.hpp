// One ceiling camera frame's tags as a message between processes: a detector process per camera
// publishes them on the site's broker, one tracker fuses them (docs/guide/overhead.md "Scaling
// out: detector processes"). The message carries what the tracker needs to turn each tag into a
// fix with its own site description (tag_fix.hpp): the corners, their sigma and the decode; the
// tracker, not the sender, decides vehicle, plane and gating. The decoder is the boundary to
// anyone who can write on the broker: it never throws, bounds every size and value, refuses a
// camera the site does not have, and names the reason. Pure.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "agv/overhead/search.hpp"
#include "agv/overhead/tag_detect.hpp"

namespace agv::overhead {

inline constexpr int kDetectionMsgVersion = 1;
inline constexpr std::size_t kMaxDetectionMsgBytes = 256 * 1024;
inline constexpr std::size_t kMaxDetectionMsgTags = 256;
inline constexpr std::size_t kMaxCameraIdChars = 64;
// Corners further than this from the image origin are refused (no camera has such images).
inline constexpr double kMaxCornerPx = 100000.0;
inline constexpr double kMaxCornerSigmaPx = 100.0;

struct MsgTag {
  TagObservation tag;
  SearchLevel level = SearchLevel::kFull;
};

struct DetectionMsg {
  std::string camera_id;
  // Exposure in the site's (tracker host's) clock, after the camera's time offset.
  std::int64_t t_ns = 0;
  std::uint64_t seq = 0;  // per detector process, +1 per frame: gaps are lost messages
  std::vector<MsgTag> tags;
};

enum class MsgReason : std::uint8_t {
  kNone,
  kTooLarge,
  kTooDeep,
  kNotJson,
  kNotObject,
  kBadVersion,
  kMissingField,
  kWrongType,
  kNonFinite,
  kOutOfRange,
  kUnknownCamera,
  kTooManyTags,
};
const char* reason_name(MsgReason r);

std::string encode_detections(const DetectionMsg& msg);
// Decodes `text` into *out; camera_ids are the site's cameras (a message from any other is
// refused). On refusal *out is left empty (no tags) and the reason says why.
MsgReason decode_detections(std::string_view text, const std::vector<std::string>& camera_ids,
                            DetectionMsg* out);

}  // namespace agv::overhead

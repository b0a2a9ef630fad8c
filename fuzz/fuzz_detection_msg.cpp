// Detections from a per-camera detector process (algo/src/overhead/detection_msg.cpp): anyone
// with access to the site broker can write on the detections topics. Properties: never throws; a
// refused message yields nothing and a named reason; an accepted one is from a site camera, has
// bounded, finite corners and decode fields, and encodes back to a message that decodes to the
// same tags.
#include <cmath>
#include <cstring>
#include <string>

#include "agv/overhead/detection_msg.hpp"
#include "agv/overhead/tag_code.hpp"
#include "fuzz_check.hpp"

namespace o = agv::overhead;

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  static const std::vector<std::string> cams = {"cam-a", "cam-b"};
  o::DetectionMsg m;
  const o::MsgReason r = o::decode_detections(agv::fuzz::as_text(data, size), cams, &m);
  if (r != o::MsgReason::kNone) {
    FUZZ_CHECK(m.tags.empty() && m.camera_id.empty(), "a refused message kept data");
    FUZZ_CHECK(std::strcmp(o::reason_name(r), "unknown") != 0, "unnamed reason");
    return 0;
  }
  FUZZ_CHECK(m.camera_id == cams[0] || m.camera_id == cams[1], "unknown camera accepted");
  FUZZ_CHECK(m.tags.size() <= o::kMaxDetectionMsgTags && m.t_ns >= 0, "size or time");
  for (const o::MsgTag& t : m.tags) {
    FUZZ_CHECK(t.tag.id < o::kTag36h11Count && t.tag.hamming >= 0 && t.tag.hamming <= 36,
               "decode fields out of range");
    FUZZ_CHECK(std::isfinite(t.tag.corner_sigma_px) && t.tag.corner_sigma_px >= 0.0, "sigma");
    for (const agv::Vec2& c : t.tag.corners_px) {
      FUZZ_CHECK(std::fabs(c.x) <= o::kMaxCornerPx && std::fabs(c.y) <= o::kMaxCornerPx,
                 "corner out of range accepted");
    }
  }
  o::DetectionMsg back;
  FUZZ_CHECK(o::decode_detections(o::encode_detections(m), cams, &back) == o::MsgReason::kNone &&
                 back.tags.size() == m.tags.size() && back.seq == m.seq && back.t_ns == m.t_ns,
             "an accepted message does not round-trip");
  return 0;
}

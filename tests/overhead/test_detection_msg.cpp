// The detections a per-camera detector process publishes (algo/src/overhead/detection_msg.cpp):
// a round trip keeps every field, and every malformed payload is refused with its reason.
#include <gtest/gtest.h>

#include <limits>
#include <string>

#include "agv/overhead/detection_msg.hpp"

namespace agv::overhead {
namespace {

const std::vector<std::string> kCams = {"cam-a", "cam-b"};

DetectionMsg sample() {
  DetectionMsg m;
  m.camera_id = "cam-b";
  m.t_ns = 1'234'567'890'123;
  m.seq = 42;
  MsgTag t;
  t.tag.id = 17;
  t.tag.code = 0xd5d628584ULL;
  t.tag.hamming = 1;
  t.tag.margin = 9;
  t.tag.restricted = true;
  t.tag.contrast = 123.5;
  t.tag.corner_sigma_px = 0.0625;
  t.tag.corners_px = {{{10.125, 20.5}, {70.25, 21.0}, {69.0, 80.75}, {9.5, 79.0}}};
  t.level = SearchLevel::kArea;
  m.tags = {t, t};
  m.tags[1].tag.id = 3;
  m.tags[1].level = SearchLevel::kTrack;
  return m;
}

MsgReason decode(const std::string& s) {
  DetectionMsg out;
  const MsgReason r = decode_detections(s, kCams, &out);
  if (r != MsgReason::kNone) {
    EXPECT_TRUE(out.tags.empty() && out.camera_id.empty());
  }
  return r;
}

std::string replaced(std::string s, const std::string& from, const std::string& to) {
  const std::size_t at = s.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return s.replace(at, from.size(), to);
}

TEST(DetectionMsg, RoundTripKeepsEveryField) {
  const DetectionMsg m = sample();
  DetectionMsg out;
  ASSERT_EQ(decode_detections(encode_detections(m), kCams, &out), MsgReason::kNone);
  EXPECT_EQ(out.camera_id, m.camera_id);
  EXPECT_EQ(out.t_ns, m.t_ns);
  EXPECT_EQ(out.seq, m.seq);
  ASSERT_EQ(out.tags.size(), 2U);
  for (std::size_t i = 0; i < 2; ++i) {
    const TagObservation &a = m.tags[i].tag, &b = out.tags[i].tag;
    EXPECT_EQ(a.id, b.id);
    EXPECT_EQ(a.code, b.code);
    EXPECT_EQ(a.hamming, b.hamming);
    EXPECT_EQ(a.margin, b.margin);
    EXPECT_EQ(a.restricted, b.restricted);
    EXPECT_EQ(a.contrast, b.contrast);
    EXPECT_EQ(a.corner_sigma_px, b.corner_sigma_px);
    for (int c = 0; c < 4; ++c) {
      EXPECT_EQ(a.corners_px[c].x, b.corners_px[c].x);  // JSON numbers round-trip exactly
      EXPECT_EQ(a.corners_px[c].y, b.corners_px[c].y);
    }
    EXPECT_EQ(m.tags[i].level, out.tags[i].level);
  }
}

TEST(DetectionMsg, EmptyFrameIsAMessage) {
  DetectionMsg m = sample();
  m.tags.clear();
  DetectionMsg out;
  EXPECT_EQ(decode_detections(encode_detections(m), kCams, &out), MsgReason::kNone);
  EXPECT_TRUE(out.tags.empty());
}

TEST(DetectionMsg, RefusesWithNamedReasons) {
  const std::string good = encode_detections(sample());
  EXPECT_EQ(decode(good.substr(0, good.size() / 2)), MsgReason::kNotJson);
  EXPECT_EQ(decode("[1,2]"), MsgReason::kNotObject);
  EXPECT_EQ(decode(std::string(300, '[')), MsgReason::kTooDeep);
  EXPECT_EQ(decode(std::string(kMaxDetectionMsgBytes + 1, ' ')), MsgReason::kTooLarge);
  EXPECT_EQ(decode(replaced(good, "\"v\":1", "\"v\":2")), MsgReason::kBadVersion);
  EXPECT_EQ(decode(replaced(good, "\"cam-b\"", "\"cam-z\"")), MsgReason::kUnknownCamera);
  EXPECT_EQ(decode(replaced(good, "\"cam-b\"", "7")), MsgReason::kWrongType);
  EXPECT_EQ(decode(replaced(good, "\"seq\":42,", "")), MsgReason::kMissingField);
  EXPECT_EQ(decode(replaced(good, "\"t_ns\":1234567890123", "\"t_ns\":-5")),
            MsgReason::kOutOfRange);
  EXPECT_EQ(decode(replaced(good, "\"t_ns\":1234567890123", "\"t_ns\":1.5")),
            MsgReason::kWrongType);
  EXPECT_EQ(decode(replaced(good, "\"id\":17", "\"id\":587")), MsgReason::kOutOfRange);
  EXPECT_EQ(decode(replaced(good, "\"hamming\":1", "\"hamming\":37")), MsgReason::kOutOfRange);
  EXPECT_EQ(decode(replaced(good, "\"level\":\"area\"", "\"level\":\"near\"")),
            MsgReason::kOutOfRange);
  EXPECT_EQ(decode(replaced(good, "[10.125,20.5]", "[10.125]")), MsgReason::kWrongType);
  EXPECT_EQ(decode(replaced(good, "[10.125,20.5]", "[1e300,20.5]")), MsgReason::kOutOfRange);
  EXPECT_EQ(decode(replaced(good, "\"sigma_px\":0.0625", "\"sigma_px\":-1")),
            MsgReason::kOutOfRange);
  EXPECT_EQ(decode(replaced(good, "\"restricted\":true", "\"restricted\":1")),
            MsgReason::kWrongType);
}

TEST(DetectionMsg, NonFiniteAndTooManyTagsRefused) {
  DetectionMsg m = sample();
  // nlohmann writes NaN as null: refused as the wrong type, never read as a number.
  m.tags[0].tag.corners_px[2].x = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(decode(encode_detections(m)), MsgReason::kWrongType);
  m = sample();
  m.tags.assign(kMaxDetectionMsgTags + 1, m.tags[0]);
  EXPECT_EQ(decode(encode_detections(m)), MsgReason::kTooManyTags);
  // A number past double's range is refused by the parser itself.
  EXPECT_EQ(
      decode(replaced(encode_detections(sample()), "\"contrast\":123.5", "\"contrast\":1e999")),
      MsgReason::kNotJson);
}

TEST(DetectionMsg, EveryReasonNamed) {
  for (int r = 0; r <= static_cast<int>(MsgReason::kTooManyTags); ++r)
    EXPECT_STRNE(reason_name(static_cast<MsgReason>(r)), "unknown");
}

}  // namespace
}  // namespace agv::overhead

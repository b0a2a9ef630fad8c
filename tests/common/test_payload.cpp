#include <gtest/gtest.h>

#include "agv/common/landmark.hpp"

using namespace agv;

TEST(Payload, FormatParseRoundTrip) {
  LandmarkPayload p;
  p.id = 17;
  p.has_pose = true;
  p.x_mm = 1000.0;
  p.y_mm = -2000.05;
  p.heading_deg = 90.0;
  const std::string s = format_payload(p);
  EXPECT_EQ(s, "AGV1/00017/+001000.0/-002000.1/+090.00");
  EXPECT_EQ(s.size(), 38u);
  LandmarkPayload q;
  ASSERT_EQ(parse_payload(s, &q), PayloadError::kOk);
  EXPECT_EQ(q.id, 17u);
  EXPECT_TRUE(q.has_pose);
  EXPECT_DOUBLE_EQ(q.x_mm, 1000.0);
  EXPECT_NEAR(q.y_mm, -2000.1, 1e-9);
  EXPECT_DOUBLE_EQ(q.heading_deg, 90.0);
}

TEST(Payload, IdOnlyForm) {
  LandmarkPayload q;
  ASSERT_EQ(parse_payload("AGV1/65535/MAP", &q), PayloadError::kOk);
  EXPECT_EQ(q.id, 65535u);
  EXPECT_FALSE(q.has_pose);
}

TEST(Payload, RejectsEverythingElse) {
  LandmarkPayload q;
  EXPECT_EQ(parse_payload("", &q), PayloadError::kEmpty);
  EXPECT_EQ(parse_payload("XYZ1/00017/MAP", &q), PayloadError::kBadPrefix);
  EXPECT_EQ(parse_payload("AGV2/00017/MAP", &q), PayloadError::kUnsupportedVersion);
  EXPECT_EQ(parse_payload("AGV1/00017/MAP ", &q), PayloadError::kBadLength);
  EXPECT_EQ(parse_payload("AGV1/0001A/MAP", &q), PayloadError::kBadField);
  EXPECT_EQ(parse_payload("AGV1/00000/MAP", &q), PayloadError::kOutOfRange);
  EXPECT_EQ(parse_payload("AGV1/00017/+001000.0/-002000.1/+180.01", &q), PayloadError::kOutOfRange);
  EXPECT_EQ(parse_payload("AGV1/00017/+001000.0/-002000.1/-180.00", &q), PayloadError::kOutOfRange);
  EXPECT_EQ(parse_payload("AGV1/00017/ 001000.0/-002000.1/+090.00", &q), PayloadError::kBadField);
  EXPECT_EQ(parse_payload("AGV1/00017/+001000,0/-002000.1/+090.00", &q), PayloadError::kBadField);
  EXPECT_EQ(parse_payload("AGV1/00017/+001000.0/-002000.1+/090.00", &q), PayloadError::kBadField);
}

TEST(LandmarkMap, ParsesAndRejectsWithLineNumbers) {
  LandmarkMap m;
  std::string err;
  ASSERT_TRUE(
      parse_landmark_map("# grid\nid,x_mm,y_mm,heading_deg\n1,0,0,0\n2,1000.5,-3,90\n", &m, &err))
      << err;
  ASSERT_NE(m.find(2), nullptr);
  EXPECT_DOUBLE_EQ(m.find(2)->pose.x_mm, 1000.5);
  EXPECT_EQ(m.find(3), nullptr);
  EXPECT_FALSE(parse_landmark_map("id,x_mm,y_mm,heading_deg\n1,0,0\n", &m, &err));
  EXPECT_EQ(err.rfind("line 2:", 0), 0u) << err;
  EXPECT_FALSE(parse_landmark_map("id,x_mm,y_mm,heading_deg\n1,0,0,0\n1,1,1,1\n", &m, &err));
  EXPECT_NE(err.find("duplicate"), std::string::npos);
  EXPECT_FALSE(parse_landmark_map("id,x,y\n", &m, &err));
  EXPECT_FALSE(parse_landmark_map("id,x_mm,y_mm,heading_deg\n1,nan,0,0\n", &m, &err));
  EXPECT_FALSE(parse_landmark_map("", &m, &err));
}

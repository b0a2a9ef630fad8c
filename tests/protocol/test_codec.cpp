#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "agv/common/geometry.hpp"
#include "agv/protocol/codec.hpp"

namespace p = agv::protocol;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

const p::SignalDef& sig(p::Msg m, const char* name) {
  const p::SignalDef* s = p::find_signal(p::message_def(m), name);
  EXPECT_NE(s, nullptr) << name;
  return *s;
}

p::PoseOut roundtrip(p::Encoder& enc, const p::PoseOut& in, const p::ProtocolConfig& cfg = {}) {
  agv::hal::CanFrame xy, hd;
  enc.encode_pose(in, &xy, &hd);
  p::PoseOut out;
  EXPECT_TRUE(p::decode_pose(cfg, xy, hd, &out));
  return out;
}

// A frame for the odometry decoder, with E2E like a motor controller would send it.
agv::hal::CanFrame odom_frame(const p::ProtocolConfig& cfg, double a, double b,
                              std::uint8_t counter, std::int64_t t_ns) {
  agv::hal::CanFrame f;
  p::encode_odometry(cfg, a, b, counter, &f);
  f.t_ns = t_ns;
  return f;
}

}  // namespace

TEST(SignalTable, LayoutIsConsistent) {
  for (const p::MessageDef& m : p::message_table()) {
    std::uint64_t used = 0;
    ASSERT_EQ(&p::message_def(m.msg), &m);
    ASSERT_GE(m.signals.size(), 2u);
    EXPECT_STREQ(m.signals[0].name, "CRC");
    EXPECT_STREQ(m.signals[1].name, "AliveCounter");
    for (const p::SignalDef& s : m.signals) {
      ASSERT_LE(s.start_bit + s.length, 8 * m.dlc) << m.name << "." << s.name;
      const std::uint64_t bits = ((s.length == 64 ? 0 : (1ull << s.length)) - 1) << s.start_bit;
      EXPECT_EQ(used & bits, 0u) << m.name << "." << s.name << " overlaps";
      used |= bits;
      // The physical range must be representable: no silent wrap inside [min, max].
      const std::int64_t lo = s.is_signed ? -(1ll << (s.length - 1)) : 0;
      const std::int64_t hi = s.is_signed ? (1ll << (s.length - 1)) - 1 : (1ll << s.length) - 1;
      EXPECT_GE(p::raw_min(s), lo) << m.name << "." << s.name;
      EXPECT_LE(p::raw_max(s), hi) << m.name << "." << s.name;
      EXPECT_GT(s.scale, 0.0);
    }
  }
}

TEST(SignalPacking, SignedAndUnsignedAtEveryBitOffset) {
  for (int len : {1, 4, 12, 16, 24}) {
    for (int start = 0; start + len <= 64; start += 3) {
      for (bool is_signed : {false, true}) {
        if (is_signed && len == 1) continue;
        const double maxv = is_signed ? std::ldexp(1.0, len - 1) - 1 : std::ldexp(1.0, len) - 1;
        const double minv = is_signed ? -std::ldexp(1.0, len - 1) : 0.0;
        p::SignalDef s{"S",
                       static_cast<std::uint8_t>(start),
                       static_cast<std::uint8_t>(len),
                       true,
                       is_signed,
                       1.0,
                       0.0,
                       minv,
                       maxv,
                       "",
                       ""};
        for (double v : {minv, maxv, 0.0, std::floor(maxv / 3)}) {
          std::uint8_t d[8];
          std::memset(d, 0xA5, sizeof d);
          std::uint8_t before[8];
          std::memcpy(before, d, sizeof d);
          p::put_phys(s, v, d);
          EXPECT_EQ(p::get_phys(s, d), v) << "len " << len << " start " << start;
          // Bits outside the signal are untouched.
          for (int bit = 0; bit < 64; ++bit) {
            if (bit >= start && bit < start + len) continue;
            EXPECT_EQ((d[bit / 8] >> (bit % 8)) & 1, (before[bit / 8] >> (bit % 8)) & 1);
          }
        }
      }
    }
  }
}

TEST(Codec, PoseRoundTripOverTheFullRange) {
  p::Encoder enc({});
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> pos(-838860.8, 838860.7), ang(-agv::kPi, agv::kPi);
  for (int i = 0; i < 2000; ++i) {
    p::PoseOut in{pos(rng), pos(rng), ang(rng), 12.3, true};
    const p::PoseOut out = roundtrip(enc, in);
    EXPECT_NEAR(out.x_mm, in.x_mm, 0.05 + 1e-9);
    EXPECT_NEAR(out.y_mm, in.y_mm, 0.05 + 1e-9);
    EXPECT_NEAR(out.theta_rad, in.theta_rad, 0.00005 + 1e-12);
    EXPECT_NEAR(out.latency_ms, 12.3, 0.05 + 1e-9);
    EXPECT_TRUE(out.valid);
  }
}

TEST(Codec, PoseSaturatesInsteadOfWrapping) {
  p::Encoder enc({});
  p::PoseOut out = roundtrip(enc, {838860.7, -838860.8, 0.0, 0.0, true});
  EXPECT_DOUBLE_EQ(out.x_mm, 838860.7);
  EXPECT_DOUBLE_EQ(out.y_mm, -838860.8);
  out = roundtrip(enc, {1e7, -1e7, 0.0, 1e9, true});  // far beyond: saturate, do not wrap
  EXPECT_DOUBLE_EQ(out.x_mm, 838860.7);
  EXPECT_DOUBLE_EQ(out.y_mm, -838860.8);
  EXPECT_DOUBLE_EQ(out.latency_ms, 6553.5);
  EXPECT_TRUE(out.valid);
  out = roundtrip(enc, {838860.76, -838860.86, 0.0, -5.0, true});  // just beyond the last LSB
  EXPECT_DOUBLE_EQ(out.x_mm, 838860.7);
  EXPECT_DOUBLE_EQ(out.y_mm, -838860.8);
  EXPECT_DOUBLE_EQ(out.latency_ms, 0.0);
}

TEST(Codec, NonFiniteInputClearsValidOrSaturates) {
  p::Encoder enc({});
  p::PoseOut out = roundtrip(enc, {kNaN, 1.0, 0.0, 0.0, true});
  EXPECT_FALSE(out.valid);
  EXPECT_EQ(out.x_mm, 0.0);
  out = roundtrip(enc, {kInf, -kInf, 0.0, kNaN, true});
  EXPECT_FALSE(out.valid);
  EXPECT_DOUBLE_EQ(out.x_mm, 838860.7);
  EXPECT_DOUBLE_EQ(out.y_mm, -838860.8);
  EXPECT_DOUBLE_EQ(out.latency_ms, 6553.5);  // unknown latency is reported as the worst
  out = roundtrip(enc, {1.0, 2.0, 0.5, 0.0, false});
  EXPECT_FALSE(out.valid);
}

TEST(Codec, HeadingIsWrappedBeforeEncoding) {
  p::Encoder enc({});
  EXPECT_NEAR(roundtrip(enc, {0, 0, 3 * agv::kPi / 2, 0, true}).theta_rad, -agv::kPi / 2, 1e-4);
  EXPECT_NEAR(roundtrip(enc, {0, 0, agv::kPi, 0, true}).theta_rad, agv::kPi, 1e-4);
  EXPECT_NEAR(roundtrip(enc, {0, 0, -7.0, 0, true}).theta_rad, agv::wrap_angle_rad(-7.0), 1e-4);
}

TEST(Codec, PosePairSharesTheCounterAndCountersWrap) {
  p::Encoder enc({});
  agv::hal::CanFrame xy, hd;
  for (int i = 0; i < 40; ++i) {
    enc.encode_pose({1, 2, 0.1, 0, true}, &xy, &hd);
    EXPECT_EQ(xy.data[1] & 0x0F, i % 15);
    EXPECT_EQ(hd.data[1] & 0x0F, i % 15);
    EXPECT_EQ(xy.data[0], p::e2e_crc(p::message_def(p::Msg::kPoseXY).data_id, xy.data));
    EXPECT_EQ(hd.data[0], p::e2e_crc(p::message_def(p::Msg::kPoseHeading).data_id, hd.data));
  }
  // Counters are per message: the velocity frame starts at 0.
  agv::hal::CanFrame v;
  enc.encode_velocity({1, 1, true}, &v);
  EXPECT_EQ(v.data[1] & 0x0F, 0);
  // A mismatched pair (counters differ) decodes as invalid.
  agv::hal::CanFrame xy2, hd2;
  enc.encode_pose({1, 2, 0.1, 0, true}, &xy2, &hd2);
  p::PoseOut out;
  ASSERT_TRUE(p::decode_pose({}, xy, hd2, &out));
  EXPECT_FALSE(out.valid);
}

// The worked example of docs/guide/can.md, byte for byte.
TEST(Codec, DocumentedPoseExample) {
  p::Encoder enc({});
  agv::hal::CanFrame xy, hd;
  enc.encode_pose({1000.0, 2000.0, 0.0, 0.0, true}, &xy, &hd);
  const std::uint8_t expected[8] = {0xD3, 0x10, 0x10, 0x27, 0x00, 0x20, 0x4E, 0x00};
  EXPECT_EQ(xy.id, 0x300u);
  EXPECT_EQ(std::memcmp(xy.data, expected, 8), 0);
}

TEST(Codec, IdsStandardAndExtended) {
  p::ProtocolConfig cfg;
  p::Encoder enc(cfg);
  agv::hal::CanFrame f, g;
  enc.encode_pose({}, &f, &g);
  EXPECT_EQ(f.id, 0x300u);
  EXPECT_EQ(g.id, 0x301u);
  EXPECT_FALSE(f.extended);
  EXPECT_EQ(f.len, 8);
  enc.encode_heartbeat({}, &f);
  EXPECT_EQ(f.id, 0x305u);

  cfg.base_id = 0x18FF1000;
  cfg.extended_ids = true;
  EXPECT_NE(p::validate(cfg), "");  // odometry still standard: 0x18FF1010 does not fit
  cfg.odometry.extended_id = true;
  EXPECT_EQ(p::validate(cfg), "");
  p::Encoder ext(cfg);
  ext.encode_status({}, &f);
  EXPECT_EQ(f.id, 0x18FF1004u);
  EXPECT_TRUE(f.extended);
  EXPECT_EQ(p::identify(cfg, f), p::Msg::kStatus);
}

TEST(Codec, ValidateRejectsBadConfigs) {
  p::ProtocolConfig cfg;
  EXPECT_EQ(p::validate(cfg), "");
  cfg.base_id = 0x7FE;  // +5 does not fit 11 bits
  EXPECT_NE(p::validate(cfg), "");
  cfg = {};
  cfg.odometry.can_id = 0x302;  // collides with AGV_Velocity
  EXPECT_NE(p::validate(cfg), "");
  cfg = {};
  cfg.odometry.track_width_mm = 0.0;
  EXPECT_NE(p::validate(cfg), "");
  cfg = {};
  cfg.odometry.max_delta_counter = 15;
  EXPECT_NE(p::validate(cfg), "");
}

TEST(Codec, VelocityQualityRoundTripAndSaturation) {
  p::Encoder enc({});
  agv::hal::CanFrame f;
  p::VelocityOut v;
  enc.encode_velocity({1.2345, -0.54321, true}, &f);
  ASSERT_TRUE(p::decode_velocity({}, f, &v));
  EXPECT_NEAR(v.v_mps, 1.2345, 0.0005 + 1e-12);
  EXPECT_NEAR(v.omega_radps, -0.54321, 0.00005 + 1e-12);
  EXPECT_TRUE(v.valid);
  enc.encode_velocity({100.0, -100.0, true}, &f);
  ASSERT_TRUE(p::decode_velocity({}, f, &v));
  EXPECT_DOUBLE_EQ(v.v_mps, 32.767);
  EXPECT_DOUBLE_EQ(v.omega_radps, -3.2768);
  enc.encode_velocity({kNaN, 0.0, true}, &f);
  ASSERT_TRUE(p::decode_velocity({}, f, &v));
  EXPECT_FALSE(v.valid);

  p::QualityOut q;
  enc.encode_quality({0.84, 1.26, 0.0123, true}, &f);
  ASSERT_TRUE(p::decode_quality({}, f, &q));
  EXPECT_NEAR(q.sigma_x_mm, 0.84, 0.05 + 1e-12);
  EXPECT_NEAR(q.sigma_y_mm, 1.26, 0.05 + 1e-12);
  EXPECT_NEAR(q.sigma_theta_rad, 0.0123, 0.00005 + 1e-12);
  EXPECT_TRUE(q.valid);
  enc.encode_quality({kInf, 1e9, -1.0, true}, &f);  // huge: saturate; negative: clamp to 0
  ASSERT_TRUE(p::decode_quality({}, f, &q));
  EXPECT_DOUBLE_EQ(q.sigma_x_mm, 6553.5);
  EXPECT_DOUBLE_EQ(q.sigma_y_mm, 6553.5);
  EXPECT_DOUBLE_EQ(q.sigma_theta_rad, 0.0);
  EXPECT_TRUE(q.valid);
  enc.encode_quality({1.0, kNaN, 0.1, true}, &f);
  ASSERT_TRUE(p::decode_quality({}, f, &q));
  EXPECT_FALSE(q.valid);
  EXPECT_FALSE(q.map_guided_fix);
}

TEST(Codec, QualityMapGuidedFlagRoundTrip) {
  p::Encoder enc({});
  agv::hal::CanFrame f0, f1;
  p::QualityOut in{0.84, 1.26, 0.0123, true, false}, q;
  enc.encode_quality(in, &f0);
  in.map_guided_fix = true;
  enc.encode_quality(in, &f1);
  ASSERT_TRUE(p::decode_quality({}, f1, &q));
  EXPECT_TRUE(q.map_guided_fix);
  EXPECT_TRUE(q.valid);
  EXPECT_NEAR(q.sigma_x_mm, 0.84, 0.05 + 1e-12);
  ASSERT_TRUE(p::decode_quality({}, f0, &q));
  EXPECT_FALSE(q.map_guided_fix);
  // Bit 13 of the payload (byte 1, bit 5), nothing else but the E2E counter and CRC differ.
  EXPECT_EQ(f1.data[1] & 0x20, 0x20);
  EXPECT_EQ(f0.data[1] & 0x20, 0x00);
  for (int i = 2; i < 8; ++i) EXPECT_EQ(f0.data[i], f1.data[i]) << i;
}

TEST(Codec, StatusFlagsAndTimeSinceFix) {
  p::Encoder enc({});
  agv::hal::CanFrame f;
  p::StatusOut s;
  s.health = p::Health::kDegraded;
  s.last_landmark_id = 65535;
  s.time_since_fix_ms = 1234.4;
  s.faults = p::fault::kOdomTimeout | p::fault::kCanBusOff | p::fault::kLoopOverrun;
  s.rejections = p::reject::kGate | p::reject::kFixTooOld | 0xE0;  // reserved bits dropped
  enc.encode_status(s, &f);
  p::StatusOut d;
  ASSERT_TRUE(p::decode_status({}, f, &d));
  EXPECT_EQ(d.health, p::Health::kDegraded);
  EXPECT_EQ(d.last_landmark_id, 65535);
  EXPECT_DOUBLE_EQ(d.time_since_fix_ms, 1234.0);
  EXPECT_EQ(d.faults, s.faults);
  EXPECT_EQ(d.rejections, p::reject::kGate | p::reject::kFixTooOld);
  // Each flag lands on its named DBC signal.
  EXPECT_EQ(p::get_raw(sig(p::Msg::kStatus, "FaultOdomTimeout"), f.data), 1);
  EXPECT_EQ(p::get_raw(sig(p::Msg::kStatus, "FaultCanBusOff"), f.data), 1);
  EXPECT_EQ(p::get_raw(sig(p::Msg::kStatus, "FaultCameraStalled"), f.data), 0);
  EXPECT_EQ(p::get_raw(sig(p::Msg::kStatus, "RejectFixTooOld"), f.data), 1);
  EXPECT_EQ(p::get_raw(sig(p::Msg::kStatus, "RejectGeometry"), f.data), 0);
  // Never / very long ago / NaN all send the saturated value, decoded as "never" (-1).
  for (double t : {-1.0, 1e12, kNaN, kInf}) {
    s.time_since_fix_ms = t;
    enc.encode_status(s, &f);
    ASSERT_TRUE(p::decode_status({}, f, &d));
    EXPECT_EQ(d.time_since_fix_ms, -1.0) << t;
  }
}

TEST(Codec, HeartbeatCarriesVersions) {
  p::Encoder enc({});
  agv::hal::CanFrame f;
  enc.encode_heartbeat({1, 2, 3, 86400.9}, &f);
  p::HeartbeatOut h;
  int pv = -1;
  ASSERT_TRUE(p::decode_heartbeat({}, f, &h, &pv));
  EXPECT_EQ(h.sw_major, 1);
  EXPECT_EQ(h.sw_minor, 2);
  EXPECT_EQ(h.sw_patch, 3);
  EXPECT_EQ(h.uptime_s, 86400.0);
  EXPECT_EQ(pv, p::kProtocolVersion);
  enc.encode_heartbeat({0, 0, 0, 1e12}, &f);
  ASSERT_TRUE(p::decode_heartbeat({}, f, &h, &pv));
  EXPECT_EQ(h.uptime_s, 16777215.0);
}

TEST(Codec, DecodersRejectOtherFrames) {
  p::Encoder enc({});
  agv::hal::CanFrame f;
  enc.encode_velocity({}, &f);
  p::QualityOut q;
  EXPECT_FALSE(p::decode_quality({}, f, &q));
  p::VelocityOut v;
  f.len = 7;
  EXPECT_FALSE(p::decode_velocity({}, f, &v));
  f.len = 8;
  f.extended = true;
  EXPECT_FALSE(p::decode_velocity({}, f, &v));
  EXPECT_EQ(p::identify({}, f), p::Msg::kCount);
}

// ------------------------------------------------------------------------- odometry input

TEST(Odometry, WheelModeComputesVAndOmega) {
  p::ProtocolConfig cfg;
  cfg.odometry.track_width_mm = 400.0;
  p::OdometryDecoder dec(cfg);
  EXPECT_EQ(dec.can_id(), 0x310u);
  p::OdomSample s;
  ASSERT_EQ(dec.decode(odom_frame(cfg, 0.9, 1.1, 0, 1000), &s), p::DecodeResult::kOk);
  EXPECT_NEAR(s.left_mps, 0.9, 1e-9);
  EXPECT_NEAR(s.right_mps, 1.1, 1e-9);
  EXPECT_NEAR(s.v_mps, 1.0, 1e-9);
  EXPECT_NEAR(s.omega_radps, 0.2 / 0.4, 1e-9);
  EXPECT_EQ(s.t_ns, 1000);
}

TEST(Odometry, TwistModeWithScalesAndConfiguredId) {
  p::ProtocolConfig cfg;
  cfg.odometry.mode = p::OdometryMode::kTwist;
  cfg.odometry.can_id = 0x1A0;
  cfg.odometry.speed_scale = 1.02;
  cfg.odometry.omega_scale = 0.5;
  ASSERT_EQ(p::validate(cfg), "");
  p::OdometryDecoder dec(cfg);
  p::OdomSample s;
  agv::hal::CanFrame f = odom_frame(cfg, -1.5, 0.25, 0, 5);
  EXPECT_EQ(f.id, 0x1A0u);
  ASSERT_EQ(dec.decode(f, &s), p::DecodeResult::kOk);
  EXPECT_NEAR(s.v_mps, -1.5 * 1.02, 1e-9);
  EXPECT_NEAR(s.omega_radps, 0.125, 1e-9);
  // The default-ID frame of the same layout is not ours any more.
  f.id = 0x311;
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kNotOdometry);
}

TEST(Odometry, MalformedFramesAreRejectedAndCounted) {
  p::ProtocolConfig cfg;
  p::OdometryDecoder dec(cfg);
  p::OdomSample s;
  s.v_mps = 42.0;
  ASSERT_EQ(dec.decode(odom_frame(cfg, 1, 1, 0, 10), &s), p::DecodeResult::kOk);
  s.v_mps = 42.0;
  agv::hal::CanFrame f = odom_frame(cfg, 2, 2, 1, 20);
  f.len = 6;
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kBadLength);
  f = odom_frame(cfg, 2, 2, 1, 20);
  f.data[3] ^= 0x40;
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kBadCrc);
  EXPECT_EQ(dec.decode(odom_frame(cfg, 2, 2, 0, 30), &s), p::DecodeResult::kRepeated);
  EXPECT_EQ(dec.decode(odom_frame(cfg, 2, 2, 9, 40), &s), p::DecodeResult::kCounterJump);
  EXPECT_EQ(s.v_mps, 42.0);  // untouched by rejected frames
  // After the jump the decoder follows the new sequence.
  EXPECT_EQ(dec.decode(odom_frame(cfg, 2, 2, 10, 50), &s), p::DecodeResult::kOk);
  // Two frames lost (11, 12): still accepted with max_delta_counter 3, and counted.
  EXPECT_EQ(dec.decode(odom_frame(cfg, 2, 2, 13, 60), &s), p::DecodeResult::kOk);
  EXPECT_EQ(s.lost_before, 2u);
  // Older receive time than the last accepted frame: stale.
  EXPECT_EQ(dec.decode(odom_frame(cfg, 2, 2, 14, 55), &s), p::DecodeResult::kStale);
  f = odom_frame(cfg, 2, 2, 14, 70);
  f.extended = true;
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kNotOdometry);
  const p::OdometryCounters& c = dec.counters();
  EXPECT_EQ(c.accepted, 3u);
  EXPECT_EQ(c.bad_length, 1u);
  EXPECT_EQ(c.bad_crc, 1u);
  EXPECT_EQ(c.repeated, 1u);
  EXPECT_EQ(c.counter_jump, 1u);
  EXPECT_EQ(c.stale, 1u);
  EXPECT_EQ(c.lost_frames, 2u);
  EXPECT_EQ(c.rejected(), 5u);
}

TEST(Odometry, UnprotectedModeIgnoresCrcAndCounter) {
  p::ProtocolConfig cfg;
  cfg.odometry.protected_e2e = false;
  p::OdometryDecoder dec(cfg);
  p::OdomSample s;
  agv::hal::CanFrame f = odom_frame(cfg, 0.5, 0.5, 3, 10);
  f.data[0] = 0;  // no CRC
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kOk);
  f.t_ns = 20;
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kOk);  // same counter: fine when unprotected
  f.len = 4;
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kBadLength);
}

TEST(Odometry, CustomDataIdIsUsedForTheCrc) {
  p::ProtocolConfig cfg;
  cfg.odometry.data_id = 0x1234;
  p::OdometryDecoder dec(cfg);
  p::OdomSample s;
  EXPECT_EQ(dec.decode(odom_frame(cfg, 1, 1, 0, 1), &s), p::DecodeResult::kOk);
  p::ProtocolConfig other;  // default data ID: the CRC no longer matches
  agv::hal::CanFrame f = odom_frame(other, 1, 1, 1, 2);
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kBadCrc);
}

// ---------------------------------------------------------------------------- gyro input

namespace {

agv::hal::CanFrame gyro_frame(const p::ProtocolConfig& cfg, double z, std::uint8_t counter,
                              std::int64_t t_ns, bool saturated = false) {
  p::GyroSample in;
  in.gyro_z_radps = z;
  in.saturated = saturated;
  agv::hal::CanFrame f;
  p::encode_gyro(cfg, in, counter, &f);
  f.t_ns = t_ns;
  return f;
}

}  // namespace

TEST(Gyro, MessageIsInTheTableAfterTheOdometry) {
  // Appended: the indices before it are unchanged.
  EXPECT_EQ(static_cast<int>(p::Msg::kOdomTwist), 7);
  EXPECT_EQ(static_cast<int>(p::Msg::kGyro), 8);
  const p::MessageDef& m = p::message_def(p::Msg::kGyro);
  EXPECT_STREQ(m.name, "AGV_Gyro");
  EXPECT_EQ(m.dir, p::Direction::kRx);
  EXPECT_EQ(m.id_offset, 0x12u);
  EXPECT_EQ(m.data_id, 0x4C12);
  EXPECT_EQ(m.dlc, 8);
  // Resolution at least 0.001 deg/s, range at least +-500 deg/s.
  const p::SignalDef& z = sig(p::Msg::kGyro, "GyroZ");
  EXPECT_TRUE(z.is_signed);
  EXPECT_LE(z.scale, 0.001 * M_PI / 180.0);
  EXPECT_GE(z.max, 500.0 * M_PI / 180.0);
  EXPECT_LE(z.min, -500.0 * M_PI / 180.0);
  EXPECT_EQ(sig(p::Msg::kGyro, "Saturated").length, 1);
  p::ProtocolConfig cfg;
  EXPECT_EQ(p::can_id_of(cfg, p::Msg::kGyro), 0x312u);
  cfg.gyro.can_id = 0x0A5;
  EXPECT_EQ(p::can_id_of(cfg, p::Msg::kGyro), 0x0A5u);
  // Configuring the odometry ID does not hide the gyro from identify().
  cfg.odometry.can_id = 0x0A0;
  agv::hal::CanFrame f = gyro_frame(cfg, 0.1, 0, 1);
  EXPECT_EQ(p::identify(cfg, f), p::Msg::kGyro);
}

TEST(Gyro, EncodeWithTheTableAndDecode) {
  p::ProtocolConfig cfg;
  p::GyroDecoder dec(cfg);
  EXPECT_EQ(dec.can_id(), 0x312u);
  EXPECT_FALSE(dec.extended());
  p::GyroSample in;
  in.gyro_z_radps = -1.2345678;
  in.gyro_x_radps = 0.5;
  in.gyro_y_radps = -0.25;
  agv::hal::CanFrame f;
  p::encode_gyro(cfg, in, 0, &f);
  f.t_ns = 123456789;
  EXPECT_EQ(f.id, 0x312u);
  EXPECT_EQ(f.len, 8);
  // The frame is what the table says: each signal where the DBC puts it, E2E as odometry's.
  EXPECT_NEAR(p::get_phys(sig(p::Msg::kGyro, "GyroZ"), f.data), -1.2345678, 0.5e-5);
  EXPECT_EQ(f.data[0], p::e2e_crc(0x4C12, f.data));
  EXPECT_EQ(f.data[1] & 0x0F, 0);
  p::GyroSample s;
  ASSERT_EQ(dec.decode(f, &s), p::DecodeResult::kOk);
  EXPECT_EQ(s.t_ns, 123456789);  // the frame's receive time
  EXPECT_NEAR(s.gyro_z_radps, -1.2345678, 0.5e-5);
  EXPECT_NEAR(s.gyro_x_radps, 0.5, 1e-3);
  EXPECT_NEAR(s.gyro_y_radps, -0.25, 1e-3);
  EXPECT_FALSE(s.saturated);
  // 0.001 deg/s is resolved; beyond the range saturates instead of wrapping.
  ASSERT_EQ(dec.decode(gyro_frame(cfg, 0.001 * M_PI / 180.0, 1, 200000000), &s),
            p::DecodeResult::kOk);
  EXPECT_NEAR(s.gyro_z_radps, 0.001 * M_PI / 180.0, 0.5e-5);
  EXPECT_GT(s.gyro_z_radps, 0.0);
  ASSERT_EQ(dec.decode(gyro_frame(cfg, -1e6, 2, 200000001), &s), p::DecodeResult::kOk);
  EXPECT_DOUBLE_EQ(s.gyro_z_radps, sig(p::Msg::kGyro, "GyroZ").min);
  ASSERT_EQ(dec.decode(gyro_frame(cfg, 8.7, 3, 200000002), &s), p::DecodeResult::kOk);
  EXPECT_NEAR(s.gyro_z_radps, 8.7, 0.5e-5);
  // The sensor's saturation bit is decoded (and counted), the rate kept.
  ASSERT_EQ(dec.decode(gyro_frame(cfg, 9.5, 4, 200000003, true), &s), p::DecodeResult::kOk);
  EXPECT_TRUE(s.saturated);
  EXPECT_EQ(dec.counters().accepted, 5u);
  EXPECT_EQ(dec.counters().saturated, 1u);
  EXPECT_EQ(dec.last_accepted_ns(), 200000003);
}

TEST(Gyro, MalformedFramesAreRejectedAndCounted) {
  p::ProtocolConfig cfg;
  p::GyroDecoder dec(cfg);
  p::GyroSample s;
  ASSERT_EQ(dec.decode(gyro_frame(cfg, 0.1, 0, 10), &s), p::DecodeResult::kOk);
  s.gyro_z_radps = 42.0;
  agv::hal::CanFrame f = gyro_frame(cfg, 0.2, 1, 20);
  f.len = 7;
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kBadLength);
  f = gyro_frame(cfg, 0.2, 1, 20);
  f.data[4] ^= 0x01;
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kBadCrc);
  EXPECT_EQ(dec.decode(gyro_frame(cfg, 0.2, 0, 30), &s), p::DecodeResult::kRepeated);
  EXPECT_EQ(dec.decode(gyro_frame(cfg, 0.2, 9, 40), &s), p::DecodeResult::kCounterJump);
  f = gyro_frame(cfg, 0.2, 10, 45);
  f.data[1] = static_cast<std::uint8_t>((f.data[1] & 0xF0) | 0x0F);  // counter 15
  f.data[0] = p::e2e_crc(0x4C12, f.data);
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kBadCounter);
  EXPECT_EQ(s.gyro_z_radps, 42.0);  // untouched by rejected frames
  EXPECT_EQ(dec.decode(gyro_frame(cfg, 0.2, 10, 50), &s), p::DecodeResult::kOk);
  EXPECT_EQ(dec.decode(gyro_frame(cfg, 0.2, 13, 60), &s), p::DecodeResult::kOk);
  EXPECT_EQ(s.lost_before, 2u);
  EXPECT_EQ(dec.decode(gyro_frame(cfg, 0.2, 14, 55), &s), p::DecodeResult::kStale);
  // An odometry frame, or the gyro's ID as a 29-bit ID, is not the gyro's.
  EXPECT_EQ(dec.decode(odom_frame(cfg, 1, 1, 0, 70), &s), p::DecodeResult::kNotOdometry);
  f = gyro_frame(cfg, 0.2, 14, 70);
  f.extended = true;
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kNotOdometry);
  // A frame with the odometry's data ID under the gyro's CAN ID (a masquerade) fails the CRC.
  f = odom_frame(cfg, 1, 1, 14, 80);
  f.id = 0x312;
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kBadCrc);
  const p::GyroCounters& c = dec.counters();
  EXPECT_EQ(c.accepted, 3u);
  EXPECT_EQ(c.bad_length, 1u);
  EXPECT_EQ(c.bad_crc, 2u);
  EXPECT_EQ(c.repeated, 1u);
  EXPECT_EQ(c.counter_jump, 1u);
  EXPECT_EQ(c.bad_counter, 1u);
  EXPECT_EQ(c.stale, 1u);
  EXPECT_EQ(c.lost_frames, 2u);
  EXPECT_EQ(c.rejected(), 7u);
}

TEST(Gyro, ConfiguredIdUnprotectedAndCustomDataId) {
  p::ProtocolConfig cfg;
  cfg.gyro.enabled = true;
  cfg.gyro.can_id = 0x0B0;
  cfg.gyro.protected_e2e = false;
  ASSERT_EQ(p::validate(cfg), "");
  p::GyroDecoder dec(cfg);
  p::GyroSample s;
  agv::hal::CanFrame f = gyro_frame(cfg, 0.3, 2, 10);
  EXPECT_EQ(f.id, 0x0B0u);
  f.data[0] = 0;  // no CRC
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kOk);
  f.t_ns = 20;
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kOk);  // same counter: fine when unprotected
  f.id = 0x312;                                        // the default ID is not ours any more
  EXPECT_EQ(dec.decode(f, &s), p::DecodeResult::kNotOdometry);

  p::ProtocolConfig own;
  own.gyro.data_id = 0x1234;
  p::GyroDecoder dec2(own);
  EXPECT_EQ(dec2.decode(gyro_frame(own, 0.1, 0, 1), &s), p::DecodeResult::kOk);
  EXPECT_EQ(dec2.decode(gyro_frame(p::ProtocolConfig{}, 0.1, 1, 2), &s), p::DecodeResult::kBadCrc);
}

TEST(Gyro, ValidateChecksAnEnabledGyroId) {
  p::ProtocolConfig cfg;
  cfg.gyro.can_id = 0x302;  // collides with AGV_Velocity, but the gyro is off
  EXPECT_EQ(p::validate(cfg), "");
  cfg.gyro.enabled = true;
  EXPECT_NE(p::validate(cfg), "");
  cfg.gyro.can_id = 0x310;  // the (wheels) odometry's ID
  EXPECT_NE(p::validate(cfg), "");
  cfg.gyro.can_id = 0x800;  // does not fit 11 bits
  EXPECT_NE(p::validate(cfg), "");
  cfg.gyro.can_id = 0;
  EXPECT_EQ(p::validate(cfg), "");
  cfg.gyro.max_delta_counter = 0;
  EXPECT_NE(p::validate(cfg), "");
  // rx_enabled: the odometry variant of the mode, the gyro when enabled, never an output.
  cfg = {};
  EXPECT_TRUE(p::rx_enabled(cfg, p::Msg::kOdomWheels));
  EXPECT_FALSE(p::rx_enabled(cfg, p::Msg::kOdomTwist));
  EXPECT_FALSE(p::rx_enabled(cfg, p::Msg::kGyro));
  EXPECT_FALSE(p::rx_enabled(cfg, p::Msg::kStatus));
  cfg.gyro.enabled = true;
  EXPECT_TRUE(p::rx_enabled(cfg, p::Msg::kGyro));
}

TEST(Gyro, StatusCarriesTheImuFaultBits) {
  p::Encoder enc({});
  agv::hal::CanFrame f;
  p::StatusOut s;
  s.faults = p::fault::kImuTimeout;
  enc.encode_status(s, &f);
  EXPECT_EQ(p::get_raw(sig(p::Msg::kStatus, "FaultImuTimeout"), f.data), 1);
  EXPECT_EQ(p::get_raw(sig(p::Msg::kStatus, "FaultImuE2E"), f.data), 0);
  EXPECT_EQ(f.data[6], 0);  // the eight older fault bits are untouched
  p::StatusOut d;
  ASSERT_TRUE(p::decode_status({}, f, &d));
  EXPECT_EQ(d.faults, p::fault::kImuTimeout);
  s.faults = p::fault::kImuE2E | p::fault::kOdomE2E;
  enc.encode_status(s, &f);
  ASSERT_TRUE(p::decode_status({}, f, &d));
  EXPECT_EQ(d.faults, s.faults);
  EXPECT_EQ(p::get_raw(sig(p::Msg::kStatus, "FaultImuE2E"), f.data), 1);
  EXPECT_EQ(p::get_raw(sig(p::Msg::kStatus, "Health"), f.data), 2);  // kLost, beside them
}

// LastLandmarkId 0 is tag36h11's first tag, so "none yet" is its own bit: a fix on
// landmark 0 and no fix at all differ on the bus only by LastLandmarkValid (bit 63).
TEST(Codec, LastLandmarkValidTellsTagZeroFromNoFix) {
  p::Encoder enc({});
  agv::hal::CanFrame none, tag0;
  p::StatusOut s;  // before any fix: id 0, not valid
  s.rejections = p::reject::kGate | p::reject::kFixTooOld;
  enc.encode_status(s, &none);
  s.last_landmark_valid = true;  // a fix accepted on landmark 0
  enc.encode_status(s, &tag0);
  EXPECT_EQ(p::get_raw(sig(p::Msg::kStatus, "LastLandmarkValid"), none.data), 0);
  EXPECT_EQ(p::get_raw(sig(p::Msg::kStatus, "LastLandmarkValid"), tag0.data), 1);
  EXPECT_EQ(tag0.data[7] & 0x80, 0x80);
  EXPECT_EQ(none.data[7] & 0x80, 0x00);
  p::StatusOut d;
  ASSERT_TRUE(p::decode_status({}, none, &d));
  EXPECT_FALSE(d.last_landmark_valid);
  EXPECT_EQ(d.last_landmark_id, 0);
  ASSERT_TRUE(p::decode_status({}, tag0, &d));
  EXPECT_TRUE(d.last_landmark_valid);
  EXPECT_EQ(d.last_landmark_id, 0);
  // The bit shares byte 7 with the rejection flags, which decode as before.
  EXPECT_EQ(d.rejections, p::reject::kGate | p::reject::kFixTooOld);
}

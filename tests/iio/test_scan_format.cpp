// Scan formats as the kernel writes them (scan_elements/in_*_type) and the conversion of raw
// buffer bytes to rad/s: what drivers/iio relies on to read a gyro correctly.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>

#include "agv/iio/scan_format.hpp"

namespace agv::iio {
namespace {

TEST(IioScanFormat, ParsesBmi160Gyro) {
  ScanFormat f;
  ASSERT_TRUE(parse_scan_format("le:s16/16>>0\n", &f));
  EXPECT_FALSE(f.big_endian);
  EXPECT_TRUE(f.is_signed);
  EXPECT_EQ(f.bits, 16);
  EXPECT_EQ(f.storage_bits, 16);
  EXPECT_EQ(f.shift, 0);
  EXPECT_EQ(f.repeat, 1);
}

TEST(IioScanFormat, ParsesBigEndianShiftedUnsignedAndRepeat) {
  ScanFormat f;
  ASSERT_TRUE(parse_scan_format("be:u12/16>>4", &f));
  EXPECT_TRUE(f.big_endian);
  EXPECT_FALSE(f.is_signed);
  EXPECT_EQ(f.bits, 12);
  EXPECT_EQ(f.shift, 4);
  ASSERT_TRUE(parse_scan_format("le:s64/64>>0", &f));
  EXPECT_EQ(f.storage_bits, 64);
  ASSERT_TRUE(parse_scan_format("le:s16/16X3>>0", &f));
  EXPECT_EQ(f.repeat, 3);
}

TEST(IioScanFormat, RejectsMalformed) {
  ScanFormat f;
  f.bits = 99;
  for (const char* bad : {"", "xe:s16/16>>0", "le:x16/16>>0", "le:s16/12>>0", "le:s16/16>>1",
                          "le:s0/16>>0", "le:s16/16", "le:s16/16>>0junk", "le:s/16>>0",
                          "le:s16/16X0>>0", "le:s17/16>>0", "le:s16/24>>0"}) {
    EXPECT_FALSE(parse_scan_format(bad, &f)) << bad;
  }
  EXPECT_EQ(f.bits, 99);  // untouched on failure
}

TEST(IioScanFormat, DecodesLittleEndianSigned) {
  ScanFormat f;
  ASSERT_TRUE(parse_scan_format("le:s16/16>>0", &f));
  const std::uint8_t pos[2] = {0xE8, 0x03};  // 1000
  const std::uint8_t neg[2] = {0x18, 0xFC};  // -1000
  const std::uint8_t min[2] = {0x00, 0x80};  // -32768
  EXPECT_EQ(decode_raw(pos, f), 1000);
  EXPECT_EQ(decode_raw(neg, f), -1000);
  EXPECT_EQ(decode_raw(min, f), -32768);
}

TEST(IioScanFormat, DecodesBigEndianShiftedAndMasked) {
  ScanFormat f;
  // 12 significant bits in the top of a big-endian 16-bit word, low 4 bits are status flags.
  ASSERT_TRUE(parse_scan_format("be:s12/16>>4", &f));
  const std::uint8_t p[2] = {0xFF, 0xFA};  // 0xFFF = -1, flags 0xA ignored
  EXPECT_EQ(decode_raw(p, f), -1);
  const std::uint8_t q[2] = {0x12, 0x3F};  // 0x123 = 291
  EXPECT_EQ(decode_raw(q, f), 291);
  ASSERT_TRUE(parse_scan_format("be:u12/16>>4", &f));
  EXPECT_EQ(decode_raw(p, f), 4095);
}

TEST(IioScanFormat, DecodesTimestamp) {
  ScanFormat f;
  ASSERT_TRUE(parse_scan_format("le:s64/64>>0", &f));
  const std::int64_t t = 1'234'567'890'123'456'789;
  std::uint8_t b[8];
  for (int i = 0; i < 8; ++i)
    b[i] = static_cast<std::uint8_t>(static_cast<std::uint64_t>(t) >> (8 * i));
  EXPECT_EQ(decode_raw(b, f), t);
}

TEST(IioScanFormat, ScaleAndOffsetFollowTheAbi) {
  // bmi160 at +-2000 deg/s: scale 0.001065 rad/s per LSB; 1000 LSB -> 1.065 rad/s.
  EXPECT_DOUBLE_EQ(apply_scale(1000, 0.001065, 0.0), 1.065);
  EXPECT_DOUBLE_EQ(apply_scale(-1000, 0.001065, 0.0), -1.065);
  EXPECT_DOUBLE_EQ(apply_scale(10, 0.5, -4.0), 3.0);  // (raw + offset) * scale
}

TEST(IioScanFormat, LayoutAlignsEachElementToItsSize) {
  ScanFormat s16, s64;
  ASSERT_TRUE(parse_scan_format("le:s16/16>>0", &s16));
  ASSERT_TRUE(parse_scan_format("le:s64/64>>0", &s64));
  // gyro x, y, z + timestamp: 6 bytes, timestamp at 8, scan 16 bytes.
  const ScanFormat xyzt[4] = {s16, s16, s16, s64};
  std::size_t off[4];
  EXPECT_EQ(scan_layout(xyzt, 4, off), 16u);
  EXPECT_EQ(off[0], 0u);
  EXPECT_EQ(off[1], 2u);
  EXPECT_EQ(off[2], 4u);
  EXPECT_EQ(off[3], 8u);
  // z only + timestamp: 2 bytes, timestamp at 8.
  const ScanFormat zt[2] = {s16, s64};
  EXPECT_EQ(scan_layout(zt, 2, off), 16u);
  EXPECT_EQ(off[1], 8u);
  EXPECT_EQ(scan_layout(zt, 0, off), 0u);
}

TEST(IioScanFormat, DecodesAScanBuiltByLayout) {
  ScanFormat s16, s64;
  ASSERT_TRUE(parse_scan_format("le:s16/16>>0", &s16));
  ASSERT_TRUE(parse_scan_format("le:s64/64>>0", &s64));
  const ScanFormat zt[2] = {s16, s64};
  std::size_t off[2];
  const std::size_t size = scan_layout(zt, 2, off);
  std::uint8_t scan[16] = {};
  ASSERT_EQ(size, sizeof scan);
  const std::int16_t z = -1234;
  const std::int64_t t = 987'654'321;
  std::memcpy(scan + off[0], &z, 2);  // this machine is little-endian (x86-64, arm64)
  std::memcpy(scan + off[1], &t, 8);
  EXPECT_EQ(decode_raw(scan + off[0], s16), -1234);
  EXPECT_EQ(decode_raw(scan + off[1], s64), t);
}

}  // namespace
}  // namespace agv::iio

#include <gtest/gtest.h>

#include <vector>

#include "agv/protocol/e2e.hpp"

namespace p = agv::protocol;

namespace {

std::uint8_t crc(const std::vector<std::uint8_t>& v) {
  return p::crc8_sae_j1850(v.data(), v.size());
}

agv::hal::CanFrame protected_frame(std::uint16_t data_id, std::uint8_t counter, std::uint8_t fill) {
  agv::hal::CanFrame f;
  f.len = 8;
  for (int i = 2; i < 8; ++i) f.data[i] = static_cast<std::uint8_t>(fill + i);
  p::e2e_protect(data_id, counter, f.data);
  return f;
}

}  // namespace

// AUTOSAR SWS CRC Library, CRC8 SAE J1850 check values.
TEST(Crc8SaeJ1850, AutosarTestVectors) {
  EXPECT_EQ(crc({0x00, 0x00, 0x00, 0x00}), 0x59);
  EXPECT_EQ(crc({0xF2, 0x01, 0x83}), 0x37);
  EXPECT_EQ(crc({0x0F, 0xAA, 0x00, 0x55}), 0x79);
  EXPECT_EQ(crc({0x00, 0xFF, 0x55, 0x11}), 0xB8);
  EXPECT_EQ(crc({0x33, 0x22, 0x55, 0xAA, 0xBB, 0xCC, 0xDD, 0xEE, 0xFF}), 0xCB);
  EXPECT_EQ(crc({0x92, 0x6B, 0x55}), 0x8C);
  EXPECT_EQ(crc({0xFF, 0xFF, 0xFF, 0xFF}), 0x74);
  // The classic CRC catalogue check value of "123456789" for CRC-8/SAE-J1850.
  const std::vector<std::uint8_t> digits = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
  EXPECT_EQ(crc(digits), 0x4B);
}

TEST(E2e, CrcCoversDataIdLowHighThenBytes1To7) {
  std::uint8_t d[8] = {0xAA, 0x13, 1, 2, 3, 4, 5, 6};
  const std::vector<std::uint8_t> expected_input = {0x34, 0x12, 0x13, 1, 2, 3, 4, 5, 6};
  EXPECT_EQ(p::e2e_crc(0x1234, d), crc(expected_input));
  // Byte 0 (the CRC itself) is not part of the input.
  d[0] = 0x55;
  EXPECT_EQ(p::e2e_crc(0x1234, d), crc(expected_input));
  // Swapping the data-ID bytes changes the CRC (both bytes are used, in order).
  EXPECT_NE(p::e2e_crc(0x3412, d), p::e2e_crc(0x1234, d));
}

TEST(E2e, ProtectKeepsUpperNibbleOfByte1) {
  std::uint8_t d[8] = {0, 0xA0, 9, 9, 9, 9, 9, 9};
  p::e2e_protect(0x4C00, 7, d);
  EXPECT_EQ(d[1], 0xA7);
  EXPECT_EQ(d[0], p::e2e_crc(0x4C00, d));
}

TEST(E2eChecker, InOrderWrapsFrom14To0) {
  p::E2eChecker c({0x4C10, 1});
  EXPECT_EQ(c.check(protected_frame(0x4C10, 12, 0)), p::E2eStatus::kInitial);
  EXPECT_EQ(c.check(protected_frame(0x4C10, 13, 0)), p::E2eStatus::kOk);
  EXPECT_EQ(c.check(protected_frame(0x4C10, 14, 0)), p::E2eStatus::kOk);
  EXPECT_EQ(c.check(protected_frame(0x4C10, 0, 0)), p::E2eStatus::kOk);
  EXPECT_EQ(c.counters().ok, 4u);
  EXPECT_EQ(c.counters().rejected(), 0u);
}

TEST(E2eChecker, RepeatedIsRejected) {
  p::E2eChecker c({0x4C10, 3});
  c.check(protected_frame(0x4C10, 3, 0));
  EXPECT_EQ(c.check(protected_frame(0x4C10, 3, 1)), p::E2eStatus::kRepeated);
  EXPECT_EQ(c.counters().repeated, 1u);
  EXPECT_EQ(c.check(protected_frame(0x4C10, 4, 0)), p::E2eStatus::kOk);
}

TEST(E2eChecker, SmallGapAcceptedAndCountedLargeGapRejectedThenResync) {
  p::E2eChecker c({0x4C10, 3});
  c.check(protected_frame(0x4C10, 13, 0));
  // 13 -> 1: delta 3 across the wrap (14, 0 lost).
  EXPECT_EQ(c.check(protected_frame(0x4C10, 1, 0)), p::E2eStatus::kOkSomeLost);
  EXPECT_EQ(c.counters().lost_frames, 2u);
  // 1 -> 5: delta 4 > 3.
  EXPECT_EQ(c.check(protected_frame(0x4C10, 5, 0)), p::E2eStatus::kWrongSequence);
  EXPECT_EQ(c.counters().wrong_sequence, 1u);
  // Resynchronised on 5.
  EXPECT_EQ(c.check(protected_frame(0x4C10, 6, 0)), p::E2eStatus::kOk);
}

TEST(E2eChecker, MaxDeltaOneRejectsAnyLoss) {
  p::E2eChecker c({0x4C10, 1});
  c.check(protected_frame(0x4C10, 0, 0));
  EXPECT_EQ(c.check(protected_frame(0x4C10, 2, 0)), p::E2eStatus::kWrongSequence);
}

TEST(E2eChecker, CorruptionWrongDataIdLengthAndCounter15) {
  p::E2eChecker c({0x4C10, 3});
  agv::hal::CanFrame f = protected_frame(0x4C10, 0, 0);
  for (int byte = 0; byte < 8; ++byte) {
    for (int bit = 0; bit < 8; ++bit) {
      agv::hal::CanFrame g = f;
      g.data[byte] ^= static_cast<std::uint8_t>(1u << bit);
      EXPECT_EQ(c.check(g), p::E2eStatus::kBadCrc) << "byte " << byte << " bit " << bit;
    }
  }
  EXPECT_EQ(c.counters().bad_crc, 64u);
  EXPECT_EQ(c.check(protected_frame(0x4C11, 0, 0)), p::E2eStatus::kBadCrc);  // masquerade
  agv::hal::CanFrame s = f;
  s.len = 7;
  EXPECT_EQ(c.check(s), p::E2eStatus::kBadLength);
  agv::hal::CanFrame bad = f;
  bad.data[1] = static_cast<std::uint8_t>((bad.data[1] & 0xF0) | 15);
  bad.data[0] = p::e2e_crc(0x4C10, bad.data);
  EXPECT_EQ(c.check(bad), p::E2eStatus::kBadCounter);
  // None of the rejected frames set a reference: the good frame is the first one.
  EXPECT_EQ(c.check(f), p::E2eStatus::kInitial);
  EXPECT_EQ(c.counters().rejected(), 67u);
}

// tag36h11 codes and the area-restricted decode (algo/src/overhead/tag_code.cpp) against paper
// 000 section 2.2/2.4's example and libapriltag's own table and renderer.
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <random>

#include "agv/overhead/tag_code.hpp"

namespace agv::overhead {
namespace {

std::uint64_t flip_bits(std::uint64_t code, const std::vector<int>& bits) {
  for (int b : bits) code ^= std::uint64_t{1} << b;
  return code;
}

// Yang et al. numbers its codes from 1: its codes 1..4 are libapriltag's ids 0..3.
TEST(TagCode, PaperCodesAreIds0To3RowMajor) {
  EXPECT_EQ(tag36h11_code(0), 0xd5d628584ULL);
  EXPECT_EQ(tag36h11_code(1), 0xd97f18b49ULL);
  EXPECT_EQ(tag36h11_code(2), 0xdd280910eULL);
  EXPECT_EQ(tag36h11_code(3), 0xe479e9c98ULL);
  EXPECT_EQ(tag36h11_code(kTag36h11Count), 0U);
}

TEST(TagCode, PaperDistancesFromCode1) {
  const std::uint64_t c = tag36h11_code(0);
  EXPECT_EQ(hamming36(c, tag36h11_code(1)), 16);
  EXPECT_EQ(hamming36(c, tag36h11_code(2)), 14);
  EXPECT_EQ(hamming36(c, tag36h11_code(3)), 17);
}

// The paper lists the three turns of its code 1 in the other direction of rotation (each turn
// 90 degrees clockwise); libapriltag turns the other way, so the same codes come in reverse.
TEST(TagCode, PaperRotationsOfCode1) {
  const std::uint64_t c = tag36h11_code(0);
  const std::uint64_t r1 = rotate90(c), r2 = rotate90(r1), r3 = rotate90(r2);
  EXPECT_EQ(r1, 0xc02cdcea4ULL);
  EXPECT_EQ(r2, 0x21a146babULL);
  EXPECT_EQ(r3, 0x2573b3403ULL);
  EXPECT_EQ(rotate90(r3), c);
  EXPECT_EQ(hamming36(c, r1), 18);
  EXPECT_EQ(hamming36(c, r2), 24);
  EXPECT_EQ(hamming36(c, r3), 18);
}

// libapriltag's rendered page: a set bit is a white data cell at (row, column) of the 6 x 6 grid.
TEST(TagCode, CodesMatchLibapriltagsRenderedPages) {
  apriltag_family_t* f = tag36h11_create();
  for (std::uint32_t id : {0U, 1U, 7U, 300U, 586U}) {
    image_u8_t* im = apriltag_to_image(f, static_cast<int>(id));
    ASSERT_EQ(im->width, 10);
    std::uint64_t code = 0;
    for (int r = 0; r < 6; ++r) {
      for (int c = 0; c < 6; ++c) {
        code = (code << 1) | (im->buf[(r + 2) * im->stride + c + 2] > 128 ? 1U : 0U);
      }
    }
    EXPECT_EQ(code, tag36h11_code(id)) << id;
    std::free(im->buf);
    std::free(im);
  }
  tag36h11_destroy(f);
}

TEST(TagCode, FamilyDistanceIsEleven) {
  std::vector<std::uint32_t> all(kTag36h11Count);
  for (std::uint32_t i = 0; i < kTag36h11Count; ++i) all[i] = i;
  EXPECT_EQ(min_distance(all), kTag36h11MinDistance);
  EXPECT_EQ(min_distance({}), 36);
  EXPECT_EQ(min_distance({0, kTag36h11Count}), 0);
  EXPECT_EQ(min_distance({0}), 18);  // its own nearest turn
}

// The pair distance the site check uses: symmetric, over every turn of the other, the family's
// minimum among the first ids.
TEST(TagCode, PairDistance) {
  EXPECT_EQ(tag_distance(1, 8), 11);  // the family's minimum
  EXPECT_EQ(tag_distance(2, 6), 12);
  EXPECT_EQ(tag_distance(5, 6), 13);
  EXPECT_EQ(tag_distance(10, 11), 19);
  EXPECT_EQ(tag_distance(7, 7), 0);
  EXPECT_EQ(tag_distance(0, kTag36h11Count), 0);
  int smallest = 36;
  for (std::uint32_t a = 0; a < 60; ++a) {
    for (std::uint32_t b = a + 1; b < 60; ++b) {
      ASSERT_EQ(tag_distance(a, b), tag_distance(b, a)) << a << " " << b;
      EXPECT_LE(min_distance({a, b}), tag_distance(a, b));  // the set's includes the pair's
      smallest = std::min(smallest, tag_distance(a, b));
      // A code turned is the same tag: the distance does not change.
      const std::uint64_t turned = rotate90(tag36h11_code(b));
      EXPECT_LE(tag_distance(a, b), hamming36(tag36h11_code(a), turned));
    }
  }
  EXPECT_EQ(smallest, kTag36h11MinDistance);
}

TEST(TagCode, PaperAreaCorrectsSixBits) {
  const std::vector<std::uint32_t> area{0, 1, 2, 3};
  const int d = min_distance(area);
  EXPECT_GE(d, 13);
  std::mt19937 rng(5);
  for (std::uint32_t id : area) {
    for (int q = 0; q < 4; ++q) {
      for (int trial = 0; trial < 50; ++trial) {
        std::vector<int> bits(36);
        for (int i = 0; i < 36; ++i) bits[static_cast<std::size_t>(i)] = i;
        std::shuffle(bits.begin(), bits.end(), rng);
        bits.resize(6);
        std::uint64_t code = tag36h11_code(id);
        for (int k = 0; k < q; ++k) code = rotate90(code);
        const DecodeResult r = decode_restricted(flip_bits(code, bits), area);
        ASSERT_TRUE(r.ok);
        EXPECT_EQ(r.id, id);
        EXPECT_EQ(r.rotation, q);
        EXPECT_EQ(r.hamming, 6);
        EXPECT_EQ(r.correctable_bits, (d - 1) / 2);
        EXPECT_GT(r.margin, 0);
      }
    }
  }
}

TEST(TagCode, SixBitErrorsRefusedGlobally) {
  const std::uint64_t code = flip_bits(tag36h11_code(0), {0, 5, 11, 17, 23, 29});
  const DecodeResult g = decode_global(code, 2);
  EXPECT_FALSE(g.ok);
  EXPECT_EQ(g.correctable_bits, 5);
  // Within two bits the global decode still reads it.
  const DecodeResult g2 = decode_global(flip_bits(tag36h11_code(42), {3, 30}), 2);
  EXPECT_TRUE(g2.ok);
  EXPECT_EQ(g2.id, 42U);
  EXPECT_EQ(g2.hamming, 2);
}

// A code exactly halfway between two candidates is refused however many bits are allowed.
TEST(TagCode, AmbiguousCodeRefused) {
  const std::uint64_t a = tag36h11_code(0), b = tag36h11_code(2);
  const std::uint64_t diff = a ^ b;  // 14 bits
  std::uint64_t mid = a;
  int moved = 0;
  for (int i = 0; i < 36 && moved < 7; ++i) {
    if ((diff >> i) & 1U) mid ^= std::uint64_t{1} << i, ++moved;
  }
  ASSERT_EQ(hamming36(mid, a), 7);
  ASSERT_EQ(hamming36(mid, b), 7);
  const DecodeResult r = decode_restricted(mid, {0, 2}, 9);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.margin, 0);
  // Over the set's own correctable bits: the nearest is still refused.
  const DecodeResult s = decode_restricted(mid, {0, 1, 2, 3});
  EXPECT_FALSE(s.ok);
}

TEST(TagCode, BadSetsDecodeNothing) {
  EXPECT_FALSE(decode_restricted(tag36h11_code(0), {}).ok);
  EXPECT_FALSE(decode_restricted(tag36h11_code(0), {0, 9999}).ok);
  const DecodeResult r = decode_restricted(tag36h11_code(5), {5, 5, 5});
  EXPECT_TRUE(r.ok);
  EXPECT_EQ(r.id, 5U);
  EXPECT_EQ(r.hamming, 0);
}

}  // namespace
}  // namespace agv::overhead

// tag36h11 codes and the area-restricted decoding of Yang et al. section 2.4: a code read from a
// tag is compared only with the codes (in all four turns) of the vehicles the tracker believes to
// be in the area, so the bits that can be corrected grow from the family's 5 to
// (d_min(area) - 1) / 2, where d_min(area) is the smallest Hamming distance among those codes.
// Pure; docs/design/overhead.md.
#pragma once

#include <cstdint>
#include <vector>

namespace agv::overhead {

inline constexpr int kTag36h11Bits = 36;
inline constexpr std::uint32_t kTag36h11Count = 587;
// Smallest Hamming distance between any two codes of the family, turns included.
inline constexpr int kTag36h11MinDistance = 11;

// The family's code of `id`: bit 35 first, row-major from the page's top-left data cell, a set
// bit for a white cell. libapriltag 3 keeps the same codes in another bit order (its bit_x/bit_y
// spiral); this is its table re-expressed row-major, the order Yang et al. quotes (the paper's
// 1-based "code numbered 1", d5d628584, is id 0 here). 0 for an id outside the family.
std::uint64_t tag36h11_code(std::uint32_t id);
// The code of the same tag turned a quarter turn: libapriltag's rotate90, in row-major order
// (cell (r, c) moves to (5 - c, r)).
std::uint64_t rotate90(std::uint64_t code);
int hamming36(std::uint64_t a, std::uint64_t b);

struct DecodeResult {
  bool ok = false;
  std::uint32_t id = 0;
  // The read code is the id's code after `rotation` rotate90 turns (0 when read in the page's
  // own orientation).
  int rotation = 0;
  int hamming = 0;  // bits that differ from the id's code in that turn
  // Bits the decode could correct: (d_min - 1) / 2 for the candidate set it used.
  int correctable_bits = 0;
  // Second-nearest candidate's distance minus `hamming` (> 0 when unambiguous).
  int margin = 0;
};

// Decodes `code` against allowed ids only (every turn of each). ok when the nearest candidate is
// within max_bits and strictly nearer than the second; max_bits < 0 means the set's own
// (d_min - 1) / 2, capped at 9. An empty set or an id outside the family decodes nothing.
// d_min costs 16 n^2 distances: meant for an area's few ids (about 4 ms for the whole family;
// decode_global is the family's decode).
DecodeResult decode_restricted(std::uint64_t code, const std::vector<std::uint32_t>& allowed_ids,
                               int max_bits = -1);
// decode_restricted against the whole family with at most max_bits corrected (max_bits < 0: none),
// without recomputing the family's distance (correctable_bits from kTag36h11MinDistance).
DecodeResult decode_global(std::uint64_t code, int max_bits);
// Smallest Hamming distance between the codes of two ids, over the four turns of b's: how many
// wrong bits turn a read of one into the other. 0 for an id outside the family; every two ids
// of the family are at least kTag36h11MinDistance apart.
int tag_distance(std::uint32_t a, std::uint32_t b);
// Smallest Hamming distance between any two codes of the set, over every turn of each (a
// code's own turns included, so a set of one id gives its nearest own turn); 36 for an empty
// set, 0 when an id is outside the family.
int min_distance(const std::vector<std::uint32_t>& ids);

}  // namespace agv::overhead

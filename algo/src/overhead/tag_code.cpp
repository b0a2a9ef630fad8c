// tag36h11 codes in the page's row-major order and the area-restricted decode (tag_code.hpp).
// libapriltag 3 stores its codes in its own bit order (family->bit_x/bit_y, a spiral); the table
// here is re-expressed row-major, which is the order Yang et al. quotes (its "code numbered 1",
// d5d628584, is libapriltag's id 0).
#include "agv/overhead/tag_code.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>

#include <algorithm>
#include <array>
#include <bit>
#include <limits>

namespace agv::overhead {

// Named, not anonymous: the library is built as one unity source.
namespace tag_code_detail {

constexpr int kSide = 6;
constexpr std::uint64_t kMask36 = (std::uint64_t{1} << kTag36h11Bits) - 1;
// The largest correction decode_restricted grants on its own: 9 bits of 36 leave a noise code
// matching by chance a rare event even in a set of one.
constexpr int kMaxAutoBits = 9;

int bit_of(std::uint64_t code, int row, int col) {
  return static_cast<int>((code >> (kTag36h11Bits - 1 - (row * kSide + col))) & 1U);
}
std::uint64_t with_bit(int row, int col) {
  return std::uint64_t{1} << (kTag36h11Bits - 1 - (row * kSide + col));
}

using Table = std::array<std::uint64_t, kTag36h11Count>;

Table make_table() {
  Table t{};
  apriltag_family_t* f = tag36h11_create();
  const bool ok = f && f->ncodes == kTag36h11Count && f->nbits == kTag36h11Bits;
  for (std::uint32_t id = 0; ok && id < kTag36h11Count; ++id) {
    std::uint64_t rm = 0;
    for (int i = 0; i < kTag36h11Bits; ++i) {
      if ((f->codes[id] >> (kTag36h11Bits - 1 - i)) & 1U) {
        // bit_x/bit_y count cells of the black square (1..6 for the data cells).
        rm |= with_bit(static_cast<int>(f->bit_y[i]) - 1, static_cast<int>(f->bit_x[i]) - 1);
      }
    }
    t[id] = rm;
  }
  if (f) tag36h11_destroy(f);
  return t;
}

const Table& table() {
  static const Table t = make_table();
  return t;
}

struct Candidate {
  std::uint32_t id;
  int rotation;
  std::uint64_t code;
};

std::vector<Candidate> candidates(const std::vector<std::uint32_t>& ids) {
  std::vector<std::uint32_t> u(ids);
  std::sort(u.begin(), u.end());
  u.erase(std::unique(u.begin(), u.end()), u.end());
  std::vector<Candidate> c;
  c.reserve(u.size() * 4);
  for (std::uint32_t id : u) {
    std::uint64_t code = tag36h11_code(id);
    for (int q = 0; q < 4; ++q) {
      c.push_back({id, q, code});
      code = rotate90(code);
    }
  }
  return c;
}

bool all_in_family(const std::vector<std::uint32_t>& ids) {
  return std::all_of(ids.begin(), ids.end(), [](std::uint32_t id) { return id < kTag36h11Count; });
}

int min_distance_of(const std::vector<Candidate>& c) {
  int best = kTag36h11Bits;
  for (std::size_t i = 0; i < c.size(); ++i) {
    for (std::size_t j = i + 1; j < c.size(); ++j)
      best = std::min(best, hamming36(c[i].code, c[j].code));
  }
  return best;
}

DecodeResult nearest(std::uint64_t code, const std::vector<Candidate>& c, int d_min, int max_bits) {
  DecodeResult r;
  r.correctable_bits = (d_min - 1) / 2;
  if (max_bits < 0) max_bits = std::min(r.correctable_bits, kMaxAutoBits);
  int best = std::numeric_limits<int>::max(), second = std::numeric_limits<int>::max();
  const Candidate* hit = nullptr;
  for (const Candidate& k : c) {
    const int d = hamming36(code, k.code);
    if (d < best) {
      second = best;
      best = d;
      hit = &k;
    } else if (d < second) {
      second = d;
    }
  }
  if (!hit) return r;
  r.id = hit->id;
  r.rotation = hit->rotation;
  r.hamming = best;
  r.margin = second == std::numeric_limits<int>::max() ? kTag36h11Bits - best : second - best;
  r.ok = best <= max_bits && r.margin > 0;
  return r;
}

}  // namespace tag_code_detail

std::uint64_t tag36h11_code(std::uint32_t id) {
  return id < kTag36h11Count ? tag_code_detail::table()[id] : 0;
}

// libapriltag's rotate90 (a 9-bit cyclic shift of its spiral order) is, in row-major order, the
// grid turned so that cell (r, c) moves to (5 - c, r).
std::uint64_t rotate90(std::uint64_t code) {
  using namespace tag_code_detail;
  std::uint64_t out = 0;
  for (int r = 0; r < kSide; ++r) {
    for (int c = 0; c < kSide; ++c) {
      if (bit_of(code, r, c)) out |= with_bit(kSide - 1 - c, r);
    }
  }
  return out;
}

int hamming36(std::uint64_t a, std::uint64_t b) {
  return std::popcount((a ^ b) & tag_code_detail::kMask36);
}

DecodeResult decode_restricted(std::uint64_t code, const std::vector<std::uint32_t>& allowed_ids,
                               int max_bits) {
  using namespace tag_code_detail;
  if (allowed_ids.empty() || !all_in_family(allowed_ids)) return {};
  const std::vector<Candidate> c = candidates(allowed_ids);
  return nearest(code, c, min_distance_of(c), max_bits);
}

DecodeResult decode_global(std::uint64_t code, int max_bits) {
  using namespace tag_code_detail;
  static const std::vector<Candidate> all = [] {
    std::vector<std::uint32_t> ids(kTag36h11Count);
    for (std::uint32_t i = 0; i < kTag36h11Count; ++i) ids[i] = i;
    return candidates(ids);
  }();
  return nearest(code, all, kTag36h11MinDistance, max_bits < 0 ? 0 : max_bits);
}

int tag_distance(std::uint32_t a, std::uint32_t b) {
  if (a >= kTag36h11Count || b >= kTag36h11Count) return 0;
  const std::uint64_t ca = tag36h11_code(a);
  std::uint64_t cb = tag36h11_code(b);
  int best = kTag36h11Bits;
  for (int turn = 0; turn < 4; ++turn, cb = rotate90(cb)) best = std::min(best, hamming36(ca, cb));
  return best;
}

int min_distance(const std::vector<std::uint32_t>& ids) {
  using namespace tag_code_detail;
  if (!all_in_family(ids)) return 0;
  return min_distance_of(candidates(ids));
}

}  // namespace agv::overhead

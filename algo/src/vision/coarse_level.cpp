// The coarse detection level's image operations (agv/vision/coarse_level.hpp): they are most of a
// landmark-free frame. aarch64 instructions for a 640x480 frame at factor 8 (80x60 coarse, block
// 13; tools/vision-cost), before -> now: box downsample 115.6k -> 42.4k (scalar loop: ~3 per input
// pixel), adaptive threshold 99.6k -> 30.8k, integral images 63.6k -> 30.8k. The threshold and
// integral loops are 128-bit GCC/Clang vectors (one NEON or SSE2 register); the box downsample is
// NEON intrinsics on aarch64, SSE2 sums of absolute differences on x86-64 (factors 8 and 16) and
// generic vector extensions elsewhere.
#include "agv/vision/coarse_level.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#if defined(__aarch64__) && defined(__ARM_NEON)
#include <arm_neon.h>
#elif defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace agv::vision {

namespace {

typedef std::uint8_t U8x16 __attribute__((vector_size(16)));
typedef std::uint16_t U16x16 __attribute__((vector_size(32)));
typedef std::uint16_t U16x8 __attribute__((vector_size(16)));
typedef std::uint16_t U16x4 __attribute__((vector_size(8)));
typedef std::uint16_t U16x2 __attribute__((vector_size(4)));
typedef std::int16_t I16x8 __attribute__((vector_size(16)));
typedef std::uint32_t U32x4 __attribute__((vector_size(16)));

// Zero-extension of the low and high halves to lanes twice as wide, written as an interleave with
// zeros (one ZIP or PUNPCK): GCC 12 turns __builtin_convertvector from an 8-byte vector into
// lane-by-lane inserts on aarch64, 4 instructions per pixel.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "widen_lo/hi interleave little-endian");
inline U16x8 widen_lo(U8x16 v) {
  const U8x16 z{};
  const U8x16 r =
      __builtin_shufflevector(v, z, 0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23);
  return std::bit_cast<U16x8>(r);
}
inline U16x8 widen_hi(U8x16 v) {
  const U8x16 z{};
  const U8x16 r =
      __builtin_shufflevector(v, z, 8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31);
  return std::bit_cast<U16x8>(r);
}
inline U32x4 widen_lo(U16x8 v) {
  const U16x8 z{};
  return std::bit_cast<U32x4>(__builtin_shufflevector(v, z, 0, 8, 1, 9, 2, 10, 3, 11));
}
inline U32x4 widen_hi(U16x8 v) {
  const U16x8 z{};
  return std::bit_cast<U32x4>(__builtin_shufflevector(v, z, 4, 12, 5, 13, 6, 14, 7, 15));
}
// Running sums of the lanes (lane i = v[0] + ... + v[i], modulo 2^bits): v plus itself shifted up
// by 1, 2 (and 4) lanes. Each shift takes consecutive lanes of (zeros, v), which GCC emits as one
// EXT; any other order of indices became TBL plus register copies.
inline U32x4 inclusive_prefix(U32x4 v) {
  const U32x4 z{};
  v += __builtin_shufflevector(z, v, 3, 4, 5, 6);
  v += __builtin_shufflevector(z, v, 2, 3, 4, 5);
  return v;
}
inline U16x8 inclusive_prefix(U16x8 v) {
  const U16x8 z{};
  v += __builtin_shufflevector(z, v, 7, 8, 9, 10, 11, 12, 13, 14);
  v += __builtin_shufflevector(z, v, 6, 7, 8, 9, 10, 11, 12, 13);
  v += __builtin_shufflevector(z, v, 4, 5, 6, 7, 8, 9, 10, 11);
  return v;
}

// Sum of neighbouring lane pairs: lanes (0+1, 2+3, ...), half as many.
inline U16x8 pair_sums(const U16x16& v) {
  return __builtin_shufflevector(v, v, 0, 2, 4, 6, 8, 10, 12, 14) +
         __builtin_shufflevector(v, v, 1, 3, 5, 7, 9, 11, 13, 15);
}
inline U16x4 pair_sums(U16x8 v) {
  return __builtin_shufflevector(v, v, 0, 2, 4, 6) + __builtin_shufflevector(v, v, 1, 3, 5, 7);
}
inline U16x2 pair_sums(U16x4 v) {
  return __builtin_shufflevector(v, v, 0, 2) + __builtin_shufflevector(v, v, 1, 3);
}
inline std::uint16_t pair_sums(U16x2 v) { return static_cast<std::uint16_t>(v[0] + v[1]); }

// Block sums of 16 columns (one column sum per lane) reduced to 16 / F outputs, rounded means
// stored to dst. Sums stay below 2^16: at most 16 * 16 * 255.
template <int F>
inline void store_means(const U16x16& col, std::uint8_t* dst) {
  constexpr int kShift = F == 2 ? 2 : F == 4 ? 4 : F == 8 ? 6 : 8;  // log2(F * F)
  constexpr std::uint16_t kHalf = static_cast<std::uint16_t>((F * F) / 2);
  if constexpr (F == 2) {
    const U16x8 s = (pair_sums(col) + kHalf) >> kShift;
    for (int i = 0; i < 8; ++i) dst[i] = static_cast<std::uint8_t>(s[i]);
  } else if constexpr (F == 4) {
    const U16x4 s = (pair_sums(pair_sums(col)) + kHalf) >> kShift;
    for (int i = 0; i < 4; ++i) dst[i] = static_cast<std::uint8_t>(s[i]);
  } else if constexpr (F == 8) {
    const U16x2 s = (pair_sums(pair_sums(pair_sums(col))) + kHalf) >> kShift;
    dst[0] = static_cast<std::uint8_t>(s[0]);
    dst[1] = static_cast<std::uint8_t>(s[1]);
  } else {
    const unsigned s = pair_sums(pair_sums(pair_sums(pair_sums(col))));
    dst[0] = static_cast<std::uint8_t>((s + kHalf) >> kShift);
  }
}

template <int F>
void box_downsample_vec(const cv::Mat& img, cv::Size cs, cv::Mat* out) {
  constexpr int kOutPerChunk = 16 / F;
  const int chunks = cs.width / kOutPerChunk;  // whole 16-pixel chunks inside cs.width * F
  for (int y = 0; y < cs.height; ++y) {
    const std::uint8_t* rows[F];
    for (int k = 0; k < F; ++k) rows[k] = img.ptr<std::uint8_t>(y * F + k);
    std::uint8_t* dst = out->ptr<std::uint8_t>(y);
    for (int c = 0; c < chunks; ++c) {
      U16x16 col{};
      for (int k = 0; k < F; ++k) {
        U8x16 v;
        std::memcpy(&v, rows[k] + c * 16, sizeof v);
        col += __builtin_convertvector(v, U16x16);
      }
      store_means<F>(col, dst + c * kOutPerChunk);
    }
    // Columns after the last whole chunk.
    constexpr unsigned kArea = F * F;
    for (int x = chunks * kOutPerChunk; x < cs.width; ++x) {
      unsigned sum = 0;
      for (int k = 0; k < F; ++k) {
        for (int i = 0; i < F; ++i) sum += rows[k][x * F + i];
      }
      dst[x] = static_cast<std::uint8_t>((sum + kArea / 2) / kArea);
    }
  }
}

#if defined(__aarch64__) && defined(__ARM_NEON)
// aarch64: UADALP adds the neighbouring pixel pairs of 16 bytes into eight 16-bit lanes, one
// instruction per 16 pixels and row (the generic path widens and adds: three). A group of eight
// outputs covers F / 2 such chunks; pairwise adds (ADDP) fold them into the eight F-column sums,
// and RSHRN rounds half up and narrows, as the scalar loop's (sum + area / 2) / area.
// Lane sums stay below 2^16: at most 16 * 16 * 255.
template <int F>
void box_downsample_neon(const cv::Mat& img, cv::Size cs, cv::Mat* out) {
  constexpr int kChunks = F / 2;
  constexpr int kShift = F == 2 ? 2 : F == 4 ? 4 : F == 8 ? 6 : 8;  // log2(F * F)
  constexpr unsigned kArea = F * F;
  const int groups = cs.width / 8;
  for (int y = 0; y < cs.height; ++y) {
    const std::uint8_t* rows[F];
    for (int k = 0; k < F; ++k) rows[k] = img.ptr<std::uint8_t>(y * F + k);
    std::uint8_t* dst = out->ptr<std::uint8_t>(y);
    for (int g = 0; g < groups; ++g) {
      const int x0 = g * 8 * F;
      uint16x8_t acc[kChunks];
      for (int c = 0; c < kChunks; ++c) acc[c] = vpaddlq_u8(vld1q_u8(rows[0] + x0 + 16 * c));
      for (int k = 1; k < F; ++k) {
        for (int c = 0; c < kChunks; ++c)
          acc[c] = vpadalq_u8(acc[c], vld1q_u8(rows[k] + x0 + 16 * c));
      }
      for (int n = kChunks; n > 1; n /= 2) {
        for (int i = 0; i < n / 2; ++i) acc[i] = vpaddq_u16(acc[2 * i], acc[2 * i + 1]);
      }
      vst1_u8(dst + g * 8, vrshrn_n_u16(acc[0], kShift));
    }
    for (int x = groups * 8; x < cs.width; ++x) {
      unsigned sum = 0;
      for (int k = 0; k < F; ++k) {
        for (int i = 0; i < F; ++i) sum += rows[k][x * F + i];
      }
      dst[x] = static_cast<std::uint8_t>((sum + kArea / 2) / kArea);
    }
  }
}
#endif

#if !(defined(__aarch64__) && defined(__ARM_NEON)) && defined(__SSE2__)
// x86-64 (SSE2 is part of the base ISA): PSADBW against zero sums each half of 16 bytes into a
// 64-bit lane, one instruction per 16 pixels and row, where the generic path widens to 16 bits,
// adds and then folds the lanes in shuffles. At F = 8 a chunk gives two outputs' block sums, at
// F = 16 one. It was an eighth of a tracked frame on x86-64 (docs/design/performance.md). The sums
// stay below 2^16 (16 * 16 * 255), so the low 16 bits of each lane hold them.
template <int F>
void box_downsample_sse2(const cv::Mat& img, cv::Size cs, cv::Mat* out) {
  static_assert(F == 8 || F == 16, "one 16-byte chunk holds whole blocks");
  constexpr int kOutPerChunk = 16 / F;
  constexpr unsigned kArea = F * F;
  const int chunks = cs.width / kOutPerChunk;
  const __m128i zero = _mm_setzero_si128();
  for (int y = 0; y < cs.height; ++y) {
    const std::uint8_t* rows[F];
    for (int k = 0; k < F; ++k) rows[k] = img.ptr<std::uint8_t>(y * F + k);
    std::uint8_t* dst = out->ptr<std::uint8_t>(y);
    for (int c = 0; c < chunks; ++c) {
      __m128i acc = zero;
      for (int k = 0; k < F; ++k) {
        const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(rows[k] + c * 16));
        acc = _mm_add_epi64(acc, _mm_sad_epu8(v, zero));
      }
      const unsigned lo = static_cast<unsigned>(_mm_extract_epi16(acc, 0));
      const unsigned hi = static_cast<unsigned>(_mm_extract_epi16(acc, 4));
      if constexpr (F == 8) {
        dst[c * 2] = static_cast<std::uint8_t>((lo + kArea / 2) / kArea);
        dst[c * 2 + 1] = static_cast<std::uint8_t>((hi + kArea / 2) / kArea);
      } else {
        dst[c] = static_cast<std::uint8_t>((lo + hi + kArea / 2) / kArea);
      }
    }
    for (int x = chunks * kOutPerChunk; x < cs.width; ++x) {
      unsigned sum = 0;
      for (int k = 0; k < F; ++k) {
        for (int i = 0; i < F; ++i) sum += rows[k][x * F + i];
      }
      dst[x] = static_cast<std::uint8_t>((sum + kArea / 2) / kArea);
    }
  }
}
#endif

template <int F>
void box_downsample_fast(const cv::Mat& img, cv::Size cs, cv::Mat* out) {
#if defined(__aarch64__) && defined(__ARM_NEON)
  box_downsample_neon<F>(img, cs, out);
#elif defined(__SSE2__)
  if constexpr (F >= 8) {
    box_downsample_sse2<F>(img, cs, out);
  } else {
    box_downsample_vec<F>(img, cs, out);
  }
#else
  box_downsample_vec<F>(img, cs, out);
#endif
}

}  // namespace

// f rows summed into one row, then f columns at a time.
void box_downsample_scalar(const cv::Mat& img, int f, cv::Size cs, cv::Mat* out,
                           std::vector<std::uint32_t>* sums) {
  out->create(cs, CV_8UC1);
  const int w = cs.width * f;
  sums->resize(static_cast<size_t>(w));
  const std::uint32_t area = static_cast<std::uint32_t>(f * f);
  for (int y = 0; y < cs.height; ++y) {
    std::uint32_t* acc = sums->data();
    std::fill(acc, acc + w, 0u);
    for (int k = 0; k < f; ++k) {
      const std::uint8_t* src = img.ptr<std::uint8_t>(y * f + k);
      for (int x = 0; x < w; ++x) acc[x] += src[x];
    }
    std::uint8_t* dst = out->ptr<std::uint8_t>(y);
    for (int x = 0; x < cs.width; ++x) {
      std::uint32_t sum = 0;
      for (int k = 0; k < f; ++k) sum += acc[x * f + k];
      dst[x] = static_cast<std::uint8_t>((sum + area / 2) / area);
    }
  }
}

void box_downsample(const cv::Mat& img, int f, cv::Size cs, cv::Mat* out,
                    std::vector<std::uint32_t>* row_sums) {
  out->create(cs, CV_8UC1);
  switch (f) {
    case 2:
      box_downsample_fast<2>(img, cs, out);
      return;
    case 4:
      box_downsample_fast<4>(img, cs, out);
      return;
    case 8:
      box_downsample_fast<8>(img, cs, out);
      return;
    case 16:
      box_downsample_fast<16>(img, cs, out);
      return;
    default:
      box_downsample_scalar(img, f, cs, out, row_sums);
  }
}

void adaptive_threshold_mean_inv(const cv::Mat& src, int block, double offset, cv::Mat* dst,
                                 std::vector<std::uint16_t>* scratch) {
  if (block > kMaxOwnAdaptiveBlock || block < 3 || block % 2 == 0 || src.empty() ||
      !std::isfinite(offset)) {
    cv::adaptiveThreshold(src, *dst, 255, cv::ADAPTIVE_THRESH_MEAN_C, cv::THRESH_BINARY_INV, block,
                          offset);
    return;
  }
  const int w = src.cols, h = src.rows, r = block / 2, area = block * block;
  dst->create(src.size(), CV_8UC1);
  // All in 16-bit lanes, 16 pixels a step: a column sum is at most 15 * 255, a window sum at most
  // 225 * 255 = 57375. With the rounded mean m = (2 sum + area) / (2 area) (area odd: no ties),
  //   src - m <= -idelta  <=>  m >= t = src + idelta  <=>  sum + (area - 1) / 2 >= area t,
  // and both sides fit 16 bits once t is clamped to [0, tmax]: t < 0 holds for every sum, and
  // t > tmax = 65535 / area for none (area (tmax + 1) > 65535 > the largest left side). idelta is
  // clamped the same way first, so src + idelta fits the signed 16-bit lanes.
  const int tmax = 65535 / area;
  const double fo = std::floor(offset);
  const int idelta = fo < -256.0 ? -256 : fo > tmax + 1.0 ? tmax + 1 : static_cast<int>(fo);
  const std::uint16_t half = static_cast<std::uint16_t>((area - 1) / 2);
  const std::uint16_t area16 = static_cast<std::uint16_t>(area);
  const I16x8 zero{}, tmax_v = zero + static_cast<std::int16_t>(tmax);
  // Column sums of the block's rows (border replicated), then the prefix sums of one row's
  // column sums with the border replicated r times on each side: a window sum is the difference
  // of two prefixes, modulo 2^16 and exact because it is below 2^16.
  const size_t wpad = static_cast<size_t>(w + 2 * r + 1);
  scratch->resize(static_cast<size_t>(w) + wpad);
  std::uint16_t* col = scratch->data();
  std::uint16_t* pre = col + w;
  auto src_row = [&](int y) { return src.ptr<std::uint8_t>(std::clamp(y, 0, h - 1)); };
  // col += add - sub (sub may be null).
  auto update_col = [&](const std::uint8_t* add, const std::uint8_t* sub) {
    int x = 0;
    for (; x + 16 <= w; x += 16) {
      U16x8 c0, c1;
      U8x16 a, b{};
      std::memcpy(&c0, col + x, sizeof c0);
      std::memcpy(&c1, col + x + 8, sizeof c1);
      std::memcpy(&a, add + x, sizeof a);
      if (sub) std::memcpy(&b, sub + x, sizeof b);
      c0 += widen_lo(a) - widen_lo(b);
      c1 += widen_hi(a) - widen_hi(b);
      std::memcpy(col + x, &c0, sizeof c0);
      std::memcpy(col + x + 8, &c1, sizeof c1);
    }
    for (; x < w; ++x) col[x] = static_cast<std::uint16_t>(col[x] + add[x] - (sub ? sub[x] : 0));
  };
  // Lanes of 8 pixels whose mean reaches t: all ones (0xffff), else 0. lo: their prefixes.
  auto passes = [&](const std::uint16_t* lo, U16x8 pix) {
    U16x8 hi_v, lo_v;
    std::memcpy(&hi_v, lo + block, sizeof hi_v);
    std::memcpy(&lo_v, lo, sizeof lo_v);
    I16x8 t = std::bit_cast<I16x8>(pix) + static_cast<std::int16_t>(idelta);
    t &= ~(t < zero);
    const I16x8 over = t > tmax_v;
    t = (t & ~over) | (tmax_v & over);
    const U16x8 rhs = std::bit_cast<U16x8>(t) * area16;
    return static_cast<I16x8>(hi_v - lo_v + half >= rhs);
  };
  std::fill(col, col + w, std::uint16_t{0});
  for (int dy = -r; dy <= r; ++dy) update_col(src_row(dy), nullptr);
  for (int y = 0; y < h; ++y) {
    std::uint16_t acc = 0;
    std::uint16_t* o = pre;
    *o++ = 0;
    for (int i = 0; i < r; ++i) *o++ = acc = static_cast<std::uint16_t>(acc + col[0]);
    int xc = 0;
    for (; xc + 8 <= w; xc += 8, o += 8) {
      U16x8 v;
      std::memcpy(&v, col + xc, sizeof v);
      v = inclusive_prefix(v) + acc;
      std::memcpy(o, &v, sizeof v);
      acc = v[7];
    }
    for (; xc < w; ++xc) *o++ = acc = static_cast<std::uint16_t>(acc + col[xc]);
    for (int i = 0; i < r; ++i) *o++ = acc = static_cast<std::uint16_t>(acc + col[w - 1]);
    const std::uint8_t* p = src.ptr<std::uint8_t>(y);
    std::uint8_t* d = dst->ptr<std::uint8_t>(y);
    int x = 0;
    for (; x + 16 <= w; x += 16) {
      U8x16 pv;
      std::memcpy(&pv, p + x, sizeof pv);
      const I16x8 m0 = passes(pre + x, widen_lo(pv)), m1 = passes(pre + x + 8, widen_hi(pv));
      const U8x16 out =
          __builtin_shufflevector(std::bit_cast<U8x16>(m0), std::bit_cast<U8x16>(m1), 0, 2, 4, 6, 8,
                                  10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
      std::memcpy(d + x, &out, sizeof out);
    }
    for (; x < w; ++x) {
      const int sum = static_cast<std::uint16_t>(pre[x + block] - pre[x]);
      d[x] = sum + half >= area * std::clamp(p[x] + idelta, 0, tmax) ? 255 : 0;
    }
    if (y + 1 < h) update_col(src_row(y + 1 + r), src_row(y - r));
  }
}

void integral_sum_sq(const cv::Mat& src, cv::Mat* sum, cv::Mat* sq) {
  const int w = src.cols, h = src.rows;
  sum->create(h + 1, w + 1, CV_32SC1);
  sq->create(h + 1, w + 1, CV_32SC1);
  std::fill(sum->ptr<std::int32_t>(0), sum->ptr<std::int32_t>(0) + w + 1, 0);
  std::fill(sq->ptr<std::uint32_t>(0), sq->ptr<std::uint32_t>(0) + w + 1, 0u);
  // Each row's running sums 16 pixels a step (squares in 16-bit lanes: 255^2 < 2^16), plus the
  // row above. The sums are written as unsigned: they stay below 2^31 for any image under 8.4
  // Mpixel, so the int32 values are the same.
  for (int y = 0; y < h; ++y) {
    const std::uint8_t* p = src.ptr<std::uint8_t>(y);
    const std::uint32_t* s0 = sum->ptr<std::uint32_t>(y) + 1;
    const std::uint32_t* q0 = sq->ptr<std::uint32_t>(y) + 1;
    std::uint32_t* s1 = sum->ptr<std::uint32_t>(y + 1) + 1;
    std::uint32_t* q1 = sq->ptr<std::uint32_t>(y + 1) + 1;
    s1[-1] = 0;
    q1[-1] = 0;
    std::uint32_t rs = 0, rq = 0;
    // out[i] = above[i] + carry + (running sum of v)[i]; carry becomes the running total.
    auto put = [](U32x4 v, std::uint32_t* carry, const std::uint32_t* above, std::uint32_t* out) {
      v = inclusive_prefix(v) + *carry;
      *carry = v[3];
      U32x4 a;
      std::memcpy(&a, above, sizeof a);
      a += v;
      std::memcpy(out, &a, sizeof a);
    };
    int x = 0;
    for (; x + 16 <= w; x += 16) {
      U8x16 pv;
      std::memcpy(&pv, p + x, sizeof pv);
      const U16x8 lo = widen_lo(pv), hi = widen_hi(pv);
      const U16x8 lo2 = lo * lo, hi2 = hi * hi;
      put(widen_lo(lo), &rs, s0 + x, s1 + x);
      put(widen_hi(lo), &rs, s0 + x + 4, s1 + x + 4);
      put(widen_lo(hi), &rs, s0 + x + 8, s1 + x + 8);
      put(widen_hi(hi), &rs, s0 + x + 12, s1 + x + 12);
      put(widen_lo(lo2), &rq, q0 + x, q1 + x);
      put(widen_hi(lo2), &rq, q0 + x + 4, q1 + x + 4);
      put(widen_lo(hi2), &rq, q0 + x + 8, q1 + x + 8);
      put(widen_hi(hi2), &rq, q0 + x + 12, q1 + x + 12);
    }
    for (; x < w; ++x) {
      const std::uint32_t v = p[x];
      rs += v;
      rq += v * v;
      s1[x] = s0[x] + rs;
      q1[x] = q0[x] + rq;
    }
  }
}

}  // namespace agv::vision

// Box downsampling for the coarse detection level (agv/vision/coarse_level.hpp). The scalar
// loop cost about 3 instructions per input pixel on aarch64, most of a landmark-free frame; the
// vector path needs about half an instruction per pixel.
#include "agv/vision/coarse_level.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#if defined(__aarch64__) && defined(__ARM_NEON)
#include <arm_neon.h>
#endif

namespace agv::vision {

namespace {

typedef std::uint8_t U8x16 __attribute__((vector_size(16)));
typedef std::uint16_t U16x16 __attribute__((vector_size(32)));
typedef std::uint16_t U16x8 __attribute__((vector_size(16)));
typedef std::uint16_t U16x4 __attribute__((vector_size(8)));
typedef std::uint16_t U16x2 __attribute__((vector_size(4)));

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

template <int F>
void box_downsample_fast(const cv::Mat& img, cv::Size cs, cv::Mat* out) {
#if defined(__aarch64__) && defined(__ARM_NEON)
  box_downsample_neon<F>(img, cs, out);
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
                                 std::vector<int>* scratch) {
  if (block > kMaxOwnAdaptiveBlock || block < 3 || block % 2 == 0 || src.empty()) {
    cv::adaptiveThreshold(src, *dst, 255, cv::ADAPTIVE_THRESH_MEAN_C, cv::THRESH_BINARY_INV, block,
                          offset);
    return;
  }
  typedef std::int32_t I32x4 __attribute__((vector_size(16)));
  typedef std::uint8_t U8x4 __attribute__((vector_size(4)));
  const int w = src.cols, h = src.rows, r = block / 2, area = block * block;
  const int idelta = static_cast<int>(std::floor(offset));
  dst->create(src.size(), CV_8UC1);
  // Horizontal window sums (replicated border) of every row, then a running vertical sum.
  scratch->resize(static_cast<size_t>(w) * static_cast<size_t>(h + 1));
  int* hs = scratch->data();
  for (int y = 0; y < h; ++y) {
    const std::uint8_t* p = src.ptr<std::uint8_t>(y);
    int* o = hs + static_cast<size_t>(y) * static_cast<size_t>(w);
    int s = 0;
    for (int dx = -r; dx <= r; ++dx) s += p[std::clamp(dx, 0, w - 1)];
    o[0] = s;
    // Clamped indices only where the window reaches past an image border.
    const int x_in0 = std::min(w, r + 1), x_in1 = std::max(x_in0, w - r);
    int x = 1;
    for (; x < x_in0; ++x) {
      s += p[std::min(x + r, w - 1)] - p[0];
      o[x] = s;
    }
    for (; x < x_in1; ++x) {
      s += p[x + r] - p[x - 1 - r];
      o[x] = s;
    }
    for (; x < w; ++x) {
      s += p[w - 1] - p[std::max(x - 1 - r, 0)];
      o[x] = s;
    }
  }
  int* col = hs + static_cast<size_t>(w) * static_cast<size_t>(h);
  auto hrow = [&](int y) { return hs + static_cast<size_t>(std::clamp(y, 0, h - 1)) * w; };
  std::fill(col, col + w, 0);
  for (int dy = -r; dy <= r; ++dy) {
    const int* hr = hrow(dy);
    for (int x = 0; x < w; ++x) col[x] += hr[x];
  }
  // The rounded mean m = (2 sum + area) / (2 area) (area odd: no ties) is compared without the
  // division: src - m <= -idelta  <=>  m >= src + idelta  <=>  2 sum + area >= 2 area (src +
  // idelta). 4 pixels a step, then the rest: 128-bit vectors, which NEON and SSE2 hold in one
  // register (GCC splits wider ones badly on aarch64: 21 instructions per pixel with 16 lanes).
  const int two_area = 2 * area;
  for (int y = 0; y < h; ++y) {
    const std::uint8_t* p = src.ptr<std::uint8_t>(y);
    std::uint8_t* d = dst->ptr<std::uint8_t>(y);
    int x = 0;
    for (; x + 4 <= w; x += 4) {
      I32x4 c;
      std::memcpy(&c, col + x, sizeof c);
      U8x4 pv;
      std::memcpy(&pv, p + x, sizeof pv);
      const I32x4 rhs = (__builtin_convertvector(pv, I32x4) + idelta) * two_area;
      const U8x4 out = __builtin_convertvector(2 * c + area >= rhs, U8x4);
      std::memcpy(d + x, &out, sizeof out);
    }
    for (; x < w; ++x) d[x] = 2 * col[x] + area >= two_area * (p[x] + idelta) ? 255 : 0;
    if (y + 1 < h) {
      const int* add = hrow(y + 1 + r);
      const int* sub = hrow(y - r);
      int k = 0;
      for (; k + 4 <= w; k += 4) {
        I32x4 c, a, b;
        std::memcpy(&c, col + k, sizeof c);
        std::memcpy(&a, add + k, sizeof a);
        std::memcpy(&b, sub + k, sizeof b);
        c += a - b;
        std::memcpy(col + k, &c, sizeof c);
      }
      for (; k < w; ++k) col[k] += add[k] - sub[k];
    }
  }
}

void integral_sum_sq(const cv::Mat& src, cv::Mat* sum, cv::Mat* sq) {
  const int w = src.cols, h = src.rows;
  sum->create(h + 1, w + 1, CV_32SC1);
  sq->create(h + 1, w + 1, CV_32SC1);
  std::fill(sum->ptr<std::int32_t>(0), sum->ptr<std::int32_t>(0) + w + 1, 0);
  std::fill(sq->ptr<std::uint32_t>(0), sq->ptr<std::uint32_t>(0) + w + 1, 0u);
  // Row prefix sums first (the only serial part), then the row above added 4 columns a step.
  typedef std::uint32_t U32x4 __attribute__((vector_size(16)));
  for (int y = 0; y < h; ++y) {
    const std::uint8_t* p = src.ptr<std::uint8_t>(y);
    std::uint32_t* s1 = sum->ptr<std::uint32_t>(y + 1);
    std::uint32_t* q1 = sq->ptr<std::uint32_t>(y + 1);
    s1[0] = 0;
    q1[0] = 0;
    std::uint32_t rs = 0, rq = 0;
    for (int x = 0; x < w; ++x) {
      const std::uint32_t v = p[x];
      rs += v;
      rq += v * v;
      s1[x + 1] = rs;
      q1[x + 1] = rq;
    }
    const std::uint32_t* s0 = sum->ptr<std::uint32_t>(y);
    const std::uint32_t* q0 = sq->ptr<std::uint32_t>(y);
    int x = 1;
    for (; x + 4 <= w + 1; x += 4) {
      U32x4 a, b;
      std::memcpy(&a, s1 + x, sizeof a);
      std::memcpy(&b, s0 + x, sizeof b);
      a += b;
      std::memcpy(s1 + x, &a, sizeof a);
      std::memcpy(&a, q1 + x, sizeof a);
      std::memcpy(&b, q0 + x, sizeof b);
      a += b;
      std::memcpy(q1 + x, &a, sizeof a);
    }
    for (; x <= w; ++x) {
      s1[x] += s0[x];
      q1[x] += q0[x];
    }
  }
}

}  // namespace agv::vision

// Box downsampling for the coarse detection level (agv/vision/coarse_level.hpp). The scalar
// loop cost about 3 instructions per input pixel on aarch64, most of a landmark-free frame; the
// vector path needs about half an instruction per pixel.
#include "agv/vision/coarse_level.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

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
      box_downsample_vec<2>(img, cs, out);
      return;
    case 4:
      box_downsample_vec<4>(img, cs, out);
      return;
    case 8:
      box_downsample_vec<8>(img, cs, out);
      return;
    case 16:
      box_downsample_vec<16>(img, cs, out);
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
  typedef std::int32_t I32x16 __attribute__((vector_size(64)));
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
  // idelta). 16 pixels a step (vector extensions), then the rest.
  const int two_area = 2 * area;
  for (int y = 0; y < h; ++y) {
    const std::uint8_t* p = src.ptr<std::uint8_t>(y);
    std::uint8_t* d = dst->ptr<std::uint8_t>(y);
    int x = 0;
    for (; x + 16 <= w; x += 16) {
      I32x16 c;
      std::memcpy(&c, col + x, sizeof c);
      U8x16 pv;
      std::memcpy(&pv, p + x, sizeof pv);
      const I32x16 rhs = (__builtin_convertvector(pv, I32x16) + idelta) * two_area;
      const U8x16 out = __builtin_convertvector(2 * c + area >= rhs, U8x16);
      std::memcpy(d + x, &out, sizeof out);
    }
    for (; x < w; ++x) d[x] = 2 * col[x] + area >= two_area * (p[x] + idelta) ? 255 : 0;
    if (y + 1 < h) {
      const int* add = hrow(y + 1 + r);
      const int* sub = hrow(y - r);
      int k = 0;
      for (; k + 16 <= w; k += 16) {
        I32x16 c, a, b;
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
  sq->create(h + 1, w + 1, CV_64FC1);
  std::fill(sum->ptr<int>(0), sum->ptr<int>(0) + w + 1, 0);
  std::fill(sq->ptr<double>(0), sq->ptr<double>(0) + w + 1, 0.0);
  for (int y = 0; y < h; ++y) {
    const std::uint8_t* p = src.ptr<std::uint8_t>(y);
    const int* s0 = sum->ptr<int>(y);
    int* s1 = sum->ptr<int>(y + 1);
    const double* q0 = sq->ptr<double>(y);
    double* q1 = sq->ptr<double>(y + 1);
    s1[0] = 0;
    q1[0] = 0.0;
    int rs = 0;
    std::int64_t rq = 0;
    for (int x = 0; x < w; ++x) {
      const int v = p[x];
      rs += v;
      rq += v * v;
      s1[x + 1] = s0[x + 1] + rs;
      q1[x + 1] = q0[x + 1] + static_cast<double>(rq);
    }
  }
}

}  // namespace agv::vision

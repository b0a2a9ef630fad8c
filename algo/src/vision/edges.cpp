#include "agv/vision/edges.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <opencv2/core.hpp>
#include <vector>

#include "agv/common/order_statistic.hpp"
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace agv::vision {

void prewitt(const cv::Mat& gray8, const cv::Rect& roi_in, cv::Mat* gx, cv::Mat* gy) {
  const cv::Rect roi = roi_in & cv::Rect(0, 0, gray8.cols, gray8.rows);
  gx->create(std::max(roi.height, 1), std::max(roi.width, 1), CV_16SC1);
  gy->create(std::max(roi.height, 1), std::max(roi.width, 1), CV_16SC1);
  gx->setTo(0);
  gy->setTo(0);
  if (roi.width <= 0 || roi.height <= 0) return;
  const int x_begin = std::max(roi.x, 1), x_end = std::min(roi.x + roi.width, gray8.cols - 1);
  const int y_begin = std::max(roi.y, 1), y_end = std::min(roi.y + roi.height, gray8.rows - 1);
  const std::ptrdiff_t step = static_cast<std::ptrdiff_t>(gray8.step[0]);
  for (int y = y_begin; y < y_end; ++y) {
    const std::uint8_t* r0 = gray8.ptr<std::uint8_t>(y);
    std::int16_t* ox = gx->ptr<std::int16_t>(y - roi.y) - roi.x;
    std::int16_t* oy = gy->ptr<std::int16_t>(y - roi.y) - roi.x;
    for (int x = x_begin; x < x_end; ++x) {
      int g_x, g_y;
      prewitt_at(r0 + x, step, &g_x, &g_y);
      ox[x] = static_cast<std::int16_t>(g_x);
      oy[x] = static_cast<std::int16_t>(g_y);
    }
  }
}

namespace {
typedef std::uint8_t U8x16 __attribute__((vector_size(16)));
typedef std::int16_t I16x16 __attribute__((vector_size(32)));
typedef std::int16_t I16x8 __attribute__((vector_size(16)));
typedef std::uint8_t U8x8 __attribute__((vector_size(8)));
typedef std::int32_t I32x4 __attribute__((vector_size(16)));
typedef float F32x4 __attribute__((vector_size(16)));
constexpr size_t kStripLanes = 16;
// Above every reachable squared Prewitt magnitude (2 * 765^2) and exact in float (< 2^24).
constexpr int kMaxExactThr2 = 1 << 22;

// Sign extension of four 16-bit lanes interleaved with their signs (one ZIP or PUNPCK after the
// shift; little-endian), then the exact conversion to float. The squares use 128-bit vectors: GCC
// 12 turns 256-bit conversions and compares into lane-by-lane code on aarch64.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "to_float interleaves little-endian");
inline F32x4 to_float(I16x8 interleaved_with_sign) {
  return __builtin_convertvector(std::bit_cast<I32x4>(interleaved_with_sign), F32x4);
}

template <typename V, typename T>
V load_lanes(const T* p) {
  V v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
template <typename V, typename T>
void store_lanes(T* p, const V& v) {
  std::memcpy(p, &v, sizeof v);
}
}  // namespace

void strip_gradients(const std::uint8_t* p, std::ptrdiff_t dj, std::ptrdiff_t di, int n, int thr2,
                     bool read_past_end, StripGradients* s) {
  const size_t m = static_cast<size_t>(std::max(n, 0));
  // Whole chunks of 16 lanes: the lanes past n are computed and never read, so no loop has a
  // scalar remainder (a band strip is ~15-30 pixels, and a remainder would be half the work).
  const size_t chunks = (m + 2 + kStripLanes - 1) / kStripLanes;
  const size_t padded = (chunks + 1) * kStripLanes;
  if (s->sum.size() < padded) {
    s->sum.resize(padded);
    s->diff.resize(padded);
    s->g_j.resize(padded);
    s->g_i.resize(padded);
    s->strong.resize(padded);
  }
  std::int16_t* __restrict sum = s->sum.data();
  std::int16_t* __restrict diff = s->diff.data();
  const std::uint8_t* a = p - di;  // one side of the strip
  const std::uint8_t* c = p + di;  // the other side
  if (dj == 1 && read_past_end) {
    for (size_t k = 0; k < chunks * kStripLanes; k += kStripLanes) {
      const I16x16 va = __builtin_convertvector(load_lanes<U8x16>(a + k), I16x16);
      const I16x16 vb = __builtin_convertvector(load_lanes<U8x16>(p + k), I16x16);
      const I16x16 vc = __builtin_convertvector(load_lanes<U8x16>(c + k), I16x16);
      store_lanes(sum + k, va + vb + vc);
      store_lanes(diff + k, vc - va);
    }
  } else {
    for (size_t k = 0; k < m + 2; ++k) {
      const std::ptrdiff_t o = static_cast<std::ptrdiff_t>(k) * dj;
      sum[k] = static_cast<std::int16_t>(a[o] + p[o] + c[o]);
      diff[k] = static_cast<std::int16_t>(c[o] - a[o]);
    }
  }
  // |g| <= 3 * 255, so 16-bit lanes hold the gradients and 32-bit ones their squares.
  std::int16_t* __restrict g_j = s->g_j.data();
  std::int16_t* __restrict g_i = s->g_i.data();
  std::uint8_t* __restrict strong = s->strong.data();
  const float thr2_f = static_cast<float>(std::clamp(thr2, 0, kMaxExactThr2));
  for (size_t q = 0; q < m; q += kStripLanes / 2) {
    const I16x8 gj = load_lanes<I16x8>(sum + q + 2) - load_lanes<I16x8>(sum + q);
    const I16x8 gi = load_lanes<I16x8>(diff + q) + load_lanes<I16x8>(diff + q + 1) +
                     load_lanes<I16x8>(diff + q + 2);
    store_lanes(g_j + q, gj);
    store_lanes(g_i + q, gi);
    // The squares in float: every value is an integer below 2^24 (|g|^2 <= 585225, the sum
    // <= 1.2e6, thr2 clamped to 2^22), so float is exact; SSE2 has no 32-bit multiply.
    const I16x8 sj = gj >> 15, si = gi >> 15;
    const F32x4 j_lo = to_float(__builtin_shufflevector(gj, sj, 0, 8, 1, 9, 2, 10, 3, 11));
    const F32x4 j_hi = to_float(__builtin_shufflevector(gj, sj, 4, 12, 5, 13, 6, 14, 7, 15));
    const F32x4 i_lo = to_float(__builtin_shufflevector(gi, si, 0, 8, 1, 9, 2, 10, 3, 11));
    const F32x4 i_hi = to_float(__builtin_shufflevector(gi, si, 4, 12, 5, 13, 6, 14, 7, 15));
    const I32x4 m_lo = j_lo * j_lo + i_lo * i_lo >= thr2_f;
    const I32x4 m_hi = j_hi * j_hi + i_hi * i_hi >= thr2_f;
    // One byte (0 or 1) per pixel, so the caller tests eight pixels with one 64-bit word. The
    // masks are 0 or -1, so the saturating packs of SSE2 narrow them exactly; without SSSE3,
    // GCC builds the generic byte shuffle on the stack (40 instructions per 8 pixels).
#if defined(__SSE2__)
    const __m128i m16 = _mm_packs_epi32(std::bit_cast<__m128i>(m_lo), std::bit_cast<__m128i>(m_hi));
    const __m128i m8 = _mm_and_si128(_mm_packs_epi16(m16, m16), _mm_set1_epi8(1));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(strong + q), m8);
#else
    // aarch64: UZP1 and one table lookup.
    const U8x16 m16 = std::bit_cast<U8x16>(__builtin_shufflevector(
        std::bit_cast<I16x8>(m_lo), std::bit_cast<I16x8>(m_hi), 0, 2, 4, 6, 8, 10, 12, 14));
    const U8x8 m8 = __builtin_shufflevector(m16, m16, 0, 2, 4, 6, 8, 10, 12, 14);
    store_lanes(strong + q, m8 & 1);
#endif
  }
}

EdgeClass classify_gradient(double gx, double gy, double up_angle_rad, double tol_rad) {
  const double tan_tol = std::tan(tol_rad);
  for (int k = 0; k < 4; ++k) {
    const double a = up_angle_rad + k * kPi / 2.0;
    if (gradient_within(gx, gy, {std::cos(a), std::sin(a)}, tan_tol)) {
      return static_cast<EdgeClass>(k);
    }
  }
  return EdgeClass::kNone;
}

double Line2::angle_rad() const { return std::atan2(-nx, ny); }

namespace {

// fit_line_tls; the extent (one more pass over the points) only when asked: the robust fit's
// intermediate lines only feed the next residuals.
bool fit_line_tls_impl(std::span<const Vec2> pts, std::span<const double> weights, bool with_extent,
                       LineFit* out) {
  const size_t n = pts.size();
  if (n < 2 || (!weights.empty() && weights.size() != n)) return false;
  double sw = 0, sx = 0, sy = 0;
  for (size_t i = 0; i < n; ++i) {
    const double w = weights.empty() ? 1.0 : weights[i];
    sw += w;
    sx += w * pts[i].x;
    sy += w * pts[i].y;
  }
  if (!(sw > 0.0)) return false;
  const double mx = sx / sw, my = sy / sw;
  double cxx = 0, cxy = 0, cyy = 0;
  int n_pos = 0;
  for (size_t i = 0; i < n; ++i) {
    const double w = weights.empty() ? 1.0 : weights[i];
    if (w > 0.0) ++n_pos;
    const double dx = pts[i].x - mx, dy = pts[i].y - my;
    cxx += w * dx * dx;
    cxy += w * dx * dy;
    cyy += w * dy * dy;
  }
  if (n_pos < 2) return false;
  // Smallest eigenvector of the scatter matrix is the normal.
  const double tr = cxx + cyy;
  const double det = cxx * cyy - cxy * cxy;
  const double disc = std::sqrt(std::max(0.0, tr * tr / 4.0 - det));
  const double l_small = tr / 2.0 - disc, l_big = tr / 2.0 + disc;
  if (!(l_big > 0.0)) return false;
  // Direction (eigenvector of l_big).
  double dx, dy;
  if (std::abs(cxy) > 1e-12 * l_big) {
    dx = l_big - cyy;
    dy = cxy;
  } else if (cxx >= cyy) {
    dx = 1.0;
    dy = 0.0;
  } else {
    dx = 0.0;
    dy = 1.0;
  }
  const double norm = std::hypot(dx, dy);
  dx /= norm;
  dy /= norm;
  LineFit f;
  f.line.nx = -dy;
  f.line.ny = dx;
  f.line.d = f.line.nx * mx + f.line.ny * my;
  f.n = n_pos;
  f.sum_w = sw;
  f.centroid = {mx, my};
  const double ssr = std::max(0.0, l_small);  // weighted sum of squared normal residuals
  const double dof = std::max(1.0, static_cast<double>(n_pos) - 2.0);
  // Effective residual variance per unit weight.
  const double s2 = ssr / dof * (static_cast<double>(n_pos) / sw);
  f.rms = std::sqrt(ssr / sw);
  // Along-line scatter l_big (weighted); angle variance = s2 / sum w t^2, offset var = s2 / sum w.
  f.var_angle = s2 / l_big;
  f.var_offset = s2 / sw;
  if (with_extent) {
    double tmin = 1e300, tmax = -1e300;
    for (size_t i = 0; i < n; ++i) {
      if (!weights.empty() && !(weights[i] > 0.0)) continue;
      const double t = (pts[i].x - mx) * dx + (pts[i].y - my) * dy;
      tmin = std::min(tmin, t);
      tmax = std::max(tmax, t);
    }
    f.extent = tmax - tmin;
  }
  *out = f;
  return true;
}

}  // namespace

bool fit_line_tls(std::span<const Vec2> pts, std::span<const double> weights, LineFit* out) {
  return fit_line_tls_impl(pts, weights, true, out);
}

bool fit_line_ols(std::span<const Vec2> pts, double* k, double* b) {
  const double n = static_cast<double>(pts.size());
  if (pts.size() < 2) return false;
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (const Vec2& p : pts) {
    sx += p.x;
    sy += p.y;
    sxx += p.x * p.x;
    sxy += p.x * p.y;
  }
  // Centred form of eq. 5-6 (same estimate, better conditioned than the raw sums).
  const double mx = sx / n, my = sy / n;
  const double vxx = sxx / n - mx * mx, vxy = sxy / n - mx * my;
  if (!(vxx > 1e-12 * (1.0 + mx * mx))) return false;
  *k = vxy / vxx;
  *b = my - *k * mx;
  return true;
}

bool fit_line_robust(std::span<const Vec2> pts, double tukey_c, double min_sigma, int iterations,
                     std::span<double> w_out, LineFit* out, int ransac_iterations,
                     double ransac_tol) {
  if (w_out.size() != pts.size()) return false;
  std::fill(w_out.begin(), w_out.end(), 1.0);
  LineFit f;
  const size_t n = pts.size();
  if (ransac_iterations > 0 && n >= 8 && ransac_tol > 0) {
    // Deterministic RANSAC start: one point from each half of the list (the points come in
    // order along the line, so the pair spans it), keep the line with the most inliers.
    size_t best_count = 0;
    Line2 best;
    const size_t half = n / 2;
    for (int k = 0; k < ransac_iterations; ++k) {
      const size_t i = (static_cast<size_t>(k) * 7919u + 13u) % half;
      const size_t j = half + (static_cast<size_t>(k) * 104729u + 7u) % (n - half);
      const double dx = pts[j].x - pts[i].x, dy = pts[j].y - pts[i].y;
      const double len = std::hypot(dx, dy);
      if (!(len > 0)) continue;
      Line2 l{-dy / len, dx / len, 0.0};
      l.d = l.nx * pts[i].x + l.ny * pts[i].y;
      // A candidate only wins with more inliers than the best so far: the count stops once
      // too many points missed for that, and no candidate can beat one that kept every point
      // (same winner as counting all, fewer operations on clean lines).
      size_t count = 0, misses = 0;
      const size_t max_misses = n - best_count;
      for (const Vec2& p : pts) {
        if (std::abs(l.nx * p.x + l.ny * p.y - l.d) <= ransac_tol) {
          ++count;
        } else if (++misses >= max_misses) {
          break;
        }
      }
      if (count > best_count) {
        best_count = count;
        best = l;
        if (best_count == n) break;
      }
    }
    if (best_count >= 2) {
      for (size_t i = 0; i < n; ++i) {
        w_out[i] =
            std::abs(best.nx * pts[i].x + best.ny * pts[i].y - best.d) <= ransac_tol ? 1.0 : 0.0;
      }
    }
  }
  if (!fit_line_tls_impl(pts, w_out, iterations <= 0, &f)) return false;
  thread_local std::vector<double> abs_r, tmp;
  for (int it = 0; it < iterations; ++it) {
    abs_r.resize(n);
    tmp.clear();
    size_t at_floor = 0;
    for (size_t i = 0; i < n; ++i) {
      abs_r[i] = std::abs(f.line.nx * pts[i].x + f.line.ny * pts[i].y - f.line.d);
      // Scale from the points the previous step kept (all of them without RANSAC).
      if (w_out[i] > 0) {
        tmp.push_back(abs_r[i]);
        at_floor += kMadToSigma * abs_r[i] <= min_sigma ? 1 : 0;
      }
    }
    if (tmp.empty()) return false;
    const auto mid = tmp.size() / 2;
    // The scale has a floor. When more than half of the kept residuals give a scale at or below
    // it, so does their median (a product with a positive constant is monotone, rounding
    // included), and the selection can be skipped: the same sigma to the bit. About half of the
    // line fits on the cost recording are at the floor, where the selection was a tenth of a
    // tracked frame on x86-64 (docs/design/performance.md).
    double sigma = min_sigma;
    if (at_floor <= mid) {
      sigma = std::max(min_sigma, kMadToSigma * select_kth(tmp, mid));
    }
    const double c = tukey_c * sigma;
    for (size_t i = 0; i < n; ++i) {
      const double u = abs_r[i] / c;
      w_out[i] = u < 1.0 ? (1.0 - u * u) * (1.0 - u * u) : 0.0;
    }
    LineFit g;
    if (!fit_line_tls_impl(pts, w_out, it + 1 == iterations, &g)) return false;
    f = g;
  }
  *out = f;
  return true;
}

double mean_angle(std::span<const double> a) {
  if (a.empty()) return 0.0;
  double s = 0.0;
  for (double v : a) s += v;
  return s / static_cast<double>(a.size());
}

double weight_000(double sum_y2, double ssr) {
  const double den = sum_y2 - ssr;
  return den > 0.0 ? sum_y2 / den : 0.0;
}

double weighted_angle_000(std::span<const double> a, std::span<const double> k) {
  double sw = 0.0, s = 0.0;
  for (size_t i = 0; i < a.size() && i < k.size(); ++i) {
    s += k[i] * a[i];
    sw += k[i];
  }
  return sw > 0.0 ? s / sw : mean_angle(a);
}

double reduce_angle_90(double angle_rad, double ref_rad) {
  const double q = std::round((angle_rad - ref_rad) / (kPi / 2.0));
  return angle_rad - q * (kPi / 2.0);
}

}  // namespace agv::vision

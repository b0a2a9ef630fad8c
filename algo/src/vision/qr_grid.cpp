#include "agv/vision/qr_grid.hpp"

#define ZX_USE_UTF8 1
#include <ZXing/ReadBarcode.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdlib>

namespace agv::vision {

namespace {

constexpr int kPxPerModule = 3;  // zxing's pure reader needs whole pixels per module
constexpr int kMargin = 4;       // quiet zone of the rendered code, modules

int finder_value(int r, int c) {  // r, c in 0..6 inside a finder pattern
  const int d = std::max(std::abs(r - 3), std::abs(c - 3));
  return d == 2 ? 0 : 1;
}

// Only the code's own modules are thresholded, so the local mean is computed for them alone; the
// ring of quiet-zone modules enters their windows. The loops add in the same order as the plain
// per-module sums they replace (up, down, left, right; then left to right and top to bottom), so
// every value is the same to the last bit: a branch-free interior and the bounds only at the
// edges cut binarize's instructions by a third (x86-64 callgrind, the tracked cost recording).
void binarize(const QrSamples& s, QrThreshold t, QrGridScratch* sc) {
  const int side = s.side();
  const size_t nn = static_cast<size_t>(side) * static_cast<size_t>(side);
  const float* v = s.v.data();
  sc->work.assign(s.v.begin(), s.v.end());
  if (t == QrThreshold::kStronglySharpenedLocalMean || t == QrThreshold::kSharpenedLocalMean) {
    const double gain = t == QrThreshold::kStronglySharpenedLocalMean ? 6.0 : 1.0;
    float* w = sc->work.data();
    for (int r = 0; r < side; ++r) {
      const bool row_inside = r > 0 && r < side - 1;
      for (int c = 0; c < side; ++c) {
        const size_t i = static_cast<size_t>(r * side + c);
        const double x = static_cast<double>(v[i]);
        if (row_inside && c > 0 && c < side - 1) {
          const double sum = static_cast<double>(v[i - static_cast<size_t>(side)]) +
                             static_cast<double>(v[i + static_cast<size_t>(side)]) +
                             static_cast<double>(v[i - 1]) + static_cast<double>(v[i + 1]);
          w[i] = static_cast<float>(x + gain * (x - sum / 4));
          continue;
        }
        double sum = 0;
        int cnt = 0;
        const int dr[4] = {-1, 1, 0, 0}, dc[4] = {0, 0, -1, 1};
        for (int k = 0; k < 4; ++k) {
          const int rr = r + dr[k], cc = c + dc[k];
          if (rr < 0 || cc < 0 || rr >= side || cc >= side) continue;
          sum += static_cast<double>(v[static_cast<size_t>(rr * side + cc)]);
          ++cnt;
        }
        w[i] = static_cast<float>(cnt ? x + gain * (x - sum / cnt) : x);
      }
    }
  }
  sc->mean.assign(nn, 0.0f);
  const int lo = s.ring, hi = s.ring + s.n;  // the code's rows and columns in the sampled grid
  if (t == QrThreshold::kMidpoint) {
    // Light level: median of the quiet zone; dark level: darkest decile of the code.
    std::vector<float>& tmp = sc->mean;
    tmp.clear();
    for (int r = 0; r < side; ++r) {
      for (int c = 0; c < side; ++c) {
        const int rr = r - s.ring, cc = c - s.ring;
        if (rr < 0 || cc < 0 || rr >= s.n || cc >= s.n) tmp.push_back(sc->work[r * side + c]);
      }
    }
    const size_t mid = tmp.size() / 2;
    std::nth_element(tmp.begin(), tmp.begin() + static_cast<std::ptrdiff_t>(mid), tmp.end());
    const float light = tmp.empty() ? 255.0f : tmp[mid];
    tmp.clear();
    for (int r = 0; r < s.n; ++r) {
      for (int c = 0; c < s.n; ++c) tmp.push_back(s.at(r, c));
    }
    const size_t dec = tmp.size() / 10;
    std::nth_element(tmp.begin(), tmp.begin() + static_cast<std::ptrdiff_t>(dec), tmp.end());
    const float dark = tmp[dec];
    sc->mean.assign(nn, 0.5f * (light + dark));
  } else {
    // Mean of the 5x5 modules around each code module (clipped to the sampled grid), separable:
    // the sums of up to 5 modules along each row, then up to 5 of those along each column. Sums
    // of these floats in double are exact, so the order does not matter, unless a value is
    // below about 1e-4 grey levels in magnitude (a rounding of 1e-16 relative then, where the
    // direct sum rounded too).
    sc->row_sum.resize(nn);
    const float* wk = sc->work.data();
    for (int r = 0; r < side; ++r) {
      const float* wr = wk + static_cast<size_t>(r * side);
      double* rs = sc->row_sum.data() + static_cast<size_t>(r * side);
      for (int c = lo; c < hi; ++c) {
        if (c >= 2 && c + 2 < side) {
          rs[c] = static_cast<double>(wr[c - 2]) + static_cast<double>(wr[c - 1]) +
                  static_cast<double>(wr[c]) + static_cast<double>(wr[c + 1]) +
                  static_cast<double>(wr[c + 2]);
          continue;
        }
        double sum = 0;
        for (int cc = std::max(0, c - 2); cc <= std::min(side - 1, c + 2); ++cc) {
          sum += static_cast<double>(wr[cc]);
        }
        rs[c] = sum;
      }
    }
    const double* rsum = sc->row_sum.data();
    for (int r = lo; r < hi; ++r) {
      const int r0 = std::max(0, r - 2), r1 = std::min(side - 1, r + 2);
      for (int c = lo; c < hi; ++c) {
        double sum = 0;
        for (int rr = r0; rr <= r1; ++rr) sum += rsum[static_cast<size_t>(rr * side + c)];
        const int cnt = (r1 - r0 + 1) * (std::min(side - 1, c + 2) - std::max(0, c - 2) + 1);
        sc->mean[static_cast<size_t>(r * side + c)] = static_cast<float>(sum / cnt);
      }
    }
  }
  sc->bits.assign(static_cast<size_t>(s.n * s.n), 0);
  for (int r = 0; r < s.n; ++r) {
    for (int c = 0; c < s.n; ++c) {
      const size_t g = static_cast<size_t>((r + s.ring) * side + c + s.ring);
      sc->bits[static_cast<size_t>(r * s.n + c)] = sc->work[g] < sc->mean[g] ? 1 : 0;
    }
  }
}

// The standard's fixed modules of a version-1 or -2 code, computed per module (qr_fixed_module
// looks them up in a table built from this once).
int fixed_module_of(int n, int r, int c) {
  // Finder patterns and separators.
  if (r < 7 && c < 7) return finder_value(r, c);
  if (r < 7 && c >= n - 7) return finder_value(r, c - (n - 7));
  if (r >= n - 7 && c < 7) return finder_value(r - (n - 7), c);
  if ((r == 7 && (c <= 7 || c >= n - 8)) || (c == 7 && (r <= 7 || r >= n - 8)) ||
      (r == n - 8 && c <= 7) || (c == n - 8 && r <= 7)) {
    return 0;
  }
  // Dark module (row 4V + 9 = n - 8, column 8); format information around the finders.
  if (r == n - 8 && c == 8) return 1;
  if ((r == 8 && c != 6 && (c <= 8 || c >= n - 8)) ||
      (c == 8 && r != 6 && (r <= 8 || r >= n - 7))) {
    return -1;
  }
  // Timing patterns.
  if (r == 6) return c % 2 == 0 ? 1 : 0;
  if (c == 6) return r % 2 == 0 ? 1 : 0;
  // Version-2 alignment pattern centred on (18, 18).
  if (n == 25 && std::abs(r - 18) <= 2 && std::abs(c - 18) <= 2) {
    const int d = std::max(std::abs(r - 18), std::abs(c - 18));
    return d == 1 ? 0 : 1;
  }
  return -1;
}

// Fixed-module tables of both versions: sampling, fill-in and rendering ask for every module of
// every grid they try, a few thousand times per frame.
struct FixedModuleTables {
  std::array<std::int8_t, 21 * 21> v1{};
  std::array<std::int8_t, 25 * 25> v2{};
  FixedModuleTables() {
    for (int r = 0; r < 21; ++r) {
      for (int c = 0; c < 21; ++c)
        v1[static_cast<size_t>(r * 21 + c)] = static_cast<std::int8_t>(fixed_module_of(21, r, c));
    }
    for (int r = 0; r < 25; ++r) {
      for (int c = 0; c < 25; ++c)
        v2[static_cast<size_t>(r * 25 + c)] = static_cast<std::int8_t>(fixed_module_of(25, r, c));
    }
  }
};

}  // namespace

int qr_fixed_module(int n, int r, int c) {
  if (n != 21 && n != 25) return -1;
  if (r < 0 || c < 0 || r >= n || c >= n) return -1;
  static const FixedModuleTables tables;
  return n == 21 ? tables.v1[static_cast<size_t>(r * 21 + c)]
                 : tables.v2[static_cast<size_t>(r * 25 + c)];
}

int qr_fixed_module_errors(const QrSamples& s, QrThreshold t, QrGridScratch* sc) {
  if ((s.n != 21 && s.n != 25) || s.v.size() != static_cast<size_t>(s.side() * s.side())) {
    return -1;
  }
  binarize(s, t, sc);
  int errors = 0;
  for (int r = 0; r < s.n; ++r) {
    for (int c = 0; c < s.n; ++c) {
      const int f = qr_fixed_module(s.n, r, c);
      if (f >= 0 && f != sc->bits[static_cast<size_t>(r * s.n + c)]) ++errors;
    }
  }
  return errors;
}

int qr_verified_max_data_errors(int n) { return n == 21 ? 4 : n == 25 ? 8 : 0; }

bool qr_format_module(int n, int r, int c) {
  if (qr_fixed_module(n, r, c) >= 0 || (n != 21 && n != 25) || r < 0 || c < 0 || r >= n || c >= n) {
    return false;
  }
  return (r == 8 && c != 6 && (c <= 8 || c >= n - 8)) ||
         (c == 8 && r != 6 && (r <= 8 || r >= n - 7));
}

namespace {

// Module i of an n x n grid is bit i % 64 of word i / 64.
template <typename Dark>
std::array<std::uint64_t, 10> pack_modules(int n, const Dark& dark) {
  std::array<std::uint64_t, 10> w{};
  for (int i = 0; i < n * n; ++i) {
    if (dark[static_cast<size_t>(i)])
      w[static_cast<size_t>(i / 64)] |= std::uint64_t{1} << (i % 64);
  }
  return w;
}

// The data modules (neither fixed nor format) and the format modules of a size, as bit masks.
struct ModuleMasks {
  std::array<std::uint64_t, 10> data{}, format{};
  explicit ModuleMasks(int n) {
    for (int r = 0; r < n; ++r) {
      for (int c = 0; c < n; ++c) {
        const int i = r * n + c;
        const std::uint64_t bit = std::uint64_t{1} << (i % 64);
        if (qr_format_module(n, r, c)) {
          format[static_cast<size_t>(i / 64)] |= bit;
        } else if (qr_fixed_module(n, r, c) < 0) {
          data[static_cast<size_t>(i / 64)] |= bit;
        }
      }
    }
  }
};

// Codeword of each module of a size (qr_codeword_of_module), in the module order of the packed
// grids: the standard's placement, pairs of columns from the right, upwards then downwards,
// skipping the vertical timing column and every function and format module.
struct CodewordTable {
  std::array<std::int8_t, 25 * 25> of{};
  explicit CodewordTable(int n) {
    of.fill(-1);
    const int codewords = n == 21 ? 26 : 44;  // version 1 and 2, every level
    int bit = 0;
    bool upward = true;
    for (int right = n - 1; right > 0; right -= 2) {
      if (right == 6) --right;
      for (int k = 0; k < n; ++k) {
        const int r = upward ? n - 1 - k : k;
        for (int c = right; c > right - 2; --c) {
          if (qr_fixed_module(n, r, c) >= 0 || qr_format_module(n, r, c)) continue;
          if (bit / 8 < codewords)
            of[static_cast<size_t>(r * n + c)] = static_cast<std::int8_t>(bit / 8);
          ++bit;
        }
      }
      upward = !upward;
    }
  }
};

const CodewordTable& codeword_table(int n) {
  static const CodewordTable t21(21), t25(25);
  return n == 21 ? t21 : t25;
}

// True when the packed grid is within the verified-read bounds of the packed code of the same size
// (qr_grid.hpp): data modules differ in at most qr_verified_max_data_errors codewords, and at most
// kQrVerifiedMaxFormatErrors format modules differ; fixed modules do not count.
bool within_verified_bounds(int n, const std::array<std::uint64_t, 10>& grid,
                            const std::array<std::uint64_t, 10>& code) {
  static const ModuleMasks masks21(21), masks25(25);
  const ModuleMasks& m = n == 21 ? masks21 : masks25;
  const int max_cw = qr_verified_max_data_errors(n);
  // More than 8 wrong modules per correctable codeword cannot be within the bound: the module
  // count screens most non-matching codes with popcounts alone.
  const int max_modules = 8 * max_cw;
  std::array<std::uint64_t, 10> data_diff{};
  int data = 0, format = 0;
  for (size_t k = 0; k < grid.size() && data <= max_modules; ++k) {
    const std::uint64_t diff = grid[k] ^ code[k];
    data_diff[k] = diff & m.data[k];
    data += std::popcount(data_diff[k]);
    format += std::popcount(diff & m.format[k]);
  }
  if (data > max_modules || format > kQrVerifiedMaxFormatErrors) return false;
  if (data <= max_cw) return true;  // each wrong module is at most one wrong codeword
  const CodewordTable& t = codeword_table(n);
  std::uint64_t wrong = 0;  // bit w: codeword w has a wrong module (44 codewords at most)
  for (size_t k = 0; k < data_diff.size(); ++k) {
    for (std::uint64_t d = data_diff[k]; d != 0; d &= d - 1) {
      const int cw = t.of[k * 64 + static_cast<size_t>(std::countr_zero(d))];
      if (cw >= 0) wrong |= std::uint64_t{1} << cw;
    }
  }
  return std::popcount(wrong) <= max_cw;
}

// The binarized grid is the expected code up to what Reed-Solomon corrects (qr_grid.hpp).
bool matches_expected(const QrSamples& s, const QrGridScratch& sc, const QrExpected& e) {
  if (!e.bits || !e.text || e.bits->n != s.n ||
      e.bits->dark.size() != static_cast<size_t>(s.n * s.n)) {
    return false;
  }
  return within_verified_bounds(s.n, pack_modules(s.n, sc.bits), pack_modules(s.n, e.bits->dark));
}

}  // namespace

int qr_codeword_of_module(int n, int r, int c) {
  if ((n != 21 && n != 25) || r < 0 || c < 0 || r >= n || c >= n) return -1;
  return codeword_table(n).of[static_cast<size_t>(r * n + c)];
}

void QrCodeBook::add(const QrBits* bits, const std::string* text) {
  if (!bits || !text || (bits->n != 21 && bits->n != 25) ||
      bits->dark.size() != static_cast<size_t>(bits->n * bits->n)) {
    return;
  }
  Code c;
  c.n = bits->n;
  c.dark = pack_modules(bits->n, bits->dark);
  c.expected = {bits, text};
  codes_.push_back(c);
}

const QrExpected* QrCodeBook::match(int n, const std::vector<unsigned char>& grid) {
  if ((n != 21 && n != 25) || grid.size() < static_cast<size_t>(n * n)) return nullptr;
  const Words g = pack_modules(n, grid);
  for (Code& c : codes_) {
    if (c.n != n || !within_verified_bounds(n, g, c.dark)) continue;
    if (c.reads_back == 0) {
      c.reads_back = qr_bits_decode_to(*c.expected.bits, *c.expected.text, &scratch_) ? 1 : -1;
    }
    // No other code can be within the bounds (qr_grid.hpp).
    return c.reads_back == 1 ? &c.expected : nullptr;
  }
  return nullptr;
}

namespace {

bool valid_samples(const QrSamples& s) {
  return (s.n == 21 || s.n == 25) && s.ring >= 1 &&
         s.v.size() == static_cast<size_t>(s.side() * s.side());
}

// The binarized grid (sc->bits) against the expected codes, then the book.
bool verify_binarized(const QrSamples& s, std::string* text, QrGridScratch* sc,
                      std::span<const QrExpected> expected, QrCodeBook* book) {
  for (const QrExpected& e : expected) {
    if (matches_expected(s, *sc, e)) {
      *text = *e.text;
      sc->verified = true;
      return true;
    }
  }
  if (const QrExpected* e = book ? book->match(s.n, sc->bits) : nullptr) {
    *text = *e->text;
    sc->verified = true;
    return true;
  }
  return false;
}

}  // namespace

bool verify_qr_grid(const QrSamples& s, QrThreshold t, std::string* text, QrGridScratch* sc,
                    std::span<const QrExpected> expected, QrCodeBook* book) {
  sc->verified = false;
  if (!valid_samples(s)) return false;
  binarize(s, t, sc);
  return verify_binarized(s, text, sc, expected, book);
}

bool decode_qr_grid(const QrSamples& s, QrThreshold t, std::string* text, QrGridScratch* sc,
                    std::span<const QrExpected> expected, QrCodeBook* book) {
  sc->verified = false;
  if (!valid_samples(s)) return false;
  binarize(s, t, sc);
  if (verify_binarized(s, text, sc, expected, book)) return true;
  const int dim = (s.n + 2 * kMargin) * kPxPerModule;
  sc->image.assign(static_cast<size_t>(dim) * static_cast<size_t>(dim), 255);
  for (int r = 0; r < s.n; ++r) {
    for (int c = 0; c < s.n; ++c) {
      const int f = qr_fixed_module(s.n, r, c);
      const bool dark = f >= 0 ? f == 1 : sc->bits[static_cast<size_t>(r * s.n + c)] != 0;
      if (!dark) continue;
      for (int y = 0; y < kPxPerModule; ++y) {
        unsigned char* row = sc->image.data() +
                             static_cast<size_t>((r + kMargin) * kPxPerModule + y) * dim +
                             static_cast<size_t>((c + kMargin) * kPxPerModule);
        std::fill(row, row + kPxPerModule, static_cast<unsigned char>(0));
      }
    }
  }
  ZXing::DecodeHints hints;
  hints.setFormats(ZXing::BarcodeFormat::QRCode)
      .setIsPure(true)
      .setBinarizer(ZXing::Binarizer::FixedThreshold)
      .setTryHarder(false)
      .setTryRotate(false)
      .setTryDownscale(false)
      .setMaxNumberOfSymbols(1);
  const ZXing::ImageView iv(sc->image.data(), dim, dim, ZXing::ImageFormat::Lum, dim);
  ++sc->zxing_runs;
  const ZXing::Result res = ZXing::ReadBarcode(iv, hints);
  if (!res.isValid() || res.isMirrored()) return false;
  *text = res.text();
  return true;
}

bool qr_bits_decode_to(const QrBits& bits, const std::string& text, QrGridScratch* sc) {
  if ((bits.n != 21 && bits.n != 25) || bits.dark.size() != static_cast<size_t>(bits.n * bits.n)) {
    return false;
  }
  QrSamples s;
  s.n = bits.n;
  s.ring = 2;
  s.v.assign(static_cast<size_t>(s.side() * s.side()), 220.0f);
  for (int r = 0; r < s.n; ++r) {
    for (int c = 0; c < s.n; ++c) {
      if (bits.dark[static_cast<size_t>(r * s.n + c)]) {
        s.v[static_cast<size_t>((r + s.ring) * s.side() + c + s.ring)] = 40.0f;
      }
    }
  }
  std::string decoded;
  return decode_qr_grid(s, QrThreshold::kMidpoint, &decoded, sc) && decoded == text;
}

}  // namespace agv::vision

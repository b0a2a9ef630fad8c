// Model-guided QR reading: once the border fit has given the landmark's pose to a fraction of a
// pixel, the position of every QR module in the image is known. Sampling the modules there and
// handing zxing a clean, re-rendered code replaces zxing's own binarizer and finder-pattern
// search, which are what fail on small (4.6 px) modules under blur, scratches and dirt.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace agv::vision {

// Modules of a QR code of side n (21 = version 1, 25 = version 2) whose value the standard fixes:
// finder patterns with their separators, timing patterns, the version-2 alignment pattern and the
// dark module. Returns 1 (dark), 0 (light) or -1 (data or format information, or n unsupported).
int qr_fixed_module(int n, int row, int col);

// Grey values sampled at module centres: (n + 2 ring)^2 values, row-major, where the outer `ring`
// modules lie in the quiet zone around the code (light on the landmark).
struct QrSamples {
  int n = 25;
  int ring = 2;
  std::vector<float> v;
  int side() const { return n + 2 * ring; }
  // row, col of the code (0..n-1); the quiet zone is at -ring..-1 and n..n+ring-1.
  float at(int row, int col) const {
    return v[static_cast<size_t>((row + ring) * side() + col + ring)];
  }
};

// How module samples become dark/light. Blur pulls a module towards its neighbours; comparing
// with the local mean (a module-scale high-pass) undoes part of it, sharpening first undoes more.
// Measured on 300 frames each (docs/design/accuracy.md): defocus 2 px + motion 7 px + noise all at
// the limits is read in 62 % of frames with gain 1, 88 % with 2, 99 % with 4, 99.7 % with 6 (the
// same with 10); the combined degradations in 100 % with 4 or 6, and scratches + dirt in 100 % with
// every gain. The localizer tries them in this order (each later one costs time only when the
// earlier ones failed).
enum class QrThreshold {
  kStronglySharpenedLocalMean,  // local mean after v' = v + 6 (v - mean of the 4 neighbours)
  kSharpenedLocalMean,          // local mean after v' = v + (v - mean of the 4 neighbours)
  kLocalMean,                   // dark when below the mean of the 5x5 modules around it
  kMidpoint,  // dark when below the midpoint of the quiet zone and the darkest decile
};

// A code as bits: n x n, row-major, 1 = dark (row 0 at the page top, as QrSamples).
struct QrBits {
  int n = 0;
  std::vector<std::uint8_t> dark;
};

// A code the reader expects to see, with the text it encodes: the predicted landmark's, from the
// map (docs/design/tracking.md "Verified read").
struct QrExpected {
  const QrBits* bits = nullptr;
  const std::string* text = nullptr;
};

// Largest number of codewords with a disagreeing data module for which a grid is taken as the
// expected ECC-M code without decoding: Reed-Solomon corrects up to (EC codewords - misdecode
// protection codewords) / 2 wrong codewords per block, so zxing would return exactly the expected
// code at this count. Version 1-M: (10 - 2) / 2 = 4; version 2-M: 16 / 2 = 8 (ISO/IEC 18004
// table 9; both have one block). 0 for other sizes. Counting codewords rather than modules
// matters for clustered errors (a smear or a shadow along one edge of the code): eight wrong
// modules of one codeword are one error, and the version-2 remainder modules none.
int qr_verified_max_data_errors(int n);
// The codeword (0-based, in the standard's placement order) that data module (row, col) of an
// n x n code carries a bit of; -1 for function, format and remainder modules, other sizes and
// positions outside the code.
int qr_codeword_of_module(int n, int row, int col);
// At most this many of the 30 format-information modules may disagree: the format BCH code
// (distance 7) then still points to the expected format in both copies.
constexpr int kQrVerifiedMaxFormatErrors = 1;

// True for a module of the two format-information copies (n = 21 or 25).
bool qr_format_module(int n, int row, int col);

// Reusable buffers (no allocation after the first call of a given size, except inside zxing).
struct QrGridScratch {
  std::vector<float> work, mean;
  std::vector<double> row_sum;
  std::vector<unsigned char> bits, image;
  bool verified = false;  // the last successful decode_qr_grid matched an expected code
  int zxing_runs = 0;     // zxing reads run so far (the caller resets it), for cost diagnostics
};

// Every code of a landmark map, packed as bits, for the verified read without a prediction
// (docs/design/tracking.md "Verified read"): which code, if any, a binarized grid is within the
// bounds above of. At most one can be. Two valid codes of the same size and format differ in at
// least d = 2 t + 1 + p codewords (t the bound, p the misdecode protection: 2 for version 1-M, 0
// for 2-M), so a grid within t wrong codewords of one is more than t from any other, and codes of
// different formats differ in at least 14 format modules (BCH distance 7, two copies). So the
// answer is what zxing would decode, whatever the order of the codes. A match costs an XOR and two
// popcounts per 64 modules and code (plus a codeword count when more than t modules differ),
// against a zxing pure read (0.16 M aarch64 instructions per landmark frame saved,
// docs/design/tracking.md).
class QrCodeBook {
 public:
  // Adds a code (n 21 or 25; others are ignored). The pointers must outlive the book.
  void add(const QrBits* bits, const std::string* text);
  size_t size() const { return codes_.size(); }
  // The code the grid (n x n, 1 = dark, row-major) is within the bounds of, or nullptr. A code is
  // returned only once zxing has decoded its clean bits back to its text (qr_bits_decode_to,
  // checked on its first match with the book's own scratch), as for an expected code.
  const QrExpected* match(int n, const std::vector<unsigned char>& grid);

 private:
  static constexpr int kWords = 10;  // 625 modules of a 25 x 25 code
  using Words = std::array<std::uint64_t, kWords>;
  struct Code {
    int n = 0;
    Words dark{};
    QrExpected expected;
    int reads_back = 0;  // 0 not checked yet, 1 zxing decodes it to its text, -1 not
  };
  std::vector<Code> codes_;
  QrGridScratch scratch_;
};

// Binarizes the samples, forces the fixed modules and decodes with zxing's pure-code reader
// (Reed-Solomon checked). Returns true and the text on success.
// expected: codes the caller predicts. When the binarized grid is within the bounds above of one
// of them (same size), its text is returned without running zxing (scratch->verified): zxing would
// decode exactly that text, so the result is the same and only the cost differs (zxing's pure
// reader is about 60 % of a tracked frame's QR stage). Anything else is decoded as before.
// book: when no expected code matches, the map's code the grid is within the bounds of, read the
// same way (scratch->verified); nullptr for none.
bool decode_qr_grid(const QrSamples& s, QrThreshold t, std::string* text, QrGridScratch* scratch,
                    std::span<const QrExpected> expected = {}, QrCodeBook* book = nullptr);

// The verified part of decode_qr_grid alone: true (and the text, scratch->verified) when the
// binarized grid is within the bounds of an expected code or of the book's; never runs zxing.
bool verify_qr_grid(const QrSamples& s, QrThreshold t, std::string* text, QrGridScratch* scratch,
                    std::span<const QrExpected> expected, QrCodeBook* book);

// True when zxing's pure reader (as decode_qr_grid runs it) decodes these bits to exactly `text`.
// An expected code is offered to decode_qr_grid only after this check: the verified read then
// returns what zxing returns by construction, whatever the payload's characters or encoding.
bool qr_bits_decode_to(const QrBits& bits, const std::string& text, QrGridScratch* scratch);

// Number of fixed modules (qr_fixed_module != -1) whose binarized value disagrees with the
// standard, for diagnostics and tests; -1 for an unsupported n.
int qr_fixed_module_errors(const QrSamples& s, QrThreshold t, QrGridScratch* scratch);

}  // namespace agv::vision

// Model-guided QR reading (qr_grid.hpp): the fixed-module layout against codes zxing encodes,
// decoding of blurred module samples, rejection of wrong grids and garbage, and the localizer
// reading blurred codes by guided sampling where zxing's own search fails.
#include <ZXing/BitMatrix.h>
#include <ZXing/MultiFormatWriter.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <random>
#include <set>
#include <span>
#include <string>

#include "agv/sim/render.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "agv/vision/map_identity.hpp"
#include "agv/vision/qr_grid.hpp"

using namespace agv;
using namespace agv::vision;

namespace {

// The landmark's QR settings (docs/design/landmark.md): ECC level M, no margin.
ZXing::BitMatrix encode(const std::string& text) {
  return ZXing::MultiFormatWriter(ZXing::BarcodeFormat::QRCode)
      .setEccLevel(4)
      .setMargin(0)
      .encode(text, 0, 0);
}

// Module samples of a code: dark 40, light 220, with a light quiet-zone ring; then a module-scale
// blur (each module mixes `mix` of the mean of its 4 neighbours) and Gaussian noise.
QrSamples samples_of(const ZXing::BitMatrix& bm, double mix, double noise, std::uint64_t seed) {
  QrSamples s;
  s.n = bm.width();
  s.ring = 2;
  const int side = s.side();
  std::vector<float> clean(static_cast<size_t>(side * side), 220.0f);
  for (int r = 0; r < s.n; ++r) {
    for (int c = 0; c < s.n; ++c) {
      if (bm.get(c, r)) clean[static_cast<size_t>((r + 2) * side + c + 2)] = 40.0f;
    }
  }
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> nd(0.0, noise);
  s.v.resize(clean.size());
  for (int r = 0; r < side; ++r) {
    for (int c = 0; c < side; ++c) {
      auto at = [&](int rr, int cc) {
        rr = std::clamp(rr, 0, side - 1);
        cc = std::clamp(cc, 0, side - 1);
        return static_cast<double>(clean[static_cast<size_t>(rr * side + cc)]);
      };
      const double nb = 0.25 * (at(r - 1, c) + at(r + 1, c) + at(r, c - 1) + at(r, c + 1));
      s.v[static_cast<size_t>(r * side + c)] =
          static_cast<float>((1.0 - mix) * at(r, c) + mix * nb + nd(rng));
    }
  }
  return s;
}

// Landmark 17 in its map and a simulator scene with its full payload, seen by the 640x480 camera.
class QrGridScene : public ::testing::Test {
 protected:
  void SetUp() override {
    map.entries[17] = {17, lw};
    std::string err;
    ASSERT_TRUE(sim::make_scene(map, LandmarkGeometry{}, sim::PayloadMode::kFull, &scene, &err))
        << err;
  }
  LandmarkMap map;
  Pose2 lw{1000.0, -2000.0, deg_to_rad(90.0)};
  sim::Scene scene;
  CameraModel cam = CameraModel::default_640x480();
};

const char* kFull = "AGV1/00017/+001000.0/-002000.0/+090.00";
const char* kIdOnly = "AGV1/00017/MAP";

}  // namespace

TEST(QrGrid, FixedModulesMatchEncodedCodes) {
  // Different payloads give different masks; the fixed modules never depend on them.
  for (const char* text : {kFull, kIdOnly, "AGV1/65535/-999999.9/+000000.1/-179.99",
                           "AGV1/00001/+000000.0/+000000.0/+000.00", "AGV1/00002/MAP"}) {
    const ZXing::BitMatrix bm = encode(text);
    const int n = bm.width();
    ASSERT_TRUE(n == 21 || n == 25) << text;
    int fixed = 0;
    for (int r = 0; r < n; ++r) {
      for (int c = 0; c < n; ++c) {
        const int f = qr_fixed_module(n, r, c);
        if (f < 0) continue;
        ++fixed;
        EXPECT_EQ(f, bm.get(c, r) ? 1 : 0) << text << " row " << r << " col " << c;
      }
    }
    // 3 finders with separators (192) + timing (2 x (n - 16)) + dark module (+ the 5 x 5
    // alignment pattern of version 2).
    EXPECT_EQ(fixed, n == 21 ? 192 + 10 + 1 : 192 + 18 + 1 + 25) << text;
  }
  EXPECT_EQ(qr_fixed_module(29, 0, 0), -1);
  EXPECT_EQ(qr_fixed_module(25, -1, 0), -1);
}

TEST(QrGrid, DecodesBlurredNoisySamples) {
  QrGridScratch scratch;
  for (const char* text : {kFull, kIdOnly}) {
    const ZXing::BitMatrix bm = encode(text);
    std::string out;
    const QrSamples clean = samples_of(bm, 0.0, 0.0, 1);
    for (QrThreshold t :
         {QrThreshold::kStronglySharpenedLocalMean, QrThreshold::kSharpenedLocalMean,
          QrThreshold::kLocalMean, QrThreshold::kMidpoint}) {
      ASSERT_TRUE(decode_qr_grid(clean, t, &out, &scratch)) << text;
      EXPECT_EQ(out, text);
      EXPECT_EQ(qr_fixed_module_errors(clean, t, &scratch), 0);
    }
    // Strong module-scale blur (40 % from the neighbours) and noise: the global midpoint loses
    // modules that the sharpened local mean keeps.
    const QrSamples blurred = samples_of(bm, 0.4, 6.0, 2);
    ASSERT_TRUE(decode_qr_grid(blurred, QrThreshold::kSharpenedLocalMean, &out, &scratch)) << text;
    EXPECT_EQ(out, text);
  }
}

TEST(QrGrid, FixedModulesAreForcedSoDamagedFindersStillDecode) {
  const ZXing::BitMatrix bm = encode(kFull);
  QrSamples s = samples_of(bm, 0.0, 0.0, 3);
  // A dirt spot over most of the top-left finder pattern.
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) s.v[static_cast<size_t>((r + 2) * s.side() + c + 2)] = 40.0f;
  }
  QrGridScratch scratch;
  EXPECT_GT(qr_fixed_module_errors(s, QrThreshold::kLocalMean, &scratch), 0);
  std::string out;
  ASSERT_TRUE(decode_qr_grid(s, QrThreshold::kLocalMean, &out, &scratch));
  EXPECT_EQ(out, kFull);
}

TEST(QrGrid, WrongGridOrGarbageNeverDecodes) {
  QrGridScratch scratch;
  std::string out;
  // Version-2 samples read as a version-1 grid (the outer 21 x 21 modules).
  const QrSamples v2 = samples_of(encode(kFull), 0.0, 0.0, 4);
  QrSamples as_v1;
  as_v1.n = 21;
  as_v1.ring = 2;
  for (int r = 0; r < as_v1.side(); ++r) {
    for (int c = 0; c < as_v1.side(); ++c) {
      as_v1.v.push_back(v2.v[static_cast<size_t>(r * v2.side() + c)]);
    }
  }
  EXPECT_FALSE(decode_qr_grid(as_v1, QrThreshold::kLocalMean, &out, &scratch));
  // Random modules (floor texture, a wrong turn of the landmark).
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<float> u(0.0f, 255.0f);
  for (int trial = 0; trial < 50; ++trial) {
    QrSamples g;
    g.n = trial % 2 ? 21 : 25;
    g.v.resize(static_cast<size_t>(g.side() * g.side()));
    for (float& v : g.v) v = u(rng);
    for (QrThreshold t :
         {QrThreshold::kStronglySharpenedLocalMean, QrThreshold::kSharpenedLocalMean,
          QrThreshold::kLocalMean, QrThreshold::kMidpoint}) {
      EXPECT_FALSE(decode_qr_grid(g, t, &out, &scratch)) << "trial " << trial;
    }
  }
  // Malformed input: unsupported size, wrong number of samples, no quiet zone.
  QrSamples bad = v2;
  bad.n = 29;
  EXPECT_FALSE(decode_qr_grid(bad, QrThreshold::kLocalMean, &out, &scratch));
  bad = v2;
  bad.v.pop_back();
  EXPECT_FALSE(decode_qr_grid(bad, QrThreshold::kLocalMean, &out, &scratch));
  EXPECT_EQ(qr_fixed_module_errors(bad, QrThreshold::kLocalMean, &scratch), -1);
  bad = v2;
  bad.ring = 0;
  EXPECT_FALSE(decode_qr_grid(bad, QrThreshold::kLocalMean, &out, &scratch));
}

namespace {

// The code as the map identity encodes it (the same writer settings as encode()).
QrBits bits_of(const std::string& text) {
  QrBits b;
  EXPECT_TRUE(encode_qr_bits(text, &b)) << text;
  return b;
}

// Inverts module (r, c) of clean samples (dark 40, light 220).
void flip(QrSamples* s, int r, int c) {
  float& v = s->v[static_cast<size_t>((r + s->ring) * s->side() + c + s->ring)];
  v = v < 130.0f ? 220.0f : 40.0f;
}

// Modules that are neither fixed nor format information: the codewords (and remainder bits).
std::vector<std::pair<int, int>> data_modules(int n) {
  std::vector<std::pair<int, int>> m;
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < n; ++c) {
      if (qr_fixed_module(n, r, c) < 0 && !qr_format_module(n, r, c)) m.emplace_back(r, c);
    }
  }
  return m;
}

// Reads the damaged grid `s` of `text` by zxing alone and verified against `expected`. Over the
// bound the read is not verified and gives zxing's answer; within it, it is verified and both give
// `text`. *verified: whether the read was verified.
void check_verified_read(const QrSamples& s, const std::string& text,
                         std::span<const QrExpected> expected, bool over, int trial,
                         QrGridScratch* scratch, bool* verified) {
  std::string via_zxing, via_expected;
  const bool z = decode_qr_grid(s, QrThreshold::kMidpoint, &via_zxing, scratch);
  EXPECT_FALSE(scratch->verified);
  const bool e = decode_qr_grid(s, QrThreshold::kMidpoint, &via_expected, scratch, expected);
  EXPECT_EQ(scratch->verified, !over) << text << " trial " << trial;
  if (over) {
    // Not verified: the grid went to zxing, with zxing's answer.
    EXPECT_EQ(e, z);
    if (e) {
      EXPECT_EQ(via_expected, via_zxing);
    }
    *verified = false;
    return;
  }
  *verified = true;
  ASSERT_TRUE(e);
  EXPECT_EQ(via_expected, text);
  ASSERT_TRUE(z) << text << " trial " << trial << ": zxing failed where the read was verified";
  EXPECT_EQ(via_zxing, text);
}

}  // namespace

TEST(QrGrid, FormatModulesAreTheTwoFifteenModuleCopies) {
  for (int n : {21, 25}) {
    int count = 0;
    for (int r = 0; r < n; ++r) {
      for (int c = 0; c < n; ++c) count += qr_format_module(n, r, c);
    }
    EXPECT_EQ(count, 30) << n;
    // Data modules: 26 codewords (208 bits) for version 1; 44 (352) + 7 remainder for version 2.
    EXPECT_EQ(data_modules(n).size(), n == 21 ? 208u : 359u) << n;
  }
  EXPECT_FALSE(qr_format_module(21, 13, 8));  // the dark module
  EXPECT_FALSE(qr_format_module(29, 8, 0));
}

// The verified read (qr_grid.hpp) returns the expected text exactly when zxing, run on the same
// grid, returns it too: up to the Reed-Solomon bound of data-module errors and one format error.
// Random error patterns at the bound check the argument against zxing itself.
TEST(QrGrid, VerifiedReadAgreesWithZxingWithinTheBound) {
  QrGridScratch scratch;
  std::mt19937_64 rng(21);
  for (const std::string text : {kFull, kIdOnly}) {
    const ZXing::BitMatrix bm = encode(text);
    const QrBits bits = bits_of(text);
    ASSERT_TRUE(qr_bits_decode_to(bits, text, &scratch)) << text;
    const QrExpected expected[] = {{&bits, &text}};
    const int bound = qr_verified_max_data_errors(bits.n);
    ASSERT_EQ(bound, bits.n == 21 ? 4 : 8);
    std::vector<std::pair<int, int>> data = data_modules(bits.n), format;
    for (int r = 0; r < bits.n; ++r) {
      for (int c = 0; c < bits.n; ++c) {
        if (qr_format_module(bits.n, r, c)) format.emplace_back(r, c);
      }
    }
    int verified = 0;
    for (int trial = 0; trial < 120; ++trial) {
      QrSamples s = samples_of(bm, 0.0, 0.0, 1);
      std::shuffle(data.begin(), data.end(), rng);
      std::shuffle(format.begin(), format.end(), rng);
      // Up to the bound of data errors plus up to one format error; every fourth trial one more
      // data error or a second format error, which must not be verified.
      // Over the bound means one more wrong codeword: bound + 1 modules of distinct codewords.
      const bool over = trial % 4 == 3;
      const int n_data = over && trial % 8 == 3 ? bound + 1 : bound - trial % 3;
      const int n_format = over && trial % 8 == 7 ? 2 : trial % 2;
      std::set<int> codewords;
      for (size_t k = 0, flipped = 0; k < data.size() && flipped < static_cast<size_t>(n_data);
           ++k) {
        const auto [r, c] = data[k];
        const int cw = qr_codeword_of_module(bits.n, r, c);
        if (n_data > bound && (cw < 0 || !codewords.insert(cw).second)) continue;
        flip(&s, r, c);
        ++flipped;
      }
      for (int k = 0; k < n_format; ++k)
        flip(&s, format[static_cast<size_t>(k)].first, format[static_cast<size_t>(k)].second);
      bool read_verified = false;
      ASSERT_NO_FATAL_FAILURE(
          check_verified_read(s, text, expected, over, trial, &scratch, &read_verified));
      verified += read_verified;
    }
    EXPECT_EQ(verified, 90) << text;
  }
}

TEST(QrGrid, VerifiedReadNeverTakesAnotherCode) {
  QrGridScratch scratch;
  // The neighbouring landmark's codes (one id apart, nearly the same payload) and a code of the
  // other size: none is within the bound of landmark 17's grid, which zxing then reads.
  const std::string other_full = "AGV1/00018/+001150.0/-002000.0/+090.00";
  const std::string other_id = "AGV1/00018/MAP";
  const QrBits b_full = bits_of(other_full), b_id = bits_of(other_id);
  const QrExpected expected[] = {{&b_full, &other_full}, {&b_id, &other_id}};
  for (const std::string text : {kFull, kIdOnly}) {
    const QrSamples s = samples_of(encode(text), 0.0, 0.0, 1);
    std::string out;
    ASSERT_TRUE(decode_qr_grid(s, QrThreshold::kMidpoint, &out, &scratch, expected));
    EXPECT_FALSE(scratch.verified);
    EXPECT_EQ(out, text);
  }
  // Malformed expectations are ignored, never dereferenced wrongly.
  const QrBits empty;
  const std::string text = kFull;
  const QrExpected broken[] = {{nullptr, &text}, {&b_full, nullptr}, {&empty, &text}};
  const QrSamples s = samples_of(encode(kFull), 0.0, 0.0, 1);
  std::string out;
  ASSERT_TRUE(decode_qr_grid(s, QrThreshold::kMidpoint, &out, &scratch, broken));
  EXPECT_FALSE(scratch.verified);
  // Bits that do not decode to the text they claim are refused by the round-trip check.
  EXPECT_FALSE(qr_bits_decode_to(b_full, other_id, &scratch));
  EXPECT_FALSE(qr_bits_decode_to(empty, text, &scratch));
}

// The code book (the verified read without a prediction) holds a whole map's codes, among them
// landmark 17's neighbours one id apart: a grid of landmark 17 with errors within the bound is
// read as landmark 17 without zxing, and zxing agrees; over the bound, or for a code not in the
// book, zxing reads as before. No other code is ever taken.
TEST(QrGrid, CodeBookReadsTheOneMappedCodeWithinTheBoundAsZxingDoes) {
  std::vector<std::string> texts;
  for (int id = 1; id <= 40; ++id) {
    if (id == 17) continue;  // kFull and kIdOnly, added last
    char full[64], short_id[32];
    std::snprintf(full, sizeof full, "AGV1/%05d/+001000.0/-002000.0/+090.00", id);
    std::snprintf(short_id, sizeof short_id, "AGV1/%05d/MAP", id);
    texts.push_back(full);
    texts.push_back(short_id);
  }
  texts.push_back(kFull);
  texts.push_back(kIdOnly);
  std::vector<QrBits> bits;
  for (const std::string& t : texts) bits.push_back(bits_of(t));
  QrCodeBook book;
  for (size_t i = 0; i < texts.size(); ++i) book.add(&bits[i], &texts[i]);
  const QrBits empty;
  book.add(&empty, &texts[0]);  // malformed: ignored
  book.add(nullptr, &texts[0]);
  ASSERT_EQ(book.size(), texts.size());

  QrGridScratch scratch;
  std::mt19937_64 rng(33);
  for (const std::string text : {kFull, kIdOnly}) {
    const int n = encode(text).height();
    const int bound = qr_verified_max_data_errors(n);
    std::vector<std::pair<int, int>> data = data_modules(n);
    int verified = 0, n_over = 0;
    for (int trial = 0; trial < 60; ++trial) {
      QrSamples s = samples_of(encode(text), 0.0, 0.0, 1);
      std::shuffle(data.begin(), data.end(), rng);
      // Every third trial has more wrong modules than the bound; it is over the bound when they
      // fall in more codewords than that (two in one codeword are one error).
      const int n_data = trial % 3 == 2 ? bound + 1 + trial % 4 : bound - trial % 2;
      std::set<int> codewords;
      for (int k = 0; k < n_data; ++k) {
        const auto [r, c] = data[static_cast<size_t>(k)];
        flip(&s, r, c);
        if (qr_codeword_of_module(n, r, c) >= 0) codewords.insert(qr_codeword_of_module(n, r, c));
      }
      const bool over = static_cast<int>(codewords.size()) > bound;
      n_over += over;
      std::string via_zxing, via_book;
      scratch.zxing_runs = 0;
      const bool z = decode_qr_grid(s, QrThreshold::kMidpoint, &via_zxing, &scratch);
      const bool b = decode_qr_grid(s, QrThreshold::kMidpoint, &via_book, &scratch, {}, &book);
      EXPECT_EQ(scratch.verified, !over) << text << " trial " << trial;
      EXPECT_EQ(scratch.zxing_runs, over ? 2 : 1) << "the book's read ran zxing";
      EXPECT_EQ(b, z) << text << " trial " << trial;
      if (b) {
        EXPECT_EQ(via_book, via_zxing);
      }
      if (!over) {
        ++verified;
        EXPECT_EQ(via_book, text);
      }
    }
    EXPECT_EQ(verified + n_over, 60) << text;
    EXPECT_GE(n_over, 10) << text;
  }
  // A mapped code that zxing does not read back to its text is never offered.
  std::string wrong_text = texts[0] + "X";
  QrCodeBook lying;
  lying.add(&bits[0], &wrong_text);
  const QrSamples s = samples_of(encode(texts[0]), 0.0, 0.0, 1);
  std::string out;
  ASSERT_TRUE(decode_qr_grid(s, QrThreshold::kMidpoint, &out, &scratch, {}, &lying));
  EXPECT_FALSE(scratch.verified);
  EXPECT_EQ(out, texts[0]);
  // A code not in the book goes to zxing.
  QrCodeBook others;
  others.add(&bits[2], &texts[2]);
  ASSERT_TRUE(decode_qr_grid(s, QrThreshold::kMidpoint, &out, &scratch, {}, &others));
  EXPECT_FALSE(scratch.verified);
  EXPECT_EQ(out, texts[0]);
}

// Full search (no prediction) with a map: the guided reader takes the code from the map's code
// book, without zxing, and the fix is the one zxing's read gives without a map.
TEST_F(QrGridScene, FullSearchReadsMappedCodesWithoutZxing) {
  LandmarkLocalizer with_map(VisionConfig{}, cam, LandmarkGeometry{}, &map);
  LandmarkLocalizer without_map(VisionConfig{}, cam, LandmarkGeometry{}, nullptr);
  std::mt19937_64 rng(8);
  for (int i = 0; i < 4; ++i) {
    const Pose2 e{-6.0 + 4.0 * i, 3.0 - 2.0 * i, deg_to_rad(11.0 + 80.0 * i)};
    const cv::Mat img = sim::render_frame(scene, cam, compose(lw, e), {}, rng);
    LandmarkFix fm, fz;
    ASSERT_EQ(with_map.process(img, &fm), FixStatus::kOk) << i;
    ASSERT_EQ(without_map.process(img, &fz), FixStatus::kOk) << i;
    EXPECT_TRUE(fm.qr_verified) << i;
    EXPECT_EQ(fm.qr_grid_decodes, 0) << i;
    EXPECT_FALSE(fz.qr_verified) << i;
    EXPECT_GE(fz.qr_grid_decodes, 1) << i;
    EXPECT_STREQ(fm.payload, fz.payload);
    EXPECT_EQ(fm.e_x_mm, fz.e_x_mm);
    EXPECT_EQ(fm.e_y_mm, fz.e_y_mm);
    EXPECT_EQ(fm.e_phi_deg, fz.e_phi_deg);
  }
}

TEST_F(QrGridScene, LocalizerReadsBlurredCodesByGuidedSampling) {
  VisionConfig guided, search;
  search.qr_guided = false;
  LandmarkLocalizer loc_g(guided, cam, LandmarkGeometry{}, &map);
  LandmarkLocalizer loc_s(search, cam, LandmarkGeometry{}, &map);
  // Clean: both read it, each by its own method.
  std::mt19937_64 rng(5);
  const Pose2 e{4.0, -3.0, deg_to_rad(33.0)};
  const cv::Mat clean = sim::render_frame(scene, cam, compose(lw, e), {}, rng);
  LandmarkFix fg, fs;
  ASSERT_EQ(loc_g.process(clean, &fg), FixStatus::kOk);
  EXPECT_EQ(fg.qr_method, 1);
  ASSERT_EQ(loc_s.process(clean, &fs), FixStatus::kOk);
  EXPECT_EQ(fs.qr_method, 2);
  // An id-only payload is a version-1 code (21 modules): the guided reader tries both sizes.
  {
    sim::Scene id_scene;
    std::string err;
    ASSERT_TRUE(
        sim::make_scene(map, LandmarkGeometry{}, sim::PayloadMode::kIdOnly, &id_scene, &err));
    const cv::Mat img = sim::render_frame(id_scene, cam, compose(lw, e), {}, rng);
    ASSERT_EQ(loc_g.process(img, &fg), FixStatus::kOk);
    EXPECT_EQ(fg.qr_method, 1);
    EXPECT_STREQ(fg.payload, "AGV1/00017/MAP");
  }
  // Defocus and motion blur both at the degraded evaluation's limits at once (harsher than any
  // frame of the evaluation's combined set, whose strengths are random up to the limits): count
  // the frames each reads. Measured when written: guided 12 (8 before the strong sharpening),
  // zxing search 2 of 12.
  int read_g = 0, read_s = 0;
  const int n = 12;
  for (int i = 0; i < n; ++i) {
    const Pose2 ei{-10.0 + 2.0 * i, 5.0 - i, deg_to_rad(17.0 + 29.0 * i)};
    sim::RenderOptions o;
    o.defocus_sigma_px = 2.0;
    o.exposure_s = 0.001;
    o.speed_mps = 7.0 * cam.mm_per_px();  // 7 px of motion blur
    o.read_noise_sigma = 3.0;
    o.degradation_seed = 100 + static_cast<std::uint64_t>(i);
    const cv::Mat img = sim::render_frame(scene, cam, compose(lw, ei), o, rng);
    if (loc_g.process(img, &fg) == FixStatus::kOk) ++read_g;
    if (loc_s.process(img, &fs) == FixStatus::kOk) ++read_s;
    if (fg.status == FixStatus::kOk) {
      EXPECT_EQ(fg.landmark_id, 17u);
      EXPECT_NEAR(fg.e_x_mm, ei.x_mm, 0.5);
    }
  }
  std::printf("blurred frames read: guided %d, zxing search %d of %d\n", read_g, read_s, n);
  EXPECT_GE(read_g, 11);
  EXPECT_GE(read_g, read_s + 8);
}

TEST_F(QrGridScene, CodesCutByTheImageBorderAreReadWithFillIn) {
  VisionConfig fill, whole;
  whole.qr_max_missing_modules = 0;
  LandmarkLocalizer loc_fill(fill, cam, LandmarkGeometry{}, &map);
  LandmarkLocalizer loc_whole(whole, cam, LandmarkGeometry{}, &map);
  // Slide the landmark out of the image in 5 mm steps at four headings and a diagonal one (2.5 mm
  // steps were twice the frames, 62 s under qemu-aarch64, for the same checks).
  std::mt19937_64 rng(11);
  int ok_fill = 0, ok_whole = 0, cut_reads = 0, unread = 0, cut_unsearched = 0;
  for (double heading_deg : {3.0, 93.0, 181.0, 272.0, 45.0}) {
    for (double y = 30.0; y <= 70.0; y += 5.0) {
      // The diagonal landmark leaves the image corner first, where its code is cut soonest.
      const Pose2 e{heading_deg == 45.0 ? 20.0 : 0.0, y, deg_to_rad(heading_deg)};
      const cv::Mat img = sim::render_frame(scene, cam, compose(lw, e), {}, rng);
      LandmarkFix ff, fw;
      if (loc_fill.process(img, &ff) == FixStatus::kOk) {
        ++ok_fill;
        cut_reads += ff.partly_outside && ff.qr_method == 1;
        // Every fix is right: the fill-in never produces a wrong payload or pose.
        EXPECT_STREQ(ff.payload, "AGV1/00017/+001000.0/-002000.0/+090.00");
        EXPECT_NEAR(ff.e_x_mm, e.x_mm, 0.05) << y << " " << heading_deg;
        EXPECT_NEAR(ff.e_y_mm, e.y_mm, 0.05) << y << " " << heading_deg;
      } else if (ff.logo_score != 0.0) {
        // The border was fitted (the logo scored) and the code not read: it is cut by the image
        // border where the logo puts it, and zxing's search, which needs the whole code, is not
        // run (six attempts, up to 12 M aarch64 instructions).
        ++unread;
        cut_unsearched += ff.qr_search_attempts == 0;
      }
      if (loc_whole.process(img, &fw) == FixStatus::kOk) ++ok_whole;
    }
  }
  std::printf(
      "cut sweep: fixes with fill-in %d, whole codes only %d (guided reads of cut codes %d); "
      "fitted but unread %d, of which without zxing's search %d\n",
      ok_fill, ok_whole, cut_reads, unread, cut_unsearched);
  EXPECT_GE(ok_fill, ok_whole + 3);  // measured: 32 vs 25
  EXPECT_GT(cut_reads, 0);
  EXPECT_GT(unread, 0);  // measured: 8
  EXPECT_EQ(cut_unsearched, unread);
}

namespace {

// The binarization's definition, module by module (qr_grid.hpp QrThreshold): sharpen against the
// mean of the 4 neighbours inside the grid, then dark where below the mean of the 5x5 modules
// inside the grid.
std::vector<int> direct_bits(const QrSamples& s, double gain) {
  const int side = s.side();
  std::vector<float> w(s.v);
  if (gain > 0) {
    for (int r = 0; r < side; ++r) {
      for (int c = 0; c < side; ++c) {
        double sum = 0;
        int cnt = 0;
        const int dr[4] = {-1, 1, 0, 0}, dc[4] = {0, 0, -1, 1};
        for (int k = 0; k < 4; ++k) {
          const int rr = r + dr[k], cc = c + dc[k];
          if (rr < 0 || cc < 0 || rr >= side || cc >= side) continue;
          sum += static_cast<double>(s.v[static_cast<size_t>(rr * side + cc)]);
          ++cnt;
        }
        const double x = static_cast<double>(s.v[static_cast<size_t>(r * side + c)]);
        w[static_cast<size_t>(r * side + c)] = static_cast<float>(x + gain * (x - sum / cnt));
      }
    }
  }
  std::vector<int> bits;
  for (int r = s.ring; r < s.ring + s.n; ++r) {
    for (int c = s.ring; c < s.ring + s.n; ++c) {
      double sum = 0;
      int cnt = 0;
      for (int rr = std::max(0, r - 2); rr <= std::min(side - 1, r + 2); ++rr) {
        double row = 0;
        for (int cc = std::max(0, c - 2); cc <= std::min(side - 1, c + 2); ++cc) {
          row += static_cast<double>(w[static_cast<size_t>(rr * side + cc)]);
        }
        sum += row;
        cnt += std::min(side - 1, c + 2) - std::max(0, c - 2) + 1;
      }
      bits.push_back(w[static_cast<size_t>(r * side + c)] < static_cast<float>(sum / cnt) ? 1 : 0);
    }
  }
  return bits;
}

}  // namespace

// The binarization's fast loops (interior without bounds, local means of the code's modules only)
// give the definition's bits exactly, for both sizes, rings 0 to 3 and the three local-mean
// thresholds: compared through the fixed-module error count, which reads the binarized bits.
TEST(QrGrid, BinarizationEqualsItsDefinitionBitForBit) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<float> grey(0.0f, 255.0f);
  int grids = 0;
  for (int n : {21, 25}) {
    for (int ring = 0; ring <= 3; ++ring) {
      for (int trial = 0; trial < 20; ++trial) {
        QrSamples s;
        s.n = n;
        s.ring = ring;
        s.v.resize(static_cast<size_t>(s.side() * s.side()));
        // Half the trials: near-ties (few distinct levels), where a changed sum order would flip
        // a module.
        for (float& x : s.v)
          x = trial % 2 ? grey(rng) : static_cast<float>(static_cast<int>(grey(rng)) % 3 * 100);
        for (const auto& [t, gain] : {std::pair{QrThreshold::kStronglySharpenedLocalMean, 6.0},
                                      std::pair{QrThreshold::kSharpenedLocalMean, 1.0},
                                      std::pair{QrThreshold::kLocalMean, 0.0}}) {
          const std::vector<int> want = direct_bits(s, gain);
          int want_errors = 0;
          for (int r = 0; r < n; ++r) {
            for (int c = 0; c < n; ++c) {
              const int f = qr_fixed_module(n, r, c);
              if (f >= 0 && f != want[static_cast<size_t>(r * n + c)]) ++want_errors;
            }
          }
          QrGridScratch sc;
          EXPECT_EQ(qr_fixed_module_errors(s, t, &sc), want_errors);
          ASSERT_EQ(sc.bits.size(), want.size());
          for (size_t i = 0; i < want.size(); ++i) {
            ASSERT_EQ(static_cast<int>(sc.bits[i]), want[i])
                << "n " << n << " ring " << ring << " module " << i;
          }
          ++grids;
        }
      }
    }
  }
  EXPECT_EQ(grids, 2 * 4 * 20 * 3);
}

// The placement of the codewords (ISO/IEC 18004 7.7.3): 8 modules each, 26 codewords for version
// 1 and 44 plus 7 remainder modules for version 2, nothing on function or format modules, and the
// first codeword in the bottom-right 2 x 4 block (read upwards, right column first).
TEST(QrGrid, CodewordPlacementCoversEveryDataModuleOnce) {
  for (int n : {21, 25}) {
    std::vector<int> per_codeword(n == 21 ? 26 : 44, 0);
    int remainder = 0;
    for (const auto& [r, c] : data_modules(n)) {
      const int cw = qr_codeword_of_module(n, r, c);
      if (cw < 0) {
        ++remainder;
        continue;
      }
      ASSERT_LT(cw, static_cast<int>(per_codeword.size()));
      ++per_codeword[static_cast<size_t>(cw)];
    }
    for (int k : per_codeword) EXPECT_EQ(k, 8) << n;
    EXPECT_EQ(remainder, n == 21 ? 0 : 7);
    for (int r = n - 4; r < n; ++r) {
      EXPECT_EQ(qr_codeword_of_module(n, r, n - 1), 0);
      EXPECT_EQ(qr_codeword_of_module(n, r, n - 2), 0);
    }
    EXPECT_EQ(qr_codeword_of_module(n, 0, 0), -1);  // finder
    EXPECT_EQ(qr_codeword_of_module(n, 8, 0), -1);  // format
    EXPECT_EQ(qr_codeword_of_module(n, -1, 3), -1);
  }
  EXPECT_EQ(qr_codeword_of_module(29, 0, 0), -1);
}

// Clustered errors (a smear along one edge of the code): many wrong modules in few codewords. The
// verified read counts codewords, so it takes up to the bound of wrong codewords however many of
// their modules are wrong, and zxing reads the same text from the same grid; one more wrong
// codeword is not verified.
TEST(QrGrid, VerifiedReadCountsWrongCodewordsNotModules) {
  QrGridScratch scratch;
  std::mt19937_64 rng(5);
  for (const std::string text : {kFull, kIdOnly}) {
    const ZXing::BitMatrix bm = encode(text);
    const QrBits bits = bits_of(text);
    const QrExpected expected[] = {{&bits, &text}};
    const int bound = qr_verified_max_data_errors(bits.n);
    const int n_cw = bits.n == 21 ? 26 : 44;
    std::vector<std::vector<std::pair<int, int>>> modules(static_cast<size_t>(n_cw));
    for (const auto& [r, c] : data_modules(bits.n)) {
      const int cw = qr_codeword_of_module(bits.n, r, c);
      if (cw >= 0) modules[static_cast<size_t>(cw)].emplace_back(r, c);
    }
    std::vector<int> order(static_cast<size_t>(n_cw));
    for (int k = 0; k < n_cw; ++k) order[static_cast<size_t>(k)] = k;
    int verified_beyond_modules = 0;
    for (int trial = 0; trial < 60; ++trial) {
      const bool over = trial % 3 == 2;
      const int wrong = over ? bound + 1 : bound - trial % 2;
      std::shuffle(order.begin(), order.end(), rng);
      QrSamples s = samples_of(bm, 0.0, 0.0, 1);
      int flipped = 0;
      for (int k = 0; k < wrong; ++k) {
        auto& ms = modules[static_cast<size_t>(order[static_cast<size_t>(k)])];
        std::shuffle(ms.begin(), ms.end(), rng);
        const int m = 1 + static_cast<int>(rng() % 8);  // 1 to 8 of its modules
        for (int j = 0; j < m; ++j)
          flip(&s, ms[static_cast<size_t>(j)].first, ms[static_cast<size_t>(j)].second);
        flipped += m;
      }
      bool read_verified = false;
      ASSERT_NO_FATAL_FAILURE(
          check_verified_read(s, text, expected, over, trial, &scratch, &read_verified));
      verified_beyond_modules += read_verified && flipped > bound;
    }
    // Most verified grids had more wrong modules than the bound: the module count refused them.
    EXPECT_GE(verified_beyond_modules, 30) << text;
  }
}

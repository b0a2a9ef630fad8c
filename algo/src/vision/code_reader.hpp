// Stage 5 of the pipeline (qr_decode.cpp): the QR code read where the fitted pose puts it (guided
// module sampling, verified against the expected and mapped codes, zxing's pure-code reader),
// zxing's search on the crop as the fallback, then the payload and map check. Owns the sampling
// grids, crops and the read's storage; the mapped codes come from the shared CodeCache.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "agv/vision/qr_grid.hpp"
#include "agv/vision/tracking.hpp"
#include "code_cache.hpp"
#include "stage_common.hpp"

namespace agv::vision {

class CodeReader {
 public:
  CodeReader(const VisionSetup& s, CodeCache& codes) : setup(s), cache(codes) {}

  // The read's storage, reused from frame to frame; the stages take it as an argument.
  QrRead& read() { return qr_read; }

  // Reads the code (read_code) expecting the tracked landmark's codes when there is a trusted
  // prediction (windows planned), and records on the fix how often zxing ran.
  int decode_qr(const cv::Mat& img, const Prediction& pred,
                const std::vector<SearchWindow>& windows, Vec2 c_px, double up, Vec2 c_mm,
                double beta, const LogoScores& logo, QrRead* rd, LandmarkFix* out);
  // Tracking's first read at the predicted turn: the turn, or -1 with out's QR fields untouched.
  int read_at_predicted_turn(const cv::Mat& img, const Prediction& pred,
                             const std::vector<SearchWindow>& windows, Vec2 c_mm, double beta,
                             QrRead* rd, LandmarkFix* out);
  FixStatus check_payload(const std::string& text, LandmarkFix* out, Pose2* world_landmark);
  // The modules of an n x n code at forward angle fwd (qr_grid.hpp QrSamples); false when the
  // code leaves the image beyond VisionConfig::qr_max_missing_modules.
  bool sample_qr(const cv::Mat& img, Vec2 c_mm, double fwd, int n, QrSamples* s,
                 bool centre_only = false);

 private:
  int read_code(const cv::Mat& img, Vec2 c_px, double up, Vec2 c_mm, double beta,
                const LogoScores& logo, QrRead* rd, LandmarkFix* out);
  void expect_tracked_code(const Prediction& pred, const std::vector<SearchWindow>& windows,
                           Vec2 c_mm, double beta, QrRead* rd);
  bool read_centres(const cv::Mat& img, Vec2 c_mm, double beta, int q, QrCodeBook* book,
                    QrRead* rd);
  bool code_cut_at_every_turn(const cv::Mat& img, Vec2 c_mm, double beta,
                              const LogoScores& logo) const;
  int decode_guided(const cv::Mat& img, Vec2 c_mm, double beta, const LogoScores& logo, QrRead* rd);
  bool read_qr_search(const cv::Mat& img, Vec2 centre_px, double up_angle, std::string* text,
                      double* qr_up_angle, bool* qr_ok, int* attempts_made);
  bool fill_missing_modules(QrSamples* s);

  const VisionSetup& setup;
  CodeCache& cache;
  cv::Mat qr_small, qr_blur, qr_sharp;
  QrSamples qr_samples;
  // decode_guided's grids at an unclear logo: four turns, two sizes, and each grid's turn.
  std::array<QrSamples, 8> qr_grids;
  std::array<int, 8> qr_grid_turns{};
  std::vector<float> qr_fill;
  QrGridScratch qr_scratch;
  QrRead qr_read;
};

}  // namespace agv::vision

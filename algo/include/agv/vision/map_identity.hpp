// Map-guided identity of a landmark whose QR code cannot be read (docs/design/map_identity.md): the
// fused pose predicts where every mapped landmark should appear; the border fit measured where
// one is. Two independent checks must both agree before the landmark gets an identity:
//   1. the pose gate: exactly one (landmark, turn) inside a chi-square gate, every other one far
//      outside it;
//   2. the module check: the QR modules sampled where the code should be agree with the code the
//      gate's candidate prints, and on the modules where it differs from any other mapped
//      landmark's code they side with the candidate. This protects against a wrong prediction (a
//      kidnapped vehicle, displaced by exactly one grid spacing, passes the gate with the wrong
//      landmark).
// Pure: no I/O, no clocks.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/common/landmark.hpp"
#include "agv/common/landmark_index.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "agv/vision/map_identity_config.hpp"
#include "agv/vision/qr_grid.hpp"

namespace agv::vision {

enum class MapIdentityResult {
  kAccepted,
  kNoPrediction,     // prediction invalid or no map
  kNoneInGate,       // no (landmark, turn) inside gate_chi2
  kTwoPlausible,     // the runner-up is inside clear_chi2
  kModulesDisagree,  // the sampled modules do not show the candidate's code (or show another's)
};
const char* to_string(MapIdentityResult r);

struct MapIdentityDecision {
  MapIdentityResult result = MapIdentityResult::kNoPrediction;
  std::uint32_t id = 0;  // the candidate (also set when the module check refuses it)
  int turn = 0;          // forward axis = beta - turn * 90 deg
  // Squared Mahalanobis distances. d2_second is exact up to clear_chi2; beyond it, with an index,
  // it is some larger value or +inf (the landmarks that far out are not visited).
  double d2_best = 0.0, d2_second = 0.0;
};

// The predicted landmark-in-vehicle pose of a map entry and its covariance, propagated from the
// vehicle's predicted pose and covariance (first order).
Pose2 predicted_landmark_in_vehicle(const Prediction& pred, const Pose2& landmark_in_world,
                                    Eigen::Matrix3d* cov);

// Stage 1, the pose gate. measured_c_mm, beta_rad: the fitted square's centre and the angle of its
// side-0 normal in the vehicle frame (the landmark's forward axis is beta - turn * 90 deg);
// meas_cov: covariance of (x_mm, y_mm, theta_rad) of the fit. allowed_turns: the turns the logo
// allows (one when it is clear, all four otherwise). index: the map's spatial index (null: every
// entry is scored). With it, only the landmarks that can lie within max(gate_chi2, clear_chi2) are
// scored: the same decision at a cost set by the prediction's uncertainty, not the map's size
// (docs/design/large_maps.md), unless the heading sigma is so large (above 1 / sqrt(clear_chi2)
// rad, 7.4 deg) that no distance bounds the gate; every entry is scored then.
MapIdentityDecision gate_identity(Vec2 measured_c_mm, double beta_rad,
                                  const Eigen::Matrix3d& meas_cov,
                                  const std::array<bool, 4>& allowed_turns, const Prediction& pred,
                                  const LandmarkMap& map, const MapIdentityConfig& cfg,
                                  const LandmarkIndex* index = nullptr);

// Radius (mm) around the measured centre beyond which no mapped landmark's squared Mahalanobis
// distance can be at most chi2: the position block of the innovation covariance is at most
// (sigma_pos + sigma_heading * |p|)^2 + the fit's largest position variance for a landmark at p
// (vehicle frame). +inf when no radius bounds it (sigma_heading * sqrt(chi2) >= 1, or a
// covariance that is not finite).
double identity_search_radius_mm(Vec2 measured_c_mm, const Eigen::Matrix3d& meas_cov,
                                 const Prediction& pred, double chi2);

// The code the landmark prints: zxing-cpp's writer at ECC level M without margin (exactly as the
// simulator and the generator render it). False when the text cannot be encoded.
bool encode_qr_bits(const std::string& payload, QrBits* out);

// The two payload forms of a map entry: the full one (pose from the map, version 2) and the
// id-only one (version 1). Empty string when the entry cannot be formatted.
std::string map_full_payload(const LandmarkMapEntry& e);
std::string map_id_payload(std::uint32_t id);

// Sampled modules as bits: dark when below the mean of the 5x5 modules around it (the guided
// reader's kLocalMean rule). Marked 2 = unknown: modules outside the image (negative sample), in a
// flat neighbourhood (local range below 0.35 of the print's contrast: the inside of a patch over
// the code, whose bits would be noise) and within 0.05 of the contrast of their local mean.
void binarize_samples(const QrSamples& s, std::vector<std::uint8_t>* bits);

struct ModuleAgreement {
  int visible = 0;          // data modules compared
  double agree = 0.0;       // fraction of them where the candidate matches
  double worst_pair = 1.0;  // lowest pairwise side-with-candidate fraction
  std::uint32_t worst_pair_id = 0;
  bool ok = false;
};

// Stage 2, the module check of `candidate` against the bits sampled for its code version (bits
// from binarize_samples, n = candidate.n) and against every code in `others` of the same n.
ModuleAgreement check_modules(const std::vector<std::uint8_t>& bits, const QrBits& candidate,
                              const std::vector<std::pair<std::uint32_t, const QrBits*>>& others,
                              const MapIdentityConfig& cfg);

}  // namespace agv::vision

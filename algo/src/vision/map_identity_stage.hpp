// Stage 5c of the pipeline (map_identity_stage.cpp, docs/design/map_identity.md): the identity of
// a landmark whose QR code was not read, from the prediction and the map, confirmed by the modules
// sampled where the candidate's code must be. Owns its samples and the module check's storage.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "code_cache.hpp"
#include "code_reader.hpp"
#include "stage_common.hpp"

namespace agv::vision {

class MapIdentityStage {
 public:
  // index: the map's spatial index (WindowPlanner::index()), null without one.
  MapIdentityStage(const VisionSetup& s, const LandmarkIndex* index, CodeCache& codes,
                   CodeReader& reader)
      : setup(s), index_(index), cache(codes), code_reader(reader) {}

  // The mapped landmark the fitted square (c_mm, beta, cov) is, its world pose and the turn of
  // its forward axis; false when the pose gate or the module check refuses.
  bool map_identity(const cv::Mat& img, const Prediction& pred, Vec2 c_mm, double beta,
                    const Eigen::Matrix3d& cov, const LogoScores& logo, Pose2* world_landmark,
                    int* turn, std::uint32_t* id);

 private:
  const VisionSetup& setup;
  const LandmarkIndex* index_;
  CodeCache& cache;
  CodeReader& code_reader;  // samples the candidate's modules
  QrSamples qr_samples;
  std::vector<std::uint8_t> identity_bits;
  std::vector<std::pair<std::uint32_t, const QrBits*>> identity_others;
  std::vector<const LandmarkMapEntry*> near_entries;
};

}  // namespace agv::vision

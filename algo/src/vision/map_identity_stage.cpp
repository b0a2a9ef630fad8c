// Stage 5c of the pipeline (docs/design/map_identity.md): the identity of a landmark whose QR code
// was not read, from the prediction and the map (pose gate), confirmed by the QR modules sampled
// where the candidate's code must be (module check). The decisions themselves are pure functions in
// map_identity.cpp; this file samples the image for them.
#include "map_identity_stage.hpp"

#include <algorithm>
#include <cmath>

#include "agv/common/landmark_index.hpp"
#include "agv/vision/map_identity.hpp"

namespace agv::vision {

bool MapIdentityStage::map_identity(const cv::Mat& img, const Prediction& pred, Vec2 c_mm,
                                    double beta, const Eigen::Matrix3d& cov, const LogoScores& logo,
                                    Pose2* world_landmark, int* turn, std::uint32_t* id) {
  if (!setup.map || !pred.valid) return false;
  std::array<bool, 4> turns{true, true, true, true};
  if (logo.clear) {
    turns = {false, false, false, false};
    turns[static_cast<size_t>(logo.best_q)] = true;
  }
  const MapIdentityDecision identity =
      gate_identity(c_mm, beta, cov, turns, pred, *setup.map, setup.cfg.identity, index_);
  if (identity.result != MapIdentityResult::kAccepted) return false;
  const LandmarkMapEntry* e = setup.map->find(identity.id);
  CodeCache::MapCodes* cand_codes = e ? cache.codes_of(identity.id) : nullptr;
  if (!cand_codes) return false;
  // The neighbours whose codes the module check compares with (MapIdentityConfig::
  // pair_neighbours), in id order as a scan of the map gives them.
  near_entries.clear();
  if (const LandmarkIndex* index = index_) {
    index->nearest({e->pose.x_mm, e->pose.y_mm},
                   static_cast<size_t>(std::max(0, setup.cfg.identity.pair_neighbours)) + 1,
                   &near_entries);
  }
  std::sort(near_entries.begin(), near_entries.end(),
            [](const LandmarkMapEntry* a, const LandmarkMapEntry* b) { return a->id < b->id; });
  for (const LandmarkMapEntry* o : near_entries) cache.codes_of(o->id);
  const double fwd = beta - identity.turn * kPi / 2.0;
  bool ok = false;
  for (size_t form = 0; form < 2 && !ok; ++form) {
    const QrBits& cand = cand_codes->bits[form];
    if (cand.n <= 0 || !code_reader.sample_qr(img, c_mm, fwd, cand.n, &qr_samples)) continue;
    binarize_samples(qr_samples, &identity_bits);
    identity_others.clear();
    for (const LandmarkMapEntry* o : near_entries) {
      if (o->id != identity.id)
        identity_others.emplace_back(o->id, &cache.codes_of(o->id)->bits[form]);
    }
    ok = check_modules(identity_bits, cand, identity_others, setup.cfg.identity).ok;
  }
  if (!ok) return false;
  *world_landmark = e->pose;
  *turn = identity.turn;
  *id = identity.id;
  return true;
}

}  // namespace agv::vision

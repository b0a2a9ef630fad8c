// Stage 5c of the pipeline (docs/map_identity.md): the identity of a landmark whose QR code was not
// read, from the prediction and the map (pose gate), confirmed by the QR modules sampled where the
// candidate's code must be (module check). The decisions themselves are pure functions in
// map_identity.cpp; this file samples the image for them.
#include <cmath>

#include "agv/vision/map_identity.hpp"
#include "localizer_impl.hpp"

namespace agv::vision {

// Both forms of a mapped landmark's code, encoded on first use and kept: the map does not change
// while the localizer lives (its constructor's contract). nullptr for an id not in the map.
LandmarkLocalizer::Impl::MapCodes* LandmarkLocalizer::Impl::codes_of(std::uint32_t id) {
  const LandmarkMapEntry* e = map ? map->find(id) : nullptr;
  if (!e) return nullptr;
  const auto [it, added] = map_codes.try_emplace(id);
  MapCodes& codes = it->second;
  if (added) {
    codes.text = {map_full_payload(*e), map_id_payload(id)};
    for (size_t form = 0; form < 2; ++form) {
      if (!encode_qr_bits(codes.text[form], &codes.bits[form])) codes.bits[form] = QrBits{};
    }
  }
  return &codes;
}

// Every mapped landmark's codes: the module check compares the candidate with all of them.
void LandmarkLocalizer::Impl::build_map_codes() {
  if (map_codes_built || !map) return;
  map_codes_built = true;
  for (const auto& entry : map->entries) codes_of(entry.first);
}

QrCodeBook* LandmarkLocalizer::Impl::code_book() {
  if (!map) return nullptr;
  if (!map_book_built) {
    map_book_built = true;
    build_map_codes();
    for (auto& [id, codes] : map_codes) {
      for (size_t form = 0; form < 2; ++form) map_book.add(&codes.bits[form], &codes.text[form]);
    }
  }
  return &map_book;
}

bool LandmarkLocalizer::Impl::map_identity(const cv::Mat& img, const Prediction& pred, Vec2 c_mm,
                                           double beta, const Eigen::Matrix3d& cov,
                                           const LogoScores& logo, Pose2* world_landmark, int* turn,
                                           std::uint32_t* id) {
  if (!map || !pred.valid) return false;
  std::array<bool, 4> turns{true, true, true, true};
  if (logo.clear) {
    turns = {false, false, false, false};
    turns[static_cast<size_t>(logo.best_q)] = true;
  }
  last_identity = gate_identity(c_mm, beta, cov, turns, pred, *map, identity_cfg);
  if (last_identity.result != MapIdentityResult::kAccepted) return false;
  build_map_codes();
  const auto it = map_codes.find(last_identity.id);
  const LandmarkMapEntry* e = map->find(last_identity.id);
  if (it == map_codes.end() || !e) return false;
  const double fwd = beta - last_identity.turn * kPi / 2.0;
  bool ok = false;
  for (size_t form = 0; form < 2 && !ok; ++form) {
    const QrBits& cand = it->second.bits[form];
    if (cand.n <= 0 || !sample_qr(img, c_mm, fwd, cand.n, &qr_samples)) continue;
    binarize_samples(qr_samples, &identity_bits);
    identity_others.clear();
    for (const auto& [oid, codes] : map_codes) {
      if (oid != last_identity.id) identity_others.emplace_back(oid, &codes.bits[form]);
    }
    last_modules = check_modules(identity_bits, cand, identity_others, identity_cfg);
    ok = last_modules.ok;
  }
  if (!ok) {
    last_identity.result = MapIdentityResult::kModulesDisagree;
    return false;
  }
  *world_landmark = e->pose;
  *turn = last_identity.turn;
  *id = last_identity.id;
  return true;
}

}  // namespace agv::vision

// Stage 5c of the pipeline (docs/design/map_identity.md): the identity of a landmark whose QR code
// was not read, from the prediction and the map (pose gate), confirmed by the QR modules sampled
// where the candidate's code must be (module check). The decisions themselves are pure functions in
// map_identity.cpp; this file samples the image for them.
#include <algorithm>
#include <cmath>

#include "agv/vision/map_identity.hpp"
#include "localizer_impl.hpp"

namespace agv::vision {

namespace {

// A map of at most this many landmarks gets the book of all its codes at start-up (at most ~60 ms
// of encoding on x86-64), as before large maps: the verified read without a prediction then
// reads every mapped code.
constexpr size_t kFullBookMaxLandmarks = 256;
// Otherwise the book holds the codes of the landmarks nearest the predicted vehicle: the camera
// sees one or two of them, and a 3 x 3 block of a grid leaves room for a prediction off by one
// spacing.
constexpr size_t kBookNearest = 9;
// The cache of encoded codes is emptied between frames past this many landmarks (~1.2 kB each).
constexpr size_t kMaxCachedCodes = 1024;

}  // namespace

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

// Between frames only: the book and the expected codes point into map_codes.
void LandmarkLocalizer::Impl::prune_map_codes() {
  if (full_book || map_codes.size() <= kMaxCachedCodes) return;
  map_codes.clear();
  map_book = QrCodeBook{};
  book_ids.clear();
  qr_read.expected.clear();
}

void LandmarkLocalizer::Impl::update_code_book(const Prediction& pred) {
  if (!map || full_book) return;
  if (map->entries.size() <= kFullBookMaxLandmarks) {
    full_book = true;
    for (const auto& entry : map->entries) {
      MapCodes* codes = codes_of(entry.first);
      for (size_t form = 0; form < 2; ++form) map_book.add(&codes->bits[form], &codes->text[form]);
    }
    return;
  }
  near_entries.clear();
  const LandmarkIndex* index = planner.index();
  if (pred.valid && index) {
    index->nearest({pred.vehicle_in_world.x_mm, pred.vehicle_in_world.y_mm}, kBookNearest,
                   &near_entries);
  }
  // Rebuilt only when the nearest landmarks change, in id order (the book returns the only code
  // a grid is within the bounds of, so the order cannot change its answer).
  std::sort(near_entries.begin(), near_entries.end(),
            [](const LandmarkMapEntry* a, const LandmarkMapEntry* b) { return a->id < b->id; });
  const bool same =
      near_entries.size() == book_ids.size() &&
      std::equal(near_entries.begin(), near_entries.end(), book_ids.begin(),
                 [](const LandmarkMapEntry* e, std::uint32_t id) { return e->id == id; });
  if (same) return;
  map_book = QrCodeBook{};
  book_ids.clear();
  for (const LandmarkMapEntry* e : near_entries) {
    book_ids.push_back(e->id);
    MapCodes* codes = codes_of(e->id);
    for (size_t form = 0; form < 2; ++form) map_book.add(&codes->bits[form], &codes->text[form]);
  }
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
  const MapIdentityDecision identity =
      gate_identity(c_mm, beta, cov, turns, pred, *map, cfg.identity, planner.index());
  if (identity.result != MapIdentityResult::kAccepted) return false;
  const LandmarkMapEntry* e = map->find(identity.id);
  MapCodes* cand_codes = e ? codes_of(identity.id) : nullptr;
  if (!cand_codes) return false;
  // The neighbours whose codes the module check compares with (MapIdentityConfig::
  // pair_neighbours), in id order as a scan of the map gives them.
  near_entries.clear();
  if (const LandmarkIndex* index = planner.index()) {
    index->nearest({e->pose.x_mm, e->pose.y_mm},
                   static_cast<size_t>(std::max(0, cfg.identity.pair_neighbours)) + 1,
                   &near_entries);
  }
  std::sort(near_entries.begin(), near_entries.end(),
            [](const LandmarkMapEntry* a, const LandmarkMapEntry* b) { return a->id < b->id; });
  for (const LandmarkMapEntry* o : near_entries) codes_of(o->id);
  const double fwd = beta - identity.turn * kPi / 2.0;
  bool ok = false;
  for (size_t form = 0; form < 2 && !ok; ++form) {
    const QrBits& cand = cand_codes->bits[form];
    if (cand.n <= 0 || !sample_qr(img, c_mm, fwd, cand.n, &qr_samples)) continue;
    binarize_samples(qr_samples, &identity_bits);
    identity_others.clear();
    for (const LandmarkMapEntry* o : near_entries) {
      if (o->id != identity.id) identity_others.emplace_back(o->id, &codes_of(o->id)->bits[form]);
    }
    ok = check_modules(identity_bits, cand, identity_others, cfg.identity).ok;
  }
  if (!ok) return false;
  *world_landmark = e->pose;
  *turn = identity.turn;
  *id = identity.id;
  return true;
}

}  // namespace agv::vision

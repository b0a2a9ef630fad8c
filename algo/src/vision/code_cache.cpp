// The mapped landmarks' codes, encoded on first use, and the verified read's code book
// (code_cache.hpp, docs/design/large_maps.md).
#include "code_cache.hpp"

#include <algorithm>

#include "agv/common/landmark_index.hpp"
#include "agv/vision/map_identity.hpp"

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
CodeCache::MapCodes* CodeCache::codes_of(std::uint32_t id) {
  const LandmarkMapEntry* e = setup.map ? setup.map->find(id) : nullptr;
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
bool CodeCache::prune() {
  if (full_book || map_codes.size() <= kMaxCachedCodes) return false;
  map_codes.clear();
  map_book = QrCodeBook{};
  book_ids.clear();
  return true;
}

void CodeCache::update_code_book(const Prediction& pred) {
  if (!setup.map || full_book) return;
  if (setup.map->entries.size() <= kFullBookMaxLandmarks) {
    full_book = true;
    for (const auto& entry : setup.map->entries) {
      MapCodes* codes = codes_of(entry.first);
      for (size_t form = 0; form < 2; ++form) map_book.add(&codes->bits[form], &codes->text[form]);
    }
    return;
  }
  near_entries.clear();
  const LandmarkIndex* index = index_;
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

}  // namespace agv::vision

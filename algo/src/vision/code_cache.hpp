// The mapped landmarks' QR codes, encoded on first use (map_identity_stage.cpp,
// docs/design/large_maps.md), and the code book of the verified read: the one cache the code
// reader and the map-guided identity share, kept from frame to frame.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "agv/vision/qr_grid.hpp"
#include "agv/vision/tracking.hpp"
#include "stage_common.hpp"

namespace agv::vision {

class CodeCache {
 public:
  // Both forms of a mapped landmark's code: [0] the full payload, [1] the id-only one.
  struct MapCodes {
    std::array<QrBits, 2> bits;
    std::array<std::string, 2> text;
    // zxing decodes the bits back to the text (qr_bits_decode_to): 0 not yet checked, 1 yes,
    // -1 no. Checked on first use as an expected code; only a 1 is offered to the verified read.
    std::array<int, 2> reads_back{0, 0};
  };

  // index: the map's spatial index (WindowPlanner::index()), null without one.
  CodeCache(const VisionSetup& s, const LandmarkIndex* index) : setup(s), index_(index) {}

  // Both codes of a mapped landmark, encoded on first use; nullptr for an id not in the map.
  MapCodes* codes_of(std::uint32_t id);
  // The mapped codes for the verified read (qr_grid.hpp QrCodeBook): every one of a small map
  // (built on the first call), else those of the landmarks nearest the predicted vehicle (none
  // without a prediction; zxing reads those codes, to the same text).
  void update_code_book(const Prediction& pred);
  QrCodeBook* code_book() { return setup.map ? &map_book : nullptr; }
  // Between frames only: empties the cache once it holds too many landmarks. True when it did;
  // the book and every expected code pointed into it.
  bool prune();

 private:
  const VisionSetup& setup;
  const LandmarkIndex* index_;
  // A site's map has tens of thousands of codes, of which a frame needs a few.
  std::map<std::uint32_t, MapCodes> map_codes;
  QrCodeBook map_book;
  std::vector<std::uint32_t> book_ids;  // whose codes map_book holds
  bool full_book = false;
  std::vector<const LandmarkMapEntry*> near_entries;
};

}  // namespace agv::vision

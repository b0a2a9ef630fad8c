#include "agv/localizer/no_fix_diagnosis.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace agv::localizer {

FrameOutcome frame_outcome(const vision::LandmarkFix& fix) {
  return {fix.status, fix.landmark_id, fix.outer_half_mm};
}

NoFixDiagnosis diagnose_no_fix(std::uint64_t frames_processed,
                               const std::uint64_t (&by_status)[kFixStatusCount],
                               const std::vector<FrameOutcome>& frames, const NoFixContext& c) {
  NoFixDiagnosis d;
  if (frames_processed == 0 || by_status[static_cast<int>(vision::FixStatus::kOk)] > 0) return d;
  auto count = [&](vision::FixStatus s) { return by_status[static_cast<int>(s)]; };
  for (int i = 0; i < kFixStatusCount; ++i) {
    if (by_status[i] == 0) continue;
    d.statuses += (d.statuses.empty() ? "" : ", ") + std::to_string(by_status[i]) + " " +
                  vision::to_string(static_cast<vision::FixStatus>(i));
  }
  const bool tag = c.family == LandmarkFamily::kTag36h11;
  const std::string family = std::string("landmark.family (") + landmark_family_name(c.family) +
                             ", " +
                             (c.family_source.empty() ? "the default: neither --config nor "
                                                        "meta.yaml sets it"
                                                      : "from " + c.family_source) +
                             ")";
  // Landmarks read but not in the map: the ids say which.
  const std::uint64_t unknown =
      count(vision::FixStatus::kUnknownLandmark) + count(vision::FixStatus::kPayloadInvalid);
  // Tags whose fitted square is off the printed size (apriltag.cpp's 3 % gate): the metric frame's
  // scale is the configured height's, so the median ratio says how far off the height (or print)
  // is. A true height H' shows the square H / H' of its size.
  std::vector<double> ratios;
  for (const FrameOutcome& f : frames) {
    if (f.status == vision::FixStatus::kTooFewEdgePoints && f.outer_half_mm > 0.0 &&
        c.size_mm > 0.0) {
      ratios.push_back(f.outer_half_mm / (c.size_mm / 2.0));
    }
  }
  const std::uint64_t not_seen =
      count(vision::FixStatus::kNoLandmark) + count(vision::FixStatus::kBadInput);
  const std::uint64_t seen = frames_processed > not_seen ? frames_processed - not_seen : 0;
  if (unknown > 0 && unknown * 2 >= seen) {
    std::string ids;
    std::vector<std::uint32_t> listed;
    for (const FrameOutcome& f : frames) {
      if (f.status != vision::FixStatus::kUnknownLandmark &&
          f.status != vision::FixStatus::kPayloadInvalid) {
        continue;
      }
      if (std::find(listed.begin(), listed.end(), f.landmark_id) != listed.end()) continue;
      listed.push_back(f.landmark_id);
      if (listed.size() <= 5) ids += (ids.empty() ? "" : ", ") + std::to_string(f.landmark_id);
    }
    if (listed.size() > 5) ids += ", ...";
    d.cause = NoFixCause::kMap;
    d.text = "the map: landmarks " + ids + " were read but " +
             (c.have_map ? "are not in the map (or disagree with it): check --map / landmark.map"
                         : "there is no map (--map, landmark.map or the recording's map.csv)" +
                               std::string(tag ? ", which a tag36h11 floor needs" : ""));
    return d;
  }
  if (ratios.size() * 2 >= std::max<std::uint64_t>(seen, 1) && !ratios.empty()) {
    std::sort(ratios.begin(), ratios.end());
    const double s = ratios[ratios.size() / 2];
    char b[512];
    std::snprintf(b, sizeof b,
                  "the camera height or the print size: %zu landmarks were found but their "
                  "square measures %.1f %% %s than landmark.size_mm %g (more than the 3 %% "
                  "allowed); with the print right, the camera is about %.0f mm above the floor, "
                  "not mounting.height_mm %g (%s)",
                  ratios.size(), std::abs(s - 1.0) * 100.0, s < 1.0 ? "smaller" : "larger",
                  c.size_mm, c.height_mm / s, c.height_mm,
                  c.calibrating ? "set mounting.height_mm in --config to about that and calibrate "
                                  "again: calibration starts from fixes"
                                : "agvloc-desk calibrate vehicle measures it");
    d.cause = NoFixCause::kScale;
    d.text = b;
    return d;
  }
  // Nothing of the family was read in any frame: a QR floor run as tags finds no tag; a tag floor
  // run as QR finds the tags' black squares as borders (an inner edge broken by the data cells,
  // no code inside), but no frame reads a code.
  const bool read_any =
      tag ? seen > 0 : unknown + count(vision::FixStatus::kDirectionAmbiguous) > 0;
  if (!read_any) {
    d.cause = NoFixCause::kFamily;
    d.text = "the family: is " + family + " the family printed on the floor? " +
             (tag ? "A QR floor needs landmark.family: qr"
                  : "A tag36h11 floor needs landmark.family: tag36h11 and the map") +
             " (--config, or a recording whose meta.yaml records it); otherwise the drive passes "
             "over no landmark";
    return d;
  }
  d.cause = NoFixCause::kUnclear;
  d.text = "see the statuses; " + family + ", the camera height and the map are the usual suspects";
  return d;
}

}  // namespace agv::localizer

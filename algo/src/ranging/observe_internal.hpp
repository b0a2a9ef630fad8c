// What observe.cpp (full sweep, measurement) and observe_windows.cpp (predicted windows) share.
// Private to algo/src/ranging.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <vector>

#include "agv/overhead/tag_detect.hpp"
#include "agv/ranging/observe.hpp"

namespace agv::ranging {

struct LandmarkObserver::Impl {
  explicit Impl(const overhead::TagDetectParams& p) : detector(p) {}
  overhead::TagDetector detector;  // full resolution: windows, mirrored reads, full sweeps
  // The full sweep's detector when ObserveOptions::full_sweep_decimate is not 1.
  std::unique_ptr<overhead::TagDetector> decimated;
  cv::Matx33d K;
  std::vector<double> dist;
  // The interval's search of the whole frame (ObserveOptions::interval_sweep_decimate > 1).
  std::unique_ptr<overhead::TagDetector> interval;
  const overhead::TagDetector& sweep_detector() const { return decimated ? *decimated : detector; }
};

// Named, not anonymous: the library is built as one unity source.
namespace observe_detail {

// The tags read in `window` of the frame mirrored left-right, their corners mapped back into the
// frame (they are the mirror images' corners, page order of the mirrored read).
std::vector<overhead::TagObservation> mirrored_reads(const overhead::TagDetector& det,
                                                     const cv::Mat& gray, const cv::Rect& window);

// Records each mirrored read as a `mirrored` refusal (once per id and place) and flags the
// direct reads at its place: the mirror image of some code also decodes there, so neither read
// can be trusted.
void refuse_mirrored(const std::vector<overhead::TagObservation>& mirrored,
                     const std::vector<overhead::TagObservation>& direct,
                     std::vector<bool>* flagged, ObserveResult* res);

}  // namespace observe_detail
}  // namespace agv::ranging

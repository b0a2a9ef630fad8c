// eval_vision --speed-compare: the speed target (5x AprilTag) on one set of simulated frames in one
// run: LandmarkLocalizer::process (QR family, full search, no prediction) against libapriltag's
// apriltag_detector_detect (tag36h11, quad_decimate 2, one thread), both on the identical QR
// frames (same pixels) and on tag36h11 frames rendered at the same vehicle poses (what AprilTag
// would see on a tag floor). Per frame the best of 3 runs of each, interleaved so load changes on
// the shared machine hit both alike; the table gives medians and ratios.
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>

#include <algorithm>
#include <cstdio>

#include "eval_vision.hpp"

namespace eval_vision {

namespace {

constexpr int kRepeats = 3;

struct AprilTagD2 {
  apriltag_family_t* fam = tag36h11_create();
  apriltag_detector_t* det = apriltag_detector_create();
  AprilTagD2() {
    apriltag_detector_add_family(det, fam);
    det->quad_decimate = 2.0f;
    det->nthreads = 1;
  }
  ~AprilTagD2() {
    apriltag_detector_destroy(det);
    tag36h11_destroy(fam);
  }
  AprilTagD2(const AprilTagD2&) = delete;
  AprilTagD2& operator=(const AprilTagD2&) = delete;
  // Best-of-kRepeats time (ms); *found = a detection in the last run.
  double time(const cv::Mat& img, bool* found) {
    image_u8_t im{img.cols, img.rows, static_cast<std::int32_t>(img.step[0]), img.data};
    double best = 1e9;
    for (int rep = 0; rep < kRepeats; ++rep) {
      const std::int64_t t0 = now_ns();
      zarray_t* dets = apriltag_detector_detect(det, &im);
      best = std::min(best, (now_ns() - t0) * 1e-6);
      *found = zarray_size(dets) > 0;
      apriltag_detections_destroy(dets);
    }
    return best;
  }
};

}  // namespace

void run_speed_compare(const Setup& su, const std::vector<Frame>& qr_frames,
                       const sim::Scene& tag_scene) {
  VisionConfig cfg = su.cfg;
  cfg.now_ns = nullptr;  // no per-stage clock reads inside the timed call
  cfg.family = LandmarkFamily::kQr;
  LandmarkLocalizer loc(cfg, su.cam, su.geom, &su.map);
  VisionConfig tag_cfg = cfg;
  tag_cfg.family = LandmarkFamily::kTag36h11;
  LandmarkLocalizer tag_loc(tag_cfg, su.cam, su.geom, &su.map);
  AprilTagD2 at;
  sim::FrameRenderer r(tag_scene, su.cam);
  std::mt19937_64 rng(4242);
  std::vector<double> ours, at_qr, at_tag, ours_tag;
  int ok = 0, tag_found = 0, tag_ok = 0;
  LandmarkFix fix;
  for (const Frame& f : qr_frames) {
    const cv::Mat tag_img = r.render(f.vehicle_world, sim::RenderOptions{}, rng);
    double best = 1e9, best_tag = 1e9;
    for (int rep = 0; rep < kRepeats; ++rep) {
      std::int64_t t0 = now_ns();
      loc.process(f.img, Prediction{}, &fix);
      best = std::min(best, (now_ns() - t0) * 1e-6);
      if (rep == 0 && fix.status == FixStatus::kOk) ++ok;
      t0 = now_ns();
      tag_loc.process(tag_img, Prediction{}, &fix);
      best_tag = std::min(best_tag, (now_ns() - t0) * 1e-6);
      if (rep == 0 && fix.status == FixStatus::kOk) ++tag_ok;
    }
    ours.push_back(best);
    ours_tag.push_back(best_tag);
    bool found = false;
    at_qr.push_back(at.time(f.img, &found));
    at_tag.push_back(at.time(tag_img, &found));
    if (found) ++tag_found;
  }
  const int n = static_cast<int>(qr_frames.size());
  const double m_ours = pct(ours, 50);
  std::printf(
      "\n## Speed comparison (simulated %dx%d frames, clean, full heading circle; best of %d per "
      "frame, medians)\n\n",
      su.cam.intrinsics.width_px, su.cam.intrinsics.height_px, kRepeats);
  std::printf("| | frames | fixes / detections | median (ms) | p95 (ms) | ratio to ours |\n");
  std::printf("|---|---|---|---|---|---|\n");
  std::printf(
      "| ours: LandmarkLocalizer::process, QR family, full search | %d | %d | %.3f | %.3f "
      "| 1.00 |\n",
      n, ok, m_ours, pct(ours, 95));
  std::printf(
      "| AprilTag d2 on the same QR frames (no tag in them) | %d | - | %.3f | %.3f | %.2f "
      "|\n",
      n, pct(at_qr, 50), pct(at_qr, 95), pct(at_qr, 50) / m_ours);
  std::printf(
      "| AprilTag d2 on tag36h11 frames at the same poses | %d | %d | %.3f | %.3f | %.2f "
      "|\n",
      n, tag_found, pct(at_tag, 50), pct(at_tag, 95), pct(at_tag, 50) / m_ours);
  std::printf(
      "| ours, tag36h11 family (AprilTag d2 + edge-fit pose) on the tag frames | %d | %d | "
      "%.3f | %.3f | %.2f |\n",
      n, tag_ok, pct(ours_tag, 50), pct(ours_tag, 95), pct(ours_tag, 50) / m_ours);
}

}  // namespace eval_vision

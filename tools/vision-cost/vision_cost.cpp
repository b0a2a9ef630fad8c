// vision_cost RECORDING [--frames N] [--class all|ok|none]
// Instruction cost of the vision pipeline (agv::vision::LandmarkLocalizer::process) on the frames
// of a recording, for docs/deployment.md. Frames are decoded first; one warm-up pass classifies
// them (status ok or not); the measured pass then calls process() once per selected frame, each
// call bracketed twice:
//   - by agv_cost_frame() (never inlined) for `valgrind --tool=callgrind
//     --toggle-collect=agv_cost_frame*`, natively;
//   - by marker system calls (prctl with an invalid option; EINVAL, no effect) for the qemu
//     plugin insn_count_plugin.c, under qemu-aarch64.
// Both count user-space instructions of the same calls. OpenCV runs single-threaded so that the
// count is one core's work. measure.sh runs the whole comparison.
#include <sys/prctl.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>
#include <string>
#include <vector>

#include "agv/recording/recording.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace {

constexpr unsigned long kMarkerOn = 0x41475631UL;   // "AGV1"
constexpr unsigned long kMarkerOff = 0x41475630UL;  // "AGV0"

}  // namespace

extern "C" __attribute__((noinline)) int agv_cost_frame(agv::vision::LandmarkLocalizer* loc,
                                                        const cv::Mat* gray,
                                                        agv::vision::LandmarkFix* fix) {
  return static_cast<int>(loc->process(*gray, fix));
}

int main(int argc, char** argv) {
  if (argc < 2 || argv[1][0] == '-') {
    std::fprintf(stderr, "usage: vision_cost RECORDING [--frames N] [--class all|ok|none]\n");
    return 2;
  }
  const std::string dir = argv[1];
  size_t max_frames = 1000000;
  std::string cls = "all";
  for (int i = 2; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--frames")) {
      max_frames = static_cast<size_t>(std::strtoul(argv[i + 1], nullptr, 10));
    } else if (!std::strcmp(argv[i], "--class")) {
      cls = argv[i + 1];
    } else {
      std::fprintf(stderr, "vision_cost: unknown option %s\n", argv[i]);
      return 2;
    }
  }
  if (cls != "all" && cls != "ok" && cls != "none") {
    std::fprintf(stderr, "vision_cost: --class must be all, ok or none\n");
    return 2;
  }
  cv::setNumThreads(0);

  agv::recording::Recording rec;
  std::string err;
  if (!agv::recording::read_recording(dir, &rec, &err)) {
    std::fprintf(stderr, "vision_cost: %s\n", err.c_str());
    return 1;
  }
  std::vector<cv::Mat> frames;
  for (size_t i = 0; i < rec.frames.size() && frames.size() < max_frames; ++i) {
    cv::Mat img;
    if (!agv::recording::load_frame(rec, i, &img, &err)) {
      std::fprintf(stderr, "vision_cost: %s\n", err.c_str());
      return 1;
    }
    frames.push_back(img);
  }
  agv::LandmarkGeometry geometry;
  geometry.size_mm = rec.meta.landmark_size_mm;
  agv::vision::VisionConfig cfg;  // defaults, no clock: timings stay 0
  agv::vision::LandmarkLocalizer loc(cfg, rec.meta.camera, geometry, nullptr);

  // Warm-up pass: first-call initialisation stays out of the measurement; classifies frames.
  std::vector<size_t> selected;
  size_t n_ok = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    agv::vision::LandmarkFix fix;
    const bool ok = loc.process(frames[i], &fix) == agv::vision::FixStatus::kOk;
    n_ok += ok ? 1 : 0;
    if (cls == "all" || (cls == "ok") == ok) selected.push_back(i);
  }
  size_t n_ok_measured = 0;
  for (size_t i : selected) {
    agv::vision::LandmarkFix fix;
    prctl(static_cast<int>(kMarkerOn), 0UL, 0UL, 0UL, 0UL);
    const int status = agv_cost_frame(&loc, &frames[i], &fix);
    prctl(static_cast<int>(kMarkerOff), 0UL, 0UL, 0UL, 0UL);
    n_ok_measured += status == static_cast<int>(agv::vision::FixStatus::kOk) ? 1 : 0;
  }
  std::printf("vision_cost: %zu frames loaded (%zu ok), class %s: %zu measured (%zu ok), %dx%d\n",
              frames.size(), n_ok, cls.c_str(), selected.size(), n_ok_measured,
              frames.empty() ? 0 : frames[0].cols, frames.empty() ? 0 : frames[0].rows);
  return selected.empty() ? 1 : 0;
}

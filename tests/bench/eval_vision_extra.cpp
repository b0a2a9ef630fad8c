// eval_vision: the AprilTag 3 comparison and the ablation rows.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "eval_vision.hpp"

#ifdef AGV_HAVE_APRILTAG
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
#endif

namespace eval_vision {

#ifdef AGV_HAVE_APRILTAG
namespace {

// A tag36h11 tag whose black border square has the landmark's outer size, painted onto a frame
// (area-sampled 4x4) at the landmark's pose, before nothing else: used on clean frames.
// A tag36h11 tag whose black border square has the landmark's outer size, painted onto a frame
// (area-sampled 4x4) at the landmark's pose, before nothing else: used on clean frames.
struct AprilTagBench {
  apriltag_family_t* fam = tag36h11_create();
  apriltag_detector_t* det = apriltag_detector_create();
  image_u8_t* tag = nullptr;
  AprilTagBench() {
    apriltag_detector_add_family(det, fam);
    det->quad_decimate = 2.0f;
    det->nthreads = 1;
    tag = apriltag_to_image(fam, 0);
  }
  ~AprilTagBench() {
    // The tag image (image_u8_create) is not freed: libapriltag does not export image_u8_destroy.
    apriltag_detector_destroy(det);
    tag36h11_destroy(fam);
  }
  // Paints the tag (outer black square = size_mm) centred at the landmark pose.
  void paint(cv::Mat* img, const CameraModel& cam, const Pose2& landmark_in_vehicle, double size_mm,
             double white, double black) const {
    const int tw = fam->total_width, bw = fam->width_at_border;
    const double cell = size_mm / bw;
    const double half_total = cell * tw / 2.0;
    const Pose2 v_to_l = inverse(landmark_in_vehicle);
    for (int y = 0; y < img->rows; ++y) {
      for (int x = 0; x < img->cols; ++x) {
        Vec2 pv;
        if (!cam.pixel_to_vehicle({static_cast<double>(x), static_cast<double>(y)}, &pv)) continue;
        const Vec2 pl = transform(v_to_l, pv);
        if (std::abs(pl.x) > half_total + 2 || std::abs(pl.y) > half_total + 2) continue;
        double acc = 0;
        int cnt = 0, inside = 0;
        for (int sy = 0; sy < 4; ++sy) {
          for (int sx = 0; sx < 4; ++sx) {
            Vec2 q;
            if (!cam.pixel_to_vehicle({x - 0.375 + 0.25 * sx, y - 0.375 + 0.25 * sy}, &q)) continue;
            const Vec2 l = transform(v_to_l, q);
            const Vec2 uv = landmark_to_page(l);
            const int cu = static_cast<int>(std::floor((uv.x + half_total) / cell));
            const int cv_ = static_cast<int>(std::floor((uv.y + half_total) / cell));
            ++cnt;
            if (cu < 0 || cv_ < 0 || cu >= tw || cv_ >= tw) {
              acc += img->at<std::uint8_t>(y, x);
              continue;
            }
            ++inside;
            const bool w = tag->buf[cv_ * tag->stride + cu] > 127;
            acc += w ? white : black;
          }
        }
        if (inside > 0 && cnt > 0) {
          img->at<std::uint8_t>(y, x) = cv::saturate_cast<std::uint8_t>(acc / cnt);
        }
      }
    }
  }
};

}  // namespace
#endif

void run_apriltag(const Setup& su, const std::vector<Frame>& clean_frames, LandmarkLocalizer& loc,
                  const Stats& s, double ours_ms, std::uint64_t seed) {
#ifdef AGV_HAVE_APRILTAG
  const CameraModel& cam = su.cam;
  const LandmarkGeometry& geom = su.geom;
  const sim::Scene& scene = su.scene;
  const double ours = ours_ms;
  AprilTagBench at;
  sim::Scene empty = scene;
  empty.landmarks.clear();
  sim::FrameRenderer r(empty, cam);
  std::mt19937_64 rng(seed * 1000 + 99);
  std::vector<double> t_at, pos_at, head_at;
  int found = 0, n = 0;
  for (const Frame& f : clean_frames) {
    sim::RenderOptions o;
    cv::Mat img = r.render(f.vehicle_world, o, rng);
    at.paint(&img, cam, inverse(f.e_true), geom.size_mm, scene.paper_white, scene.ink_black);
    image_u8_t im{img.cols, img.rows, static_cast<std::int32_t>(img.step[0]), img.data};
    ++n;
    double best = 1e9;
    for (int rep = 0; rep < 3; ++rep) {
      const std::int64_t t0 = now_ns();
      zarray_t* dets = apriltag_detector_detect(at.det, &im);
      const std::int64_t t1 = now_ns();
      best = std::min(best, (t1 - t0) * 1e-6);
      if (rep == 2 && zarray_size(dets) > 0) {
        apriltag_detection_t* d;
        zarray_get(dets, 0, &d);
        ++found;
        Vec2 cv_mm;
        cam.pixel_to_vehicle({d->c[0], d->c[1]}, &cv_mm);
        const Pose2 l_in_v = inverse(f.e_true);
        pos_at.push_back(std::hypot(cv_mm.x - l_in_v.x_mm, cv_mm.y - l_in_v.y_mm));
        // Heading modulo 90 deg from the four quad edges (mean of the reduced angles).
        double sum = 0;
        for (int k = 0; k < 4; ++k) {
          Vec2 p0, p1;
          cam.pixel_to_vehicle({d->p[k][0], d->p[k][1]}, &p0);
          cam.pixel_to_vehicle({d->p[(k + 1) % 4][0], d->p[(k + 1) % 4][1]}, &p1);
          const double ang = std::atan2(p1.y - p0.y, p1.x - p0.x);
          const double q = std::round((ang - l_in_v.theta_rad) / (kPi / 2));
          sum += ang - q * kPi / 2 - l_in_v.theta_rad;
        }
        head_at.push_back(std::abs(rad_to_deg(sum / 4)));
      }
      apriltag_detections_destroy(dets);
    }
    t_at.push_back(best);
  }
  // Our pipeline: also the best of 3 per frame, to compare like with like.
  std::vector<double> ours_best;
  LandmarkFix fix;
  for (const Frame& f : clean_frames) {
    double best = 1e9;
    for (int rep = 0; rep < 3; ++rep) {
      const std::int64_t t0 = now_ns();
      loc.process(f.img, &fix);
      best = std::min(best, (now_ns() - t0) * 1e-6);
    }
    ours_best.push_back(best);
  }
  std::printf(
      "\n## AprilTag 3 (tag36h11, quad_decimate 2, 1 thread), same clean frames with a tag of "
      "the same outer size\n\n");
  std::printf(
      "| | detected | median time (ms) | pos p50 / p95 (mm) | heading mod 90 p50 / p95 (deg) "
      "|\n|---|---|---|---|---|\n");
  std::printf("| AprilTag 3 detection | %.1f %% | %.3f | %.3f / %.3f | %.4f / %.4f |\n",
              100.0 * found / std::max(1, n), pct(t_at, 50), pct(pos_at, 50), pct(pos_at, 95),
              pct(head_at, 50), pct(head_at, 95));
  std::printf(
      "| this pipeline, full (detect+decode+pose+direction) | %.1f %% | %.3f | %.3f / %.3f | "
      "%.4f / %.4f |\n",
      100.0 * s.ok / std::max(1, s.n), pct(ours_best, 50), pct(s.pos_err, 50), pct(s.pos_err, 95),
      pct(s.head_err, 50), pct(s.head_err, 95));
  std::printf(
      "\nSpeed ratio AprilTag / ours (medians, best of 3 per frame): %.2fx (ours with "
      "per-stage clock: %.3f ms)\n",
      pct(t_at, 50) / pct(ours_best, 50), ours);
#else
  (void)su;
  (void)clean_frames;
  (void)loc;
  (void)s;
  (void)ours_ms;
  (void)seed;
#endif
}

void run_ablation(const Setup& su, const std::vector<Frame>& clean_frames,
                  const std::vector<Frame>& combined_frames) {
  const VisionConfig& cfg = su.cfg;
  const CameraModel& cam = su.cam;
  const CameraModel& cam_dist = su.cam_dist;
  const LandmarkGeometry& geom = su.geom;
  const LandmarkMap& map = su.map;
  std::printf("\n## Ablation (same frames; each row adds one change to the paper baseline)\n\n");
  struct Variant {
    const char* name;
    std::function<void(VisionConfig*)> set;
  };
  auto paper = [](VisionConfig* c) {
    c->metric = MetricMode::kLinearRatio;
    c->pose_method = PoseMethod::kPaperCornerA;
    c->heading_method = HeadingMethod::kMean;
    c->subpixel = false;
    c->robust = false;
  };
  std::vector<Variant> vars = {
      {"Li et al. (eq. 7, corner A eq. 8-11, one mm/px ratio, pixel edges)", paper},
      {"+ Yang et al. weighted heading (eq. 10-11)",
       [&](VisionConfig* c) {
         paper(c);
         c->heading_method = HeadingMethod::kWeighted000;
       }},
      {"+ inverse-variance heading",
       [&](VisionConfig* c) {
         paper(c);
         c->heading_method = HeadingMethod::kInverseVariance;
       }},
      {"+ subpixel edges",
       [&](VisionConfig* c) {
         paper(c);
         c->heading_method = HeadingMethod::kInverseVariance;
         c->subpixel = true;
       }},
      {"+ corners as line intersections",
       [&](VisionConfig* c) {
         paper(c);
         c->heading_method = HeadingMethod::kInverseVariance;
         c->subpixel = true;
         c->pose_method = PoseMethod::kLineIntersections;
       }},
      {"+ joint square fit",
       [&](VisionConfig* c) {
         paper(c);
         c->subpixel = true;
         c->pose_method = PoseMethod::kJointSquareFit;
       }},
      {"+ robust (Tukey IRLS)",
       [&](VisionConfig* c) {
         paper(c);
         c->subpixel = true;
         c->pose_method = PoseMethod::kJointSquareFit;
         c->robust = true;
       }},
      {"+ camera model per edge point (= default)", [](VisionConfig*) {}},
  };
  for (int set = 0; set < 2; ++set) {
    const auto& frames = set == 0 ? clean_frames : combined_frames;
    const CameraModel& cm = set == 0 ? cam : cam_dist;
    std::printf("\n### %s\n\n", set == 0 ? "clean" : "all degradations combined (distorted lens)");
    print_header();
    for (const Variant& v : vars) {
      VisionConfig c = cfg;
      v.set(&c);
      LandmarkLocalizer loc(c, cm, geom, &map);
      Stats s;
      evaluate(loc, frames, &s);
      print_row(v.name, s);
    }
  }
}

}  // namespace eval_vision

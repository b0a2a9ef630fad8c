// LandmarkLocalizer::process on mutated real frames: the four golden frames of
// tests/data/vision (640x480, landmark 17 in a one-landmark map). The first byte picks the frame;
// every further 6 bytes paint (or XOR) one rectangle of up to 16x16 pixels, at most 32 of them.
// Bits 2-3 of the first byte choose the prediction (docs/design/tracking.md): none, the unmutated
// fix's pose with a tight covariance (tracked detection, windows, map-guided identity of a damaged
// code), or that pose 40 mm and 30 degrees off with the same tight covariance (a wrong trusted
// prediction: the fallbacks).
// Property: the fix from a mutated frame is either absent (any status but kOk) or consistent with
// the unmutated frame's fix: same landmark, finite pose and covariance, within 5 mm and 2 degrees
// plus four of its own reported standard deviations.
#include <cmath>
#include <string>
#include <vector>

#include "agv/recording/png_io.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "fuzz_check.hpp"

using namespace agv;

namespace {

struct Base {
  cv::Mat image;
  vision::LandmarkFix fix;
};

struct World {
  LandmarkMap map;
  std::vector<Base> bases;
  std::unique_ptr<vision::LandmarkLocalizer> loc;
  cv::Mat work;
};

World& world() {
  static World* w = [] {
    auto* x = new World;
    x->map.entries[17] = {17, {1000.0, -2000.0, deg_to_rad(90.0)}};
    x->loc = std::make_unique<vision::LandmarkLocalizer>(
        vision::VisionConfig{}, CameraModel::default_640x480(), LandmarkGeometry{}, &x->map);
    for (const char* name : {"golden_clean", "golden_realistic", "golden_damaged", "golden_cut"}) {
      Base b;
      std::string err;
      const std::string path = std::string(AGV_SOURCE_DIR) + "/tests/data/vision/" + name + ".png";
      FUZZ_CHECK(png::read_gray(path, &b.image, &err, 640, 480), "%s", err.c_str());
      x->loc->process(b.image, &b.fix);
      FUZZ_CHECK(b.fix.status == vision::FixStatus::kOk, "%s: reference fix %s", name,
                 vision::to_string(b.fix.status));
      // The prediction modes must reach the windowed paths on the unmutated frame.
      vision::Prediction p;
      p.valid = true;
      p.vehicle_in_world = b.fix.vehicle_in_world;
      p.cov = Eigen::Vector3d(9.0, 9.0, 1e-4).asDiagonal();
      vision::LandmarkFix f;
      x->loc->process(b.image, p, &f);
      FUZZ_CHECK(f.status == vision::FixStatus::kOk && f.search == vision::SearchMode::kWindow,
                 "%s: predicted fix %s, search %d", name, vision::to_string(f.status),
                 static_cast<int>(f.search));
      x->bases.push_back(b);
    }
    return x;
  }();
  return *w;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  if (size < 1) return 0;
  World& w = world();
  const Base& base = w.bases[data[0] % w.bases.size()];
  vision::Prediction pred;
  const int pred_mode = (data[0] >> 2) & 3;
  if (pred_mode != 0) {
    pred.valid = true;
    pred.vehicle_in_world = base.fix.vehicle_in_world;
    if (pred_mode == 3) {
      pred.vehicle_in_world.x_mm += 40.0;
      pred.vehicle_in_world.theta_rad += deg_to_rad(30.0);
    }
    const double s_rad = deg_to_rad(0.3);
    pred.cov = Eigen::Vector3d(9.0, 9.0, s_rad * s_rad).asDiagonal();
  }
  base.image.copyTo(w.work);
  int ops = 0;
  for (std::size_t at = 1; at + 6 <= size && ops < 32; at += 6, ++ops) {
    const unsigned char* b = data + at;
    const int x = ((b[0] | (b[1] & 0x7F) << 8)) % w.work.cols;
    const int y = (b[2] | b[3] << 8) % w.work.rows;
    const int rw = std::min(1 + (b[4] & 15), w.work.cols - x);
    const int rh = std::min(1 + (b[4] >> 4), w.work.rows - y);
    cv::Mat roi = w.work(cv::Rect(x, y, rw, rh));
    if (b[1] & 0x80) {
      cv::bitwise_xor(roi, cv::Scalar(b[5]), roi);
    } else {
      roi.setTo(cv::Scalar(b[5]));
    }
  }
  vision::LandmarkFix fix;
  const vision::FixStatus st = w.loc->process(w.work, pred, &fix);
  FUZZ_CHECK(st == fix.status && vision::to_string(st) != nullptr, "status");
  if (st != vision::FixStatus::kOk) return 0;
  const Pose2& a = base.fix.vehicle_in_world;
  const Pose2& m = fix.vehicle_in_world;
  FUZZ_CHECK(fix.landmark_id == base.fix.landmark_id, "landmark %u instead of %u", fix.landmark_id,
             base.fix.landmark_id);
  FUZZ_CHECK(std::isfinite(m.x_mm) && std::isfinite(m.y_mm) && std::isfinite(m.theta_rad) &&
                 fix.cov_world.allFinite(),
             "non-finite fix");
  const double sigma_pos = std::sqrt(std::max(0.0, fix.cov_world(0, 0) + fix.cov_world(1, 1)));
  const double sigma_th = std::sqrt(std::max(0.0, fix.cov_world(2, 2)));
  const double dpos = std::hypot(m.x_mm - a.x_mm, m.y_mm - a.y_mm);
  const double dth = std::abs(wrap_angle_rad(m.theta_rad - a.theta_rad));
  FUZZ_CHECK(dpos <= 5.0 + 4.0 * sigma_pos && dth <= deg_to_rad(2.0) + 4.0 * sigma_th,
             "fix moved %.3f mm (sigma %.3f) and %.3f deg (sigma %.3f) from the unmutated frame's",
             dpos, sigma_pos, rad_to_deg(dth), rad_to_deg(sigma_th));
  return 0;
}

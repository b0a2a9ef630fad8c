// make_tray_dataset: rendered ceiling-camera frames of random fleets cut into rectified windows
// of the tray plane (the detector's input, tray_net.hpp), with every tray's oriented box, for
// train.py. tools/train/tray_obb/README.md has the commands.
//
//   make_tray_dataset --out DIR --split train|test --frames N [--seed S] [--crop 128]
//                     [--mm-per-px 8] [--tray-length-mm 600 --tray-width-mm 400
//                      --tray-height-mm 400] [--overhang F: vehicles with a parcel overhanging the
//                      tray]
//
// Writes DIR/crops/NNNNNN.png (8-bit gray, crop x crop), DIR/crops.csv
// (file,frame,camera_height_mm,native_mm_per_px,lighting) and DIR/boxes.csv
// (file,cx,cy,length,width,angle_deg,full): a row per tray whose centre lies in the crop, in the
// crop's pixels (pixel centres at integers), the long axis's angle in [0, 180) degrees, x right,
// y down; full = 0 for a tray not wholly in the camera's frame (to be ignored, not learned).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <string>

#include "agv/overhead/tray_net.hpp"
#include "tray_scene.hpp"

namespace {

using namespace agv;

struct Args {
  std::string out;
  tray_obb::Split split = tray_obb::Split::kTrain;
  int frames = 100;
  std::uint64_t seed = 1;
  int crop = 128;
  double mm_per_px = 8.0;
  tray_obb::SceneOptions scene;
};

[[noreturn]] void usage(const std::string& why) {
  std::fprintf(stderr,
               "make_tray_dataset: %s\nusage: make_tray_dataset --out DIR --split train|test "
               "--frames N [--seed S] [--crop 128] [--mm-per-px 8] [--tray-length-mm 600] "
               "[--tray-width-mm 400] [--tray-height-mm 400] [--overhang 0]\n",
               why.c_str());
  std::exit(2);
}

Args parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    if (i + 1 >= argc) usage("missing value for " + k);
    const std::string v = argv[++i];
    try {
      if (k == "--out")
        a.out = v;
      else if (k == "--split" && (v == "train" || v == "test"))
        a.split = v == "train" ? tray_obb::Split::kTrain : tray_obb::Split::kTest;
      else if (k == "--frames")
        a.frames = std::stoi(v);
      else if (k == "--seed")
        a.seed = std::stoull(v);
      else if (k == "--crop")
        a.crop = std::stoi(v);
      else if (k == "--mm-per-px")
        a.mm_per_px = std::stod(v);
      else if (k == "--tray-length-mm")
        a.scene.tray_length_mm = std::stod(v);
      else if (k == "--tray-width-mm")
        a.scene.tray_width_mm = std::stod(v);
      else if (k == "--tray-height-mm")
        a.scene.tray_height_mm = std::stod(v);
      else if (k == "--overhang")
        a.scene.overhang_fraction = std::stod(v);
      else
        usage("unknown option or value: " + k + " " + v);
    } catch (const std::exception&) {
      usage("bad value for " + k + ": " + v);
    }
  }
  if (a.out.empty() || a.frames < 1 || a.crop < 32 || a.crop % 8 != 0 || !(a.mm_per_px > 0.0)) {
    usage("--out, --frames >= 1, --crop a multiple of 8 and >= 32, --mm-per-px > 0 needed");
  }
  return a;
}

// Window angle of the tray's long axis, [0, 180) degrees (window y runs against site y).
double window_angle_deg(double heading_rad, bool long_is_x) {
  const double axis = long_is_x ? heading_rad : heading_rad + 0.5 * kPi;
  double a = std::fmod(rad_to_deg(-axis), 180.0);
  if (a < 0.0) a += 180.0;
  return a >= 180.0 ? a - 180.0 : a;
}

}  // namespace

int main(int argc, char** argv) {
  const Args a = parse(argc, argv);
  namespace fs = std::filesystem;
  fs::create_directories(fs::path(a.out) / "crops");
  std::ofstream crops(fs::path(a.out) / "crops.csv"), boxes(fs::path(a.out) / "boxes.csv");
  if (!crops || !boxes) usage("cannot write in " + a.out);
  crops << "file,frame,camera_height_mm,native_mm_per_px,lighting\n";
  boxes << "file,cx,cy,length,width,angle_deg,full\n";
  std::mt19937_64 rng(a.seed * 7919 + (a.split == tray_obb::Split::kTest ? 1 : 0));
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const bool long_is_x = a.scene.tray_length_mm >= a.scene.tray_width_mm;
  const double tray_long = std::max(a.scene.tray_length_mm, a.scene.tray_width_mm);
  const double tray_short = std::min(a.scene.tray_length_mm, a.scene.tray_width_mm);
  int written = 0, labelled = 0;
  for (int f = 0; f < a.frames; ++f) {
    const std::uint64_t seed = a.seed * 1000003ULL + static_cast<std::uint64_t>(f) +
                               (a.split == tray_obb::Split::kTest ? 500000ULL : 0ULL);
    const tray_obb::SceneDraw d = tray_obb::draw_scene(seed, a.split, a.scene);
    const sim::RenderResult r =
        sim::render_site_frame(d.scene, sim::RenderCamera::from_ceiling(d.cam), d.render, seed);
    // Windows: one around each tray (its centre anywhere in the window), two anywhere in view.
    std::vector<Vec2> centres;
    const double reach = 0.5 * a.crop * a.mm_per_px - 0.6 * tray_long;
    for (const sim::AgvTruth& t : r.agvs) {
      centres.push_back(
          {t.pose.x_mm + reach * (2.0 * u(rng) - 1.0), t.pose.y_mm + reach * (2.0 * u(rng) - 1.0)});
    }
    for (int k = 0; k < 2; ++k) {
      Vec2 px{u(rng) * d.cam.intrinsics.width_px, u(rng) * d.cam.intrinsics.height_px}, xy;
      if (overhead::pixel_to_plane(d.cam, px, a.scene.tray_height_mm, &xy)) centres.push_back(xy);
    }
    for (const Vec2& c : centres) {
      overhead::RectifiedWindow w;
      if (!overhead::rectify_window(r.image, d.cam, c, a.scene.tray_height_mm, a.crop, a.mm_per_px,
                                    &w) ||
          w.inside_fraction < 0.5) {
        continue;
      }
      char name[32];
      std::snprintf(name, sizeof name, "%06d.png", written);
      cv::imwrite((fs::path(a.out) / "crops" / name).string(), w.gray);
      crops << name << ',' << f << ',' << d.camera_height_mm << ',' << d.native_mm_per_px << ','
            << d.lighting << '\n';
      for (const sim::AgvTruth& t : r.agvs) {
        const Vec2 p = overhead::plane_to_window(w, {t.pose.x_mm, t.pose.y_mm});
        if (!(p.x >= -0.5 && p.y >= -0.5 && p.x < a.crop - 0.5 && p.y < a.crop - 0.5)) continue;
        const bool full =
            tray_obb::tray_in_frame(t, d.cam.intrinsics.width_px, d.cam.intrinsics.height_px);
        boxes << name << ',' << p.x << ',' << p.y << ',' << tray_long / a.mm_per_px << ','
              << tray_short / a.mm_per_px << ',' << window_angle_deg(t.pose.theta_rad, long_is_x)
              << ',' << (full ? 1 : 0) << '\n';
        labelled += full ? 1 : 0;
      }
      ++written;
    }
    if ((f + 1) % 50 == 0) std::fprintf(stderr, "%d frames, %d crops\n", f + 1, written);
  }
  std::printf("%d frames -> %d crops, %d trays labelled, in %s\n", a.frames, written, labelled,
              a.out.c_str());
  return 0;
}

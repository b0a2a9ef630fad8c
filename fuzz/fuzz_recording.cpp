// One file of a recording (docs/guide/recording.md), chosen at compile time by AGV_FUZZ_FILE:
// 0 meta.yaml, 1 frames.csv, 2 odom.csv, 3 truth.csv. Properties: a rejected file names itself
// and a line; an accepted one has strictly increasing times in [0, kMaxTimeNs], values in the
// documented ranges, frame paths that cannot escape the recording directory, and the writer's
// text for it parses back to the same rows (exactly for meta and frames, to the written
// resolution for odom and truth).
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "agv/recording/recording.hpp"
#include "fuzz_check.hpp"

namespace rec = agv::recording;

namespace {

template <typename Row>
void check_times(const std::vector<Row>& rows) {
  for (std::size_t i = 0; i < rows.size(); ++i) {
    FUZZ_CHECK(rows[i].t_ns >= 0 && rows[i].t_ns <= rec::kMaxTimeNs, "row %zu t_ns %lld", i,
               static_cast<long long>(rows[i].t_ns));
    FUZZ_CHECK(i == 0 || rows[i].t_ns > rows[i - 1].t_ns, "row %zu not after the previous", i);
  }
}

bool close(double a, double b, double abs_tol, double rel_tol) {
  return std::abs(a - b) <= abs_tol + rel_tol * std::abs(a);
}

void check_error(const std::string& error, const char* name) {
  FUZZ_CHECK(error.rfind(std::string(name) + ":", 0) == 0, "error must start with '%s:': %s", name,
             error.c_str());
}

void meta(const std::string& text) {
  rec::Meta m;
  std::string error;
  if (!rec::parse_meta_yaml(text, &m, &error)) return check_error(error, "meta.yaml");
  const auto& k = m.camera.intrinsics;
  FUZZ_CHECK(k.width_px >= 1 && k.width_px <= 16384 && k.height_px >= 1 && k.height_px <= 16384,
             "image %dx%d", k.width_px, k.height_px);
  FUZZ_CHECK(k.fx >= 1 && k.fy >= 1 && std::isfinite(m.camera.mm_per_px()), "focal lengths");
  const std::string back = rec::format_meta_yaml(m);
  rec::Meta m2;
  FUZZ_CHECK(rec::parse_meta_yaml(back, &m2, &error), "written meta rejected: %s", error.c_str());
  const auto& k2 = m2.camera.intrinsics;
  FUZZ_CHECK(k2.width_px == k.width_px && k2.height_px == k.height_px && k2.fx == k.fx &&
                 k2.fy == k.fy && k2.cx == k.cx && k2.cy == k.cy && k2.k1 == k.k1 &&
                 k2.k2 == k.k2 && k2.p1 == k.p1 && k2.p2 == k.p2 && k2.k3 == k.k3 &&
                 m2.landmark_size_mm == m.landmark_size_mm && m2.source == m.source &&
                 m2.camera.mount.height_mm == m.camera.mount.height_mm &&
                 m2.camera.mount.offset_x_mm == m.camera.mount.offset_x_mm &&
                 m2.camera.mount.offset_y_mm == m.camera.mount.offset_y_mm &&
                 close(m2.camera.mount.yaw_rad, m.camera.mount.yaw_rad, 1e-12, 0),
             "meta changed in a write/read round trip");
}

void frames(const std::string& text) {
  std::vector<rec::FrameRow> rows;
  std::string error;
  if (!rec::parse_frames_csv(text, &rows, &error)) return check_error(error, "frames.csv");
  check_times(rows);
  const std::filesystem::path dir = "/recording";
  for (const auto& r : rows) {
    // No path escapes the recording: lexically below it, whatever the file name.
    const std::string p = (dir / r.file).lexically_normal().string();
    FUZZ_CHECK(p.rfind("/recording/", 0) == 0 && p.size() > 11, "'%s' escapes as '%s'",
               r.file.c_str(), p.c_str());
    FUZZ_CHECK(r.file.find('\0') == std::string::npos, "NUL in '%s'", r.file.c_str());
  }
  std::string back;
  FUZZ_CHECK(rec::format_frames_csv(rows, &back, &error), "accepted rows cannot be written: %s",
             error.c_str());
  std::vector<rec::FrameRow> rows2;
  FUZZ_CHECK(rec::parse_frames_csv(back, &rows2, &error), "written frames.csv rejected: %s",
             error.c_str());
  FUZZ_CHECK(rows2.size() == rows.size(), "row count");
  for (std::size_t i = 0; i < rows.size(); ++i) {
    FUZZ_CHECK(rows2[i].t_ns == rows[i].t_ns && rows2[i].file == rows[i].file, "row %zu", i);
  }
}

void odom(const std::string& text) {
  std::vector<rec::OdomRow> rows;
  std::string error;
  if (!rec::parse_odom_csv(text, &rows, &error)) return check_error(error, "odom.csv");
  check_times(rows);
  for (const auto& r : rows) {
    FUZZ_CHECK(std::abs(r.v_mps) <= 20 && std::abs(r.omega_radps) <= 20, "odometry range");
  }
  std::vector<rec::OdomRow> rows2;
  FUZZ_CHECK(rec::parse_odom_csv(rec::format_odom_csv(rows), &rows2, &error),
             "written odom.csv rejected: %s", error.c_str());
  FUZZ_CHECK(rows2.size() == rows.size(), "row count");
  for (std::size_t i = 0; i < rows.size(); ++i) {
    FUZZ_CHECK(rows2[i].t_ns == rows[i].t_ns &&
                   close(rows[i].v_mps, rows2[i].v_mps, 1e-300, 1e-8) &&
                   close(rows[i].omega_radps, rows2[i].omega_radps, 1e-300, 1e-8),
               "row %zu: %.17g %.17g -> %.17g %.17g", i, rows[i].v_mps, rows[i].omega_radps,
               rows2[i].v_mps, rows2[i].omega_radps);
  }
}

// The writer rounds the heading to 1e-6 deg: a value exactly on a half step (x.xxxxxx5) is off by
// 5e-7 plus the representation error of a double near 180 (~3e-14), so the bound carries a margin.
constexpr double kHalfMicroDeg = 5e-7 + 1e-10;

void truth(const std::string& text) {
  std::vector<rec::TruthRow> rows;
  std::string error;
  if (!rec::parse_truth_csv(text, &rows, &error)) return check_error(error, "truth.csv");
  check_times(rows);
  std::vector<rec::TruthRow> rows2;
  FUZZ_CHECK(rec::parse_truth_csv(rec::format_truth_csv(rows), &rows2, &error),
             "written truth.csv rejected: %s", error.c_str());
  FUZZ_CHECK(rows2.size() == rows.size(), "row count");
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const double dth = std::remainder(rows2[i].theta_deg - rows[i].theta_deg, 360.0);
    FUZZ_CHECK(rows2[i].t_ns == rows[i].t_ns && close(rows[i].x_mm, rows2[i].x_mm, 5e-5, 1e-15) &&
                   close(rows[i].y_mm, rows2[i].y_mm, 5e-5, 1e-15) &&
                   std::abs(dth) <= kHalfMicroDeg,
               "row %zu", i);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  const std::string text(agv::fuzz::as_text(data, size));
  static constexpr void (*kCheck[])(const std::string&) = {meta, frames, odom, truth};
  kCheck[AGV_FUZZ_FILE](text);
  return 0;
}

// Recording format: exact round trip, and every kind of malformed input is rejected with
// "file:line: reason" instead of crashing or being half-accepted.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <random>
#include <sstream>

#include "../support/fresh_dir.hpp"
#include "agv/recording/recording.hpp"

using namespace agv;
using namespace agv::recording;
namespace fs = std::filesystem;

namespace {

fs::path fresh_dir(const std::string& name) {
  return test_support::fresh_dir("recording", name);
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

void spit(const fs::path& p, const std::string& text) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f << text;
}

Meta sample_meta() {
  Meta m;
  m.camera = CameraModel::default_640x480();
  m.camera.intrinsics.width_px = 64;
  m.camera.intrinsics.height_px = 48;
  m.camera.intrinsics.cx = 31.7;
  m.camera.intrinsics.cy = 23.25;
  m.camera.intrinsics.k1 = -0.2134;
  m.camera.intrinsics.k2 = 0.051;
  m.camera.intrinsics.p1 = 1e-4;
  m.camera.intrinsics.p2 = -3e-4;
  m.camera.intrinsics.k3 = -0.01;
  m.camera.mount = {35.5, -12.25, deg_to_rad(3.5), 201.5};
  m.landmark_size_mm = 60.0;
  m.source = "agvloc sim --seed 3 \"quoted\"";
  return m;
}

// Writes a small valid recording and returns its directory.
fs::path write_sample(const std::string& name) {
  const fs::path d = fresh_dir(name);
  std::string err;
  EXPECT_TRUE(write_meta(d.string(), sample_meta(), &err)) << err;
  std::vector<FrameRow> frames;
  for (int i = 0; i < 3; ++i) {
    cv::Mat img(48, 64, CV_8UC1, cv::Scalar(40 * i));
    char f[32];
    std::snprintf(f, sizeof f, "frames/%06d.png", i);
    EXPECT_TRUE(write_frame_png(d.string(), f, img, &err)) << err;
    frames.push_back({1000000000LL + i * 33333333LL, f});
  }
  EXPECT_TRUE(write_frames_csv(d.string(), frames, &err)) << err;
  std::vector<OdomRow> odom;
  std::vector<TruthRow> truth;
  for (int i = 0; i < 10; ++i) {
    odom.push_back({1000000000LL + i * 10000000LL, 0.5 + 0.001 * i, -0.1234567});
    truth.push_back({1000000000LL + i * 10000000LL, 1000.0 + 5.0 * i, -20.125, 179.9999999});
  }
  EXPECT_TRUE(write_odom_csv(d.string(), odom, &err)) << err;
  EXPECT_TRUE(write_truth_csv(d.string(), truth, &err)) << err;
  std::vector<ImuRow> imu;
  for (int i = 0; i < 20; ++i) imu.push_back({1000000000LL + i * 5000000LL, 0.0123456789 * i});
  EXPECT_TRUE(write_imu_csv(d.string(), imu, &err)) << err;
  return d;
}

// Reads and expects failure with a message starting with `prefix` (file:line).
void expect_rejected(const fs::path& d, const std::string& prefix) {
  Recording r;
  std::string err;
  EXPECT_FALSE(read_recording(d.string(), &r, &err));
  EXPECT_EQ(err.rfind(prefix, 0), 0u) << "got: " << err;
}

}  // namespace

TEST(Recording, RoundTrip) {
  const fs::path d = write_sample("roundtrip");
  Recording r;
  std::string err;
  ASSERT_TRUE(read_recording(d.string(), &r, &err)) << err;
  const Meta m = sample_meta();
  const auto& a = r.meta.camera.intrinsics;
  const auto& b = m.camera.intrinsics;
  EXPECT_EQ(a.width_px, b.width_px);
  EXPECT_EQ(a.height_px, b.height_px);
  EXPECT_EQ(a.fx, b.fx);
  EXPECT_EQ(a.cx, b.cx);
  EXPECT_EQ(a.cy, b.cy);
  EXPECT_EQ(a.k1, b.k1);
  EXPECT_EQ(a.k2, b.k2);
  EXPECT_EQ(a.p1, b.p1);
  EXPECT_EQ(a.p2, b.p2);
  EXPECT_EQ(a.k3, b.k3);
  EXPECT_EQ(r.meta.camera.mount.offset_x_mm, m.camera.mount.offset_x_mm);
  EXPECT_EQ(r.meta.camera.mount.offset_y_mm, m.camera.mount.offset_y_mm);
  EXPECT_EQ(r.meta.camera.mount.height_mm, m.camera.mount.height_mm);
  EXPECT_NEAR(r.meta.camera.mount.yaw_rad, m.camera.mount.yaw_rad, 1e-15);
  EXPECT_EQ(r.meta.landmark_size_mm, 60.0);
  EXPECT_EQ(r.meta.source, m.source);
  ASSERT_EQ(r.frames.size(), 3u);
  EXPECT_EQ(r.frames[2].t_ns, 1000000000LL + 2 * 33333333LL);
  EXPECT_EQ(r.frames[1].file, "frames/000001.png");
  ASSERT_EQ(r.odom.size(), 10u);
  EXPECT_EQ(r.odom[9].t_ns, 1090000000LL);
  EXPECT_NEAR(r.odom[9].v_mps, 0.509, 1e-12);
  EXPECT_NEAR(r.odom[3].omega_radps, -0.1234567, 1e-12);
  ASSERT_TRUE(r.has_truth);
  ASSERT_EQ(r.truth.size(), 10u);
  EXPECT_NEAR(r.truth[4].x_mm, 1020.0, 1e-9);
  EXPECT_NEAR(r.truth[4].y_mm, -20.125, 1e-9);
  EXPECT_NEAR(r.truth[4].theta_deg, 180.0, 1e-6);  // 179.9999999 rounds to 180, stays in range
  cv::Mat img;
  ASSERT_TRUE(load_frame(r, 2, &img, &err)) << err;
  EXPECT_EQ(img.at<std::uint8_t>(5, 5), 80);
  EXPECT_FALSE(load_frame(r, 3, &img, &err));
  // truth.csv is optional.
  fs::remove(d / "truth.csv");
  ASSERT_TRUE(read_recording(d.string(), &r, &err)) << err;
  EXPECT_FALSE(r.has_truth);
  EXPECT_TRUE(r.truth.empty());
  fs::remove_all(d);
}

TEST(Recording, WrongImageSizeRejectedOnLoad) {
  const fs::path d = write_sample("imgsize");
  std::string err;
  ASSERT_TRUE(write_frame_png(d.string(), "frames/000001.png",
                              cv::Mat(10, 10, CV_8UC1, cv::Scalar(0)), &err));
  Recording r;
  ASSERT_TRUE(read_recording(d.string(), &r, &err)) << err;
  cv::Mat img;
  EXPECT_FALSE(load_frame(r, 1, &img, &err));
  EXPECT_EQ(err.rfind("frames.csv:3:", 0), 0u) << err;
  fs::remove_all(d);
}

TEST(Recording, MalformedCsvRejectedWithFileAndLine) {
  struct Case {
    const char* file;
    std::string text;
    const char* prefix;
  };
  const std::vector<Case> cases = {
      {"frames.csv", "t,file\n1,frames/000000.png\n", "frames.csv:1:"},
      {"frames.csv", "", "frames.csv:1:"},
      {"frames.csv", "t_ns,file\n1000000000,frames/000000.png\n1000000000,frames/000001.png\n",
       "frames.csv:3:"},
      {"frames.csv", "t_ns,file\n1000000000,frames/000000.png\n999,frames/000001.png\n",
       "frames.csv:3:"},
      {"frames.csv", "t_ns,file\n1000000000,frames/nope.png\n1000000001,frames/000001.png\n",
       "frames.csv:2:"},
      {"frames.csv", "t_ns,file\n1000000000,../etc/passwd\n", "frames.csv:2:"},
      {"frames.csv", "t_ns,file\n1e9,frames/000000.png\n", "frames.csv:2:"},
      {"frames.csv", "t_ns,file\n1000000000,frames/000000.png,x\n", "frames.csv:2:"},
      {"frames.csv", "t_ns,file\n1000000000,frames/000000.png\n\n", "frames.csv:3:"},
      {"frames.csv", "t_ns,file\n-5,frames/000000.png\n", "frames.csv:2:"},
      {"odom.csv", "t_ns,v_mps,omega_radps\n1,0.5,0.1\n2,abc,0.1\n", "odom.csv:3:"},
      {"odom.csv", "t_ns,v_mps,omega_radps\n1,0.5,0.1\n2,0.5,nan\n", "odom.csv:3:"},
      {"odom.csv", "t_ns,v_mps,omega_radps\n1,0.5,0.1\n2,0.5\n", "odom.csv:3:"},
      {"odom.csv", "t_ns,v_mps,om", "odom.csv:1:"},  // the header itself cut
      {"odom.csv", "t_ns,v_mps,omega_radps\n1,0.5,0.1\n1,0.5,0.1\n", "odom.csv:3:"},
      {"odom.csv", "t_ns,v_mps,omega_radps\n1,99,0.1\n", "odom.csv:2:"},
      {"odom.csv", "t_ns,v_mps,omega_radps\n1, 0.5,0.1\n", "odom.csv:2:"},
      {"odom.csv", "t_ns,v_mps\n1,0.5\n", "odom.csv:1:"},
      {"odom.csv", "t_ns,v_mps,omega_radps\n99999999999999999999,0.5,0.1\n", "odom.csv:2:"},
      {"odom.csv", std::string("t_ns,v_mps,omega_radps\n1,0.5,0.1\n2,0.\0,0.1\n", 43),
       "odom.csv:3:"},
      {"truth.csv", "t_ns,x_mm,y_mm,theta_deg\n1,0,0,-180\n", "truth.csv:2:"},
      {"truth.csv", "t_ns,x_mm,y_mm,theta_deg\n1,0,0,0\n2,0,0,0\n0,0,0,0\n", "truth.csv:4:"},
  };
  for (const Case& c : cases) {
    const fs::path d = write_sample("csv");
    spit(d / c.file, c.text);
    SCOPED_TRACE(std::string(c.file) + " <<" + c.text + ">>");
    expect_rejected(d, c.prefix);
    fs::remove_all(d);
  }
}

// A recording cut by a power loss: each CSV's last line may lack its newline. Everything before
// it replays; the cut line is dropped (never parsed: "2,0.5,0.1" may be "2,0.5,0.125" cut short)
// and named in the warnings.
TEST(Recording, ACutLastLineIsDroppedWithAWarning) {
  const fs::path d = write_sample("cut");
  spit(d / "odom.csv", "t_ns,v_mps,omega_radps\n1,0.5,0.1\n2,0.5,0.1\n3,0.5,0.1");
  spit(d / "imu.csv", "t_ns,gyro_z_radps\n1,0.1\n2,0.");
  agv::recording::Recording r;
  std::string err;
  ASSERT_TRUE(agv::recording::read_recording(d.string(), &r, &err)) << err;
  ASSERT_EQ(r.odom.size(), 2u);
  EXPECT_EQ(r.odom.back().t_ns, 2);
  ASSERT_EQ(r.imu.size(), 1u);
  ASSERT_EQ(r.warnings.size(), 2u);
  EXPECT_EQ(r.warnings[0].rfind("odom.csv:4: last line cut", 0), 0u) << r.warnings[0];
  EXPECT_EQ(r.warnings[1].rfind("imu.csv:3: last line cut", 0), 0u) << r.warnings[1];
  // The last frames' PNGs lost with them: those rows are dropped and named; one lost before a
  // good frame is an error, and so is a recording whose every frame is lost.
  fs::remove(d / "frames" / "000002.png");
  spit(d / "frames" / "000001.png", "");
  ASSERT_TRUE(agv::recording::read_recording(d.string(), &r, &err)) << err;
  ASSERT_EQ(r.frames.size(), 1u);
  ASSERT_EQ(r.warnings.size(), 3u);
  EXPECT_EQ(r.warnings[0].rfind("frames.csv:3-4: the last 2 frame(s)", 0), 0u) << r.warnings[0];
  fs::remove(d / "frames" / "000000.png");
  EXPECT_FALSE(agv::recording::read_recording(d.string(), &r, &err));
  EXPECT_EQ(err.rfind("frames.csv:2: image", 0), 0u) << err;
  const cv::Mat black(48, 64, CV_8UC1, cv::Scalar(0));
  ASSERT_TRUE(agv::recording::write_frame_png(d.string(), "frames/000000.png", black, &err));
  ASSERT_TRUE(agv::recording::write_frame_png(d.string(), "frames/000002.png", black, &err));
  EXPECT_FALSE(agv::recording::read_recording(d.string(), &r, &err));
  EXPECT_EQ(err.rfind("frames.csv:3: image", 0), 0u) << err;
  ASSERT_TRUE(agv::recording::write_frame_png(d.string(), "frames/000001.png", black, &err));
  // Whole files give no warning; the strict parsers on their own still refuse a cut line.
  spit(d / "odom.csv", "t_ns,v_mps,omega_radps\n1,0.5,0.1\n");
  fs::remove(d / "imu.csv");
  ASSERT_TRUE(agv::recording::read_recording(d.string(), &r, &err)) << err;
  EXPECT_TRUE(r.warnings.empty());
  std::vector<agv::recording::OdomRow> rows;
  EXPECT_FALSE(
      agv::recording::parse_odom_csv("t_ns,v_mps,omega_radps\n1,0.5,0.1\n2,0.5", &rows, &err));
  fs::remove_all(d);
}

TEST(Recording, MissingFilesAndBrokenImages) {
  fs::path d = write_sample("missing");
  fs::remove(d / "frames" / "000001.png");
  expect_rejected(d, "frames.csv:3:");
  fs::remove_all(d);
  d = write_sample("notpng");
  spit(d / "frames" / "000001.png", "GIF89a....");
  expect_rejected(d, "frames.csv:3:");
  fs::remove_all(d);
  d = write_sample("noodom");
  fs::remove(d / "odom.csv");
  expect_rejected(d, "odom.csv:");
  fs::remove_all(d);
  d = write_sample("nometa");
  fs::remove(d / "meta.yaml");
  expect_rejected(d, "meta.yaml:");
  fs::remove_all(d);
  expect_rejected("/nonexistent/agv/recording", "/nonexistent/agv/recording: not a directory");
}

TEST(Recording, MalformedMetaRejectedNamingTheKey) {
  const fs::path d = write_sample("meta");
  const std::string good = slurp(d / "meta.yaml");
  auto replace = [&](const std::string& from, const std::string& to) {
    std::string s = good;
    const size_t p = s.find(from);
    EXPECT_NE(p, std::string::npos) << from;
    return s.replace(p, from.size(), to);
  };
  struct Case {
    std::string text;
    std::string must_contain;
  };
  const std::vector<Case> cases = {
      {replace("  fx: ", "  fxx: "), "unknown key 'intrinsics.fxx'"},
      {replace("  k3: ", "  k3: 1\n  k4: "), "unknown key 'distortion.k4'"},
      {replace("landmark:\n  size_mm: 60\n", ""), "missing key 'landmark'"},
      {replace("  height_px: 48\n", ""), "missing key 'image.height_px'"},
      {replace("  width_px: 64", "  width_px: 64.5"), "'image.width_px' must be an integer"},
      {replace("  width_px: 64", "  width_px: wide"), "'image.width_px' must be an integer"},
      {replace("  cy: 23.25", "  cy: [1, 2]"), "'intrinsics.cy' must be a number"},
      {replace("  height_mm: ", "  height_mm: -"), "'mount.height_mm'"},
      {replace("  fy: ", "  fy: .nan\n  fq: "), "unknown key"},
      {replace("format_version: 1", "format_version: 2"), "unsupported format_version 2"},
      {replace("  size_mm: 60", "  size_mm: .inf"), "'landmark.size_mm' must be a finite number"},
      {replace("image:", "image: [\n"), "YAML syntax"},
      {"just a string\n", "top level must be a mapping"},
      {"", "top level must be a mapping"},
      {replace("  yaw_deg: ", "  yaw_deg: 400 #"), "'mount.yaw_deg' = 400 is outside"},
  };
  for (const Case& c : cases) {
    spit(d / "meta.yaml", c.text);
    Recording r;
    std::string err;
    EXPECT_FALSE(read_recording(d.string(), &r, &err)) << c.text;
    EXPECT_EQ(err.rfind("meta.yaml:", 0), 0u) << err;
    EXPECT_NE(err.find(c.must_contain), std::string::npos) << "got: " << err;
  }
  // The line number points at the offending key.
  spit(d / "meta.yaml", replace("  fx: ", "  fxx: "));
  Recording r;
  std::string err;
  EXPECT_FALSE(read_recording(d.string(), &r, &err));
  std::istringstream in(replace("  fx: ", "  fxx: "));
  std::string line;
  int n = 0, fx_line = 0;
  while (std::getline(in, line)) {
    ++n;
    if (line.find("fxx") != std::string::npos) fx_line = n;
  }
  EXPECT_EQ(err.rfind("meta.yaml:" + std::to_string(fx_line) + ":", 0), 0u) << err;
  fs::remove_all(d);
}

// The landmark family is recorded (a tag recording replayed without --config ran the QR
// pipeline); a recording without it, as made before the key existed, still reads, family empty.
TEST(Recording, LandmarkFamilyRoundTripsAndIsOptional) {
  const fs::path d = fresh_dir("family");
  std::string err;
  for (const std::string family : {"tag36h11", "qr"}) {
    Meta m = sample_meta();
    m.landmark_family = family;
    ASSERT_TRUE(write_meta(d.string(), m, &err)) << err;
    EXPECT_NE(slurp(d / "meta.yaml").find("landmark:\n  size_mm: 60\n  family: " + family + "\n"),
              std::string::npos)
        << slurp(d / "meta.yaml");
    Meta back;
    ASSERT_TRUE(read_meta(d.string(), &back, &err)) << err;
    EXPECT_EQ(back.landmark_family, family);
  }
  Meta older = sample_meta();
  ASSERT_TRUE(write_meta(d.string(), older, &err)) << err;
  EXPECT_EQ(slurp(d / "meta.yaml").find("family"), std::string::npos);
  Meta back;
  ASSERT_TRUE(read_meta(d.string(), &back, &err)) << err;
  EXPECT_TRUE(back.landmark_family.empty());
  std::string text = slurp(d / "meta.yaml");
  text.replace(text.find("  size_mm: 60\n"), 14, "  size_mm: 60\n  family: apriltag\n");
  spit(d / "meta.yaml", text);
  EXPECT_FALSE(read_meta(d.string(), &back, &err));
  EXPECT_NE(err.find("'landmark.family' must be qr or tag36h11"), std::string::npos) << err;
  fs::remove_all(d);
}

TEST(Recording, GarbageAndTruncationNeverCrash) {
  const fs::path d = write_sample("garbage");
  std::mt19937 rng(5);
  const std::vector<std::string> files = {"meta.yaml", "frames.csv", "odom.csv", "truth.csv",
                                          "imu.csv"};
  for (const std::string& f : files) {
    const std::string good = slurp(d / f);
    auto parse = [&](const std::string& text, std::string* err) {
      if (f == "meta.yaml") {
        Meta m;
        return parse_meta_yaml(text, &m, err);
      } else if (f == "frames.csv") {
        std::vector<FrameRow> rows;
        return parse_frames_csv(text, &rows, err);
      } else if (f == "odom.csv") {
        std::vector<OdomRow> rows;
        return parse_odom_csv(text, &rows, err);
      } else if (f == "imu.csv") {
        std::vector<ImuRow> rows;
        return parse_imu_csv(text, &rows, err);
      }
      std::vector<TruthRow> rows;
      return parse_truth_csv(text, &rows, err);
    };
    // Every truncation point: the parser accepts it (cut exactly at a line end) or rejects it;
    // the whole reader (every 9th point) drops a CSV's cut last line with a warning and decides
    // on the rest.
    for (size_t cut = 0; cut < good.size(); ++cut) {
      const std::string part = good.substr(0, cut);
      std::string err;
      const bool ok = parse(part, &err);
      if (cut % 9 == 0) {
        const size_t nl = part.rfind('\n');
        const bool cut_line =
            f != "meta.yaml" && !part.empty() && part.back() != '\n' && nl != std::string::npos;
        std::string ignored;
        const bool reader_ok = cut_line ? parse(part.substr(0, nl + 1), &ignored) : ok;
        spit(d / f, part);
        Recording r;
        std::string err2;
        EXPECT_EQ(read_recording(d.string(), &r, &err2), reader_ok)
            << f << " cut " << cut << ": " << err2;
        if (reader_ok) {
          EXPECT_EQ(r.warnings.size(), cut_line ? 1u : 0u) << f << " cut " << cut;
        }
      }
      if (!ok) {
        EXPECT_FALSE(err.empty());
      } else {
        EXPECT_TRUE(f == "meta.yaml" || cut == 0 || good[cut - 1] == '\n') << f << " cut " << cut;
      }
    }
    for (int trial = 0; trial < 50; ++trial) {
      std::string g = good;
      for (int k = 0; k < 4; ++k) {
        g[rng() % g.size()] = static_cast<char>(rng() % 256);
      }
      spit(d / f, g);
      Recording r;
      std::string err;
      (void)read_recording(d.string(), &r, &err);
    }
    spit(d / f, good);
  }
  fs::remove_all(d);
}

// ---- Hostile recordings ----------------------------------------------------------------------

// A frame that is a symlink to itself was reported as "missing".
TEST(Recording, UnreadableImageSaysWhy) {
  const fs::path d = write_sample("symloop");
  fs::remove(d / "frames" / "000001.png");
  fs::create_symlink("000001.png", d / "frames" / "000001.png");
  Recording r;
  std::string err;
  EXPECT_FALSE(read_recording(d.string(), &r, &err));
  EXPECT_EQ(err.rfind("frames.csv:3: image 'frames/000001.png': cannot be read (", 0), 0u) << err;
  EXPECT_NE(err.find("symbolic links"), std::string::npos) << err;
  fs::remove(d / "frames" / "000001.png");
  fs::create_directories(d / "frames" / "000001.png");
  expect_rejected(d, "frames.csv:3: image 'frames/000001.png': not a regular file");
  fs::remove_all(d);
}

// Every file of a recording is a bounded regular file; a device is never read.
TEST(Recording, DevicesAndOversizedFilesAreRejected) {
  fs::path d = write_sample("devzero");
  fs::remove(d / "odom.csv");
  fs::create_symlink("/dev/zero", d / "odom.csv");
  expect_rejected(d, "odom.csv: not a regular file");
  fs::remove(d / "odom.csv");
  spit(d / "odom.csv", "t_ns,v_mps,omega_radps\n" + std::string(33u << 20, '#'));
  expect_rejected(d, "odom.csv: larger than 33554432 bytes");
  fs::remove_all(d);
  d = write_sample("bigmeta");
  spit(d / "meta.yaml", std::string(65537, '#'));
  expect_rejected(d, "meta.yaml: larger than 65536 bytes");
  fs::remove_all(d);
}

TEST(Recording, ReadFileBoundedRefusesDevices) {
  std::string text, err;
  EXPECT_FALSE(read_file_bounded("/dev/zero", 1024, &text, &err));
  EXPECT_EQ(err, "/dev/zero: not a regular file");
}

// Times near INT64_MAX are rejected, so later time arithmetic cannot overflow.
TEST(Recording, TimesAreBounded) {
  std::vector<OdomRow> rows;
  std::string err;
  EXPECT_FALSE(parse_odom_csv("t_ns,v_mps,omega_radps\n9223372036854775807,0,0\n", &rows, &err));
  EXPECT_EQ(err.rfind("odom.csv:2: t_ns outside [0, 4611686018427387904]", 0), 0u) << err;
  EXPECT_TRUE(parse_odom_csv("t_ns,v_mps,omega_radps\n4611686018427387904,0,0\n", &rows, &err));
}

// A PNG whose header declares 16384x16384 was decoded (268 MB) before its size was
// compared with meta.yaml. The header alone is now enough to reject it.
TEST(Recording, ImageHeaderIsCheckedBeforeDecoding) {
  const fs::path d = write_sample("hugeheader");
  // Signature, IHDR 16384x16384 8-bit grey, a 1-byte IDAT, IEND: 71 bytes.
  auto be32 = [](std::uint32_t v) {
    return std::string{static_cast<char>(v >> 24), static_cast<char>(v >> 16),
                       static_cast<char>(v >> 8), static_cast<char>(v)};
  };
  const std::string ihdr = "IHDR" + be32(16384) + be32(16384) + std::string("\x08\0\0\0\0", 5);
  // CRC-32 of chunk type + data (the PNG polynomial).
  auto crc = [](const std::string& s) {
    std::uint32_t c = 0xFFFFFFFFu;
    for (unsigned char ch : s) {
      c ^= ch;
      for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
    }
    return c ^ 0xFFFFFFFFu;
  };
  const std::string png = std::string("\x89PNG\r\n\x1a\n", 8) + be32(13) + ihdr + be32(crc(ihdr)) +
                          be32(1) + "IDATx" + be32(crc("IDATx")) + be32(0) + "IEND" +
                          be32(crc("IEND"));
  spit(d / "frames" / "000001.png", png);
  Recording r;
  std::string err;
  ASSERT_TRUE(read_recording(d.string(), &r, &err)) << err;
  cv::Mat img;
  EXPECT_FALSE(load_frame(r, 1, &img, &err));
  EXPECT_EQ(err.rfind("frames.csv:3: cannot decode 'frames/000001.png'", 0), 0u) << err;
  EXPECT_NE(err.find("image is 16384x16384, expected 64x48"), std::string::npos) << err;
  EXPECT_TRUE(img.empty());  // nothing was allocated for it
  fs::remove_all(d);
}

// Replay bounds the time it simulates; the error names the rows.
TEST(Recording, ReplaySpanIsBounded) {
  Recording r;
  r.odom = {{10'000'000'000, 0, 0}, {9'000'000'000'000'000'000, 0, 0}};
  std::string err;
  EXPECT_FALSE(check_replay_span(r, 10'000'000, 1'000'000, &err));
  EXPECT_NE(err.find("odom.csv:2 (t_ns 10000000000) to odom.csv:3 (t_ns 9000000000000000000)"),
            std::string::npos)
      << err;
  r.odom = {{0, 0, 0}, {9'990'000'000'000, 0, 0}};  // 999000 periods of 10 ms
  r.frames = {{5, "a.png"}};
  EXPECT_TRUE(check_replay_span(r, 10'000'000, 1'000'000, &err)) << err;
  r.frames = {{10'000'000'000'000, "a.png"}};  // 10^6 periods
  EXPECT_FALSE(check_replay_span(r, 10'000'000, 1'000'000, &err));
  EXPECT_NE(err.find("frames.csv:2 (t_ns 10000000000000)"), std::string::npos) << err;
}

// Found by fuzz_recording_frames: "." named the recording directory itself.
TEST(Recording, FramePathsNameFilesBelowTheRecording) {
  std::vector<FrameRow> rows;
  std::string err;
  for (const char* f : {".", "./", "frames/.", "frames/", "./frames/0.png", "a/../0.png"}) {
    EXPECT_FALSE(parse_frames_csv(std::string("t_ns,file\n1,") + f + "\n", &rows, &err)) << f;
    EXPECT_EQ(err.rfind("frames.csv:2: file", 0), 0u) << err;
  }
  EXPECT_TRUE(parse_frames_csv("t_ns,file\n1,frames/.hidden.png\n", &rows, &err)) << err;
}

// Hostile input: the number of frames (one fix record each in replay) is bounded.
TEST(Recording, FrameCountIsBounded) {
  std::string text = "t_ns,file\n";
  for (int i = 0; i <= kMaxFrames; ++i) text += std::to_string(i) + ",a\n";
  std::vector<FrameRow> rows;
  std::string err;
  EXPECT_FALSE(parse_frames_csv(text, &rows, &err));
  EXPECT_EQ(err, "frames.csv:250002: more than 250000 frames");
  text.resize(text.rfind("250000,a\n"));
  EXPECT_TRUE(parse_frames_csv(text, &rows, &err)) << err;
  EXPECT_EQ(rows.size(), 250000u);
}

// ---- imu.csv (optional gyro) ------------------------------------------------------------------

TEST(Recording, ImuCsvRoundTripsAndIsOptional) {
  const fs::path d = write_sample("imu");
  Recording r;
  std::string err;
  ASSERT_TRUE(read_recording(d.string(), &r, &err)) << err;
  ASSERT_TRUE(r.has_imu);
  ASSERT_EQ(r.imu.size(), 20u);
  EXPECT_EQ(r.imu[7].t_ns, 1035000000LL);
  EXPECT_NEAR(r.imu[7].gyro_z_radps, 7 * 0.0123456789, 1e-9);  // 9 significant digits
  EXPECT_EQ(slurp(d / "imu.csv").rfind("t_ns,gyro_z_radps\n1000000000,0\n", 0), 0u);
  // Absent: no gyro, everything else as before.
  fs::remove(d / "imu.csv");
  ASSERT_TRUE(read_recording(d.string(), &r, &err)) << err;
  EXPECT_FALSE(r.has_imu);
  EXPECT_TRUE(r.imu.empty());
  EXPECT_EQ(r.odom.size(), 10u);
  fs::remove_all(d);
}

TEST(Recording, ImuCsvExtraColumnsOnlyWhenTheHeaderNamesThem) {
  std::vector<ImuRow> rows;
  std::string err;
  ASSERT_TRUE(parse_imu_csv(
      "t_ns,gyro_z_radps,gyro_x_radps,gyro_y_radps,accel_x_mps2,accel_y_mps2,accel_z_mps2\n"
      "1,0.5,0.01,-0.02,0.1,-0.2,9.81\n2,-0.25,0,0,0,0,9.8\r\n",
      &rows, &err))
      << err;
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[1].t_ns, 2);
  EXPECT_EQ(rows[1].gyro_z_radps, -0.25);
  struct Case {
    std::string text;
    std::string error;  // exact start of the message
  };
  const std::vector<Case> cases = {
      // A field the header does not name.
      {"t_ns,gyro_z_radps\n1,0.5,0.1\n", "imu.csv:2: expected 2 fields, got 3"},
      {"t_ns,gyro_z_radps,gyro_x_radps\n1,0.5,0.1,7\n",
       "imu.csv:2: expected 3 fields (as many as the header names), got 4"},
      {"t_ns,gyro_z_radps,gyro_x_radps\n1,0.5\n", "imu.csv:2: expected 3 fields"},
      // Extra columns are numbers too, finite like the rest.
      {"t_ns,gyro_z_radps,accel_x_mps2\n1,0.5,nan\n",
       "imu.csv:2: accel_x_mps2 'nan' is not a finite number"},
      // Their names: words, distinct.
      {"t_ns,gyro_z_radps,\n1,0.5,\n", "imu.csv:1: header column 3 '' is not a name"},
      {"t_ns,gyro_z_radps,a b\n1,0.5,1\n", "imu.csv:1: header column 3 'a b' is not a name"},
      {"t_ns,gyro_z_radps,ax,ax\n1,0.5,1,1\n", "imu.csv:1: header column 4 'ax' is a duplicate"},
      {"t_ns,gyro_z_radps,t_ns\n1,0.5,1\n", "imu.csv:1: header column 3 't_ns' is a duplicate"},
  };
  for (const Case& c : cases) {
    EXPECT_FALSE(parse_imu_csv(c.text, &rows, &err)) << c.text;
    EXPECT_EQ(err.rfind(c.error, 0), 0u) << c.text << " -> " << err;
  }
}

TEST(Recording, MalformedImuCsvRejectedWithFileAndLine) {
  struct Case {
    std::string text;
    std::string error;  // exact start of the message from read_recording
  };
  const std::vector<Case> cases = {
      {"t_ns,gyro_x_radps\n1,0.5\n",
       "imu.csv:1: expected header 't_ns,gyro_z_radps[,more columns]', got 't_ns,gyro_x_radps'"},
      {"t_ns,gyro_z_radpsX\n1,0.5\n", "imu.csv:1: expected header"},
      {"gyro_z_radps,t_ns\n0.5,1\n", "imu.csv:1: expected header"},
      {"", "imu.csv:1: empty file"},
      {"t_ns,gyro_z_radps\n1,0.5\n1,0.5\n", "imu.csv:3: t_ns 1 is not after the previous row's 1"},
      {"t_ns,gyro_z_radps\n5,0.5\n4,0.5\n", "imu.csv:3: t_ns 4 is not after the previous row's 5"},
      {"t_ns,gyro_z_radps\n1,0.5\n2,nan\n", "imu.csv:3: gyro_z_radps 'nan' is not a finite number"},
      {"t_ns,gyro_z_radps\n1,inf\n", "imu.csv:2: gyro_z_radps 'inf' is not a finite number"},
      // (A cut last line is dropped with a warning: ACutLastLineIsDroppedWithAWarning.)
      {"t_ns,gyro_z_rad", "imu.csv:1: truncated"},
      {"t_ns,gyro_z_radps\n1,0.5\n\n", "imu.csv:3: empty line"},
      {"t_ns,gyro_z_radps\n-1,0.5\n", "imu.csv:2: t_ns outside [0, 4611686018427387904]"},
      {"t_ns,gyro_z_radps\n1,150\n", "imu.csv:2: gyro_z_radps outside [-100, 100]"},
      {"t_ns,gyro_z_radps\n1,+0.5\n", "imu.csv:2: gyro_z_radps '+0.5' is not a finite number"},
  };
  for (const Case& c : cases) {
    const fs::path d = write_sample("imubad");
    spit(d / "imu.csv", c.text);
    SCOPED_TRACE("<<" + c.text + ">>");
    expect_rejected(d, c.error);
    fs::remove_all(d);
  }
  // Not a regular file, or too large: like every other file.
  fs::path d = write_sample("imudev");
  fs::remove(d / "imu.csv");
  fs::create_directories(d / "imu.csv");
  expect_rejected(d, "imu.csv: not a regular file");
  fs::remove_all(d);
}

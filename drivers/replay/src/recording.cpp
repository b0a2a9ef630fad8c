// Recording format reader (docs/guide/recording.md): the whole recording and its frames. Strict:
// anything unexpected is an error that names the file and line; nothing here throws or crashes on
// malformed input. The parts: recording_files.cpp (bounded reads), recording_meta.cpp (meta.yaml),
// recording_csv.cpp (the CSV files); writers: recording_write.cpp.
#include "agv/recording/recording.hpp"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <opencv2/core.hpp>

#include "agv/recording/png_io.hpp"
#include "recording_internal.hpp"

namespace agv::recording {

namespace fs = std::filesystem;

namespace {

// A recording cut by a power loss or a kill ends in a partial row: the recorder writes whole
// rows, so a last line without its newline is the one cut short. read_recording drops it and
// says so (Recording::warnings) rather than refusing everything before it; the parse_* functions
// on their own still refuse it. A file whose header is cut keeps the parser's error.
void drop_cut_last_line(std::string* text, const std::string& name,
                        std::vector<std::string>* warnings) {
  if (text->empty() || text->back() == '\n') return;
  const size_t last_nl = text->rfind('\n');
  if (last_nl == std::string::npos) return;
  const size_t line_no =
      2 + static_cast<size_t>(std::count(text->begin(), text->begin() + last_nl, '\n'));
  warnings->push_back(name + ":" + std::to_string(line_no) +
                      ": last line cut (no newline: interrupted write), ignored");
  text->resize(last_nl + 1);
}

}  // namespace

bool check_replay_span(const Recording& rec, std::int64_t period_ns, std::int64_t max_ticks,
                       std::string* error) {
  // The first and last time of each file, with the row (line) it is on.
  struct End {
    std::int64_t t;
    std::string where;
  };
  std::vector<End> ends;
  if (!rec.frames.empty()) {
    ends.push_back({rec.frames.front().t_ns, "frames.csv:2"});
    ends.push_back({rec.frames.back().t_ns, "frames.csv:" + std::to_string(rec.frames.size() + 1)});
  }
  if (!rec.odom.empty()) {
    ends.push_back({rec.odom.front().t_ns, "odom.csv:2"});
    ends.push_back({rec.odom.back().t_ns, "odom.csv:" + std::to_string(rec.odom.size() + 1)});
  }
  if (ends.empty() || period_ns <= 0) return true;
  const auto [lo, hi] = std::minmax_element(ends.begin(), ends.end(),
                                            [](const End& a, const End& b) { return a.t < b.t; });
  // Both times are in [0, kMaxTimeNs], so the difference cannot overflow.
  const std::int64_t span = hi->t - lo->t;
  if (span / period_ns < max_ticks) return true;
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "%s (t_ns %lld) to %s (t_ns %lld) span %.6g s; replay simulates at most %lld "
                "output periods (%.6g s at this output rate)",
                lo->where.c_str(), static_cast<long long>(lo->t), hi->where.c_str(),
                static_cast<long long>(hi->t), static_cast<double>(span) / 1e9,
                static_cast<long long>(max_ticks),
                static_cast<double>(max_ticks) * static_cast<double>(period_ns) / 1e9);
  if (error) *error = buf;
  return false;
}

bool read_recording(const std::string& dir, Recording* out, std::string* error) {
  std::string err;
  auto fail = [&](const std::string& why) {
    if (error) *error = why;
    return false;
  };
  try {
    const fs::path d(dir);
    std::error_code ec;
    if (!fs::is_directory(d, ec)) return fail(dir + ": not a directory");
    Recording r;
    r.dir = dir;
    if (!read_meta(dir, &r.meta, &err)) return fail(err);
    // Reads one CSV, drops a cut last line (with its warning), then parses strictly.
    auto read_csv = [&](const char* name, size_t max_bytes, auto parse) {
      std::string text;
      if (!read_text(d / name, max_bytes, &text, &err)) return false;
      drop_cut_last_line(&text, name, &r.warnings);
      return parse(text);
    };
    if (!read_csv("frames.csv", kMaxFramesCsvBytes,
                  [&](const std::string& t) { return parse_frames_csv(t, &r.frames, &err); })) {
      return fail(err);
    }
    // Every referenced image must be a readable regular file that carries the PNG signature,
    // except at the very end: a power loss can leave the last second's rows naming PNGs that
    // never reached the medium. Up to kMaxLostTailFrames such rows at the end (not all of them)
    // are dropped and named; a bad image anywhere before them is an error.
    constexpr size_t kMaxLostTailFrames = 64;
    size_t first_bad = r.frames.size();
    std::string first_bad_why;
    for (size_t i = r.frames.size(); i-- > 0;) {
      std::string why;
      if (check_png_file(d / r.frames[i].file, &why)) continue;
      const size_t from_end = r.frames.size() - i;
      if (first_bad != i + 1 || from_end > kMaxLostTailFrames || i == 0) {
        return fail("frames.csv:" + std::to_string(i + 2) + ": image '" + r.frames[i].file +
                    "': " + why);
      }
      first_bad = i;
      first_bad_why = why;
    }
    if (first_bad < r.frames.size()) {
      r.warnings.push_back("frames.csv:" + std::to_string(first_bad + 2) + "-" +
                           std::to_string(r.frames.size() + 1) + ": the last " +
                           std::to_string(r.frames.size() - first_bad) +
                           " frame(s) name unreadable images (" + first_bad_why +
                           "; interrupted recording?), ignored");
      r.frames.resize(first_bad);
    }
    if (!read_csv("odom.csv", kMaxTimedCsvBytes,
                  [&](const std::string& t) { return parse_odom_csv(t, &r.odom, &err); })) {
      return fail(err);
    }
    if (fs::exists(d / "truth.csv", ec)) {
      if (!read_csv("truth.csv", kMaxTimedCsvBytes,
                    [&](const std::string& t) { return parse_truth_csv(t, &r.truth, &err); })) {
        return fail(err);
      }
      r.has_truth = true;
    }
    // Absent = a vehicle without a gyro (or a recording older than the gyro input).
    if (fs::exists(d / "imu.csv", ec)) {
      if (!read_csv("imu.csv", kMaxTimedCsvBytes,
                    [&](const std::string& t) { return parse_imu_csv(t, &r.imu, &err); })) {
        return fail(err);
      }
      r.has_imu = true;
    }
    *out = std::move(r);
    return true;
  } catch (const std::exception& e) {
    return fail(dir + ": " + e.what());
  }
}

bool load_frame(const Recording& rec, size_t i, cv::Mat* image, std::string* error) {
  if (i >= rec.frames.size()) {
    if (error) *error = "frame index " + std::to_string(i) + " out of range";
    return false;
  }
  const std::string path = (fs::path(rec.dir) / rec.frames[i].file).string();
  // Decoded straight into the caller's buffer, so a reused Mat (the replay camera's slots) keeps
  // its allocation.
  cv::Mat& img = *image;
  std::string png_error;
  const auto& k = rec.meta.camera.intrinsics;
  std::string why;
  if (!check_png_file(fs::path(path), &why)) {
    if (error)
      *error =
          "frames.csv:" + std::to_string(i + 2) + ": image '" + rec.frames[i].file + "': " + why;
    return false;
  }
  // The header is compared with meta.yaml before anything is decoded.
  if (!png::read_gray(path, &img, &png_error, k.width_px, k.height_px)) {
    if (error) {
      *error = "frames.csv:" + std::to_string(i + 2) + ": cannot decode '" + rec.frames[i].file +
               "' (" + png_error + ")";
    }
    return false;
  }
  return true;
}

}  // namespace agv::recording

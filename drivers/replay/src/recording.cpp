// Recording format readers (docs/guide/recording.md). Strict: anything unexpected is an error that
// names the file and line; nothing here throws or crashes on malformed input. Writers:
// recording_write.cpp.
#include "agv/recording/recording.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/core.hpp>
#include <set>
#include <sstream>
#include <string_view>

#include "agv/common/geometry.hpp"
#include "agv/common/landmark.hpp"
#include "agv/recording/png_io.hpp"
#include "recording_internal.hpp"

namespace agv::recording {

namespace fs = std::filesystem;

namespace {

// Per-file caps (docs/design/security.md): with them a hostile recording cannot make the reader
// hold more than a few hundred MB (the longest legitimate files, odom.csv and truth.csv at 100 Hz,
// are ~3 MB per hour; imu.csv at 200 Hz with only t_ns,gyro_z_radps ~20 MB per hour).
constexpr std::uintmax_t kMaxMetaBytes = 64u << 10;      // 64 KiB
constexpr std::uintmax_t kMaxFramesCsvBytes = 8u << 20;  // 8 MiB: ~250k frames, 2.3 h at 30 fps
constexpr std::uintmax_t kMaxTimedCsvBytes = 32u << 20;  // 32 MiB: ~10 h of 100 Hz odometry
constexpr std::uintmax_t kMaxPngBytes = 64u << 20;       // one frame

// False with *why ("missing", "cannot be read (Too many levels of symbolic links)", "not a
// regular file", "larger than N bytes") unless `p` is a regular file of at most max_bytes.
bool check_regular_file(const fs::path& p, std::uintmax_t max_bytes, std::uintmax_t* size,
                        std::string* why) {
  std::error_code ec;
  const fs::file_status st = fs::status(p, ec);
  if (ec && ec != std::errc::no_such_file_or_directory) {
    *why = "cannot be read (" + ec.message() + ")";
    return false;
  }
  if (!fs::exists(st)) {
    *why = "missing";
    return false;
  }
  if (!fs::is_regular_file(st)) {
    *why = "not a regular file";
    return false;
  }
  *size = fs::file_size(p, ec);
  if (ec) {
    *why = "cannot be read (" + ec.message() + ")";
    return false;
  }
  if (*size > max_bytes) {
    *why = "larger than " + std::to_string(max_bytes) + " bytes";
    return false;
  }
  return true;
}

// `who` names the file in messages: the recording's files by name, others by path.
bool read_bounded(const fs::path& path, std::uintmax_t max_bytes, const std::string& who,
                  std::string* text, std::string* error) {
  std::uintmax_t size = 0;
  std::string why;
  if (!check_regular_file(path, max_bytes, &size, &why)) {
    if (why == "missing") {
      why = who == path.string() ? "cannot open (no such file)"
                                 : "missing (expected at " + path.string() + ")";
    }
    *error = who + ": " + why;
    return false;
  }
  std::ifstream f(path, std::ios::binary);
  if (!f) {
    *error = who + ": cannot open";
    return false;
  }
  // Never more than the cap, even if the file grows while it is read.
  text->assign(static_cast<size_t>(size) + 1, '\0');
  f.read(text->data(), static_cast<std::streamsize>(text->size()));
  const auto got = static_cast<std::uintmax_t>(f.gcount());
  if (got > max_bytes) {
    *error = who + ": larger than " + std::to_string(max_bytes) + " bytes";
    return false;
  }
  text->resize(static_cast<size_t>(got));
  return true;
}

bool read_text(const fs::path& path, std::uintmax_t max_bytes, std::string* text,
               std::string* error) {
  return read_bounded(path, max_bytes, path.filename().string(), text, error);
}

// ---- meta.yaml ------------------------------------------------------------------------------

struct MetaParser {
  const std::string& name;
  std::string* error;

  bool fail(const YAML::Node& n, const std::string& why) {
    const int line = n.Mark().is_null() ? 0 : n.Mark().line + 1;
    if (error) *error = name + ":" + std::to_string(line) + ": " + why;
    return false;
  }

  // The mapping must have exactly these keys (all required).
  bool keys(const YAML::Node& map, const std::string& where, const std::set<std::string>& required,
            const std::set<std::string>& optional = {}) {
    if (!map.IsMap()) return fail(map, where + " must be a mapping");
    std::set<std::string> seen;
    for (const auto& kv : map) {
      std::string k;
      try {
        k = kv.first.as<std::string>();
      } catch (const YAML::Exception&) {
        return fail(kv.first, where + ": keys must be plain strings");
      }
      if (!required.count(k) && !optional.count(k)) {
        return fail(kv.first, "unknown key '" + (where.empty() ? k : where + "." + k) + "'");
      }
      if (!seen.insert(k).second) return fail(kv.first, "duplicate key '" + k + "'");
    }
    for (const auto& k : required) {
      if (!seen.count(k)) {
        return fail(map, "missing key '" + (where.empty() ? k : where + "." + k) + "'");
      }
    }
    return true;
  }

  bool number(const YAML::Node& map, const std::string& where, const std::string& key, double lo,
              double hi, double* out) {
    const YAML::Node n = map[key];
    const std::string full = where.empty() ? key : where + "." + key;
    if (!n.IsScalar()) return fail(n, "'" + full + "' must be a number");
    double v = 0.0;
    if (!YAML::convert<double>::decode(n, v) || !std::isfinite(v)) {
      return fail(n, "'" + full + "' must be a finite number, got '" + n.Scalar() + "'");
    }
    if (v < lo || v > hi) {
      char buf[160];
      std::snprintf(buf, sizeof buf, "'%s' = %g is outside [%g, %g]", full.c_str(), v, lo, hi);
      return fail(n, buf);
    }
    *out = v;
    return true;
  }

  bool integer(const YAML::Node& map, const std::string& where, const std::string& key, int lo,
               int hi, int* out) {
    const YAML::Node n = map[key];
    const std::string full = where.empty() ? key : where + "." + key;
    int v = 0;
    if (!n.IsScalar() || !YAML::convert<int>::decode(n, v)) {
      return fail(n, "'" + full + "' must be an integer");
    }
    if (v < lo || v > hi) {
      return fail(n, "'" + full + "' = " + std::to_string(v) + " is outside [" +
                         std::to_string(lo) + ", " + std::to_string(hi) + "]");
    }
    *out = v;
    return true;
  }
};

// ---- CSV ------------------------------------------------------------------------------------

struct CsvLine {
  size_t line_no;
  std::string_view text;
};

std::vector<std::string_view> split_commas(std::string_view line);

// The header columns after `header` ("" when there are none) must be distinct names of letters,
// digits and '_' that repeat none of `header`'s: a row then has a field for each named column.
bool extra_columns(std::string_view rest, const char* header, std::vector<std::string>* names,
                   std::string* why) {
  if (rest.empty()) return true;
  const auto given = split_commas(header);
  const auto extra = split_commas(rest.substr(1));  // after the leading ','
  for (size_t i = 0; i < extra.size(); ++i) {
    const std::string_view c = extra[i];
    const std::string col = "header column " + std::to_string(given.size() + i + 1);
    const bool word = !c.empty() && std::all_of(c.begin(), c.end(), [](char ch) {
      return std::isalnum(static_cast<unsigned char>(ch)) || ch == '_';
    });
    if (!word || c.size() > 64) {
      *why = col + " '" + std::string(c.substr(0, 40)) +
             "' is not a name of up to 64 letters, digits and '_'";
      return false;
    }
    if (std::find(given.begin(), given.end(), c) != given.end() ||
        std::find(extra.begin(), extra.begin() + static_cast<std::ptrdiff_t>(i), c) !=
            extra.begin() + static_cast<std::ptrdiff_t>(i)) {
      *why = col + " '" + std::string(c) + "' is a duplicate";
      return false;
    }
    names->emplace_back(c);
  }
  return true;
}

// Splits into lines; the header must match exactly, or, with `extra` not null, start with
// `header` followed by further named columns (returned in *extra); every line must end with '\n'
// (a missing final newline means the writer was interrupted). CRLF is accepted.
bool csv_lines(const std::string& text, const std::string& name, const char* header,
               std::vector<CsvLine>* rows, std::string* error,
               std::vector<std::string>* extra = nullptr) {
  auto fail = [&](size_t line, const std::string& why) {
    if (error) *error = name + ":" + std::to_string(line) + ": " + why;
    return false;
  };
  if (text.empty()) return fail(1, std::string("empty file, expected header '") + header + "'");
  if (text.find('\0') != std::string::npos) {
    const size_t line =
        1 + static_cast<size_t>(std::count(
                text.begin(), text.begin() + static_cast<std::ptrdiff_t>(text.find('\0')), '\n'));
    return fail(line, "binary data (NUL byte)");
  }
  size_t pos = 0, line_no = 0;
  while (pos < text.size()) {
    ++line_no;
    const size_t end = text.find('\n', pos);
    if (end == std::string::npos) {
      return fail(line_no, "truncated: last line has no newline (interrupted write?)");
    }
    std::string_view line(text.data() + pos, end - pos);
    pos = end + 1;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line_no == 1) {
      const std::string_view h(header);
      const bool prefix =
          line.substr(0, h.size()) == h && (line.size() == h.size() || line[h.size()] == ',');
      if (extra ? !prefix : line != header) {
        return fail(1, std::string("expected header '") + header +
                           (extra ? "[,more columns]" : "") + "', got '" +
                           std::string(line.substr(0, 80)) + "'");
      }
      std::string why;
      if (extra && !extra_columns(line.substr(h.size()), header, extra, &why)) return fail(1, why);
      continue;
    }
    if (line.empty()) return fail(line_no, "empty line");
    rows->push_back({line_no, line});
  }
  return true;
}

std::vector<std::string_view> split_commas(std::string_view line) {
  std::vector<std::string_view> f;
  size_t start = 0;
  for (size_t i = 0; i <= line.size(); ++i) {
    if (i == line.size() || line[i] == ',') {
      f.push_back(line.substr(start, i - start));
      start = i + 1;
    }
  }
  return f;
}

bool parse_i64(std::string_view s, std::int64_t* v) {
  if (s.empty()) return false;
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), *v);
  return ec == std::errc() && p == s.data() + s.size();
}

bool parse_f64(std::string_view s, double* v) {
  if (s.empty()) return false;
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), *v);
  return ec == std::errc() && p == s.data() + s.size() && std::isfinite(*v);
}

// Parses rows with a t_ns column first and `n` more numeric columns; checks strict time order.
// With extra_columns_allowed the header may name more numeric columns after these; `fill` gets
// their values after the named ones.
template <typename Fill>
bool parse_timed_csv(const std::string& text, const std::string& name, const char* header,
                     std::vector<std::string> cols, Fill fill, std::string* error,
                     bool extra_columns_allowed = false) {
  std::vector<CsvLine> lines;
  std::vector<std::string> extra;
  if (!csv_lines(text, name, header, &lines, error, extra_columns_allowed ? &extra : nullptr)) {
    return false;
  }
  cols.insert(cols.end(), extra.begin(), extra.end());
  std::int64_t prev = 0;
  bool have_prev = false;
  std::vector<double> vals(cols.size());
  for (const CsvLine& l : lines) {
    auto fail = [&](const std::string& why) {
      if (error) *error = name + ":" + std::to_string(l.line_no) + ": " + why;
      return false;
    };
    const auto f = split_commas(l.text);
    if (f.size() != cols.size() + 1) {
      return fail("expected " + std::to_string(cols.size() + 1) + " fields" +
                  (extra.empty() ? "" : " (as many as the header names)") + ", got " +
                  std::to_string(f.size()));
    }
    std::int64_t t = 0;
    if (!parse_i64(f[0], &t))
      return fail("t_ns '" + std::string(f[0].substr(0, 40)) + "' is not an integer");
    if (t < 0 || t > kMaxTimeNs)
      return fail("t_ns outside [0, " + std::to_string(kMaxTimeNs) + "]");
    if (have_prev && t <= prev) {
      return fail("t_ns " + std::to_string(t) + " is not after the previous row's " +
                  std::to_string(prev));
    }
    for (size_t i = 0; i < cols.size(); ++i) {
      if (!parse_f64(f[i + 1], &vals[i])) {
        return fail(cols[i] + " '" + std::string(f[i + 1].substr(0, 40)) +
                    "' is not a finite number");
      }
    }
    std::string why;
    if (!fill(t, vals, &why)) return fail(why);
    prev = t;
    have_prev = true;
  }
  return true;
}

// Says why `p` cannot be a frame: not a readable regular file of at most kMaxPngBytes (with
// the system's reason, e.g. a symlink loop), or without the PNG signature.
bool check_png_file(const fs::path& p, std::string* why) {
  std::uintmax_t size = 0;
  if (!check_regular_file(p, kMaxPngBytes, &size, why)) return false;
  std::ifstream in(p, std::ios::binary);
  if (!in.is_open()) {
    *why = "cannot be opened";
    return false;
  }
  unsigned char sig[8] = {0};
  in.read(reinterpret_cast<char*>(sig), 8);
  static constexpr unsigned char kPng[8] = {0x89, 'P', 'N', 'G', 0x0d, 0x0a, 0x1a, 0x0a};
  if (in.gcount() != 8 || !std::equal(sig, sig + 8, kPng)) {
    *why = "not a PNG file";
    return false;
  }
  return true;
}

}  // namespace

bool safe_relative_path(std::string_view f) {
  if (f.empty() || f.front() == '/' || f.find('\\') != std::string_view::npos) return false;
  for (char c : f) {
    if (static_cast<unsigned char>(c) < 0x20 || c == '"') return false;
  }
  // A file below the directory: no "..", and no "." or trailing "/" that names a directory
  // ("." alone is the recording directory itself; found by fuzz_recording_frames).
  if (f.back() == '/') return false;
  const fs::path p{std::string(f)};
  for (const auto& part : p) {
    if (part == ".." || part == ".") return false;
  }
  return true;
}

bool read_file_bounded(const std::string& path, std::uintmax_t max_bytes, std::string* text,
                       std::string* error) {
  return read_bounded(fs::path(path), max_bytes, path, text, error);
}

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

bool parse_meta_yaml(const std::string& text, Meta* out, std::string* error,
                     const std::string& name) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    if (error) *error = name + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax: " + e.msg;
    return false;
  } catch (const std::exception& e) {
    if (error) *error = name + ":0: " + e.what();
    return false;
  }
  MetaParser p{name, error};
  try {
    if (!root.IsMap()) return p.fail(root, "top level must be a mapping");
    if (!p.keys(root, "",
                {"format_version", "image", "intrinsics", "distortion", "mount", "landmark"},
                {"source"})) {
      return false;
    }
    Meta m;
    if (!p.integer(root, "", "format_version", 1, 1000000, &m.format_version)) return false;
    if (m.format_version != kFormatVersion) {
      return p.fail(root["format_version"],
                    "unsupported format_version " + std::to_string(m.format_version) +
                        " (this build reads " + std::to_string(kFormatVersion) + ")");
    }
    const YAML::Node img = root["image"], in = root["intrinsics"], di = root["distortion"],
                     mo = root["mount"], lm = root["landmark"];
    auto& k = m.camera.intrinsics;
    auto& mt = m.camera.mount;
    if (!p.keys(img, "image", {"width_px", "height_px"}) ||
        !p.integer(img, "image", "width_px", 1, 16384, &k.width_px) ||
        !p.integer(img, "image", "height_px", 1, 16384, &k.height_px)) {
      return false;
    }
    if (!p.keys(in, "intrinsics", {"fx", "fy", "cx", "cy"}) ||
        !p.number(in, "intrinsics", "fx", 1.0, 1e6, &k.fx) ||
        !p.number(in, "intrinsics", "fy", 1.0, 1e6, &k.fy) ||
        !p.number(in, "intrinsics", "cx", -k.width_px, 2.0 * k.width_px, &k.cx) ||
        !p.number(in, "intrinsics", "cy", -k.height_px, 2.0 * k.height_px, &k.cy)) {
      return false;
    }
    if (!p.keys(di, "distortion", {"k1", "k2", "p1", "p2", "k3"}) ||
        !p.number(di, "distortion", "k1", -100, 100, &k.k1) ||
        !p.number(di, "distortion", "k2", -100, 100, &k.k2) ||
        !p.number(di, "distortion", "p1", -1, 1, &k.p1) ||
        !p.number(di, "distortion", "p2", -1, 1, &k.p2) ||
        !p.number(di, "distortion", "k3", -100, 100, &k.k3)) {
      return false;
    }
    double yaw_deg = 0.0, roll_deg = 0.0, pitch_deg = 0.0;
    if (!p.keys(mo, "mount", {"height_mm", "offset_x_mm", "offset_y_mm", "yaw_deg"},
                {"roll_deg", "pitch_deg"}) ||
        !p.number(mo, "mount", "height_mm", 1.0, 10000.0, &mt.height_mm) ||
        !p.number(mo, "mount", "offset_x_mm", -10000.0, 10000.0, &mt.offset_x_mm) ||
        !p.number(mo, "mount", "offset_y_mm", -10000.0, 10000.0, &mt.offset_y_mm) ||
        !p.number(mo, "mount", "yaw_deg", -180.0, 180.0, &yaw_deg)) {
      return false;
    }
    if (yaw_deg == -180.0) return p.fail(mo["yaw_deg"], "'mount.yaw_deg' must be in (-180, 180]");
    mt.yaw_rad = deg_to_rad(yaw_deg);
    if ((mo["roll_deg"] && !p.number(mo, "mount", "roll_deg", -45.0, 45.0, &roll_deg)) ||
        (mo["pitch_deg"] && !p.number(mo, "mount", "pitch_deg", -45.0, 45.0, &pitch_deg))) {
      return false;
    }
    mt.roll_rad = deg_to_rad(roll_deg);
    mt.pitch_rad = deg_to_rad(pitch_deg);
    if (!p.keys(lm, "landmark", {"size_mm"}, {"family"}) ||
        !p.number(lm, "landmark", "size_mm", 1.0, 1000.0, &m.landmark_size_mm)) {
      return false;
    }
    if (lm["family"]) {
      const YAML::Node f = lm["family"];
      LandmarkFamily family;
      if (!f.IsScalar() || !parse_landmark_family(f.Scalar(), &family)) {
        return p.fail(f, "'landmark.family' must be qr or tag36h11");
      }
      m.landmark_family = f.Scalar();
    }
    if (root["source"]) {
      if (!root["source"].IsScalar()) return p.fail(root["source"], "'source' must be a string");
      m.source = root["source"].Scalar();
    }
    *out = std::move(m);
    return true;
  } catch (const YAML::Exception& e) {
    if (error) *error = name + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg;
    return false;
  }
}

bool read_meta(const std::string& dir, Meta* out, std::string* error) {
  std::string text, err;
  if (!read_text(fs::path(dir) / "meta.yaml", kMaxMetaBytes, &text, &err)) {
    if (error) *error = err;
    return false;
  }
  return parse_meta_yaml(text, out, error);
}

bool parse_frames_csv(const std::string& text, std::vector<FrameRow>* out, std::string* error,
                      const std::string& name) {
  std::vector<CsvLine> lines;
  if (!csv_lines(text, name, "t_ns,file", &lines, error)) return false;
  if (lines.size() > static_cast<size_t>(kMaxFrames)) {
    if (error) {
      *error = name + ":" + std::to_string(lines[kMaxFrames].line_no) + ": more than " +
               std::to_string(kMaxFrames) + " frames";
    }
    return false;
  }
  std::vector<FrameRow> rows;
  rows.reserve(lines.size());
  for (const CsvLine& l : lines) {
    auto fail = [&](const std::string& why) {
      if (error) *error = name + ":" + std::to_string(l.line_no) + ": " + why;
      return false;
    };
    const auto f = split_commas(l.text);
    if (f.size() != 2) return fail("expected 2 fields, got " + std::to_string(f.size()));
    FrameRow r;
    if (!parse_i64(f[0], &r.t_ns)) {
      return fail("t_ns '" + std::string(f[0].substr(0, 40)) + "' is not an integer");
    }
    if (r.t_ns < 0 || r.t_ns > kMaxTimeNs) {
      return fail("t_ns outside [0, " + std::to_string(kMaxTimeNs) + "]");
    }
    if (!rows.empty() && r.t_ns <= rows.back().t_ns) {
      return fail("t_ns " + std::to_string(r.t_ns) + " is not after the previous row's " +
                  std::to_string(rows.back().t_ns));
    }
    if (!safe_relative_path(f[1])) {
      return fail("file '" + std::string(f[1].substr(0, 80)) +
                  "' must be a relative path inside the recording");
    }
    r.file = std::string(f[1]);
    rows.push_back(std::move(r));
  }
  *out = std::move(rows);
  return true;
}

bool parse_odom_csv(const std::string& text, std::vector<OdomRow>* out, std::string* error,
                    const std::string& name) {
  std::vector<OdomRow> rows;
  const bool ok = parse_timed_csv(
      text, name, "t_ns,v_mps,omega_radps", {"v_mps", "omega_radps"},
      [&](std::int64_t t, const std::vector<double>& v, std::string* why) {
        if (std::abs(v[0]) > 20.0) return *why = "v_mps outside [-20, 20]", false;
        if (std::abs(v[1]) > 20.0) return *why = "omega_radps outside [-20, 20]", false;
        rows.push_back({t, v[0], v[1]});
        return true;
      },
      error);
  if (ok) *out = std::move(rows);
  return ok;
}

bool parse_truth_csv(const std::string& text, std::vector<TruthRow>* out, std::string* error,
                     const std::string& name) {
  std::vector<TruthRow> rows;
  const bool ok = parse_timed_csv(
      text, name, "t_ns,x_mm,y_mm,theta_deg", {"x_mm", "y_mm", "theta_deg"},
      [&](std::int64_t t, const std::vector<double>& v, std::string* why) {
        if (std::abs(v[0]) > 1e9 || std::abs(v[1]) > 1e9) {
          return *why = "x_mm/y_mm outside [-1e9, 1e9]", false;
        }
        if (!(v[2] > -180.0 && v[2] <= 180.0)) return *why = "theta_deg outside (-180, 180]", false;
        rows.push_back({t, v[0], v[1], v[2]});
        return true;
      },
      error);
  if (ok) *out = std::move(rows);
  return ok;
}

bool parse_imu_csv(const std::string& text, std::vector<ImuRow>* out, std::string* error,
                   const std::string& name) {
  // 100 rad/s (5730 deg/s) is beyond the range of any MEMS gyro (at most 4000 deg/s): a larger
  // value is a unit or encoding mistake, not a measurement.
  constexpr double kMaxGyroRadps = 100.0;
  std::vector<ImuRow> rows;
  const bool ok = parse_timed_csv(
      text, name, "t_ns,gyro_z_radps", {"gyro_z_radps"},
      [&](std::int64_t t, const std::vector<double>& v, std::string* why) {
        if (std::abs(v[0]) > kMaxGyroRadps) return *why = "gyro_z_radps outside [-100, 100]", false;
        rows.push_back({t, v[0]});
        return true;
      },
      error, /*extra_columns_allowed=*/true);
  if (ok) *out = std::move(rows);
  return ok;
}

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

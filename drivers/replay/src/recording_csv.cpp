// The CSV files of a recording (frames.csv, odom.csv, truth.csv, imu.csv; docs/guide/recording.md):
// exact headers, strictly increasing t_ns, finite numbers in range; every error names the file and
// line.
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <string_view>

#include "agv/recording/recording.hpp"
#include "recording_internal.hpp"

namespace agv::recording {

namespace {

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

}  // namespace

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

}  // namespace agv::recording

#include "agv/common/landmark.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>

namespace agv {

std::vector<Vec2> LandmarkGeometry::outer_corners_landmark_mm() const {
  const double h = outer_half_mm();
  return {{h, h}, {-h, h}, {-h, -h}, {h, -h}};
}

const char* to_string(PayloadError e) {
  switch (e) {
    case PayloadError::kOk:
      return "ok";
    case PayloadError::kEmpty:
      return "empty payload";
    case PayloadError::kBadPrefix:
      return "payload does not start with AGV";
    case PayloadError::kUnsupportedVersion:
      return "unsupported payload version";
    case PayloadError::kBadLength:
      return "payload has the wrong length";
    case PayloadError::kBadField:
      return "malformed payload field";
    case PayloadError::kOutOfRange:
      return "payload value out of range";
  }
  return "unknown payload error";
}

namespace {

bool all_digits(std::string_view s) {
  if (s.empty()) return false;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
  }
  return true;
}

// Parses "sDDDDDD.D"-style fixed-width signed decimals: sign, int_digits digits, '.', frac digits.
bool parse_fixed(std::string_view s, int int_digits, int frac_digits, double* out) {
  const size_t len = 1 + static_cast<size_t>(int_digits) + 1 + static_cast<size_t>(frac_digits);
  if (s.size() != len) return false;
  if (s[0] != '+' && s[0] != '-') return false;
  const std::string_view ip = s.substr(1, static_cast<size_t>(int_digits));
  const std::string_view fp = s.substr(2 + static_cast<size_t>(int_digits));
  if (s[1 + static_cast<size_t>(int_digits)] != '.' || !all_digits(ip) || !all_digits(fp)) {
    return false;
  }
  long long iv = 0, fv = 0;
  std::from_chars(ip.data(), ip.data() + ip.size(), iv);
  std::from_chars(fp.data(), fp.data() + fp.size(), fv);
  const double v = static_cast<double>(iv) + static_cast<double>(fv) / std::pow(10.0, frac_digits);
  *out = s[0] == '-' ? -v : v;
  return true;
}

void append_fixed(std::string* out, double v, int int_digits, int frac_digits) {
  char buf[64];
  const double scale = std::pow(10.0, frac_digits);
  const long long q = std::llround(std::abs(v) * scale);
  const long long ip = q / static_cast<long long>(scale);
  const long long fp = q % static_cast<long long>(scale);
  std::snprintf(buf, sizeof buf, "%c%0*lld.%0*lld", v < 0 && q != 0 ? '-' : '+', int_digits, ip,
                frac_digits, fp);
  *out += buf;
}

constexpr double kMaxCoord_mm = 999999.9;

}  // namespace

PayloadError parse_payload(std::string_view t, LandmarkPayload* out) {
  if (t.empty()) return PayloadError::kEmpty;
  if (t.size() < 4 || t.substr(0, 3) != "AGV") return PayloadError::kBadPrefix;
  if (t[3] != '1') return PayloadError::kUnsupportedVersion;
  if (t.size() != 14 && t.size() != 38) return PayloadError::kBadLength;
  if (t[4] != '/' || t[10] != '/') return PayloadError::kBadField;
  const std::string_view id_s = t.substr(5, 5);
  if (!all_digits(id_s)) return PayloadError::kBadField;
  unsigned id = 0;
  std::from_chars(id_s.data(), id_s.data() + id_s.size(), id);
  LandmarkPayload p;
  p.format_version = 1;
  p.id = id;
  if (t.size() == 14) {
    if (t.substr(11) != "MAP") return PayloadError::kBadField;
    p.has_pose = false;
  } else {
    if (t[20] != '/' || t[30] != '/') return PayloadError::kBadField;
    if (!parse_fixed(t.substr(11, 9), 6, 1, &p.x_mm) ||
        !parse_fixed(t.substr(21, 9), 6, 1, &p.y_mm) ||
        !parse_fixed(t.substr(31, 7), 3, 2, &p.heading_deg)) {
      return PayloadError::kBadField;
    }
    p.has_pose = true;
    if (!(p.heading_deg > -180.0 && p.heading_deg <= 180.0)) return PayloadError::kOutOfRange;
  }
  if (id < 1 || id > 65535) return PayloadError::kOutOfRange;
  *out = p;
  return PayloadError::kOk;
}

std::string format_payload(const LandmarkPayload& p) {
  if (p.format_version != 1 || p.id < 1 || p.id > 65535) return {};
  char idbuf[16];
  std::snprintf(idbuf, sizeof idbuf, "%05u", static_cast<unsigned>(p.id));
  std::string s = std::string("AGV1/") + idbuf + "/";
  if (!p.has_pose) return s + "MAP";
  if (!std::isfinite(p.x_mm) || !std::isfinite(p.y_mm) || !std::isfinite(p.heading_deg) ||
      std::abs(p.x_mm) > kMaxCoord_mm || std::abs(p.y_mm) > kMaxCoord_mm) {
    return {};
  }
  double h = std::round(p.heading_deg * 100.0) / 100.0;
  if (!(h > -180.0 && h <= 180.0)) return {};
  append_fixed(&s, p.x_mm, 6, 1);
  s += '/';
  append_fixed(&s, p.y_mm, 6, 1);
  s += '/';
  append_fixed(&s, h, 3, 2);
  return s;
}

Pose2 payload_pose(const LandmarkPayload& p) {
  return {p.x_mm, p.y_mm, wrap_angle_rad(deg_to_rad(p.heading_deg))};
}

const LandmarkMapEntry* LandmarkMap::find(std::uint32_t id) const {
  auto it = entries.find(id);
  return it == entries.end() ? nullptr : &it->second;
}

namespace {

bool parse_double(std::string_view s, double* v) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r'))
    s.remove_suffix(1);
  if (s.empty()) return false;
  if (s.front() == '+') s.remove_prefix(1);
  auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), *v);
  return ec == std::errc() && ptr == s.data() + s.size() && std::isfinite(*v);
}

std::vector<std::string_view> split(std::string_view line, char sep) {
  std::vector<std::string_view> f;
  size_t start = 0;
  for (size_t i = 0; i <= line.size(); ++i) {
    if (i == line.size() || line[i] == sep) {
      f.push_back(line.substr(start, i - start));
      start = i + 1;
    }
  }
  return f;
}

}  // namespace

bool parse_landmark_map(std::string_view text, LandmarkMap* out, std::string* error) {
  LandmarkMap map;
  bool header_seen = false;
  size_t line_no = 0;
  size_t pos = 0;
  auto fail = [&](const std::string& why) {
    if (error) *error = "line " + std::to_string(line_no) + ": " + why;
    return false;
  };
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    std::string_view trimmed = line;
    while (!trimmed.empty() && (trimmed.front() == ' ' || trimmed.front() == '\t')) {
      trimmed.remove_prefix(1);
    }
    if (trimmed.empty() || trimmed.front() == '#') continue;
    if (!header_seen) {
      if (trimmed != "id,x_mm,y_mm,heading_deg") {
        return fail("expected header 'id,x_mm,y_mm,heading_deg'");
      }
      header_seen = true;
      continue;
    }
    auto f = split(trimmed, ',');
    if (f.size() != 4)
      return fail("expected 4 comma-separated fields, got " + std::to_string(f.size()));
    double id_d = 0, x = 0, y = 0, h = 0;
    // Id 0 is the first tag every AprilTag generator prints; a QR payload cannot carry it, which
    // the configuration check (firmware/src/config.cpp) refuses for the QR family.
    if (!parse_double(f[0], &id_d) || id_d != std::floor(id_d) || id_d < 0 || id_d > 65535) {
      return fail("id must be an integer in 0..65535");
    }
    if (!parse_double(f[1], &x) || !parse_double(f[2], &y) || std::abs(x) > kMaxCoord_mm ||
        std::abs(y) > kMaxCoord_mm) {
      return fail("x_mm and y_mm must be numbers with |value| <= 999999.9");
    }
    if (!parse_double(f[3], &h) || h <= -180.0 || h > 180.0) {
      return fail("heading_deg must be a number in (-180, 180]");
    }
    const auto id = static_cast<std::uint32_t>(id_d);
    if (map.entries.count(id)) return fail("duplicate id " + std::to_string(id));
    map.entries[id] = {id, {x, y, deg_to_rad(h)}};
  }
  if (!header_seen) {
    if (error) *error = "line " + std::to_string(line_no) + ": missing header";
    return false;
  }
  *out = std::move(map);
  return true;
}

}  // namespace agv

// Strict YAML reading for the site file (site_yaml.hpp).
#include "site_yaml.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace agv::site::detail {

int line_of(const YAML::Node& n) {
  if (!n.IsDefined()) return 0;
  const YAML::Mark m = n.Mark();
  return m.is_null() ? 0 : m.line + 1;
}

std::string did_you_mean(const std::string& key, const std::vector<const char*>& allowed) {
  // Levenshtein distance, bounded: keys are short and a long one is no typo of any.
  if (key.size() > 64) return "";
  std::string best;
  std::size_t best_d = 3;
  for (const char* a : allowed) {
    const std::string b(a);
    std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
    for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
    for (std::size_t i = 1; i <= key.size(); ++i) {
      cur[0] = i;
      for (std::size_t j = 1; j <= b.size(); ++j) {
        const std::size_t sub = prev[j - 1] + (key[i - 1] == b[j - 1] ? 0 : 1);
        cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, sub});
      }
      std::swap(prev, cur);
    }
    if (prev[b.size()] < best_d) {
      best_d = prev[b.size()];
      best = b;
    }
  }
  return best;
}

namespace {
std::string join(const std::string& path, const std::string& key) {
  return path.empty() ? key : path + "." + key;
}

const char* kind_of(const YAML::Node& n) {
  if (n.IsSequence()) return "a sequence";
  if (n.IsMap()) return "a mapping";
  if (n.IsNull()) return "empty";
  return "a plain value";
}
}  // namespace

Fields::Fields(ReadContext* ctx, const YAML::Node& node, std::string path,
               const std::vector<const char*>& allowed)
    : ctx_(ctx), path_(std::move(path)), line_(line_of(node)) {
  if (!node.IsMap()) {
    ctx_->errors->add(path_.empty() ? "top level" : path_, line_,
                      std::string("expected a mapping (key: value lines), found ") + kind_of(node));
    return;
  }
  is_map_ = true;
  for (const auto& kv : node) {
    const int line = line_of(kv.first);
    if (!kv.first.IsScalar()) {
      ctx_->errors->add(path_.empty() ? "top level" : path_, line,
                        std::string("a key must be a plain name, found ") + kind_of(kv.first));
      continue;
    }
    const std::string& k = kv.first.Scalar();
    if (k.empty()) {
      ctx_->errors->add(path_.empty() ? "top level" : path_, line, "an empty key");
      continue;
    }
    const auto known =
        std::find_if(allowed.begin(), allowed.end(), [&](const char* a) { return k == a; });
    if (known == allowed.end()) {
      const std::string hint = did_you_mean(k, allowed);
      ctx_->errors->add(join(path_, k), line,
                        "unknown key" + (hint.empty() ? "" : " (did you mean '" + hint + "'?)"));
      continue;
    }
    const auto [it, inserted] = entries_.emplace(k, kv.second);
    if (!inserted) {
      ctx_->errors->add(
          join(path_, k), line,
          "duplicate key (first at line " + std::to_string(line_of(it->second)) + ")");
    }
  }
}

YAML::Node Fields::get(const char* key) const {
  const auto it = entries_.find(key);
  return it == entries_.end() ? YAML::Node(YAML::NodeType::Undefined) : it->second;
}

std::string Fields::path(const char* key) const { return join(path_, key); }

bool Fields::require(const char* key) {
  if (!is_map_ || has(key)) return true;
  ctx_->errors->add(path(key), line_, "missing (required)");
  return false;
}

bool read_number(ReadContext* ctx, const YAML::Node& n, const std::string& path, double lo,
                 double hi, double* out, bool lo_open) {
  // Appended piecewise: GCC 12 at -O3 warns (-Wrestrict, a false positive) on a
  // `const char* + std::string` chain here.
  std::string range(lo_open ? "(" : "[");
  range += fmt_number(lo);
  range += ", ";
  range += fmt_number(hi);
  range += "]";
  double d = 0.0;
  if (!n.IsScalar() || !YAML::convert<double>::decode(n, d)) {
    ctx->errors->add(path, line_of(n), "expected a number in " + range);
    return false;
  }
  if (!std::isfinite(d)) {
    ctx->errors->add(path, line_of(n), "not a finite number (" + n.Scalar() + ")");
    return false;
  }
  if (d < lo || d > hi || (lo_open && d == lo)) {
    ctx->errors->add(path, line_of(n), "value " + fmt_number(d) + " outside " + range);
    return false;
  }
  *out = d;
  return true;
}

bool Fields::number(const char* key, double lo, double hi, double* out, bool lo_open) {
  if (!has(key)) return false;
  return read_number(ctx_, get(key), path(key), lo, hi, out, lo_open);
}

bool Fields::integer(const char* key, std::int64_t lo, std::int64_t hi, std::int64_t* out) {
  if (!has(key)) return false;
  const YAML::Node n = get(key);
  long long i = 0;
  const std::string range = "[" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
  if (!n.IsScalar() || !YAML::convert<long long>::decode(n, i)) {
    ctx_->errors->add(path(key), line_of(n), "expected an integer in " + range);
    return false;
  }
  if (i < lo || i > hi) {
    ctx_->errors->add(path(key), line_of(n), "value " + std::to_string(i) + " outside " + range);
    return false;
  }
  *out = i;
  return true;
}

bool Fields::text(const char* key, std::string* out) {
  if (!has(key)) return false;
  const YAML::Node n = get(key);
  if (!n.IsScalar()) {
    ctx_->errors->add(path(key), line_of(n), std::string("expected a string, found ") + kind_of(n));
    return false;
  }
  const std::string& s = n.Scalar();
  // Names end up in one-line messages, file names and SVG labels.
  if (s.empty() || s.size() > 256) {
    ctx_->errors->add(path(key), line_of(n), "expected 1 to 256 characters");
    return false;
  }
  if (std::any_of(s.begin(), s.end(),
                  [](char c) { return static_cast<unsigned char>(c) < 0x20 || c == 0x7f; })) {
    ctx_->errors->add(path(key), line_of(n), "contains a control character");
    return false;
  }
  *out = s;
  return true;
}

bool read_list(ReadContext* ctx, const YAML::Node& n, const std::string& path, std::size_t max) {
  if (n.IsNull()) return true;  // `obstacles:` with nothing under it: none
  if (!n.IsSequence()) {
    ctx->errors->add(path, line_of(n),
                     std::string("expected a sequence (- item lines), found ") + kind_of(n));
    return false;
  }
  if (n.size() > max) {
    ctx->errors->add(path, line_of(n),
                     std::to_string(n.size()) + " items, at most " + std::to_string(max));
    return false;
  }
  return true;
}

bool read_polygon(ReadContext* ctx, const YAML::Node& n, const std::string& path, Polygon* out) {
  const SiteLimits& lim = *ctx->limits;
  if (!n.IsSequence()) {
    ctx->errors->add(
        path, line_of(n),
        std::string("expected a sequence of [x_mm, y_mm] vertices, found ") + kind_of(n));
    return false;
  }
  if (n.size() > lim.max_vertices_per_polygon) {
    ctx->errors->add(path, line_of(n),
                     std::to_string(n.size()) + " vertices, at most " +
                         std::to_string(lim.max_vertices_per_polygon));
    return false;
  }
  ctx->vertices_read += n.size();
  if (ctx->vertices_read > lim.max_total_vertices) {
    ctx->errors->add(
        path, line_of(n),
        "more than " + std::to_string(lim.max_total_vertices) + " polygon vertices in the file");
    return false;
  }
  Polygon p;
  bool ok = true;
  for (std::size_t i = 0; i < n.size() && !ctx->errors->full(); ++i) {
    const YAML::Node v = n[i];
    const std::string vp = path + "[" + std::to_string(i) + "]";
    if (!v.IsSequence() || v.size() != 2) {
      ctx->errors->add(vp, line_of(v), "expected a vertex [x_mm, y_mm]");
      ok = false;
      continue;
    }
    Vec2 xy;
    const double e = lim.max_extent_mm;
    ok &= read_number(ctx, v[0], vp + ".x", -e, e, &xy.x);
    ok &= read_number(ctx, v[1], vp + ".y", -e, e, &xy.y);
    p.vertices_mm.push_back(xy);
  }
  if (ok) *out = std::move(p);
  return ok;
}

}  // namespace agv::site::detail

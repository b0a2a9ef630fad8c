// replay_trace: the fixes of an eval_overhead trace (--trace-prefix) through a FleetTracker again,
// in their arrival order, scored at the trace's output ticks against its truth: the tracker's
// filter compared on the same fixes in a second instead of re-rendering a run (the camera
// pipeline's windows follow the original run's tracker, so this holds while tracking is not lost).
//   replay_trace PREFIX [--alpha-noise A] [--maneuver-alpha-noise A] [--maneuver-chi2 C]
//     [--accel-noise A]
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "agv/overhead/tracker.hpp"
#include "metrics.hpp"

namespace {

using Row = std::map<std::string, std::string>;

// A CSV with a header line as rows of named fields; empty when the file cannot be read.
std::vector<Row> read_csv(const std::string& path) {
  std::ifstream f(path);
  std::string line;
  std::vector<Row> rows;
  if (!std::getline(f, line)) return rows;
  auto chomp = [](std::string* l) {  // a file written on Windows (or by Python's csv) ends in CR LF
    if (!l->empty() && l->back() == '\r') l->pop_back();
  };
  chomp(&line);
  std::vector<std::string> names;
  std::stringstream hs(line);
  for (std::string n; std::getline(hs, n, ',');) names.push_back(n);
  while (std::getline(f, line)) {
    chomp(&line);
    std::stringstream ls(line);
    Row r;
    std::size_t i = 0;
    for (std::string v; std::getline(ls, v, ',') && i < names.size(); ++i) r[names[i]] = v;
    rows.push_back(std::move(r));
  }
  return rows;
}

double num(const Row& r, const std::string& k) { return std::strtod(r.at(k).c_str(), nullptr); }
std::int64_t ns(const Row& r, const std::string& k) { return std::llround(num(r, k) * 1e9); }

struct Stats {
  std::vector<double> pos, head;
  double nees = 0.0, head_nees = 0.0;  // 3 dof (x, y, theta) and the heading's alone
  std::size_t nees_n = 0, in95 = 0, head_in3 = 0;
};

void score(const agv::overhead::TrackOutput& o, const Row& t, Stats* s) {
  if (!o.valid()) return;
  const double ex = o.pose.x_mm - num(t, "true_x_mm"), ey = o.pose.y_mm - num(t, "true_y_mm");
  const double et = agv::wrap_angle_rad(o.pose.theta_rad - num(t, "true_theta_rad"));
  s->pos.push_back(std::hypot(ex, ey));
  s->head.push_back(std::abs(agv::rad_to_deg(et)));
  Eigen::Matrix3d p;
  for (int i = 0; i < 9; ++i) p(i / 3, i % 3) = o.cov[static_cast<std::size_t>(i)];
  const Eigen::Vector3d e(ex, ey, et);
  const double d2 = e.dot(p.ldlt().solve(e));
  s->nees += d2;
  ++s->nees_n;
  if (d2 <= 7.815) ++s->in95;
  const double h2 = et * et / p(2, 2);
  s->head_nees += h2;
  if (h2 <= 9.0) ++s->head_in3;
}

// The first field a row of either file lacks (a truncated last line, another program's CSV); empty
// when every row has every field the replay reads.
std::string missing_field(const std::vector<Row>& fixes, const std::vector<Row>& ticks) {
  std::vector<std::string> fix_keys = {"t_s",  "agv",           "arrival_s",        "x_mm",
                                       "y_mm", "fix_theta_rad", "true_omega_radps", "true_v_mps"};
  for (int i = 0; i < 9; ++i) {
    fix_keys.push_back("cov" + std::to_string(i));
    fix_keys.push_back("cov_camera" + std::to_string(i));
  }
  const std::vector<std::string> tick_keys = {"t_s", "agv", "true_x_mm", "true_y_mm",
                                              "true_theta_rad"};
  auto first_missing = [](const std::vector<Row>& rows, const std::vector<std::string>& keys) {
    for (const Row& r : rows) {
      for (const std::string& k : keys) {
        if (r.find(k) == r.end()) return k;
      }
    }
    return std::string();
  };
  const std::string k = first_missing(fixes, fix_keys);
  if (!k.empty()) return k;
  return first_missing(ticks, tick_keys);
}

// Tracker settings from the options after the prefix; false with a message on a bad one.
bool parse(int argc, char** argv, agv::overhead::TrackerParams* params) {
  if (argc < 2) {
    std::fprintf(stderr,
                 "usage: replay_trace PREFIX [--alpha-noise A] [--maneuver-alpha-noise A] "
                 "[--maneuver-chi2 C] [--accel-noise A]\n");
    return false;
  }
  for (int i = 2; i < argc; i += 2) {
    const std::string a = argv[i];
    char* end = nullptr;
    const double v = i + 1 < argc ? std::strtod(argv[i + 1], &end) : 0.0;
    if (i + 1 >= argc || end == argv[i + 1] || *end != '\0') {
      std::fprintf(stderr, "replay_trace: %s: missing or bad value\n", a.c_str());
      return false;
    }
    const std::pair<const char*, double*> options[] = {
        {"--alpha-noise", &params->alpha_noise_radps2},
        {"--maneuver-alpha-noise", &params->maneuver_alpha_noise_radps2},
        {"--maneuver-chi2", &params->maneuver_chi2},
        {"--accel-noise", &params->accel_noise_mps2}};
    const auto* o = std::find_if(std::begin(options), std::end(options),
                                 [&](const auto& kv) { return a == kv.first; });
    if (o == std::end(options)) {
      std::fprintf(stderr, "replay_trace: unknown option %s\n", a.c_str());
      return false;
    }
    *o->second = v;
  }
  const std::string err = agv::overhead::validate(*params);
  if (!err.empty()) std::fprintf(stderr, "replay_trace: %s\n", err.c_str());
  return err.empty();
}

}  // namespace

int main(int argc, char** argv) {
  agv::overhead::TrackerParams params;
  if (!parse(argc, argv, &params)) return 2;
  const std::string prefix = argv[1];
  const std::vector<Row> fixes = read_csv(prefix + "_fixes.csv");
  const std::vector<Row> ticks = read_csv(prefix + "_ticks.csv");
  if (fixes.empty() || ticks.empty()) {
    std::fprintf(stderr, "replay_trace: cannot read %s_fixes.csv / _ticks.csv\n", prefix.c_str());
    return 2;
  }
  const std::string missing = missing_field(fixes, ticks);
  if (!missing.empty()) {
    std::fprintf(stderr, "replay_trace: %s: a row without field %s\n", prefix.c_str(),
                 missing.c_str());
    return 2;
  }
  std::size_t n = 0;
  for (const Row& t : ticks) n = std::max(n, static_cast<std::size_t>(num(t, "agv")) + 1);
  agv::overhead::FleetTracker tracker(n, params);
  Stats s;
  std::size_t f = 0;
  for (std::size_t k = 0; k < ticks.size(); k += n) {
    const std::int64_t t_ns = ns(ticks[k], "t_s");
    // Ticks are scored before the frames that arrive at or after them, as eval_overhead does.
    for (; f < fixes.size() && ns(fixes[f], "arrival_s") < t_ns; ++f) {
      agv::overhead::TagFix fx;
      fx.pose = {num(fixes[f], "x_mm"), num(fixes[f], "y_mm"), num(fixes[f], "fix_theta_rad")};
      for (std::size_t i = 0; i < 9; ++i) {
        fx.cov[i] = num(fixes[f], "cov" + std::to_string(i));
        fx.cov_camera[i] = num(fixes[f], "cov_camera" + std::to_string(i));
      }
      const agv::overhead::FixResult res =
          tracker.add_fix(static_cast<std::size_t>(num(fixes[f], "agv")), ns(fixes[f], "t_s"), fx);
      if (res == agv::overhead::FixResult::kGated) {
        std::printf("gated: agv %s at %s s (true turn rate %s rad/s, speed %s m/s)\n",
                    fixes[f].at("agv").c_str(), fixes[f].at("t_s").c_str(),
                    fixes[f].at("true_omega_radps").c_str(), fixes[f].at("true_v_mps").c_str());
      }
    }
    tracker.update_states(t_ns);
    for (std::size_t j = k; j < k + n && j < ticks.size(); ++j) {
      score(tracker.output(static_cast<std::size_t>(num(ticks[j], "agv")), t_ns), ticks[j], &s);
    }
  }
  const auto& c = tracker.counters();
  std::printf(
      "valid %zu: position p50 %.2f p95 %.2f max %.2f mm; heading p50 %.3f p95 %.3f max %.3f "
      "deg; NEES mean %.2f, within chi2 95 %% %.1f %%; heading alone: NEES mean %.2f (1 if "
      "honest), within 3 sigma %.1f %%; applied %llu gated %llu started %llu\n",
      s.pos.size(), agv::eval::percentile(s.pos, 0.5), agv::eval::percentile(s.pos, 0.95),
      agv::eval::percentile(s.pos, 1.0), agv::eval::percentile(s.head, 0.5),
      agv::eval::percentile(s.head, 0.95), agv::eval::percentile(s.head, 1.0),
      s.nees / static_cast<double>(std::max<std::size_t>(1, s.nees_n)),
      100.0 * static_cast<double>(s.in95) / static_cast<double>(std::max<std::size_t>(1, s.nees_n)),
      s.head_nees / static_cast<double>(std::max<std::size_t>(1, s.nees_n)),
      100.0 * static_cast<double>(s.head_in3) /
          static_cast<double>(std::max<std::size_t>(1, s.nees_n)),
      static_cast<unsigned long long>(c.applied), static_cast<unsigned long long>(c.gated),
      static_cast<unsigned long long>(c.started));
  return 0;
}

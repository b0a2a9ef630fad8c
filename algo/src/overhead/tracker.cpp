// The fleet's tracks: one filter per vehicle (tracker_model.hpp), a ring of its posteriors for
// delayed fixes, and the track states (docs/design/overhead.md).
#include "agv/overhead/tracker.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "tracker_model.hpp"

namespace agv::overhead {

namespace tracker_detail {

// One accepted fix and the posterior after it.
struct TrackEntry {
  std::int64_t t_ns = 0;
  Belief belief;
  Measurement fix;
};

// The posteriors of one track in time order, oldest first, in a ring sized once.
struct TrackCore {
  TrackState state = TrackState::kNone;
  std::vector<TrackEntry> ring;
  std::size_t head = 0, count = 0;
  RoutePath route;  // empty: none
  std::int64_t route_t_ns = 0;

  TrackEntry& at(std::size_t i) { return ring[(head + i) % ring.size()]; }
  const TrackEntry& at(std::size_t i) const { return ring[(head + i) % ring.size()]; }
  const TrackEntry& newest() const { return at(count - 1); }
  void clear() { head = count = 0; }
};

}  // namespace tracker_detail

struct FleetTracker::Track : tracker_detail::TrackCore {};

// Helpers in a namespace of their own: the library may be built as a unity batch.
namespace tracker_detail {
namespace {

// a - b, saturated: a clock jump in the input must not overflow.
std::int64_t diff_ns(std::int64_t a, std::int64_t b) {
  std::int64_t d = 0;
  if (__builtin_sub_overflow(a, b, &d)) {
    return a > b ? std::numeric_limits<std::int64_t>::max()
                 : std::numeric_limits<std::int64_t>::min();
  }
  return d;
}

double seconds(std::int64_t dt_ns) { return static_cast<double>(dt_ns) * 1e-9; }
double ms_as_ns(double ms) { return ms * 1e6; }

tracker_detail::ProcessNoise noise_of(const TrackerParams& p) {
  const double a = 1000.0 * p.accel_noise_mps2;  // the state's speed is in mm/s
  return {a * a, p.alpha_noise_radps2 * p.alpha_noise_radps2};
}

// The steady model and the one for a turn's start or end (tracker.hpp).
struct Models {
  ProcessNoise steady, maneuver;
  bool maneuvers = false;
  double maneuver_chi2 = 0.0;
  double steady_span_s = 0.0;
};

Models models_of(const TrackerParams& p) {
  Models m;
  m.steady = noise_of(p);
  m.maneuver = m.steady;
  m.maneuver.alpha = p.maneuver_alpha_noise_radps2 * p.maneuver_alpha_noise_radps2;
  m.maneuvers = p.maneuver_alpha_noise_radps2 > 0.0;
  m.maneuver_chi2 = p.maneuver_chi2;
  m.steady_span_s = p.coast_after_ms * 1e-3;
  return m;
}

// b predicted over dt_s: with the steady density while the track is confirmed by fixes, with the
// manoeuvre density over the whole gap once it has had none for coast_after_ms. A vehicle that
// began to turn after the newest fix shows it in the next one; a track that missed its fixes cannot
// tell, and its output and the search window drawn from it must allow for the turn.
Belief predict_unseen(const Belief& b, double dt_s, const Models& q) {
  const bool unseen = q.maneuvers && std::abs(dt_s) > q.steady_span_s;
  return tracker_detail::predict(b, dt_s, unseen ? q.maneuver : q.steady);
}

// The prior of fix m dt_s after b (b carrying the calibration error bias): predict_unseen's, or
// the manoeuvre one when the fix's heading is beyond that prediction's reach.
Belief prior_for(const Belief& b, double dt_s, const Mat3& bias, const Measurement& m,
                 const Models& q) {
  Belief prior = predict_unseen(b, dt_s, q);
  if (q.maneuvers && !(tracker_detail::heading_distance2(prior, bias, m) <= q.maneuver_chi2)) {
    prior = tracker_detail::predict(b, dt_s, q.maneuver);
  }
  return prior;
}

// The newest entry at or before t (the oldest when t precedes them all), predicted to t.
Belief belief_at(const TrackCore& tr, std::int64_t t_ns, const Models& q) {
  std::size_t j = tr.count - 1;
  while (j > 0 && tr.at(j).t_ns > t_ns) --j;
  const TrackEntry& e = tr.at(j);
  return predict_unseen(e.belief, seconds(diff_ns(t_ns, e.t_ns)), q);
}

// The belief as reported: the calibration error of the newest fix's camera passes through the
// filter whole, so it is added on top of the filter's covariance.
Belief reported_at(const TrackCore& tr, std::int64_t t_ns, const Models& q) {
  Belief b = belief_at(tr, t_ns, q);
  b.p.topLeftCorner<3, 3>() += tr.newest().fix.bias;
  return b;
}

// The belief at t extrapolated along the track's route (route_prior.hpp), when the prior is on,
// the track is confirmed or coasting, has had no fix for coast_after_ms and its newest fix (at or
// after the route was set) lies on the route. Speed and turn rate keep the filter's covariance
// grown by the process noise; the turn rate is 0 on a route's straight segments.
bool route_belief_at(const TrackCore& tr, std::int64_t t_ns, const TrackerParams& p,
                     const ProcessNoise& q, Belief* out) {
  if (!p.route_prior || tr.route.empty() || tr.count == 0) return false;
  if (tr.state != TrackState::kConfirmed && tr.state != TrackState::kCoasting) return false;
  const TrackEntry& e = tr.newest();
  if (e.t_ns < tr.route_t_ns) return false;
  const std::int64_t age_ns = diff_ns(t_ns, e.t_ns);
  if (!(static_cast<double>(age_ns) > ms_as_ns(p.coast_after_ms))) return false;
  RouteFixState fs;
  fs.pose = {e.belief.x(0), e.belief.x(1), e.belief.x(2)};
  fs.v_mmps = e.belief.x(3);
  const int idx[3] = {0, 1, 3};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j)
      fs.cov_xyv[static_cast<std::size_t>(3 * i + j)] = e.belief.p(idx[i], idx[j]);
  }
  fs.var_theta_rad2 = e.belief.p(2, 2);
  const double dt_s = seconds(age_ns);
  RoutePrediction r;
  if (predict_on_route(tr.route, fs, dt_s, q.accel, p.route, &r) != RouteFit::kOnRoute) {
    return false;
  }
  Belief b;
  b.x << r.pose.x_mm, r.pose.y_mm, r.pose.theta_rad, e.belief.x(3), 0.0;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) b.p(i, j) = r.cov[static_cast<std::size_t>(3 * i + j)];
  }
  b.p(3, 3) = e.belief.p(3, 3) + q.accel * dt_s;
  b.p(4, 4) = e.belief.p(4, 4) + q.alpha * dt_s;
  *out = b;
  return true;
}

// The belief as reported at t: along the route when route_belief_at gives one, otherwise the
// motion model's (reported_at).
Belief reported_with_route(const TrackCore& tr, std::int64_t t_ns, const TrackerParams& p) {
  const Models q = models_of(p);
  Belief b;
  if (route_belief_at(tr, t_ns, p, q.steady, &b)) {
    b.p.topLeftCorner<3, 3>() += tr.newest().fix.bias;
    return b;
  }
  return reported_at(tr, t_ns, q);
}

// The state the track is in at t, given its position sigma then: the stored state aged by the
// time since its newest fix. Never better than the stored one (only a fix confirms).
TrackState state_at(const TrackCore& tr, std::int64_t t_ns, double sigma_xy_mm,
                    const TrackerParams& p) {
  if (tr.state == TrackState::kNone || tr.state == TrackState::kLost || tr.count == 0) {
    return tr.state == TrackState::kLost ? TrackState::kLost : TrackState::kNone;
  }
  const double age_ns = static_cast<double>(diff_ns(t_ns, tr.newest().t_ns));
  if (tr.state == TrackState::kTentative) {
    // Its sigma is wide by construction (the speed is unknown); only a miss drops it.
    return age_ns > ms_as_ns(p.coast_after_ms) ? TrackState::kNone : TrackState::kTentative;
  }
  if (age_ns > ms_as_ns(p.lost_after_ms) || !(sigma_xy_mm <= p.lost_sigma_mm)) {
    return TrackState::kLost;
  }
  if (age_ns > ms_as_ns(p.coast_after_ms)) return TrackState::kCoasting;
  return TrackState::kConfirmed;
}

// Index at which a fix at t goes: after every entry at or before t.
std::size_t insertion_index(const TrackCore& tr, std::int64_t t_ns) {
  std::size_t k = tr.count;
  while (k > 0 && tr.at(k - 1).t_ns > t_ns) --k;
  return k;
}

// Puts e at index k (0 < k <= count), dropping the oldest entry when the ring is full, and
// replays the entries after it. Returns the number of entries replayed.
std::size_t insert_and_replay(TrackCore* tr, std::size_t k, const TrackEntry& e, const Models& q) {
  if (tr->count == tr->ring.size()) {
    tr->head = (tr->head + 1) % tr->ring.size();
    --tr->count;
    --k;
  }
  ++tr->count;
  for (std::size_t j = tr->count - 1; j > k; --j) tr->at(j) = tr->at(j - 1);
  tr->at(k) = e;
  for (std::size_t j = k + 1; j < tr->count; ++j) {
    const TrackEntry& prev = tr->at(j - 1);
    TrackEntry& cur = tr->at(j);
    cur.belief = tracker_detail::update(
        prior_for(prev.belief, seconds(diff_ns(cur.t_ns, prev.t_ns)), prev.fix.bias, cur.fix, q),
        cur.fix, prev.fix);
  }
  return tr->count - 1 - k;
}

// Fixes of the track within the confirmation window ending at its newest.
int recent_fixes(const TrackCore& tr, double window_ms) {
  int n = 0;
  const std::int64_t newest = tr.newest().t_ns;
  for (std::size_t j = tr.count; j > 0; --j) {
    if (static_cast<double>(diff_ns(newest, tr.at(j - 1).t_ns)) > ms_as_ns(window_ms)) break;
    ++n;
  }
  return n;
}

bool finite_positive(double v) { return std::isfinite(v) && v > 0.0; }
// Durations become nanoseconds in 64 bits; an hour is far beyond any use.
bool duration_ok(double ms) { return finite_positive(ms) && ms <= 3.6e6; }

}  // namespace
}  // namespace tracker_detail

namespace td = tracker_detail;

std::string validate(const TrackerParams& p) {
  if (!(std::isfinite(p.accel_noise_mps2) && p.accel_noise_mps2 >= 0.0)) {
    return "accel_noise_mps2 must be finite and >= 0";
  }
  if (!(std::isfinite(p.alpha_noise_radps2) && p.alpha_noise_radps2 >= 0.0)) {
    return "alpha_noise_radps2 must be finite and >= 0";
  }
  if (!(std::isfinite(p.maneuver_alpha_noise_radps2) && p.maneuver_alpha_noise_radps2 >= 0.0)) {
    return "maneuver_alpha_noise_radps2 must be finite and >= 0";
  }
  if (!td::finite_positive(p.maneuver_chi2)) return "maneuver_chi2 must be finite and > 0";
  if (!td::finite_positive(p.gate_chi2)) return "gate_chi2 must be finite and > 0";
  if (p.confirm_fixes < 1) return "confirm_fixes must be >= 1";
  if (!td::duration_ok(p.confirm_window_ms)) return "confirm_window_ms must be in (0, 3.6e6]";
  if (!td::duration_ok(p.coast_after_ms)) return "coast_after_ms must be in (0, 3.6e6]";
  if (!td::duration_ok(p.lost_after_ms) || p.lost_after_ms < p.coast_after_ms) {
    return "lost_after_ms must be in [coast_after_ms, 3.6e6]";
  }
  if (!td::finite_positive(p.lost_sigma_mm)) return "lost_sigma_mm must be finite and > 0";
  if (!(std::isfinite(p.max_fix_age_ms) && p.max_fix_age_ms >= 0.0 && p.max_fix_age_ms <= 3.6e6)) {
    return "max_fix_age_ms must be in [0, 3.6e6]";
  }
  if (p.history < 2 || p.history < p.confirm_fixes || p.history > 100000) {
    return "history must be in [max(2, confirm_fixes), 100000]";
  }
  if (!td::finite_positive(p.initial_speed_sigma_mps)) {
    return "initial_speed_sigma_mps must be finite and > 0";
  }
  if (!td::finite_positive(p.initial_turn_sigma_radps)) {
    return "initial_turn_sigma_radps must be finite and > 0";
  }
  if (p.route_prior) {
    const std::string err = validate(p.route);
    if (!err.empty()) return "route." + err;
  }
  return {};
}

FleetTracker::FleetTracker(std::size_t fleet_size, const TrackerParams& params) : p_(params) {
  const std::string err = validate(p_);
  if (!err.empty()) throw std::invalid_argument("TrackerParams: " + err);
  tracks_.resize(fleet_size);
  for (Track& t : tracks_) t.ring.resize(static_cast<std::size_t>(p_.history));
}

FleetTracker::~FleetTracker() = default;
FleetTracker::FleetTracker(const FleetTracker&) = default;
FleetTracker& FleetTracker::operator=(const FleetTracker&) = default;
FleetTracker::FleetTracker(FleetTracker&&) noexcept = default;
FleetTracker& FleetTracker::operator=(FleetTracker&&) noexcept = default;

std::size_t FleetTracker::size() const { return tracks_.size(); }

FixResult FleetTracker::add_fix(std::size_t agv, std::int64_t t_ns, const TagFix& fix) {
  td::Measurement m;
  if (agv >= tracks_.size() || !td::make_measurement(fix, &m)) {
    ++counters_.invalid;
    return FixResult::kInvalid;
  }
  Track& tr = tracks_[agv];
  const td::Models models = td::models_of(p_);
  std::size_t k = 0;
  td::Belief prior;
  td::Mat3 prior_bias = td::Mat3::Zero();
  td::Measurement prior_fix = m;  // the fix the prior came from
  bool restart = tr.state == TrackState::kNone || tr.state == TrackState::kLost || tr.count == 0;
  if (!restart) {
    k = td::insertion_index(tr, t_ns);
    if (k == tr.count) {
      prior_bias = tr.newest().fix.bias;
      prior_fix = tr.newest().fix;
      if (!td::route_belief_at(tr, t_ns, p_, models.steady, &prior)) {
        prior = td::prior_for(tr.newest().belief, td::seconds(td::diff_ns(t_ns, tr.newest().t_ns)),
                              prior_bias, m, models);
      }
      const TrackState now = td::state_at(tr, t_ns, td::position_sigma_mm(prior.p), p_);
      if (now == TrackState::kLost) ++counters_.lost;
      restart = now == TrackState::kNone || now == TrackState::kLost;
    } else if (k == 0 || static_cast<double>(td::diff_ns(tr.newest().t_ns, t_ns)) >
                             td::ms_as_ns(p_.max_fix_age_ms)) {
      ++counters_.too_old;
      return FixResult::kTooOld;
    } else {
      const td::TrackEntry& before = tr.at(k - 1);
      prior_bias = before.fix.bias;
      prior_fix = before.fix;
      prior = td::prior_for(before.belief, td::seconds(td::diff_ns(t_ns, before.t_ns)), prior_bias,
                            m, models);
    }
  }
  if (restart) {
    tr.clear();
    tr.ring[0] = {
        t_ns, td::start(m, 1000.0 * p_.initial_speed_sigma_mps, p_.initial_turn_sigma_radps), m};
    tr.count = 1;
    tr.state = p_.confirm_fixes <= 1 ? TrackState::kConfirmed : TrackState::kTentative;
    ++counters_.started;
    return FixResult::kStarted;
  }
  if (!(td::distance2(prior, prior_bias, m) <= p_.gate_chi2)) {
    ++counters_.gated;
    return FixResult::kGated;
  }
  if (td::insert_and_replay(&tr, k, {t_ns, td::update(prior, m, prior_fix), m}, models) > 0) {
    ++counters_.replays;
  }
  ++counters_.applied;
  if (tr.state == TrackState::kCoasting ||
      (tr.state == TrackState::kTentative &&
       td::recent_fixes(tr, p_.confirm_window_ms) >= p_.confirm_fixes)) {
    tr.state = TrackState::kConfirmed;
  }
  return FixResult::kApplied;
}

void FleetTracker::update_states(std::int64_t now_ns) {
  for (Track& tr : tracks_) {
    if (tr.count == 0 || tr.state == TrackState::kNone || tr.state == TrackState::kLost) continue;
    const td::Belief b = td::reported_with_route(tr, now_ns, p_);
    const TrackState s = td::state_at(tr, now_ns, td::position_sigma_mm(b.p), p_);
    if (s == tr.state) continue;
    if (s == TrackState::kLost) ++counters_.lost;
    if (s == TrackState::kNone) tr.clear();
    tr.state = s;
  }
}

TrackOutput FleetTracker::output(std::size_t agv, std::int64_t t_ns) const {
  TrackOutput o;
  o.agv = agv;
  o.t_ns = t_ns;
  if (agv >= tracks_.size()) return o;
  const Track& tr = tracks_[agv];
  if (tr.count == 0 || tr.state == TrackState::kNone) return o;
  const td::Belief b = td::reported_with_route(tr, t_ns, p_);
  o.pose = {b.x(0), b.x(1), b.x(2)};
  o.v_mps = b.x(3) / 1000.0;
  o.omega_radps = b.x(4);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) o.cov[static_cast<std::size_t>(3 * i + j)] = b.p(i, j);
  }
  o.sigma_xy_mm = td::position_sigma_mm(b.p);
  o.sigma_theta_rad = std::sqrt(std::max(0.0, b.p(2, 2)));
  o.last_fix_t_ns = tr.newest().t_ns;
  o.state = td::state_at(tr, t_ns, o.sigma_xy_mm, p_);
  return o;
}

std::vector<TrackOutput> FleetTracker::outputs(std::int64_t t_ns) const {
  std::vector<TrackOutput> out;
  out.reserve(tracks_.size());
  for (std::size_t i = 0; i < tracks_.size(); ++i) out.push_back(output(i, t_ns));
  return out;
}

bool FleetTracker::set_route(std::size_t agv, const std::vector<Vec2>& waypoints_mm,
                             std::int64_t t_ns, std::string* error) {
  auto fail = [&](const std::string& why) {
    if (error != nullptr) *error = why;
    return false;
  };
  if (!p_.route_prior) return fail("the route prior is off (TrackerParams::route_prior)");
  if (agv >= tracks_.size()) return fail("vehicle index outside the fleet");
  RoutePath path;
  std::string why;
  if (!path.assign(waypoints_mm, &why)) return fail(why);
  tracks_[agv].route = std::move(path);
  tracks_[agv].route_t_ns = t_ns;
  return true;
}

void FleetTracker::clear_route(std::size_t agv) {
  if (agv < tracks_.size()) tracks_[agv].route.clear();
}

void FleetTracker::reset(std::size_t agv) {
  if (agv >= tracks_.size()) return;
  tracks_[agv].clear();
  tracks_[agv].state = TrackState::kNone;
}

}  // namespace agv::overhead

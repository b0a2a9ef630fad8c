// Blockages the reservation table cannot clear by itself: vehicles waiting on each other in a
// cycle (a deadlock: head-on in a corridor, crossing paths), or on a vehicle that has nothing
// left to do. Reported, then resolved by one vehicle driving aside (docs/design/fleet_sim.md
// "Deadlocks").
#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

#include "fleet_internal.hpp"

namespace agv::sim::fleet_internal {

namespace {

constexpr double kFleetRetryS = 2.0;         // between attempts on a blockage not yet resolved
constexpr double kFleetEvadeBoxMm = 8000.0;  // half side of the square searched for a refuge
constexpr int kFleetEvadeDraws = 200;
constexpr int kFleetEvadeTries = 12;

std::string fleet_member_list(const std::vector<int>& members, const char* sep) {
  std::string s;
  for (std::size_t i = 0; i < members.size(); ++i) {
    if (i) s += sep;
    s += std::to_string(members[i]);
  }
  return s;
}

}  // namespace

bool FleetSim::waiting(const Vehicle& v) const {
  return v.phase == Phase::kDrive && v.blocked && v.leg.alpha == 0.0;
}

void FleetSim::resolve_blockages() {
  for (Vehicle& v : vehicles_) {
    if (!waiting(v) || v.stopped_s < p_.deadlock_after_s) continue;
    if (v.reported && t_s_ < v.retry_s) continue;
    // Follow who waits on whom: a vehicle still moving or dwelling will free its cells.
    std::vector<int> chain{v.index};
    int j = v.waits_on;
    bool handled = false;
    for (std::size_t guard = 0; guard <= vehicles_.size() && j >= 0; ++guard) {
      const auto it = std::find(chain.begin(), chain.end(), j);
      if (it != chain.end()) {
        if (!handle_blockage(std::vector<int>(it, chain.end()), true)) {
          // A cycle packed in by its queue: the vehicles queued behind it make room instead,
          // nearest the cycle first, so that a member can then back out.
          for (auto q = it; q != chain.begin(); --q) {
            Vehicle& y = vehicles_[static_cast<std::size_t>(*(q - 1))];
            if (try_evade(y, &vehicles_[static_cast<std::size_t>(*q)])) {
              event(FleetEventKind::kEvade, {y.index, *q},
                    "vehicle " + std::to_string(y.index) +
                        " drives aside to make room for vehicle " + std::to_string(*q));
              break;
            }
          }
        }
        handled = true;
        break;
      }
      const Vehicle& w = vehicles_[static_cast<std::size_t>(j)];
      if (waiting(w)) {
        chain.push_back(j);
        j = w.waits_on;
        continue;
      }
      if (idle(w)) {
        handle_blockage({chain.back(), j}, false);
        handled = true;
      }
      break;
    }
    // Everyone on the chain waits for the outcome before it is looked at again.
    for (int m : handled ? chain : std::vector<int>{}) {
      Vehicle& w = vehicles_[static_cast<std::size_t>(m)];
      if (!w.reported) w.retry_s = t_s_ + kFleetRetryS;
      w.reported = true;
    }
  }
}

bool FleetSim::handle_blockage(const std::vector<int>& members, bool cycle) {
  Vehicle& first = vehicles_[static_cast<std::size_t>(members.front())];
  const bool new_episode = !first.reported;
  // Several vehicles queued behind one blockage lead to it: one attempt per retry period.
  if (!new_episode && t_s_ < first.retry_s) return true;
  if (new_episode) {
    if (cycle) {
      ++out_->deadlocks;
      event(FleetEventKind::kDeadlock, members,
            "vehicles " + fleet_member_list(members, " -> ") + " -> " +
                std::to_string(members.front()) + " wait on each other");
    } else {
      ++out_->blocked_by_idle;
      event(FleetEventKind::kBlockedByIdle, members,
            "vehicle " + std::to_string(members[0]) + " waits on vehicle " +
                std::to_string(members[1]) + ", which has nothing left to do");
    }
  }
  for (int m : members) {
    Vehicle& w = vehicles_[static_cast<std::size_t>(m)];
    w.reported = true;
    w.retry_s = t_s_ + kFleetRetryS;
  }
  // Who drives aside: the idle vehicle, then the one waiting on it (an idle vehicle boxed in
  // between vehicles coming from both ends can only leave once one of them has backed away); in
  // a cycle the lowest priority (highest index) first, out of the way of the member waiting on
  // it.
  std::vector<std::size_t> order{1, 0};
  if (cycle) {
    order.resize(members.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    std::sort(order.begin(), order.end(),
              [&](std::size_t a, std::size_t b) { return members[a] > members[b]; });
  }
  for (std::size_t i : order) {
    Vehicle& y = vehicles_[static_cast<std::size_t>(members[i])];
    const std::size_t before = cycle ? (i + members.size() - 1) % members.size() : 1 - i;
    const Vehicle& x = vehicles_[static_cast<std::size_t>(members[before])];
    if (try_evade(y, &x)) {
      event(FleetEventKind::kEvade, {y.index, x.index},
            "vehicle " + std::to_string(y.index) + " drives aside for vehicle " +
                std::to_string(x.index));
      return true;
    }
  }
  if (new_episode) {
    ++out_->unresolved;
    event(FleetEventKind::kUnresolved, members,
          "no vehicle of " + fleet_member_list(members, ", ") +
              " found a free place to drive aside to; they keep waiting");
  }
  return false;
}

void FleetSim::remaining_cells(const Vehicle& x, std::vector<std::uint8_t>* mark) const {
  if (x.has_leg) {
    for (int k = std::max(0, x.leg.lo); k < static_cast<int>(x.leg.samples()); ++k) {
      const int* c = x.leg.cells_of(k);
      for (std::size_t i = 0; i < x.leg.count_of(k); ++i)
        (*mark)[static_cast<std::size_t>(c[i])] = 1;
    }
  }
  for (int c : x.base_cells) (*mark)[static_cast<std::size_t>(c)] = 1;
}

bool FleetSim::try_evade(Vehicle& y, const Vehicle* x) {
  const Vec2 here{y.pose.x_mm, y.pose.y_mm};
  if (!planner_.point_free(here)) return false;  // no route can start here (mid-corner)
  std::mt19937_64 rng(p_.seed * 0x2545F4914F6CDD1DULL +
                      static_cast<std::uint64_t>(std::llround(t_s_ * 1000.0)) * 131 +
                      static_cast<std::uint64_t>(y.index));
  std::uniform_real_distribution<double> u(-kFleetEvadeBoxMm, kFleetEvadeBoxMm);
  std::vector<std::pair<double, Vec2>> refuges;
  for (int i = 0; i < kFleetEvadeDraws; ++i) {
    const Vec2 q{here.x + u(rng), here.y + u(rng)};
    const double d = std::hypot(q.x - here.x, q.y - here.y);
    if (d > 2.0 * y.reserve_mm && planner_.point_free(q)) refuges.push_back({d, q});
  }
  std::sort(refuges.begin(), refuges.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  // First a refuge on nobody's way, so that it does not start the next blockage; in a busy
  // aisle every free point can be on someone's plan, and then one on others' plans (but never on
  // the remaining route of the vehicle to let through) is better than standing in a jam.
  for (int pass = 0; pass < 2; ++pass) {
    std::fill(mark_.begin(), mark_.end(), std::uint8_t{0});
    if (x) remaining_cells(*x, &mark_);
    if (pass == 0) {
      const std::uint16_t* own =
          plan_own_.data() + static_cast<std::size_t>(y.index) * grid_.size();
      for (std::size_t c = 0; c < mark_.size(); ++c) {
        if (plan_total_[c] > own[c]) mark_[c] = 1;
      }
    }
    if (evade_to_refuge(y, refuges)) return true;
  }
  return false;
}

bool FleetSim::evade_to_refuge(Vehicle& y, const std::vector<std::pair<double, Vec2>>& refuges) {
  int tries = 0;
  for (const auto& [d, q] : refuges) {
    scratch_.clear();
    grid_.cells_near(q, y.reserve_mm, &scratch_);
    bool ok = grid_.blocker(y.index, scratch_.data(), scratch_.size()) < 0;
    for (std::size_t i = 0; ok && i < scratch_.size(); ++i)
      ok = mark_[static_cast<std::size_t>(scratch_[i])] == 0;
    if (!ok) continue;
    if (++tries > kFleetEvadeTries) break;
    Leg leg;
    std::string why;
    // A refuge behind a long detour is no refuge (and costly to try).
    if (!build_leg(y, q, &leg, &why, 2.0 * kFleetEvadeBoxMm)) continue;
    // The whole way is reserved at once: the vehicle never stops on it.
    if (grid_.blocker(y.index, leg.cells.data(), leg.cells.size()) >= 0) continue;
    grid_.acquire(y.index, leg.cells.data(), leg.cells.size());
    release_holdings(y);
    leg.lo = 0;
    leg.hi = static_cast<int>(leg.samples()) - 1;
    y.leg = std::move(leg);
    y.has_leg = true;
    y.leg_kind = LegKind::kEvade;
    y.phase = Phase::kTurn;
    y.turn_target_rad = y.leg.traj.at(0.0).pose.theta_rad;
    y.blocked = false;
    y.stopped_s = 0.0;
    ++out_->vehicles[static_cast<std::size_t>(y.index)].evasions;
    return true;
  }
  return false;
}

}  // namespace agv::sim::fleet_internal

// Map-guided identity: the pose gate and the module check (map_identity.hpp,
// docs/design/map_identity.md).
#include "agv/vision/map_identity.hpp"

#include <ZXing/BitMatrix.h>
#include <ZXing/MultiFormatWriter.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>

namespace agv::vision {

namespace {

// zxing-cpp 1.4 maps setEccLevel(0..8) to QR levels L,L,L,M,M,Q,Q,H,H; 4 is M, as in
// sim::encode_qr (the printed codes).
constexpr int kZxingEccLevelM = 4;
constexpr std::uint8_t kUnknownBit = 2;
constexpr int kLocalMeanRadius = 2;  // 5 x 5 modules
// Relative to the print's contrast (paper minus ink): below this local range the 5 x 5
// neighbourhood is flat (a cover), below this distance from the local mean a bit is undecided.
// Blur keeps a clean code's local range near the full contrast; noise (sigma ~3 DN on a
// ~180 DN contrast) stays far below both.
constexpr double kMinLocalRangeRel = 0.35;
constexpr double kMinMarginRel = 0.05;

double largest_eigen2(double a, double b, double c) {
  const double h = 0.5 * (a - c);
  return 0.5 * (a + c) + std::sqrt(h * h + b * b);
}

double mahalanobis2(const Eigen::Vector3d& r, const Eigen::Matrix3d& s) {
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(s);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) {
    return std::numeric_limits<double>::infinity();
  }
  const double d2 = r.dot(ldlt.solve(r));
  return std::isfinite(d2) && d2 >= 0.0 ? d2 : std::numeric_limits<double>::infinity();
}

}  // namespace

const char* to_string(MapIdentityResult r) {
  switch (r) {
    case MapIdentityResult::kAccepted:
      return "accepted";
    case MapIdentityResult::kNoPrediction:
      return "no prediction or map";
    case MapIdentityResult::kNoneInGate:
      return "no mapped landmark in the gate";
    case MapIdentityResult::kTwoPlausible:
      return "two mapped landmarks plausible";
    case MapIdentityResult::kModulesDisagree:
      return "QR modules disagree with the candidate";
  }
  return "unknown";
}

// V<-L = inverse(W<-V) * (W<-L). With d = L - V (world), p = R(-tv) d, heading tl - tv:
// dp/dV_xy = -R(-tv), dp/dtv = (p_y, -p_x), dheading/dtv = -1.
Pose2 predicted_landmark_in_vehicle(const Prediction& pred, const Pose2& lw, Eigen::Matrix3d* cov) {
  const Pose2& v = pred.vehicle_in_world;
  const Pose2 p = compose(inverse(v), lw);
  if (cov) {
    const double c = std::cos(v.theta_rad), s = std::sin(v.theta_rad);
    Eigen::Matrix3d j;
    j << -c, -s, p.y_mm, s, -c, -p.x_mm, 0.0, 0.0, -1.0;
    *cov = j * pred.cov * j.transpose();
  }
  return p;
}

double identity_search_radius_mm(Vec2 c_mm, const Eigen::Matrix3d& meas_cov, const Prediction& pred,
                                 double chi2) {
  const double inf = std::numeric_limits<double>::infinity();
  const Eigen::Matrix3d& p = pred.cov;
  if (!p.allFinite() || !meas_cov.allFinite() || !(chi2 >= 0.0) || !std::isfinite(chi2)) {
    return inf;
  }
  const double pos_var = largest_eigen2(p(0, 0), p(0, 1), p(1, 1));
  const double meas_var = largest_eigen2(meas_cov(0, 0), meas_cov(0, 1), meas_cov(1, 1));
  if (!(pos_var >= 0.0) || !(meas_var >= 0.0) || !(p(2, 2) >= 0.0)) return inf;
  const double k = std::sqrt(chi2);
  const double sigma_heading = std::sqrt(p(2, 2));
  if (!(k * sigma_heading < 1.0)) return inf;
  // |p - c| <= k * sqrt((sp + sh |p|)^2 + m) <= k * (sp + sh (|c| + |p - c|) + sqrt(m)),
  // solved for |p - c|.
  const double a =
      std::sqrt(pos_var) + sigma_heading * std::hypot(c_mm.x, c_mm.y) + std::sqrt(meas_var);
  return k * a / (1.0 - k * sigma_heading);
}

MapIdentityDecision gate_identity(Vec2 c_mm, double beta, const Eigen::Matrix3d& meas_cov,
                                  const std::array<bool, 4>& allowed_turns, const Prediction& pred,
                                  const LandmarkMap& map, const MapIdentityConfig& cfg,
                                  const LandmarkIndex* index) {
  MapIdentityDecision d;
  if (!pred.valid || map.entries.empty()) return d;
  const double inf = std::numeric_limits<double>::infinity();
  d.d2_best = inf;
  d.d2_second = inf;
  const auto score = [&](const LandmarkMapEntry& e) {
    const std::uint32_t id = e.id;
    Eigen::Matrix3d pc;
    const Pose2 p = predicted_landmark_in_vehicle(pred, e.pose, &pc);
    const Eigen::Matrix3d s = pc + meas_cov;
    for (int q = 0; q < 4; ++q) {
      if (!allowed_turns[static_cast<size_t>(q)]) continue;
      const Eigen::Vector3d r(p.x_mm - c_mm.x, p.y_mm - c_mm.y,
                              wrap_angle_rad(p.theta_rad - (beta - q * kPi / 2.0)));
      const double d2 = mahalanobis2(r, s);
      if (d2 < d.d2_best) {
        d.d2_second = d.d2_best;
        d.d2_best = d2;
        d.id = id;
        d.turn = q;
      } else if (d2 < d.d2_second) {
        d.d2_second = d2;
      }
    }
  };
  // Landmarks beyond the radius cannot be within either threshold, so leaving them out changes
  // neither the decision nor the candidate; the index returns the rest in the map's order.
  const double radius_mm =
      index
          ? identity_search_radius_mm(c_mm, meas_cov, pred, std::max(cfg.gate_chi2, cfg.clear_chi2))
          : std::numeric_limits<double>::infinity();
  if (std::isfinite(radius_mm)) {
    thread_local std::vector<const LandmarkMapEntry*> near;
    const Vec2 c_world = transform(pred.vehicle_in_world, c_mm);
    // The slack covers the rounding of the two distance computations at the disc's edge.
    index->within(c_world, radius_mm * (1.0 + 1e-9) + 1e-6, &near);
    for (const LandmarkMapEntry* e : near) score(*e);
  } else {
    for (const auto& [id, e] : map.entries) score(e);
  }
  if (!(d.d2_best <= cfg.gate_chi2)) {
    d.result = MapIdentityResult::kNoneInGate;
  } else if (!(d.d2_second > cfg.clear_chi2)) {
    d.result = MapIdentityResult::kTwoPlausible;
  } else {
    d.result = MapIdentityResult::kAccepted;
  }
  return d;
}

bool encode_qr_bits(const std::string& payload, QrBits* out) {
  if (payload.empty()) return false;
  try {
    const ZXing::BitMatrix bm = ZXing::MultiFormatWriter(ZXing::BarcodeFormat::QRCode)
                                    .setEccLevel(kZxingEccLevelM)
                                    .setMargin(0)
                                    .encode(payload, 0, 0);
    if (bm.width() <= 0 || bm.width() != bm.height()) return false;
    out->n = bm.width();
    out->dark.assign(static_cast<size_t>(out->n * out->n), 0);
    for (int r = 0; r < out->n; ++r) {
      for (int c = 0; c < out->n; ++c) {
        out->dark[static_cast<size_t>(r * out->n + c)] = bm.get(c, r) ? 1 : 0;
      }
    }
    return true;
  } catch (...) {
    return false;
  }
}

std::string map_full_payload(const LandmarkMapEntry& e) {
  LandmarkPayload p;
  p.id = e.id;
  p.has_pose = true;
  p.x_mm = e.pose.x_mm;
  p.y_mm = e.pose.y_mm;
  p.heading_deg = rad_to_deg(wrap_angle_rad(e.pose.theta_rad));
  return format_payload(p);
}

std::string map_id_payload(std::uint32_t id) {
  LandmarkPayload p;
  p.id = id;
  return format_payload(p);
}

void binarize_samples(const QrSamples& s, std::vector<std::uint8_t>* bits) {
  const int side = s.side();
  bits->assign(static_cast<size_t>(s.n * s.n), kUnknownBit);
  // Contrast of the print: the quiet zone's median (paper) against the code's darkest decile (ink).
  std::vector<float> tmp;
  for (int r = 0; r < side; ++r) {
    for (int c = 0; c < side; ++c) {
      const int rr = r - s.ring, cc = c - s.ring;
      const float v = s.v[static_cast<size_t>(r * side + c)];
      if (v >= 0.0f && (rr < 0 || cc < 0 || rr >= s.n || cc >= s.n)) tmp.push_back(v);
    }
  }
  if (tmp.empty()) return;
  std::nth_element(tmp.begin(), tmp.begin() + static_cast<std::ptrdiff_t>(tmp.size() / 2),
                   tmp.end());
  const double light = static_cast<double>(tmp[tmp.size() / 2]);
  tmp.clear();
  for (int r = 0; r < s.n; ++r) {
    for (int c = 0; c < s.n; ++c) {
      if (s.at(r, c) >= 0.0f) tmp.push_back(s.at(r, c));
    }
  }
  if (tmp.empty()) return;
  std::nth_element(tmp.begin(), tmp.begin() + static_cast<std::ptrdiff_t>(tmp.size() / 10),
                   tmp.end());
  const double contrast = light - static_cast<double>(tmp[tmp.size() / 10]);
  if (!(contrast > 0.0)) return;
  for (int r = 0; r < s.n; ++r) {
    for (int c = 0; c < s.n; ++c) {
      const float v = s.at(r, c);
      if (v < 0.0f) continue;
      double sum = 0, lo = static_cast<double>(v), hi = lo;
      int cnt = 0;
      const int gr = r + s.ring, gc = c + s.ring;
      for (int rr = std::max(0, gr - kLocalMeanRadius);
           rr <= std::min(side - 1, gr + kLocalMeanRadius); ++rr) {
        for (int cc = std::max(0, gc - kLocalMeanRadius);
             cc <= std::min(side - 1, gc + kLocalMeanRadius); ++cc) {
          const float w = s.v[static_cast<size_t>(rr * side + cc)];
          if (w < 0.0f) continue;
          sum += static_cast<double>(w);
          lo = std::min(lo, static_cast<double>(w));
          hi = std::max(hi, static_cast<double>(w));
          ++cnt;
        }
      }
      const double mean = sum / cnt;
      // A flat neighbourhood is a patch over the code (printed data always mixes both inks
      // within 5 x 5 modules), and a sample at its local mean is a coin flip: neither is evidence.
      if (hi - lo < kMinLocalRangeRel * contrast ||
          std::abs(static_cast<double>(v) - mean) < kMinMarginRel * contrast) {
        continue;
      }
      (*bits)[static_cast<size_t>(r * s.n + c)] = static_cast<double>(v) < mean ? 1 : 0;
    }
  }
}

// Only data (and format) modules count: the fixed patterns are the same in every code of one
// version, so they would raise every candidate's agreement alike.
ModuleAgreement check_modules(const std::vector<std::uint8_t>& bits, const QrBits& cand,
                              const std::vector<std::pair<std::uint32_t, const QrBits*>>& others,
                              const MapIdentityConfig& cfg) {
  ModuleAgreement a;
  const int n = cand.n;
  if (n <= 0 || bits.size() != static_cast<size_t>(n * n)) return a;
  int agree = 0;
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < n; ++c) {
      const size_t i = static_cast<size_t>(r * n + c);
      if (bits[i] == kUnknownBit || qr_fixed_module(n, r, c) >= 0) continue;
      ++a.visible;
      agree += bits[i] == cand.dark[i] ? 1 : 0;
    }
  }
  if (a.visible == 0) return a;
  a.agree = static_cast<double>(agree) / a.visible;
  bool pairs_ok = true;
  for (const auto& [id, o] : others) {
    if (!o || o->n != n || o == &cand) continue;
    int differ = 0, side_cand = 0;
    for (size_t i = 0; i < bits.size(); ++i) {
      if (bits[i] == kUnknownBit || o->dark[i] == cand.dark[i]) continue;
      ++differ;
      side_cand += bits[i] == cand.dark[i] ? 1 : 0;
    }
    if (differ == 0) continue;  // the same code (the same payload): nothing to tell apart
    const double f = differ >= cfg.min_pair_modules ? static_cast<double>(side_cand) / differ : 0.0;
    if (f < a.worst_pair) {
      a.worst_pair = f;
      a.worst_pair_id = id;
    }
    if (f < cfg.min_pair_agreement) pairs_ok = false;
  }
  a.ok = a.agree >= cfg.min_agreement && pairs_ok;
  return a;
}

}  // namespace agv::vision

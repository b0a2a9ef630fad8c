// The simulated site, fleet and frames of eval_overhead (world.hpp).
#include "world.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <utility>

#include "agv/site/planner.hpp"

namespace agv::eval {

namespace {

site::Polygon box(double x0, double y0, double x1, double y1) {
  return {{{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}}};
}

// Camera centres along one axis: the quarter points, moved in when the views would not overlap
// by 200 mm at tray height.
std::vector<double> camera_centres(double length_mm, double half_cover_mm, int n) {
  if (n == 1) return {0.5 * length_mm};
  const double c = std::min(0.5 * length_mm,
                            std::max(0.25 * length_mm, 0.5 * length_mm - half_cover_mm + 100.0));
  return {c, length_mm - c};
}

cv::Mat gain_map(int w, int h, const sim::SiteRenderParams& p) {
  cv::Mat g(h, w, CV_32F);
  const double a = deg_to_rad(p.illumination_direction_deg);
  const double dx = std::cos(a), dy = std::sin(a);
  double lo = 1e300, hi = -1e300;
  for (const auto& c : {Vec2{0, 0}, Vec2{double(w - 1), 0}, Vec2{0, double(h - 1)},
                        Vec2{double(w - 1), double(h - 1)}}) {
    lo = std::min(lo, c.x * dx + c.y * dy);
    hi = std::max(hi, c.x * dx + c.y * dy);
  }
  const double cx = 0.5 * (w - 1), cy = 0.5 * (h - 1);
  const double rc2 = cx * cx + cy * cy;
  for (int y = 0; y < h; ++y) {
    float* row = g.ptr<float>(y);
    for (int x = 0; x < w; ++x) {
      const double t = (x * dx + y * dy - lo) / std::max(1e-9, hi - lo);
      const double r2 = ((x - cx) * (x - cx) + (y - cy) * (y - cy)) / rc2;
      row[x] = static_cast<float>((1.0 - (1.0 - p.illumination_ratio) * t) *
                                  (1.0 - p.vignetting * r2) * p.exposure_gain);
    }
  }
  return g;
}

void apply_gain(cv::Mat* img, const cv::Mat& gain, const cv::Rect& r) {
  cv::Mat roi = (*img)(r), f;
  roi.convertTo(f, CV_32F);
  f = f.mul(gain(r));
  f.convertTo(roi, CV_8U);
}

}  // namespace

RegionRenderer::RegionRenderer(const CameraIntrinsics& k, const sim::SiteRenderParams& params)
    : k_(k), params_(params) {
  gain_ = gain_map(k.width_px, k.height_px, params);
  params_.illumination_ratio = 1.0;
  params_.vignetting = 0.0;
  params_.exposure_gain = 1.0;
}

void RegionRenderer::set_background(std::size_t camera, const sim::SiteScene& empty_scene,
                                    const sim::RenderCamera& cam, std::uint64_t seed) {
  if (background_.size() <= camera) background_.resize(camera + 1);
  sim::SiteFrameRenderer full(k_);
  cv::Mat& bg = background_[camera];
  bg = full.render(empty_scene, cam, params_, seed).image;
  if (!bg.empty()) apply_gain(&bg, gain_, {0, 0, k_.width_px, k_.height_px});
}

cv::Mat RegionRenderer::render(std::size_t camera, const sim::SiteScene& scene,
                               const sim::RenderCamera& cam, std::uint64_t seed) {
  if (camera >= background_.size() || background_[camera].empty()) return {};
  cv::Mat img = background_[camera].clone();
  std::vector<cv::Rect> boxes;
  for (std::size_t i = 0; i < scene.agvs.size() && i < scene.site.fleet.size(); ++i) {
    const cv::Rect b = vehicle_box(scene, i, cam);
    if (b.area() > 0) boxes.push_back(b);
  }
  // Overlapping boxes are merged (a region is rendered once, with every vehicle in it).
  for (bool merged = true; merged;) {
    merged = false;
    for (std::size_t a = 0; a < boxes.size() && !merged; ++a) {
      for (std::size_t b = a + 1; b < boxes.size() && !merged; ++b) {
        if ((boxes[a] & boxes[b]).area() > 0) {
          boxes[a] |= boxes[b];
          boxes.erase(boxes.begin() + static_cast<std::ptrdiff_t>(b));
          merged = true;
        }
      }
    }
  }
  std::uint64_t n = 0;
  for (const cv::Rect& dst : boxes) {
    // The region's own camera: the same lens and pose, the principal point moved; rendered with
    // a margin so the defocus filter sees real neighbours at the region's edge.
    CameraIntrinsics t = k_;
    t.width_px = dst.width + 2 * kMargin;
    t.height_px = dst.height + 2 * kMargin;
    t.cx = k_.cx - (dst.x - kMargin);
    t.cy = k_.cy - (dst.y - kMargin);
    const sim::SiteFrameRenderer rr(t);
    sim::RenderCamera rc = cam;
    rc.intrinsics = t;
    const cv::Mat part = rr.render(scene, rc, params_, seed * 1000003ULL + n++).image;
    if (part.empty()) continue;
    part(cv::Rect(kMargin, kMargin, dst.width, dst.height)).copyTo(img(dst));
    apply_gain(&img, gain_, dst);
    pixels_rendered_ += static_cast<std::size_t>(dst.area());
  }
  return img;
}

cv::Rect RegionRenderer::vehicle_box(const sim::SiteScene& scene, std::size_t i,
                                     const sim::RenderCamera& cam) const {
  const site::FleetAgv& a = scene.site.fleet[i];
  const Pose2& p = scene.agvs[i].pose;
  // Body and tray (and the parcels on it, which may overhang it, up to their tops).
  double r = std::max(a.radius_mm, 0.5 * std::hypot(a.tray_length_mm, a.tray_width_mm));
  double top = a.tray_height_mm;
  for (const sim::Parcel& pc : scene.parcels) {
    if (pc.agv != i) continue;
    r = std::max(r, std::hypot(pc.x_mm, pc.y_mm) + 0.5 * std::hypot(pc.length_mm, pc.width_mm));
    top = std::max(top, a.tray_height_mm + pc.height_mm);
  }
  r += 60.0;
  std::vector<sim::Vec3> pts;
  for (int k = 0; k < 8; ++k) {
    const double ang = k * kPi / 4;
    for (double z : {0.0, top + 20.0}) {
      pts.push_back({p.x_mm + r * std::cos(ang), p.y_mm + r * std::sin(ang), z});
    }
  }
  std::vector<std::uint8_t> ok;
  const std::vector<Vec2> px = sim::project_points(cam, pts, &ok);
  double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
  for (std::size_t j = 0; j < px.size(); ++j) {
    if (!ok[j]) continue;
    x0 = std::min(x0, px[j].x), x1 = std::max(x1, px[j].x);
    y0 = std::min(y0, px[j].y), y1 = std::max(y1, px[j].y);
  }
  if (!(x0 < x1 && y0 < y1) || x1 < 0 || y1 < 0 || x0 >= k_.width_px || y0 >= k_.height_px) {
    return {};
  }
  const cv::Rect b(static_cast<int>(std::floor(std::max(0.0, x0))),
                   static_cast<int>(std::floor(std::max(0.0, y0))), 0, 0);
  const int xe = static_cast<int>(std::ceil(std::min<double>(k_.width_px, x1)));
  const int ye = static_cast<int>(std::ceil(std::min<double>(k_.height_px, y1)));
  return {b.x, b.y, xe - b.x, ye - b.y};
}

namespace {

// Load times (and, with cover_tags, a first parcel over the whole tag) for the parcels drawn.
void load_parcels(const WorldOptions& o, const std::vector<site::FleetAgv>& fleet,
                  std::vector<sim::Parcel>* parcels, std::vector<std::int64_t>* load_ns) {
  std::mt19937_64 rng(o.seed * 31 + 17);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<std::int64_t> agv_load_ns(fleet.size(), 0);
  for (std::int64_t& t : agv_load_ns) {
    if (o.load_from_s >= 0.0) {
      t = static_cast<std::int64_t>(1e9 * (o.load_from_s + 0.5 * o.duration_s * u01(rng)));
    }
  }
  std::vector<std::uint8_t> first(fleet.size(), 1);
  load_ns->clear();
  for (sim::Parcel& p : *parcels) {
    if (p.agv >= fleet.size()) continue;
    load_ns->push_back(agv_load_ns[p.agv]);
    if (!o.cover_tags || !first[p.agv]) continue;
    first[p.agv] = 0;
    // Wider than the tag's diagonal whatever its turn, and off centre by less than the margin.
    const double side = 1.5 * fleet[p.agv].tag_size_mm + 80.0 * u01(rng);
    p.length_mm = side;
    p.width_mm = side;
    p.x_mm = 20.0 * (u01(rng) - 0.5);
    p.y_mm = 20.0 * (u01(rng) - 0.5);
  }
}

}  // namespace

bool World::build(const WorldOptions& o, std::string* error) {
  site_ = site::Site{};
  site_.name = "eval_overhead";
  site_.outline = box(0, 0, o.site_mm, o.site_mm);
  site_.clearance_mm = 100.0;
  for (int i = 0; i < o.agvs; ++i) {
    site::FleetAgv a;
    a.id = "agv-" + std::to_string(i + 1);
    a.tag_id = static_cast<std::uint32_t>(i + 1);
    site_.fleet.push_back(a);
  }
  const double tray_mm = site::FleetAgv{}.tray_height_mm;
  const double depth_mm = o.camera_height_mm - tray_mm;
  const double f = o.tag_px * depth_mm / site::FleetAgv{}.tag_size_mm;
  CameraIntrinsics k;
  k.width_px = o.width_px;
  k.height_px = o.height_px;
  k.fx = k.fy = f;
  k.cx = 0.5 * (o.width_px - 1);
  k.cy = 0.5 * (o.height_px - 1);
  k.k1 = o.k1;
  k.k2 = o.k2;
  const int per_axis = o.cameras == 1 ? 1 : 2;
  const std::vector<double> xs =
      camera_centres(o.site_mm, 0.5 * o.width_px / f * depth_mm, per_axis);
  const std::vector<double> ys =
      camera_centres(o.site_mm, 0.5 * o.height_px / f * depth_mm, per_axis);
  for (double y : ys) {
    for (double x : xs) {
      site::CeilingCamera c;
      c.id = "ceiling-" + std::to_string(site_.cameras.size() + 1);
      c.intrinsics = k;
      c.t_site_cam_mm = {x, y, o.camera_height_mm};
      site_.cameras.push_back(c);
    }
  }
  const std::vector<double> radii(static_cast<std::size_t>(o.agvs), site::FleetAgv{}.radius_mm);
  site::RoutePlanner& planner = planner_;
  if (!sim::route_planner_for_fleet(site_, radii, &planner, error)) return false;
  std::vector<sim::FleetVehicleSpec> specs;
  const int tasks = 2 + static_cast<int>(o.duration_s / 10.0);
  if (!sim::make_random_fleet(planner, site_, radii, tasks, o.seed, &specs, error, 2500.0)) {
    return false;
  }
  sim::FleetParams fp;
  fp.duration_s = o.duration_s + 0.1;
  fp.seed = o.seed;
  fp.gyro_enabled = false;
  if (!sim::simulate_fleet(site_, planner, specs, fp, &fleet_, error)) return false;

  sim::SiteScene s = scene_at(0);
  if (o.parcels > 0.0) sim::add_random_parcels(&s, o.parcels, o.seed + 11);
  load_parcels(o, site_.fleet, &s.parcels, &parcel_load_ns);
  // Pallets only: low, so a vehicle driving over one's spot (clutter is placed at the start
  // poses, not along the routes) still shows its tray.
  if (o.clutter > 0) sim::add_random_clutter(&s, 0, o.clutter, o.seed + 13);
  parcels = s.parcels;
  clutter = s.clutter;
  draw_tray_planes(o, site_.fleet.size());
  return true;
}

void World::draw_tray_planes(const WorldOptions& o, std::size_t n) {
  std::mt19937_64 rng(o.seed + 17);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const double tilt = o.tray_tilt_deg * kPi / 180.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double dir = 2.0 * kPi * u01(rng);
    tray_roll_rad.push_back(tilt * std::cos(dir));
    tray_pitch_rad.push_back(tilt * std::sin(dir));
    tray_dz_mm.push_back(o.tray_height_error_mm * (2.0 * u01(rng) - 1.0));
  }
}

std::vector<sim::AgvState> World::states_at(std::int64_t t_ns) const {
  std::vector<sim::AgvState> out;
  for (const sim::FleetVehicleOutput& v : fleet_.vehicles) {
    sim::AgvState st;
    if (!v.truth.empty()) {
      const std::int64_t period = v.truth.size() > 1 ? v.truth[1].t_ns - v.truth[0].t_ns : 1;
      const std::int64_t idx =
          std::clamp<std::int64_t>((t_ns - v.truth[0].t_ns + period / 2) / period, 0,
                                   static_cast<std::int64_t>(v.truth.size()) - 1);
      const sim::FleetTruthSample& s = v.truth[static_cast<std::size_t>(idx)];
      st.v_mps = s.v_mps;
      st.omega_radps = s.omega_radps;
      st.pose = s.pose;
      st.pose = sim::advance_agv_pose(st, 1e-9 * static_cast<double>(t_ns - s.t_ns));
    }
    if (out.size() < tray_roll_rad.size()) {
      st.tray_roll_rad = tray_roll_rad[out.size()];
      st.tray_pitch_rad = tray_pitch_rad[out.size()];
    }
    out.push_back(st);
  }
  return out;
}

std::vector<RouteEvent> World::route_events() const {
  std::vector<RouteEvent> out;
  for (const sim::FleetTaskRecord& r : fleet_.tasks) {
    const auto agv = static_cast<std::size_t>(r.vehicle);
    if (agv >= fleet_.vehicles.size()) continue;
    const std::pair<double, Vec2> legs[2] = {{r.start_s, r.task.pick_mm},
                                             {r.picked_s, r.task.drop_mm}};
    for (const auto& [t_s, goal] : legs) {
      if (t_s < 0.0) continue;
      const auto t_ns = static_cast<std::int64_t>(std::llround(t_s * 1e9));
      const Pose2 at = states_at(t_ns)[agv].pose;
      const site::Route route = planner_.plan({at.x_mm, at.y_mm}, goal);
      if (route.status != site::PlanStatus::kOk || route.waypoints_mm.size() < 2) continue;
      out.push_back({t_ns, agv, route.waypoints_mm});
    }
  }
  std::stable_sort(out.begin(), out.end(),
                   [](const RouteEvent& a, const RouteEvent& b) { return a.t_ns < b.t_ns; });
  return out;
}

sim::SiteScene World::scene_at(std::int64_t t_ns) const {
  sim::SiteScene s;
  s.site = site_;
  for (std::size_t i = 0; i < s.site.fleet.size() && i < tray_dz_mm.size(); ++i) {
    s.site.fleet[i].tray_height_mm += tray_dz_mm[i];
  }
  s.agvs = states_at(t_ns);
  for (std::size_t i = 0; i < parcels.size(); ++i) {
    if (parcel_load_ns[i] <= t_ns) s.parcels.push_back(parcels[i]);
  }
  s.clutter = clutter;
  return s;
}

std::vector<std::uint8_t> World::tags_covered_at(std::int64_t t_ns) const {
  std::vector<std::uint8_t> out(site_.fleet.size(), 0);
  for (std::size_t i = 0; i < parcels.size(); ++i) {
    const sim::Parcel& p = parcels[i];
    if (parcel_load_ns[i] > t_ns || p.agv >= out.size()) continue;
    const double h = 0.5 * site_.fleet[p.agv].tag_size_mm;
    const Pose2 parcel_on_tray{p.x_mm, p.y_mm, p.yaw_rad};
    bool all = true;
    for (const Vec2 c : {Vec2{h, h}, Vec2{h, -h}, Vec2{-h, -h}, Vec2{-h, h}}) {
      const Vec2 q = transform(inverse(parcel_on_tray), c);
      all = all && std::abs(q.x) < 0.5 * p.length_mm && std::abs(q.y) < 0.5 * p.width_mm;
    }
    if (all) out[p.agv] = 1;
  }
  return out;
}

std::vector<std::array<Vec2, 4>> World::tag_corners(const sim::RenderCamera& cam,
                                                    const std::vector<sim::AgvState>& states,
                                                    std::vector<std::uint8_t>* ok) const {
  std::vector<sim::Vec3> pts;
  for (std::size_t i = 0; i < states.size(); ++i) {
    const site::FleetAgv& a = site_.fleet[i];
    const double h = 0.5 * a.tag_size_mm;
    // Page order seen from above: top-left = front-left, then front-right, rear-right, rear-left.
    for (const Vec2 c : {Vec2{h, h}, Vec2{h, -h}, Vec2{-h, -h}, Vec2{-h, h}}) {
      const Vec2 p = transform(states[i].pose, c);
      const double dz = i < tray_dz_mm.size() ? tray_dz_mm[i] : 0.0;
      pts.push_back({p.x, p.y, a.tray_height_mm + dz});
    }
  }
  std::vector<std::uint8_t> pok;
  const std::vector<Vec2> px = sim::project_points(cam, pts, &pok);
  std::vector<std::array<Vec2, 4>> out(states.size());
  ok->assign(states.size(), 1);
  for (std::size_t i = 0; i < states.size(); ++i) {
    for (std::size_t c = 0; c < 4; ++c) {
      out[i][c] = px[4 * i + c];
      if (!pok[4 * i + c]) (*ok)[i] = 0;
    }
  }
  return out;
}

int flip_tag_cells(cv::Mat* gray, const std::array<Vec2, 4>& corners_px, int n,
                   std::mt19937_64* rng) {
  // Grid units: the black square spans 0..8 (a border cell, 6 data cells, a border cell).
  std::vector<cv::Point2f> grid{{0, 0}, {8, 0}, {8, 8}, {0, 8}}, img;
  for (const Vec2& c : corners_px)
    img.emplace_back(static_cast<float>(c.x), static_cast<float>(c.y));
  const cv::Matx33d hm = cv::getPerspectiveTransform(grid, img);
  auto map = [&](double u, double v) {
    const cv::Vec3d q = hm * cv::Vec3d(u, v, 1.0);
    return cv::Point2d(q[0] / q[2], q[1] / q[2]);
  };
  auto sample = [&](double u, double v) {
    const cv::Point2d p = map(u, v);
    const int x = static_cast<int>(std::lround(p.x)), y = static_cast<int>(std::lround(p.y));
    if (x < 0 || y < 0 || x >= gray->cols || y >= gray->rows) return -1.0;
    return static_cast<double>(gray->at<std::uint8_t>(y, x));
  };
  double black = 0.0;
  int nb = 0;
  for (int k = 0; k < 8; ++k) {
    for (const auto& uv : {cv::Point2d(k + 0.5, 0.5), cv::Point2d(k + 0.5, 7.5),
                           cv::Point2d(0.5, k + 0.5), cv::Point2d(7.5, k + 0.5)}) {
      const double s = sample(uv.x, uv.y);
      if (s < 0) return 0;
      black += s, ++nb;
    }
  }
  black /= nb;
  std::array<double, 36> cell{};
  double white = black;
  for (int i = 0; i < 36; ++i) {
    cell[static_cast<std::size_t>(i)] = sample(1.5 + i % 6, 1.5 + i / 6);
    white = std::max(white, cell[static_cast<std::size_t>(i)]);
  }
  if (white - black < 20.0) return 0;
  std::array<int, 36> order{};
  for (int i = 0; i < 36; ++i) order[static_cast<std::size_t>(i)] = i;
  std::shuffle(order.begin(), order.end(), *rng);
  const int m = std::clamp(n, 0, 36);
  for (int j = 0; j < m; ++j) {
    const int i = order[static_cast<std::size_t>(j)];
    const double u = 1 + i % 6, v = 1 + i / 6;
    const bool is_white = cell[static_cast<std::size_t>(i)] > 0.5 * (black + white);
    std::vector<cv::Point> poly;
    for (const auto& uv : {cv::Point2d(u, v), cv::Point2d(u + 1, v), cv::Point2d(u + 1, v + 1),
                           cv::Point2d(u, v + 1)}) {
      const cv::Point2d p = map(uv.x, uv.y);
      poly.emplace_back(static_cast<int>(std::lround(p.x * 16)),
                        static_cast<int>(std::lround(p.y * 16)));
    }
    cv::fillConvexPoly(*gray, poly, cv::Scalar(is_white ? black : white), cv::LINE_AA, 4);
  }
  return m;
}

site::CeilingCamera perturbed(const site::CeilingCamera& cam, double error_mm, double error_deg,
                              std::mt19937_64* rng) {
  std::normal_distribution<double> nd(0.0, 1.0);
  auto unit = [&]() {
    cv::Vec3d v(nd(*rng), nd(*rng), nd(*rng));
    return v / std::max(1e-12, cv::norm(v));
  };
  site::CeilingCamera out = cam;
  const cv::Vec3d d = unit() * error_mm;
  for (int i = 0; i < 3; ++i) out.t_site_cam_mm[static_cast<std::size_t>(i)] += d[i];
  const cv::Vec3d axis = unit();
  const double a = deg_to_rad(error_deg);
  // Rodrigues: R' = Rot(axis, a) * R (a rotation in the site frame).
  const double c = std::cos(a), s = std::sin(a), t = 1.0 - c;
  const double x = axis[0], y = axis[1], z = axis[2];
  const cv::Matx33d rot(t * x * x + c, t * x * y - s * z, t * x * z + s * y, t * x * y + s * z,
                        t * y * y + c, t * y * z - s * x, t * x * z - s * y, t * y * z + s * x,
                        t * z * z + c);
  const auto& r = cam.r_site_cam;
  const cv::Matx33d rm(r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8]);
  const cv::Matx33d rn = rot * rm;
  for (int i = 0; i < 9; ++i) out.r_site_cam[static_cast<std::size_t>(i)] = rn.val[i];
  return out;
}

}  // namespace agv::eval

#include "diag.hpp"

#include <cstdio>
#include <utility>

#include "agv/diag/diag.hpp"

namespace agv::overhead_app {

namespace {

constexpr overhead::TrackState kStates[] = {
    overhead::TrackState::kNone, overhead::TrackState::kTentative, overhead::TrackState::kConfirmed,
    overhead::TrackState::kCoasting, overhead::TrackState::kLost};

// A Prometheus label value: backslash, double quote and newline escaped.
std::string label(const std::string& v) {
  std::string out;
  for (const char c : v) {
    if (c == '\\' || c == '"') out += '\\';
    out += c == '\n' ? std::string("\\n") : std::string(1, c);
  }
  return out;
}

void line(std::string* out, const char* name, const std::string& labels, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, " %.17g\n", v);
  *out += name;
  if (!labels.empty()) *out += "{" + labels + "}";
  *out += buf;
}

void help(std::string* out, const char* name, const char* type, const char* text) {
  *out += std::string("# HELP ") + name + " " + text + "\n# TYPE " + name + " " + type + "\n";
}

// Seconds from the vehicle's last fix to the view's time; -1 without a track.
double fix_age_s(const AgvDiag& a, std::int64_t t_ns) {
  if (a.track.state == overhead::TrackState::kNone) return -1.0;
  return 1e-9 * static_cast<double>(t_ns - a.track.last_fix_t_ns);
}

void camera_metrics(const DiagView& v, std::string* out) {
  struct Row {
    const char* name;
    const char* type;
    const char* text;
    double (*get)(const CameraDiag&);
  };
  static const Row rows[] = {
      {"agvloc_overhead_camera_frames_total", "counter", "Frames taken from the camera",
       [](const CameraDiag& c) { return static_cast<double>(c.health.frames); }},
      {"agvloc_overhead_camera_fps", "gauge", "Frames per second over the last second",
       [](const CameraDiag& c) { return c.fps; }},
      {"agvloc_overhead_camera_driver_dropped_total", "counter",
       "Frames the driver dropped (known when the stream stops)",
       [](const CameraDiag& c) { return static_cast<double>(c.health.driver_dropped); }},
      {"agvloc_overhead_camera_faults_total", "counter",
       "Camera faults: failed starts and disconnects, one per outage",
       [](const CameraDiag& c) { return static_cast<double>(c.health.faults); }},
      {"agvloc_overhead_camera_recoveries_total", "counter", "Streaming again after a fault",
       [](const CameraDiag& c) { return static_cast<double>(c.health.recoveries); }},
      {"agvloc_overhead_camera_fault", "gauge", "1 while the camera is in a fault",
       [](const CameraDiag& c) { return c.health.failing ? 1.0 : 0.0; }},
      {"agvloc_overhead_camera_stamps_backwards_total", "counter",
       "Frames stamped no later than the camera's previous one",
       [](const CameraDiag& c) { return static_cast<double>(c.health.stamps_backwards); }},
      {"agvloc_overhead_camera_clock_mapped", "gauge",
       "1 when the camera's own clock is mapped onto the host's",
       [](const CameraDiag& c) { return c.health.clock_mapped ? 1.0 : 0.0; }},
      {"agvloc_overhead_camera_clock_offset_seconds", "gauge",
       "Host clock minus camera clock (when mapped)",
       [](const CameraDiag& c) { return 1e-9 * static_cast<double>(c.health.clock_offset_ns); }},
      {"agvloc_overhead_camera_clock_drift_ppm", "gauge",
       "The camera clock's rate against the host's (when mapped)",
       [](const CameraDiag& c) { return c.health.clock_drift_ppm; }},
      {"agvloc_overhead_camera_clock_jumps_total", "counter",
       "Jumps of the camera clock (the mapping restarted)",
       [](const CameraDiag& c) { return static_cast<double>(c.health.clock_jumps); }},
  };
  for (const Row& r : rows) {
    help(out, r.name, r.type, r.text);
    for (const CameraDiag& c : v.cameras)
      line(out, r.name, "camera=\"" + label(c.id) + "\"", r.get(c));
  }
}

void agv_metrics(const DiagView& v, std::string* out) {
  help(out, "agvloc_overhead_agv_state", "gauge", "1 for the track's state (none: never seen)");
  for (const AgvDiag& a : v.agvs) {
    for (const overhead::TrackState s : kStates) {
      line(out, "agvloc_overhead_agv_state",
           "agv=\"" + label(a.id) + "\",state=\"" + overhead::to_string(s) + "\"",
           a.track.state == s ? 1.0 : 0.0);
    }
  }
  help(out, "agvloc_overhead_agv_sigma_xy_mm", "gauge", "1 sigma of the position (mm)");
  for (const AgvDiag& a : v.agvs)
    line(out, "agvloc_overhead_agv_sigma_xy_mm", "agv=\"" + label(a.id) + "\"",
         a.track.sigma_xy_mm);
  help(out, "agvloc_overhead_agv_sigma_theta_rad", "gauge", "1 sigma of the heading (rad)");
  for (const AgvDiag& a : v.agvs) {
    line(out, "agvloc_overhead_agv_sigma_theta_rad", "agv=\"" + label(a.id) + "\"",
         a.track.sigma_theta_rad);
  }
  help(out, "agvloc_overhead_agv_last_fix_age_seconds", "gauge",
       "Time since the vehicle's last fix (-1: no track)");
  for (const AgvDiag& a : v.agvs) {
    line(out, "agvloc_overhead_agv_last_fix_age_seconds", "agv=\"" + label(a.id) + "\"",
         fix_age_s(a, v.t_ns));
  }
  help(out, "agvloc_overhead_agv_fix_source", "gauge",
       "1 for where the last fix came from: the tag or the tray's box");
  for (const AgvDiag& a : v.agvs) {
    for (const char* s : {"tag", "tray"}) {
      line(out, "agvloc_overhead_agv_fix_source",
           "agv=\"" + label(a.id) + "\",source=\"" + s + "\"",
           std::string(a.source) == s ? 1.0 : 0.0);
    }
  }
}

void bus_metrics(const BusDiag& b, std::string* out) {
  const auto total = [out](const char* name, const char* text, std::uint64_t v) {
    help(out, name, "counter", text);
    line(out, name, "", static_cast<double>(v));
  };
  total("agvloc_overhead_detections_messages_total",
        "Detections messages taken from the broker, refused ones included", b.messages);
  help(out, "agvloc_overhead_detections_refused_total", "counter",
       "Detections messages refused (never applied), by reason");
  for (const auto& [reason, n] : b.refused) {
    line(out, "agvloc_overhead_detections_refused_total", "reason=\"" + label(reason) + "\"",
         static_cast<double>(n));
  }
  total("agvloc_overhead_detections_lost_total",
        "Detections messages lost on the way (skipped sequence numbers)", b.lost);
  total("agvloc_overhead_detections_dropped_total",
        "Detections messages dropped undecoded because the tracker was behind", b.dropped_behind);
  total("agvloc_overhead_detections_tags_total", "Tags of the applied detections messages", b.tags);
  help(out, "agvloc_overhead_detections_tags_refused_total", "counter",
       "Tags of applied messages that moved no track, by reason");
  const std::pair<const char*, std::uint64_t> tags[] = {
      {"unknown_id", b.unknown_ids},
      {"no_fix", b.no_fix},
      {"restricted_decode", b.restricted_refused}};
  for (const auto& [reason, n] : tags) {
    line(out, "agvloc_overhead_detections_tags_refused_total",
         std::string("reason=\"") + reason + "\"", static_cast<double>(n));
  }
}

void orders_metrics(const OrdersDiag& o, std::string* out) {
  const auto total = [out](const char* name, const char* text, std::uint64_t v) {
    help(out, name, "counter", text);
    line(out, name, "", static_cast<double>(v));
  };
  total("agvloc_overhead_orders_messages_total", "Messages on the vehicles' order topics",
        o.messages);
  total("agvloc_overhead_orders_routes_set_total", "Orders whose base became a vehicle's route",
        o.routes_set);
  total("agvloc_overhead_orders_routes_cleared_total",
        "Orders that left a vehicle without a route (one node, or one it cannot follow)",
        o.routes_cleared);
  total("agvloc_overhead_orders_duplicates_total", "Orders repeated (same update)", o.duplicates);
  help(out, "agvloc_overhead_orders_refused_total", "counter",
       "Orders refused (never applied), by reason");
  for (const auto& [reason, n] : o.refused) {
    line(out, "agvloc_overhead_orders_refused_total", "reason=\"" + label(reason) + "\"",
         static_cast<double>(n));
  }
}

void tray_metrics(const TrayDiag& t, std::string* out) {
  const char* boxes = "agvloc_overhead_tray_boxes_total";
  help(out, boxes, "counter", "Tray boxes of covered tags, by what the track did with them");
  line(out, boxes, "result=\"applied\"", static_cast<double>(t.applied));
  line(out, boxes, "result=\"gated\"", static_cast<double>(t.gated));
  help(out, "agvloc_overhead_tray_refused_total", "counter",
       "Covered tags whose tray box was refused, by reason (sides_hidden, no_outline: the "
       "parcel hides the outline; uncertain_prediction: too long without a fix)");
  for (const auto& [reason, n] : t.refused) {
    line(out, "agvloc_overhead_tray_refused_total", "reason=\"" + label(reason) + "\"",
         static_cast<double>(n));
  }
  help(out, "agvloc_overhead_tray_tag_disagree_total", "counter",
       "Learned boxes at a vehicle whose tag was read that disagree with the tag (the tag wins)");
  line(out, "agvloc_overhead_tray_tag_disagree_total", "", static_cast<double>(t.tag_disagree));
}

}  // namespace

std::string overhead_metrics_text(const DiagView& v, const HttpCounters& http) {
  std::string out;
  struct Total {
    const char* name;
    const char* text;
    std::uint64_t value;
  };
  const Total totals[] = {
      {"agvloc_overhead_ticks_total", "Publish ticks", v.ticks},
      {"agvloc_overhead_ticks_skipped_total", "Ticks skipped (the loop fell behind)",
       v.ticks_skipped},
      {"agvloc_overhead_frames_total", "Frames received from every camera", v.frames},
      {"agvloc_overhead_frames_dropped_total",
       "Frames dropped because the pipeline was behind (every camera)", v.frames_dropped},
      {"agvloc_overhead_diag_requests_total", "Diagnostics requests answered", http.requests},
      {"agvloc_overhead_diag_refused_busy_total", "Diagnostics requests refused: busy",
       http.refused_busy},
      {"agvloc_overhead_diag_refused_bad_total", "Diagnostics requests refused: bad request",
       http.refused_bad},
  };
  for (const Total& t : totals) {
    help(&out, t.name, "counter", t.text);
    line(&out, t.name, "", static_cast<double>(t.value));
  }
  camera_metrics(v, &out);
  agv_metrics(v, &out);
  if (v.has_bus) bus_metrics(v.bus, &out);
  if (v.has_orders) orders_metrics(v.orders, &out);
  if (v.has_tray) tray_metrics(v.tray, &out);
  return out;
}

std::string overhead_status_json(const DiagView& v, const site::Site* site) {
  using diag::append_json_number;
  using diag::append_json_string;
  std::string o = "{\"t_ns\":" + std::to_string(v.t_ns) + ",\"ticks\":" + std::to_string(v.ticks) +
                  ",\"frames\":" + std::to_string(v.frames) +
                  ",\"frames_dropped\":" + std::to_string(v.frames_dropped) + ",\"cameras\":[";
  for (std::size_t i = 0; i < v.cameras.size(); ++i) {
    const CameraDiag& c = v.cameras[i];
    o += i ? ",{\"id\":" : "{\"id\":";
    append_json_string(&o, c.id.c_str());
    o += ",\"frames\":" + std::to_string(c.health.frames) + ",\"fps\":";
    append_json_number(&o, c.fps);
    o += ",\"faults\":" + std::to_string(c.health.faults) +
         ",\"fault\":" + (c.health.failing ? "true" : "false") +
         ",\"driver_dropped\":" + std::to_string(c.health.driver_dropped) +
         ",\"clock_mapped\":" + (c.health.clock_mapped ? "true" : "false") +
         ",\"clock_offset_ns\":" + std::to_string(c.health.clock_offset_ns) + "}";
  }
  o += "],\"agvs\":[";
  for (std::size_t i = 0; i < v.agvs.size(); ++i) {
    const AgvDiag& a = v.agvs[i];
    o += i ? ",{\"id\":" : "{\"id\":";
    append_json_string(&o, a.id.c_str());
    o += ",\"state\":";
    append_json_string(&o, overhead::to_string(a.track.state));
    for (const auto& [k, val] :
         {std::pair{"x_mm", a.track.pose.x_mm}, std::pair{"y_mm", a.track.pose.y_mm},
          std::pair{"theta_rad", a.track.pose.theta_rad},
          std::pair{"sigma_xy_mm", a.track.sigma_xy_mm},
          std::pair{"sigma_theta_rad", a.track.sigma_theta_rad},
          std::pair{"last_fix_age_s", fix_age_s(a, v.t_ns)}}) {
      o += std::string(",\"") + k + "\":";
      append_json_number(&o, val);
    }
    o += ",\"source\":";
    append_json_string(&o, a.source);
    o += "}";
  }
  o += "],\"views\":[";
  for (std::size_t i = 0; site && i < site->cameras.size(); ++i) {
    o += (i ? ",{\"index\":" : "{\"index\":") + std::to_string(i) + ",\"id\":";
    append_json_string(&o, site->cameras[i].id.c_str());
    o += "}";
  }
  return o + "]}";
}

namespace {

const char* kPage = R"(<!doctype html>
<html><head><meta charset="utf-8"><title>agvloc-overhead</title>
<style>body{font:14px sans-serif;margin:1em}table{border-collapse:collapse;margin-bottom:1em}
td,th{border:1px solid #bbb;padding:2px 8px;text-align:right}.bad{background:#fcc}</style></head>
<body><h1>agvloc-overhead</h1><p id="t"></p><h2>Cameras</h2><table id="c"></table>
<h2>Vehicles</h2><table id="a"></table>
<h2>Site</h2><p><a href="/site.svg"><img id="site" alt="no site map" style="max-width:100%"></a></p>
<h2>Camera views</h2><div id="v"></div><p><a href="/metrics">/metrics</a></p>
<script>
function row(cells,cls){const r=document.createElement('tr');if(cls)r.className=cls;
for(const c of cells){const d=document.createElement('td');d.textContent=c;r.appendChild(d);}return r;}
function head(t,names){t.replaceChildren();const r=document.createElement('tr');
for(const n of names){const h=document.createElement('th');h.textContent=n;r.appendChild(h);}t.appendChild(r);}
function fmt(v,d){return v===null?'':Number(v).toFixed(d);}
async function tick(){try{const s=await (await fetch('/api/status.json')).json();
document.getElementById('t').textContent='ticks '+s.ticks+', frames '+s.frames+', dropped '+s.frames_dropped;
const c=document.getElementById('c');head(c,['camera','frames','fps','faults','fault','clock offset ns']);
for(const k of s.cameras)c.appendChild(row([k.id,k.frames,fmt(k.fps,1),k.faults,k.fault?'yes':'',
k.clock_mapped?k.clock_offset_ns:''],k.fault?'bad':''));
const a=document.getElementById('a');head(a,['vehicle','state','x mm','y mm','theta deg','sigma mm','last fix s','source']);
for(const v of s.agvs)a.appendChild(row([v.id,v.state,fmt(v.x_mm,1),fmt(v.y_mm,1),fmt(v.theta_rad*57.29578,2),
fmt(v.sigma_xy_mm,2),fmt(v.last_fix_age_s,2),v.source],v.state==='lost'?'bad':''));
const vs=document.getElementById('v');for(const w of s.views||[])if(!document.getElementById('view'+w.index)){
const f=document.createElement('figure');const i=document.createElement('img');i.id='view'+w.index;
i.alt='camera '+w.id+': no frame yet';i.style.maxWidth='100%';const c=document.createElement('figcaption');
const l=document.createElement('a');l.href='/camera/'+w.index+'.png';l.textContent=w.id;c.appendChild(l);
f.appendChild(i);f.appendChild(c);vs.appendChild(f);}}catch(e){}
setTimeout(tick,500);}
function pictures(){const t='?t='+Date.now();document.getElementById('site').src='/site.svg'+t;
for(const i of document.querySelectorAll('#v img'))i.src='/camera/'+i.id.slice(4)+'.png'+t;
setTimeout(pictures,1000);}
tick();pictures();
</script></body></html>
)";

}  // namespace

OverheadDiag::OverheadDiag(const DiagOutput& cfg)
    : view_width_px_(cfg.view_width_px),
      http_(app::http_settings_of(cfg), [this](DiagRoute r, HttpAnswer* a) { answer(r, a); }) {}

void OverheadDiag::attach(const site::Site& site, const overhead::SearchParams& search) {
  std::lock_guard<std::mutex> lock(attach_mutex_);
  if (attached_.load(std::memory_order_acquire)) return;
  site_ = &site;
  search_ = search;
  for (const site::FleetAgv& a : site.fleet) agv_ids_.push_back(a.id);
  for (std::size_t i = 0; i < site.cameras.size(); ++i) {
    taps_.push_back(std::make_unique<CameraViewTap>());
    caches_.push_back(std::make_unique<ViewCache>());
  }
  attached_.store(true, std::memory_order_release);
}

void OverheadDiag::offer_frame(std::size_t camera, std::int64_t t_ns, const cv::Mat& gray,
                               const overhead::FleetTracker& tracker,
                               const std::vector<overhead::Detection>& detections) {
  if (!attached_.load(std::memory_order_acquire) || camera >= taps_.size()) return;
  CameraViewTap& tap = *taps_[camera];
  if (!tap.due(t_ns)) return;
  tap.offer(t_ns, [&](CameraView& v) {
    fill_camera_view(*site_, camera, tracker, detections, search_, t_ns, gray, &v);
  });
}

void OverheadDiag::put_view(std::size_t camera, CameraView v) {
  if (!attached_.load(std::memory_order_acquire) || camera >= taps_.size()) return;
  taps_[camera]->put(std::move(v));
}

// Drawn and encoded here, on the server's thread, once per new frame in the slot; the tracker is
// asked for a fresh one for the next request.
void OverheadDiag::answer_camera(int camera, HttpAnswer* a) {
  if (!attached_.load(std::memory_order_acquire) || camera < 0 ||
      static_cast<std::size_t>(camera) >= taps_.size()) {
    a->status = 404;
    a->body = "no camera " + std::to_string(camera) + " (see \"views\" in /api/status.json)\n";
    return;
  }
  const auto i = static_cast<std::size_t>(camera);
  CameraViewTap& tap = *taps_[i];
  ViewCache& cache = *caches_[i];
  tap.request();
  std::lock_guard<std::mutex> lock(cache.mutex);
  const std::uint64_t seq = tap.seq();
  if (seq != cache.seq) {
    cv::Mat bgr;
    std::int64_t t_ns = 0;
    tap.read([&](const CameraView& v) {
      bgr = draw_camera_view(v, agv_ids_, view_width_px_);
      t_ns = v.t_ns;
    });
    std::string png;
    if (!bgr.empty() && app::encode_png(bgr, &png)) {
      cache.png = std::move(png);
      cache.t_ns = t_ns;
    }
    cache.seq = seq;
  }
  if (cache.png.empty()) {
    a->status = 503;
    a->body = "camera " + site_->cameras[i].id + ": no frame yet\n";
    a->headers.emplace_back("Retry-After", "1");
    return;
  }
  a->status = 200;
  a->body = cache.png;
  a->type = "image/png";
  a->headers.emplace_back("X-Frame-Exposure-Ns", std::to_string(cache.t_ns));
}

bool OverheadDiag::start(std::string* error) { return http_.start(error); }

void OverheadDiag::update(DiagView v) {
  std::lock_guard<std::mutex> lock(mutex_);
  view_ = std::move(v);
}

void OverheadDiag::answer(DiagRoute route, HttpAnswer* a) {
  if (route == DiagRoute::kCamera) return answer_camera(a->camera, a);
  const site::Site* site = attached_.load(std::memory_order_acquire) ? site_ : nullptr;
  if (route == DiagRoute::kSite) {
    if (!site) return;  // 404 as the server set it
    DiagView v;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      v = view_;
    }
    a->status = 200;
    a->body = overhead_site_svg(*site, v);
    a->type = "image/svg+xml";
    return;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  switch (route) {
    case DiagRoute::kPage:
      a->body = kPage;
      a->type = "text/html; charset=utf-8";
      a->headers.emplace_back("Content-Security-Policy",
                              "default-src 'none'; script-src 'unsafe-inline'; style-src "
                              "'unsafe-inline'; img-src 'self'; connect-src 'self'");
      break;
    case DiagRoute::kStatus:
      a->body = overhead_status_json(view_, site);
      a->type = "application/json";
      break;
    case DiagRoute::kMetrics:
      a->body = overhead_metrics_text(view_, http_.counters());
      a->type = "text/plain; version=0.0.4; charset=utf-8";
      break;
    default:  // the vehicle's map and camera image: not served here
      a->status = 404;
      a->body = "not found\n";
      break;
  }
}

}  // namespace agv::overhead_app

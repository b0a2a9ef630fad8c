// The diagnostics page (docs/guide/diagnostics.md): one self-contained HTML file, inline CSS and
// JS, no external resource (a vehicle's network has no CDN). It polls /api/status.json (2 Hz),
// /api/map.json (1 Hz) and /frame.png (1 Hz); everything it shows comes from those. The body's
// data-frame / data-map attributes say when the frame and the map were first drawn (the headless
// browser test waits for them).
namespace agv::app {

namespace {

constexpr const char kDiagPage[] = R"HTML(<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>agvloc diagnostics</title>
<style>
body{font:13px/1.35 system-ui,sans-serif;margin:0;background:#f3f4f6;color:#111}
header{background:#1f2937;color:#fff;padding:6px 12px;display:flex;gap:16px;align-items:center}
header h1{font-size:16px;margin:0}
#health{padding:2px 10px;border-radius:4px;font-weight:bold}
.OK{background:#16a34a;color:#fff}.DEGRADED{background:#ca8a04;color:#fff}
.LOST{background:#dc2626;color:#fff}.FAULT{background:#7f1d1d;color:#fff}.STALE{background:#6b7280;color:#fff}
main{display:grid;grid-template-columns:minmax(320px,1fr) minmax(320px,1fr);gap:10px;padding:10px}
section{background:#fff;border-radius:6px;padding:8px 10px;box-shadow:0 1px 2px #0002}
h2{font-size:13px;margin:0 0 6px 0;color:#374151;text-transform:uppercase;letter-spacing:.04em}
table{border-collapse:collapse;width:100%}td,th{padding:1px 6px;text-align:right;white-space:nowrap}
td:first-child,th:first-child{text-align:left}tr:nth-child(even){background:#f9fafb}
.flag{display:inline-block;margin:1px 3px;padding:0 6px;border-radius:3px;background:#fee2e2;color:#991b1b}
.none{color:#6b7280}
#frame{max-width:100%;image-rendering:pixelated;background:#000;min-height:120px}
canvas{width:100%;height:360px;background:#fcfcfd;border:1px solid #e5e7eb}
.big{font-size:18px;font-weight:600;font-variant-numeric:tabular-nums}
#err{color:#b91c1c}
</style></head>
<body data-frame="" data-map="">
<header><h1>agvloc diagnostics</h1><span id="health" class="STALE">—</span>
<span id="mode"></span><span id="t"></span><span id="err"></span></header>
<main>
<section><h2>Pose</h2>
<div class="big" id="pose">—</div>
<table id="posetab"></table>
<h2 style="margin-top:8px">Faults and rejections</h2><div id="flags"></div></section>
<section><h2>Camera (newest frame with detection overlay)</h2>
<img id="frame" alt="no frame yet"><div id="frameinfo" class="none"></div></section>
<section><h2>Map and trajectory</h2><canvas id="map" width="800" height="480"></canvas>
<div id="mapinfo" class="none"></div></section>
<section><h2>Rates and latencies</h2><table id="rates"></table>
<h2 style="margin-top:8px">Last fixes</h2><table id="fixes"></table></section>
</main>
<script>
"use strict";
const $ = id => document.getElementById(id);
const f = (v, d) => (v === null || v === undefined) ? "—" : Number(v).toFixed(d);
let prev = null, lastMap = null, lastStatus = null;
function esc(s){return String(s).replace(/[&<>"]/g,c=>({"&":"&amp;","<":"&lt;",">":"&gt;","\"":"&quot;"}[c]));}
function row(cells, th){const t=th?"th":"td";return "<tr>"+cells.map(c=>"<"+t+">"+c+"</"+t+">").join("")+"</tr>";}
function rate(s, key){
  if(!prev || s.t_ns <= prev.t_ns) return "—";
  return f((s.counters[key]-prev.counters[key])/((s.t_ns-prev.t_ns)/1e9), 1);
}
function showStatus(s){
  lastStatus = s;
  const h = $("health"); h.textContent = s.has_tick ? s.health + " · " + s.fusion_state : "waiting for the loop";
  h.className = s.has_tick ? s.health : "STALE";
  $("mode").textContent = s.mode + (s.finished ? " (finished)" : "");
  $("t").textContent = "t = " + f(s.t_ns/1e9, 2) + " s";
  const p = s.pose;
  $("pose").textContent = p.initialised ? ("x " + f(p.x_mm,1) + " mm  y " + f(p.y_mm,1) + " mm  θ " + f(p.theta_deg,2) + "°" + (p.valid ? "" : "  (PoseValid 0: not for control)")) : "no pose yet";
  $("posetab").innerHTML =
    row(["σ position (largest axis)", f(p.position_sigma_mm,2)+" mm"]) +
    row(["σ x / σ y", f(p.sigma_x_mm,2)+" / "+f(p.sigma_y_mm,2)+" mm"]) +
    row(["σ θ", f(p.sigma_theta_deg,3)+"°"]) +
    row(["speed / yaw rate", f(p.v_mps,3)+" m/s / "+f(p.omega_radps,3)+" rad/s"]) +
    row(["time since fix", p.time_since_fix_ms < 0 ? "never" : f(p.time_since_fix_ms,0)+" ms"]) +
    row(["last landmark", s.last_landmark_valid ? s.last_landmark_id : "—"]);
  const fl = s.faults.map(n=>"<span class=flag>fault: "+esc(n)+"</span>")
    .concat(s.rejections.map(n=>"<span class=flag>rejected: "+esc(n)+"</span>"));
  $("flags").innerHTML = fl.length ? fl.join("") : "<span class=none>none</span>";
  const c = s.counters, L = s.latency;
  $("rates").innerHTML = row(["", "total", "per s"], true) +
    row(["output ticks", c.ticks, rate(s,"ticks")]) +
    row(["fixes received", c.fixes_received, rate(s,"fixes_received")]) +
    row(["fixes fused", c.fixes_fused, rate(s,"fixes_fused")]) +
    row(["rejected: gate / too old / invalid", c.fixes_rejected_gate+" / "+c.fixes_rejected_too_old+" / "+c.fixes_rejected_invalid, ""]) +
    row(["odometry samples (rejected)", c.odometry_samples+" ("+c.odometry_rejected+")", rate(s,"odometry_samples")]) +
    row(["CAN tx ok / failed", c.can_tx_ok+" / "+c.can_tx_failed, rate(s,"can_tx_ok")]) +
    row(["missed periods / frames dropped", c.missed_periods+" / "+c.frames_dropped, ""]) +
    row(["latency", "p50 ms", "p99 ms"], true) +
    ["end_to_end","period_jitter","fusion","can_send"].map(k=>row([k.replace(/_/g," "), f(L[k].p50_ms,3), f(L[k].p99_ms,3)])).join("");
  $("fixes").innerHTML = row(["exposure s","status","id","x mm","y mm","σ mm","latency ms"], true) +
    s.fixes.map(x=>row([f(x.t_exposure_ns/1e9,3), esc(x.status), x.landmark_id||"—",
      x.status=="ok"?f(x.x_mm,1):"—", x.status=="ok"?f(x.y_mm,1):"—", x.status=="ok"?f(x.sigma_mm,2):"—", f(x.latency_ms,1)])).join("");
  prev = s;
}
function drawMap(m){
  const cv = $("map"), g = cv.getContext("2d");
  const W = cv.width, H = cv.height;
  g.clearRect(0,0,W,H);
  const pts = m.landmarks.map(l=>[l.x_mm,l.y_mm]).concat(m.track.map(t=>[t[1],t[2]]));
  if (m.pose) pts.push([m.pose.x_mm, m.pose.y_mm]);
  if (!pts.length){ $("mapinfo").textContent = "no landmarks, no valid pose yet"; return false; }
  let x0=Infinity,x1=-Infinity,y0=Infinity,y1=-Infinity;
  for (const [x,y] of pts){x0=Math.min(x0,x);x1=Math.max(x1,x);y0=Math.min(y0,y);y1=Math.max(y1,y);}
  const pad = 150; x0-=pad;x1+=pad;y0-=pad;y1+=pad;
  const k = Math.min(W/(x1-x0), H/(y1-y0));
  const ox = (W - k*(x1-x0))/2, oy = (H - k*(y1-y0))/2;
  const X = x => ox + k*(x-x0), Y = y => H - (oy + k*(y-y0));  // world y up
  g.strokeStyle="#e5e7eb"; g.lineWidth=1;  // 1 m grid
  for (let gx=Math.ceil(x0/1000)*1000; gx<=x1; gx+=1000){g.beginPath();g.moveTo(X(gx),0);g.lineTo(X(gx),H);g.stroke();}
  for (let gy=Math.ceil(y0/1000)*1000; gy<=y1; gy+=1000){g.beginPath();g.moveTo(0,Y(gy));g.lineTo(W,Y(gy));g.stroke();}
  for (const l of m.landmarks){
    const s = Math.max(4, 60*k); g.save(); g.translate(X(l.x_mm),Y(l.y_mm)); g.rotate(-l.heading_deg*Math.PI/180);
    g.fillStyle="#111"; g.fillRect(-s/2,-s/2,s,s); g.fillStyle="#fff"; g.fillRect(-s/4,-s/4,s/2,s/2); g.restore();
    g.fillStyle="#374151"; g.font="10px sans-serif"; g.fillText(l.id, X(l.x_mm)+s/2+2, Y(l.y_mm)-2);
  }
  if (m.track.length){
    g.strokeStyle="#2563eb"; g.lineWidth=2; g.beginPath();
    m.track.forEach((t,i)=>{ if(i) g.lineTo(X(t[1]),Y(t[2])); else g.moveTo(X(t[1]),Y(t[2])); }); g.stroke();
  }
  if (m.pose){
    const px=X(m.pose.x_mm), py=Y(m.pose.y_mm), a=-m.pose.theta_deg*Math.PI/180;
    g.strokeStyle="#dc2626"; g.lineWidth=1; g.beginPath();
    g.arc(px,py,Math.max(3,3*m.pose.position_sigma_mm*k),0,2*Math.PI); g.stroke();  // 3 sigma
    g.fillStyle="#dc2626"; g.beginPath(); g.moveTo(px+12*Math.cos(a),py+12*Math.sin(a));
    g.lineTo(px+6*Math.cos(a+2.5),py+6*Math.sin(a+2.5)); g.lineTo(px+6*Math.cos(a-2.5),py+6*Math.sin(a-2.5)); g.fill();
  }
  $("mapinfo").textContent = m.landmarks.length + " landmarks, " + m.track.length + " trajectory points (1 m grid; red: pose and 3σ)";
  return true;
}
async function poll(url, fn){
  try { const r = await fetch(url, {cache:"no-store"}); if (!r.ok) throw new Error(url+": "+r.status);
        fn(await r.json()); $("err").textContent=""; }
  catch(e){ $("err").textContent = String(e.message || e); }
}
function loadFrame(){
  const img = new Image();
  img.onload = () => { $("frame").src = img.src; document.body.dataset.frame = "ok";
    $("frameinfo").textContent = img.naturalWidth + "×" + img.naturalHeight + " px"; setTimeout(loadFrame, 1000); };
  img.onerror = () => setTimeout(loadFrame, 1000);
  img.src = "/frame.png?t=" + Date.now();
}
function loop(){ poll("/api/status.json", showStatus).finally(()=>setTimeout(loop, 500)); }
function mapLoop(){ poll("/api/map.json", m=>{ lastMap=m; if (drawMap(m) && m.landmarks.length) document.body.dataset.map = "ok"; })
  .finally(()=>setTimeout(mapLoop, 1000)); }
loop(); mapLoop(); loadFrame();
</script></body></html>
)HTML";

}  // namespace

const char* diag_page_html() { return kDiagPage; }

}  // namespace agv::app

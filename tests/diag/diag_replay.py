#!/usr/bin/env python3
"""The diagnostics page served by a replay (docs/guide/diagnostics.md), with the real server:
  - `agvloc replay --serve` of a simulated recording, while clients poll it: the replay's poses.csv
    equals that of the same replay without the page (the page costs the loop nothing it could see);
  - the final state on /api/status.json, /api/map.json and /metrics equals poses.csv and the run
    summary; /metrics is valid Prometheus text; /frame.png is a PNG of the camera's size;
  - 50 concurrent clients all get an answer (200) or a clean refusal (503), the server still serves;
  - hostile requests (huge header, other methods, unknown paths, a silent connection) are refused
    and do not stop it;
  - a non-loopback address is refused without diag.allow_remote, served with it;
  - SIGTERM ends the serving process with exit code 0.
usage: diag_replay.py AGVLOC WORKDIR
"""
import json, os, re, socket, struct, subprocess, sys, threading, time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from diag_common import Served, fail, get, make_recording, read_poses

CONFIG = "diag:\n  port: 0\n  max_clients: 8\n  threads: 2\n"


def check_metrics(text):
    """Text format 0.0.4: HELP and TYPE before samples, cumulative buckets ending in +Inf ==
    _count. Returns {series: value}."""
    types, helps, samples, buckets = {}, set(), {}, {}
    for line in text.splitlines():
        if line.startswith("# HELP "):
            helps.add(line.split()[2])
            continue
        if line.startswith("# TYPE "):
            _, _, name, t = line.split()
            types[name] = t
            continue
        m = re.fullmatch(r'([a-zA-Z_:][a-zA-Z0-9_:]*)(\{[^}]*\})? (\S+)', line)
        if not m:
            fail("metrics: bad line %r" % line)
        name, labels, value = m.group(1), m.group(2) or "", m.group(3)
        fam = re.sub(r"_(bucket|sum|count)$", "", name) if re.sub(
            r"_(bucket|sum|count)$", "", name) in types and types[re.sub(
                r"_(bucket|sum|count)$", "", name)] == "histogram" else name
        if fam not in types or fam not in helps:
            fail("metrics: %s without HELP/TYPE before it" % name)
        samples[name + labels] = float(value)
        if name.endswith("_bucket"):
            le = re.search(r'le="([^"]+)"', labels).group(1)
            buckets.setdefault(fam, []).append((float(le), float(value)))
    for fam, b in buckets.items():
        if b[-1][0] != float("inf"):
            fail("metrics: %s has no +Inf bucket" % fam)
        if any(b[i][1] < b[i - 1][1] for i in range(1, len(b))):
            fail("metrics: %s buckets not cumulative" % fam)
        if b[-1][1] != samples[fam + "_count"] or fam + "_sum" not in samples:
            fail("metrics: %s +Inf != _count or no _sum" % fam)
    if not buckets:
        fail("metrics: no histogram")
    return samples


def png_size(data):
    if data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR":
        fail("frame.png is not a PNG")
    return struct.unpack(">II", data[16:24])


def main():
    agvloc, work = sys.argv[1], sys.argv[2]
    os.makedirs(work, exist_ok=True)
    rec = os.path.join(work, "rec")
    make_recording(agvloc, rec)

    # Reference: the same replay without the page.
    ref = os.path.join(work, "reference")
    subprocess.run([agvloc, "replay", rec, "--out", ref, "--quiet"], check=True,
                   stdout=subprocess.DEVNULL)
    ref_poses = open(os.path.join(ref, "poses.csv")).read()

    out = os.path.join(work, "served")
    srv = Served(agvloc, rec, out, CONFIG)
    if not srv.port:
        fail("no 'diag: serving' line:\n" + srv.output())
    print("serving on port %d" % srv.port, flush=True)

    # Clients during the replay: poll every endpoint until the final state is served.
    stop = threading.Event()
    during = {"answers": 0, "refusals": 0, "other": []}
    lock = threading.Lock()

    def poller(path):
        while not stop.is_set():
            status, _, _ = get(srv.port, path, timeout=30)
            with lock:
                if status == 200:
                    during["answers"] += 1
                elif status == 503:
                    during["refusals"] += 1
                else:
                    during["other"].append((path, status))

    threads = [threading.Thread(target=poller, args=(p,))
               for p in ["/api/status.json", "/api/map.json", "/metrics", "/frame.png", "/"] * 2]
    for t in threads:
        t.start()
    final = srv.wait_finished()
    stop.set()
    for t in threads:
        t.join()
    print("during the replay: %d answers, %d refusals" % (during["answers"], during["refusals"]))
    if during["other"]:
        fail("answers other than 200 / 503 during the replay: %r" % during["other"][:5])

    # The page cost the loop nothing it could see: the same poses.
    poses_text = open(os.path.join(out, "poses.csv")).read()
    if poses_text != ref_poses:
        fail("poses.csv of the served replay differs from the reference replay")

    # Final state against poses.csv and the summary.
    poses = read_poses(os.path.join(out, "poses.csv"))
    last = poses[-1]
    summary = open(os.path.join(out, "summary.txt")).read()
    m = re.search(r"(\d+) landmark fixes fused, (\d+) output ticks", summary)
    fused, n_ticks = int(m.group(1)), int(m.group(2))
    if final["t_ns"] != int(last["t_ns"]):
        fail("status t_ns %d, poses.csv's last %s" % (final["t_ns"], last["t_ns"]))
    p = final["pose"]
    for k, ref_v, res in (("x_mm", float(last["x_mm"]), 1e-4), ("y_mm", float(last["y_mm"]), 1e-4),
                          ("theta_deg", float(last["theta_deg"]), 1e-5),
                          ("sigma_x_mm", float(last["sigma_x_mm"]), 1e-4)):
        if abs(p[k] - ref_v) > res:
            fail("status %s %r, poses.csv %r" % (k, p[k], ref_v))
    # poses.csv's valid is "initialised"; the page's pose.valid is the CAN PoseValid: initialised,
    # fusion state neither uninitialised (0) nor lost (3), no FaultOdomTimeout (fault bit 2).
    if p["initialised"] != (last["valid"] == "1"):
        fail("status initialised differs from poses.csv's valid")
    can_valid = (last["valid"] == "1" and int(last["health"]) not in (0, 3)
                 and int(last["faults"]) & (1 << 2) == 0)
    if p["valid"] != can_valid:
        fail("status valid %r, PoseValid from poses.csv %r" % (p["valid"], can_valid))
    if final["counters"]["fixes_fused"] != fused or final["counters"]["ticks"] != n_ticks:
        fail("status counters %r, summary: %d fused, %d ticks" % (final["counters"], fused, n_ticks))
    if fused == 0 or not final["fixes"]:
        fail("no fixes in the final state")
    fixes_csv = open(os.path.join(out, "fixes.csv")).read()
    if str(final["fixes"][0]["t_exposure_ns"]) not in fixes_csv:
        fail("the newest fix on the page is not in fixes.csv")
    if final["faults_bits"] != int(last["faults"]) or final["rejections_bits"] != int(last["rejections"]):
        fail("faults / rejections differ from poses.csv")

    status, body, headers = get(srv.port, "/metrics")
    if status != 200 or not headers.get("Content-Type", "").startswith("text/plain; version=0.0.4"):
        fail("/metrics: %d %r" % (status, headers))
    samples = check_metrics(body.decode())
    if samples["agvloc_pose_valid"] != int(can_valid):
        fail("/metrics agvloc_pose_valid %r, PoseValid from poses.csv %r" % (
            samples["agvloc_pose_valid"], can_valid))
    if samples["agvloc_fixes_fused_total"] != fused or samples["agvloc_ticks_total"] != n_ticks:
        fail("/metrics fixes %r ticks %r, summary %d / %d" % (
            samples["agvloc_fixes_fused_total"], samples["agvloc_ticks_total"], fused, n_ticks))
    print("metrics: %d series, end_to_end count %d" % (
        len(samples), samples["agvloc_end_to_end_seconds_count"]))

    status, body, _ = get(srv.port, "/api/map.json")
    mp = json.loads(body)
    map_rows = [l for l in open(os.path.join(rec, "map.csv")).read().splitlines()
                if l and not l.startswith("#") and not l.startswith("id,")]
    if len(mp["landmarks"]) != len(map_rows):
        fail("map.json has %d landmarks, map.csv %d" % (len(mp["landmarks"]), len(map_rows)))
    if not mp["track"] or abs(mp["track"][-1][1] - float(last["x_mm"])) > 1e-4:
        fail("the trajectory does not end at the final pose")

    status, body, headers = get(srv.port, "/frame.png")
    if status != 200:
        fail("/frame.png: %d %r" % (status, body[:100]))
    w, h = png_size(body)
    meta = open(os.path.join(rec, "meta.yaml")).read()
    mw = re.search(r"width(?:_px)?:\s*(\d+)", meta)
    mh = re.search(r"height(?:_px)?:\s*(\d+)", meta)
    if mw and mh and (w, h) != (int(mw.group(1)), int(mh.group(1))):
        fail("frame %dx%d, recording %sx%s" % (w, h, mw.group(1), mh.group(1)))
    status, page, _ = get(srv.port, "/")
    if status != 200 or b"<canvas" not in page or b"http://" in page or b"https://" in page:
        fail("the page is not the self-contained HTML")

    # 50 concurrent clients: each an answer or a clean refusal.
    results = []
    start = threading.Barrier(50)

    def client(i):
        path = ["/api/status.json", "/metrics", "/frame.png", "/api/map.json", "/"][i % 5]
        start.wait()
        status, _, _ = get(srv.port, path, timeout=60)
        with lock:
            results.append(status)

    threads = [threading.Thread(target=client, args=(i,)) for i in range(50)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    ok, busy = results.count(200), results.count(503)
    print("50 concurrent clients: %d answered, %d refused (503)" % (ok, busy))
    if ok + busy != 50 or ok == 0:
        fail("50 clients: statuses %r" % sorted(results))

    # Hostile requests.
    status, _, _ = get(srv.port, "/api/status.json", headers={"X-Big": "a" * 20000})
    if status not in (0, 400, 413, 431):
        fail("a 20 kB header was answered %d" % status)
    for method in ("POST", "PUT", "DELETE"):
        status, _, _ = get(srv.port, "/api/status.json", method=method)
        if status < 400:
            fail("%s answered %d" % (method, status))
    status, _, _ = get(srv.port, "/../../etc/passwd")
    if status != 404 and status != 400:
        fail("a path outside the page answered %d" % status)
    silent = [socket.create_connection(("127.0.0.1", srv.port)) for _ in range(3)]
    silent[0].sendall(b"GET / HTTP/1.1\r\nHost: x\r\n")  # never finishes its headers
    deadline = time.monotonic() + 60
    while True:  # answered while the silent ones hold workers, or once they time out
        status, _, _ = get(srv.port, "/api/status.json", timeout=30)
        if status == 200:
            break
        if time.monotonic() > deadline:
            fail("not served beside 3 silent connections (last status %d)" % status)
        time.sleep(0.2)
    for s in silent:
        s.close()

    rc = srv.stop()
    if rc != 0:
        fail("agvloc replay --serve ended with %d after SIGTERM:\n%s" % (rc, srv.output()))
    if "diag: " not in srv.output() or "requests" not in srv.output():
        fail("no diag counters line at exit")

    # A non-loopback address only with diag.allow_remote.
    bad = Served(agvloc, rec, os.path.join(work, "remote_refused"),
                 "diag:\n  bind_address: 0.0.0.0\n  port: 0\n", deadline_s=60)
    rc = bad.proc.wait(timeout=120)
    if rc != 2 or "allow_remote" not in bad.output() or bad.port:
        fail("0.0.0.0 without allow_remote: rc %d, output:\n%s" % (rc, bad.output()))
    ok_remote = Served(agvloc, rec, os.path.join(work, "remote_allowed"),
                       "diag:\n  bind_address: 0.0.0.0\n  allow_remote: true\n  port: 0\n")
    if not ok_remote.port or "http://0.0.0.0:" not in ok_remote.output():
        fail("0.0.0.0 with allow_remote not served:\n" + ok_remote.output())
    ok_remote.wait_finished()
    if ok_remote.stop() != 0:
        fail("remote-allowed replay did not stop cleanly")
    print("PASS", flush=True)


if __name__ == "__main__":
    main()

"""Scaling out: one `agvloc-overhead detect --replay` process per camera of the two-camera site
publishing tags to a mosquitto broker of its own, one `run --detections-from-broker` tracking from
them; the tracks must equal `replay` of the same recordings in one process (same vehicles and
states, positions within a few mm), and refused messages (malformed, another version, an unknown
camera) are counted by reason in the summary and on /metrics, never applied. The tracker also
reads the vehicles' VDA 5050 orders (orders.subscribe): a fleet vehicle's order sets its route, an
update of it extends the route, a repeat is a duplicate, and orders for another vehicle, cut short
or unstitched are refused by reason (tests/overhead/detect_broker.cmake). Usage: test_overhead_detect_broker.py OVERHEAD_CMD DESK_CMD
SITE WORK"""
import math, os, re, shutil, signal, subprocess, sys, time, urllib.request

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from mqtt_brokers import start_broker
from test_overhead_util import SKIP, fail, read_csv, render, run

FRAMES = 24
TOLERANCE_MM = 5.0


def final_rows(tracks_csv):
    """{agv: (t_ns, x, y, theta, v_mps, omega, state)} of the last row of each vehicle."""
    out = {}
    for r in read_csv(tracks_csv)[1]:
        out[r[1]] = (int(r[0]), float(r[2]), float(r[3]), float(r[4]), float(r[5]), float(r[6]),
                     r[-1])
    return out


def at(row, t_ns):
    """A row's position moved to t_ns at its speed and heading (the rows are a tick apart)."""
    dt = (t_ns - row[0]) * 1e-9
    return (row[1] + 1000.0 * row[4] * dt * math.cos(row[3]),
            row[2] + 1000.0 * row[4] * dt * math.sin(row[3]))


# Refused by the tracker, never applied: another version, a camera the site does not have, and
# (last: the test waits for it) a message cut short.
BAD_MESSAGES = ['{"v":2,"camera":"cam-west","t_ns":1,"seq":0,"tags":[]}',
                '{"v":1,"camera":"cam-nowhere","t_ns":1,"seq":0,"tags":[]}',
                '{"v":1,"camera":']
REFUSED = ["bad_version", "unknown_camera", "not_json"]


def order(serial, update, first, xs_m):
    """A VDA 5050 2.1.0 order o1 (update `update`) through (x, 2.0) m, node ids from `first`."""
    import json
    nodes = [{"nodeId": "o1_n%d" % (first + i), "sequenceId": 2 * (first + i), "released": True,
              "actions": [], "nodePosition": {"x": x, "y": 2.0, "mapId": "site"}}
             for i, x in enumerate(xs_m)]
    edges = [{"edgeId": "o1_e%d" % (first + i), "sequenceId": 2 * (first + i) + 1,
              "released": True, "startNodeId": nodes[i]["nodeId"],
              "endNodeId": nodes[i + 1]["nodeId"], "actions": []} for i in range(len(xs_m) - 1)]
    return json.dumps({"headerId": update, "timestamp": "2026-12-03T10:00:00.000Z",
                       "version": "2.1.0", "manufacturer": "acme", "serialNumber": serial,
                       "orderId": "o1", "orderUpdateId": update, "nodes": nodes, "edges": edges})


# (topic, payload): set, extended, repeated; then another vehicle's, cut short, unstitched.
ORDERS = [("uagv/v2/acme/agv-1/order", order("agv-1", 0, 0, [1.0, 2.0, 3.0])),
          ("uagv/v2/acme/agv-1/order", order("agv-1", 1, 2, [3.0, 4.0])),
          ("uagv/v2/acme/agv-1/order", order("agv-1", 1, 2, [3.0, 4.0])),
          ("uagv/v2/acme/agv-9/order", order("agv-9", 0, 0, [1.0, 2.0])),
          ("uagv/v2/acme/agv-2/order", order("agv-2", 0, 0, [1.0, 2.0])[:60]),
          ("uagv/v2/acme/agv-1/order", order("agv-1", 2, 1, [9.0, 8.0]))]
ORDERS_SUMMARY = "orders: 6 messages, 2 routes set, 0 cleared, 1 duplicates, 3 refused"
ORDERS_REFUSED = ["unknown_vehicle", "malformed", "not_stitched"]


def check_metrics(log_path, messages, timeout_s=30.0):
    """The tracker's /metrics counts every message and each refusal by reason (the view is
    refreshed when its queue runs empty: polled until the count arrives)."""
    port = int(re.search(r"diag: serving http://127\.0\.0\.1:(\d+)/",
                         open(log_path).read()).group(1))
    want = "agvloc_overhead_detections_messages_total %d\n" % messages
    end = time.time() + timeout_s
    text = ""
    while time.time() < end and want not in text:
        text = urllib.request.urlopen("http://127.0.0.1:%d/metrics" % port, timeout=5).read()
        text = text.decode()
        time.sleep(0.1)
    if want not in text:
        fail("no '%s' in /metrics:\n%s" % (want.strip(), text))
    for reason in ["too_large", "bad_version", "unknown_camera", "not_json", "missing_field"]:
        n = 1 if reason in REFUSED else 0
        line = 'agvloc_overhead_detections_refused_total{reason="%s"} %d\n' % (reason, n)
        if line not in text:
            fail("no '%s' in /metrics:\n%s" % (line.strip(), text))
    for line in ["agvloc_overhead_detections_lost_total 0\n",
                 "agvloc_overhead_detections_dropped_total 0\n",
                 "agvloc_overhead_orders_messages_total %d\n" % len(ORDERS),
                 "agvloc_overhead_orders_routes_set_total 2\n",
                 'agvloc_overhead_orders_refused_total{reason="not_stitched"} 1\n']:
        if line not in text:
            fail("no '%s' in /metrics:\n%s" % (line.strip(), text))
    print("metrics: %d messages, refused %s once each" % (messages, ", ".join(REFUSED)))


def wait_for(path, text, proc, timeout_s=60.0):
    end = time.time() + timeout_s
    while time.time() < end and proc.poll() is None:
        if text in open(path).read():
            return
        time.sleep(0.1)
    fail("no '%s' in %s:\n%s" % (text, path, open(path).read()))


def main():
    overhead, desk, site, work = sys.argv[1:5]
    pub = shutil.which("mosquitto_pub")
    if not pub:
        print("SKIP: mosquitto_pub not installed")
        sys.exit(SKIP)
    os.makedirs(work, exist_ok=True)
    recs = render(desk, site, os.path.join(work, "rec"), frames=FRAMES)
    one = os.path.join(work, "one")
    rc, so, se = run(overhead, ["replay", "--site", site, "--recordings"] + recs +
                     ["--out", one, "--fast"])
    if rc != 0:
        fail("replay rc %d:\n%s%s" % (rc, so, se))
    broker = start_broker("mosquitto", work)
    if broker is None:
        print("SKIP: mosquitto not installed")
        sys.exit(SKIP)
    port, stop_broker = broker
    cfg = os.path.join(work, "overhead.yaml")
    with open(cfg, "w") as f:
        f.write("output:\n  mqtt:\n    broker_host: 127.0.0.1\n    port: %d\n"
                "detections:\n  topic_prefix: site-7\ndiag:\n  enabled: true\n  port: 0\n"
                "tracker:\n  route_prior: true\norders:\n  subscribe: true\n" % port)
    bus = os.path.join(work, "bus")
    log_path = os.path.join(work, "tracker.log")
    tracker = None
    try:
        log = open(log_path, "w")
        tracker = subprocess.Popen(
            overhead.split() + ["run", "--detections-from-broker", "--config", cfg, "--site", site,
                                "--out", bus, "--duration-s", "300"], stdout=log, stderr=log)
        wait_for(log_path, "orders from uagv/+/+/+/order", tracker)
        detectors = []
        for rec in recs:
            cam = open(os.path.join(rec, "camera.yaml")).read().split("id:")[1].split()[0]
            detectors.append(subprocess.Popen(
                overhead.split() + ["detect", "--config", cfg, "--site", site, "--camera", cam,
                                    "--replay", rec, "--fast"],
                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True))
        for d in detectors:
            so, _ = d.communicate(timeout=180)
            if d.returncode != 0 or "%d frames" % FRAMES not in so:
                fail("detect rc %d:\n%s" % (d.returncode, so))
            print(so.strip())
        for topic, payload in ORDERS:
            subprocess.run([pub, "-h", "127.0.0.1", "-p", str(port), "-t", topic, "-m", payload],
                           check=True)
        # Refused messages after every detector has gone, a malformed one last: the broker
        # forwards in the order it received, and the tracker handles its queue in order, so once
        # it names that refusal it has handled every message before it (no waiting on the clock).
        for bad in BAD_MESSAGES:
            subprocess.run([pub, "-h", "127.0.0.1", "-p", str(port), "-t",
                            "site-7/detections/cam-west", "-m", bad], check=True)
        wait_for(log_path, "detections message refused: not_json", tracker, timeout_s=120.0)
        check_metrics(log_path, 2 * FRAMES + len(BAD_MESSAGES))
        tracker.send_signal(signal.SIGTERM)
        tracker.wait(60)
    finally:
        if tracker and tracker.poll() is None:
            tracker.kill()
        stop_broker()
    text = open(log_path).read()
    print(text)
    if tracker.returncode != 0:
        fail("tracker rc %d" % tracker.returncode)
    want = "%d messages (3 refused, 0 lost by sequence, 0 dropped behind)" % (2 * FRAMES + 3)
    if want not in text or any("refused %s: 1" % r not in text for r in REFUSED):
        fail("expected '%s' and one refusal of each of %s" % (want, REFUSED))
    if ORDERS_SUMMARY not in text or any("order refused %s: 1" % r not in text
                                         for r in ORDERS_REFUSED):
        fail("expected '%s' and one order refused of each of %s" % (ORDERS_SUMMARY,
                                                                    ORDERS_REFUSED))
    a, b = final_rows(os.path.join(one, "tracks.csv")), final_rows(os.path.join(bus, "tracks.csv"))
    if sorted(a) != sorted(b) or not a:
        fail("vehicles differ: replay %s, broker %s" % (sorted(a), sorted(b)))
    for agv in sorted(a):
        if a[agv][6] != b[agv][6]:
            fail("%s: state %s in replay, %s through the broker" % (agv, a[agv][6], b[agv][6]))
        x, y = at(a[agv], b[agv][0])
        err = math.hypot(x - b[agv][1], y - b[agv][2])
        print("%s: %s, final position %.3f mm apart" % (agv, b[agv][6], err))
        if err > TOLERANCE_MM:
            fail("%s: %.3f mm from replay's track (> %g)" % (agv, err, TOLERANCE_MM))
    print("OK")


if __name__ == "__main__":
    main()

"""agvloc-overhead replay publishing VDA 5050 visualization per vehicle to a mosquitto broker of
its own (tests/overhead/binary.cmake, label mqtt; skipped without mosquitto). Usage:
test_overhead_mqtt.py OVERHEAD_CMD DESK_CMD SITE WORK"""
import json, os, re, shutil, socket, subprocess, sys, time

try:
    import jsonschema
except ImportError:  # the messages' fields are still checked below
    jsonschema = None

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from test_overhead_util import SKIP, fail, read_csv, render, run


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def wait_port(port, timeout_s=5.0):
    end = time.time() + timeout_s
    while time.time() < end:
        try:
            socket.create_connection(("127.0.0.1", port), 0.2).close()
            return True
        except OSError:
            time.sleep(0.05)
    return False


def visualization_schema():
    """VDA 5050 2.1.0's visualization schema (tests/vda5050/schemas), or None without jsonschema."""
    if jsonschema is None:
        return None
    here = os.path.dirname(os.path.abspath(__file__))
    path = os.path.join(here, "..", "vda5050", "schemas", "2.1.0", "visualization.schema")
    return json.loads(re.sub(r",(\s*[}\]])", r"\1", open(path).read()))


def main():
    overhead, desk, site, work = sys.argv[1:5]
    broker = shutil.which("mosquitto") or ("/usr/sbin/mosquitto" if os.path.exists("/usr/sbin/mosquitto") else None)
    sub = shutil.which("mosquitto_sub")
    if not broker or not sub:
        print("SKIP: mosquitto or mosquitto_sub not installed")
        sys.exit(SKIP)
    recs = render(desk, site, os.path.join(work, "rec"), frames=12)
    port = free_port()
    conf = os.path.join(work, "broker.conf")
    with open(conf, "w") as f:
        f.write("listener %d 127.0.0.1\nallow_anonymous true\npersistence false\n" % port)
    cfg = os.path.join(work, "overhead.yaml")
    with open(cfg, "w") as f:
        f.write("output:\n  mqtt:\n    enabled: true\n    broker_host: 127.0.0.1\n    port: %d\n"
                "    manufacturer: acme\n    map_id: floor-1\n" % port)
    procs = [subprocess.Popen([broker, "-c", conf], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        if not wait_port(port):
            fail("the broker did not start")
        log = open(os.path.join(work, "messages.txt"), "w")
        procs.append(subprocess.Popen([sub, "-h", "127.0.0.1", "-p", str(port), "-v", "-t",
                                       "agvloc-overhead/#"], stdout=log))
        time.sleep(0.5)  # the subscription is in place before the first message
        out = os.path.join(work, "out")
        rc, so, se = run(overhead, ["replay", "--config", cfg, "--site", site, "--recordings"] +
                         recs + ["--out", out, "--fast"])
        if rc != 0:
            fail("replay rc %d:\n%s%s" % (rc, so, se))
        time.sleep(0.5)
    finally:
        for p in reversed(procs):
            p.terminate()
            p.wait(5)
    tracks = read_csv(os.path.join(out, "tracks.csv"))[1]
    want = {}
    for r in tracks:
        want[r[1]] = want.get(r[1], 0) + 1
    schema = visualization_schema()
    got, last = {}, {}
    for line in open(os.path.join(work, "messages.txt")):
        topic, payload = line.split(" ", 1)
        parts = topic.split("/")
        if parts[:3] != ["agvloc-overhead", "v2", "acme"] or parts[4] != "visualization":
            fail("topic " + topic)
        msg = json.loads(payload)
        if schema is not None:
            jsonschema.validate(msg, schema)
        if msg["serialNumber"] != parts[3] or msg["headerId"] != got.get(parts[3], 0):
            fail("%s: serialNumber / headerId out of order: %s" % (topic, payload))
        got[parts[3]] = got.get(parts[3], 0) + 1
        last[parts[3]] = msg
    if got != want:
        fail("messages per vehicle %s, tracks.csv rows %s" % (got, want))
    final = {r[1]: r for r in tracks}
    for agv, msg in last.items():
        p, r = msg["agvPosition"], final[agv]
        if p["mapId"] != "floor-1" or abs(p["x"] * 1000 - float(r[2])) > 0.01 or \
                abs(p["y"] * 1000 - float(r[3])) > 0.01:
            fail("%s: last message %s, last tracks.csv row %s" % (agv, msg, r))
        if p["positionInitialized"] != (r[9] in ("confirmed", "coasting")):
            fail("%s: positionInitialized %s with state %s" % (agv, p["positionInitialized"], r[9]))
    print("PASS: %s messages per vehicle, as tracks.csv%s" %
          (got, ", valid against VDA 5050 2.1.0's schema" if schema else ""))


if __name__ == "__main__":
    main()

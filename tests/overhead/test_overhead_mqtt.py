"""agvloc-overhead replay publishing VDA 5050 visualization per vehicle to a broker of its own:
mosquitto, or RabbitMQ's MQTT plugin (tests/overhead/binary.cmake, label mqtt; skipped without
the broker). Usage: test_overhead_mqtt.py OVERHEAD_CMD DESK_CMD SITE WORK [mosquitto|rabbitmq]"""
import json, os, shutil, subprocess, sys, time

try:
    import jsonschema
except ImportError:  # the messages' fields are still checked below
    jsonschema = None

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from mqtt_brokers import start_broker
from test_overhead_util import SKIP, fail, read_csv, render, run, vda5050_schema


PROBE = "agvtest/probe"


def subscribed(port, messages, timeout_s=30.0):
    """Returns once the subscriber receives a probe: its subscription is in place before the
    first real message (a broker may take seconds to set one up on a loaded machine)."""
    end = time.time() + timeout_s
    while time.time() < end:
        subprocess.run(["mosquitto_pub", "-h", "127.0.0.1", "-p", str(port), "-t", PROBE, "-m", "1"],
                       check=False)
        time.sleep(0.2)
        if PROBE in open(messages).read():
            return
    fail("the subscriber saw no probe within %g s" % timeout_s)


def delivered(messages, want, timeout_s=15.0):
    """Waits until `want` non-probe messages arrived (or the timeout: the count check says)."""
    end = time.time() + timeout_s
    while time.time() < end:
        n = sum(1 for line in open(messages) if not line.startswith(PROBE + " "))
        if n >= want:
            time.sleep(0.2)  # anything beyond `want` shows up in the count check
            return
        time.sleep(0.1)


def main():
    overhead, desk, site, work = sys.argv[1:5]
    kind = sys.argv[5] if len(sys.argv) > 5 else "mosquitto"
    sub = shutil.which("mosquitto_sub")  # a client only: it speaks to either broker
    if not sub:
        print("SKIP: mosquitto_sub not installed")
        sys.exit(SKIP)
    os.makedirs(work, exist_ok=True)
    recs = render(desk, site, os.path.join(work, "rec"), frames=12)
    broker = start_broker(kind, work)
    if broker is None:
        print("SKIP: %s not installed" % kind)
        sys.exit(SKIP)
    port, stop_broker = broker
    cfg = os.path.join(work, "overhead.yaml")
    with open(cfg, "w") as f:
        f.write("output:\n  mqtt:\n    enabled: true\n    broker_host: 127.0.0.1\n    port: %d\n"
                "    manufacturer: acme\n    map_id: floor-1\n" % port)
    procs = []
    messages = os.path.join(work, "messages.txt")
    try:
        log = open(messages, "w")
        procs.append(subprocess.Popen([sub, "-h", "127.0.0.1", "-p", str(port), "-v", "-t",
                                       "agvloc-overhead/#", "-t", PROBE], stdout=log))
        subscribed(port, messages)
        out = os.path.join(work, "out")
        rc, so, se = run(overhead, ["replay", "--config", cfg, "--site", site, "--recordings"] +
                         recs + ["--out", out, "--fast"])
        if rc != 0:
            fail("replay rc %d:\n%s%s" % (rc, so, se))
        delivered(messages, len(read_csv(os.path.join(out, "tracks.csv"))[1]))
    finally:
        for p in reversed(procs):
            p.terminate()
            p.wait(5)
        stop_broker()
    tracks = read_csv(os.path.join(out, "tracks.csv"))[1]
    want = {}
    for r in tracks:
        want[r[1]] = want.get(r[1], 0) + 1
    schema = vda5050_schema(jsonschema, "visualization")
    got, last = {}, {}
    for line in open(messages):
        if line.startswith(PROBE + " "):
            continue
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
    print("PASS (%s): %s messages per vehicle, as tracks.csv%s" %
          (kind, got, ", valid against VDA 5050 2.1.0's schema" if schema else ""))


if __name__ == "__main__":
    main()

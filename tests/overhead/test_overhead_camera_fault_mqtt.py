"""agvloc-overhead run publishing a camera fault over MQTT: a camera whose device does not exist
is a fault from the start; its VDA 5050 state message (serialNumber the camera's id, on
<interface>/v2/<manufacturer>/<camera>/state) carries a cameraFault error naming it, valid against
VDA 5050 2.1.0's state schema where python3-jsonschema is installed. The same live run reads the
vehicles' orders (orders.subscribe): an order left retained on the broker becomes agv-1's route
(tests/overhead/binary.cmake, label mqtt; skipped without mosquitto). Usage: test_overhead_camera_fault_mqtt.py OVERHEAD_CMD
SITE WORK"""
import json, os, shutil, subprocess, sys

try:
    import jsonschema
except ImportError:  # the fields are still checked below
    jsonschema = None

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from mqtt_brokers import start_broker
from test_overhead_mqtt import PROBE, subscribed
from test_overhead_util import SKIP, fail, run, vda5050_schema


ORDER = json.dumps({
    "headerId": 1, "timestamp": "2026-12-03T10:00:00.000Z", "version": "2.1.0",
    "manufacturer": "acme", "serialNumber": "agv-1", "orderId": "o1", "orderUpdateId": 0,
    "nodes": [{"nodeId": "n%d" % i, "sequenceId": 2 * i, "released": True, "actions": [],
               "nodePosition": {"x": 1.0 + i, "y": 2.0, "mapId": "site"}} for i in range(3)],
    "edges": [{"edgeId": "e%d" % i, "sequenceId": 2 * i + 1, "released": True,
               "startNodeId": "n%d" % i, "endNodeId": "n%d" % (i + 1), "actions": []}
              for i in range(2)]})


def main():
    overhead, site, work = sys.argv[1:4]
    sub, pub = shutil.which("mosquitto_sub"), shutil.which("mosquitto_pub")
    if not sub or not pub:
        print("SKIP: mosquitto_sub / mosquitto_pub not installed")
        sys.exit(SKIP)
    os.makedirs(work, exist_ok=True)
    broker = start_broker("mosquitto", work)
    if broker is None:
        print("SKIP: mosquitto not installed")
        sys.exit(SKIP)
    port, stop_broker = broker
    cfg = os.path.join(work, "overhead.yaml")
    with open(cfg, "w") as f:
        f.write("output:\n  mqtt:\n    enabled: true\n    broker_host: 127.0.0.1\n    port: %d\n"
                "    manufacturer: acme\ncameras:\n  cam-west:\n"
                "    device: /dev/agvloc-no-such-video\n"
                "tracker:\n  route_prior: true\norders:\n  subscribe: true\n" % port)
    messages = os.path.join(work, "messages.txt")
    proc = None
    try:
        log = open(messages, "w")
        proc = subprocess.Popen([sub, "-h", "127.0.0.1", "-p", str(port), "-v", "-t",
                                 "agvloc-overhead/#", "-t", PROBE], stdout=log)
        subscribed(port, messages)
        # Retained: the broker hands it to the run's subscription as soon as it is made.
        subprocess.run([pub, "-h", "127.0.0.1", "-p", str(port), "-r", "-t",
                        "uagv/v2/acme/agv-1/order", "-m", ORDER], check=True)
        rc, so, se = run(overhead, ["run", "--config", cfg, "--site", site, "--duration-s", "1.5"])
        if rc != 0:
            fail("run rc %d:\n%s%s" % (rc, so, se))
        if "camera cam-west: fault" not in se:
            fail("no fault on stderr:\n" + se)
        if "orders: 1 messages, 1 routes set, 0 cleared, 0 duplicates, 0 refused" not in so:
            fail("the retained order was not taken as agv-1's route:\n" + so + se)
        import time
        time.sleep(0.5)
    finally:
        if proc:
            proc.terminate()
            proc.wait(5)
        stop_broker()
    schema = vda5050_schema(jsonschema, "state")
    states = []
    for line in open(messages):
        if line.startswith(PROBE + " "):
            continue
        topic, payload = line.split(" ", 1)
        if topic == "agvloc-overhead/v2/acme/cam-west/state":
            states.append(json.loads(payload))
        elif topic.endswith("/state"):
            fail("a state message for another camera: " + topic)
    if not states:
        fail("no state message for cam-west")
    msg = states[0]
    if schema is not None:
        jsonschema.validate(msg, schema)
    errors = msg["errors"]
    if msg["serialNumber"] != "cam-west" or len(errors) != 1 or \
            errors[0]["errorType"] != "cameraFault" or errors[0]["errorLevel"] != "WARNING" or \
            errors[0]["errorReferences"] != [{"referenceKey": "cameraId",
                                              "referenceValue": "cam-west"}] or \
            "cannot start" not in errors[0]["errorDescription"]:
        fail("state message: " + json.dumps(msg))
    # One fault, one message: a camera that keeps failing is not republished every tick.
    if len(states) != 1:
        fail("%d state messages for one fault" % len(states))
    print("PASS: cam-west's fault published as a VDA 5050 state error%s: %s" %
          (" (valid against 2.1.0's schema)" if schema else "", errors[0]["errorDescription"]))


if __name__ == "__main__":
    main()

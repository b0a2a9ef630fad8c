// An independent VDA 5050 2.0.0 master control (npm vda-5050-lib, pinned in package-lock.json)
// against agvloc over a mosquitto of its own (docs/guide/vda5050.md "Fleet controls on 2.0.0").
// The library validates every inbound object against its compiled 2.0 schemas and drops what
// fails; this script counts what it let through and what it dropped, and checks that
//   - visualization and connection arrive and validate, ONLINE first and OFFLINE last,
//   - an initPosition sent with the library's initiateInstantActions is answered by a state it
//     validates, FINISHED, at the pose set (the position after the action),
//   - one for a map agvloc does not know is answered FAILED,
//   - nothing agvloc sent was dropped.
// usage: node master_control.cjs AGVLOC AGVLOC_DESK WORKDIR
"use strict";
const { spawn, spawnSync } = require("child_process");
const fs = require("fs");
const net = require("net");
const path = require("path");
const { MasterController, Topic } = require("vda-5050-lib");

const [agvloc, desk, work] = process.argv.slice(2);
const agvId = { manufacturer: "acme", serialNumber: "agv-7" };
const children = [];

function fail(msg) {
  console.log("FAIL: " + msg);
  for (const c of children) if (c.exitCode === null) c.kill("SIGKILL");
  process.exit(1);
}

function freePort() {
  return new Promise((resolve, reject) => {
    const s = net.createServer();
    s.on("error", reject);
    s.listen(0, "127.0.0.1", () => {
      const { port } = s.address();
      s.close(() => resolve(port));
    });
  });
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function waitFor(pred, timeoutMs, what) {
  const end = Date.now() + timeoutMs;
  while (Date.now() < end) {
    if (pred()) return;
    await sleep(20);
  }
  fail(what + " within " + timeoutMs / 1000 + " s");
}

async function startBroker(port) {
  const conf = path.join(work, "mosquitto.conf");
  fs.writeFileSync(conf, `listener ${port} 127.0.0.1\nallow_anonymous true\npersistence false\n`);
  const log = fs.openSync(path.join(work, "mosquitto.log"), "w");
  const broker = spawn("mosquitto", ["-c", conf], { stdio: ["ignore", log, log] });
  broker.on("error", (e) => fail("mosquitto: " + e.message + " (tools/install-deps.sh)"));
  children.push(broker);
  const end = Date.now() + 10000;  // a loaded machine
  while (Date.now() < end) {
    const up = await new Promise((resolve) => {
      const c = net.connect(port, "127.0.0.1", () => { c.destroy(); resolve(true); });
      c.on("error", () => resolve(false));
    });
    if (up) return broker;
    await sleep(50);
  }
  fail("mosquitto did not start (log " + path.join(work, "mosquitto.log") + ")");
}

function initPosition(actionId, x, y, theta, mapId) {
  return {
    actionId, actionType: "initPosition", blockingType: "NONE",
    actionParameters: [{ key: "x", value: x }, { key: "y", value: y },
                       { key: "theta", value: theta }, { key: "mapId", value: mapId },
                       { key: "lastNodeId", value: "n1" }],
  };
}

async function main() {
  fs.mkdirSync(work, { recursive: true });
  const rec = path.join(work, "rec");
  if (!fs.existsSync(path.join(rec, "frames.csv"))) {
    const r = spawnSync(desk, ["sim", "--out", rec, "--trajectory", "line", "--duration-s", "6",
                               "--fps", "15", "--seed", "7", "--speed-mps", "0.5"],
                        { stdio: ["ignore", "ignore", "inherit"] });
    if (r.status !== 0) fail("agvloc-desk sim exited " + r.status);
  }
  const port = await freePort();
  await startBroker(port);

  const mc = new MasterController(
      { interfaceName: "uagv", vdaVersion: "2.0.0",
        transport: { brokerUrl: `mqtt://127.0.0.1:${port}`, connectTimeout: 20000 } },
      { targetAgvs: agvId });
  // Every inbound object passes validateTopicObject before a handler sees it: count both ways.
  const valid = {}, dropped = [];
  const validate = mc.validateTopicObject.bind(mc);
  mc.validateTopicObject = (topic, object, version) => {
    try {
      validate(topic, object, version);
    } catch (e) {
      if (topic !== Topic.InstantActions) dropped.push(topic + ": " + e.message);
      throw e;
    }
    if (topic !== Topic.InstantActions) valid[topic] = (valid[topic] || 0) + 1;
  };
  const vis = [], conn = [];
  await mc.start();
  await mc.subscribe(Topic.Visualization, agvId, (v) => vis.push(v));
  await mc.subscribe(Topic.Connection, agvId, (c) => conn.push(c.connectionState));

  const cfg = path.join(work, "agvloc.yaml");
  fs.writeFileSync(cfg, `vda5050:\n  enabled: true\n  broker_port: ${port}\n  version: "2.0.0"\n` +
                   "  manufacturer: acme\n  serial_number: agv-7\n  map_id: hall-1\n  rate_hz: 20\n");
  const log = fs.openSync(path.join(work, "replay.log"), "w");
  const replay = spawn(agvloc, ["replay", rec, "--out", path.join(work, "out"), "--config", cfg,
                                "--realtime", "--quiet"], { stdio: ["ignore", log, log] });
  children.push(replay);
  let replayExit = null;
  replay.on("exit", (code) => { replayExit = code; });

  await waitFor(() => vis.some((v) => v.agvPosition.positionInitialized), 15000,
                "no initialized position validated by the master control");
  const answers = {};
  const handler = {
    onActionStateChanged: (actionState, error, action, id, state) => {
      answers[action.actionId] = { status: actionState.actionStatus, actionState, state };
    },
    onActionError: (error, action) => {
      answers[action.actionId] = { status: "ERROR " + JSON.stringify(error) };
    },
  };
  // The library's 2.0.0 instant actions carry the array as `instantActions`.
  await mc.initiateInstantActions(agvId, { instantActions: [initPosition("init-1", 5, -3, 1, "hall-1")] },
                                  handler);
  await mc.initiateInstantActions(agvId, { instantActions: [initPosition("bad-2", 1, 1, 0, "other-map")] },
                                  handler);
  await waitFor(() => answers["init-1"] && answers["bad-2"], 10000,
                "initPosition not answered (answers " + JSON.stringify(Object.keys(answers)) + ")");
  await waitFor(() => replayExit !== null, 30000, "replay did not end");
  if (replayExit !== 0) fail("replay exited " + replayExit + " (log " + path.join(work, "replay.log") + ")");
  await waitFor(() => conn.includes("OFFLINE"), 5000, "no OFFLINE connection message");
  await mc.stop();

  const a = answers["init-1"];
  if (a.status !== "FINISHED") fail("init-1 answered " + a.status);
  const p = a.state.agvPosition;
  if (Math.hypot(p.x - 5, p.y + 3) > 0.05) {
    fail(`the state answering init-1 is at (${p.x.toFixed(3)}, ${p.y.toFixed(3)}), not at (5, -3)`);
  }
  const b = answers["bad-2"];
  if (b.status !== "FAILED" || !String(b.actionState.resultDescription).includes("unknown_map")) {
    fail("bad-2 answered " + JSON.stringify(b.actionState || b.status));
  }
  if (conn[0] !== "ONLINE" || conn[conn.length - 1] !== "OFFLINE") fail("connection states " + conn);
  if (dropped.length) fail(dropped.length + " messages dropped by the master control, first: " + dropped[0]);
  for (const t of [Topic.Visualization, Topic.Connection, Topic.State]) {
    if (!valid[t]) fail("no " + t + " message validated");
  }
  console.log("vda-5050-lib 2.0.0 validated: " + JSON.stringify(valid) + ", dropped 0");
  console.log(`initPosition: FINISHED, state at (${p.x.toFixed(3)}, ${p.y.toFixed(3)}); ` +
              "unknown map: FAILED (" + b.actionState.resultDescription + ")");
  for (const c of children) if (c.exitCode === null) c.kill("SIGTERM");
  console.log("PASS");
  process.exit(0);
}

main().catch((e) => fail(e.stack || String(e)));

#!/usr/bin/python3
"""A reference double of `agvloc replay` for the HIL harness's own tests (hil_harness_selftest):
dead reckoning from odometry only, speaking the CAN contract with an implementation written from
the DBC (hil_dbc.py), in Python, so slower than the real one. It lets the harness be proven -- that it passes a correct localizer and
fails a broken one -- independently of the real localizer. It is NOT the localizer.

  fake_agvloc.py replay REC --out DIR --config CFG [--can IF --odom-from-can --realtime
                 [--speed S]]

Offline: DIR/poses.csv, one row per odometry sample; on the bus DIR/poses.csv holds what was
sent, one row per output tick, and DIR/odom_received.csv the odometry it accepted (its row's
time, the decoded values) as the localizer writes it. On the bus: the same poses, the replay
clock slaved to the first accepted odometry frame (that frame = the first odom.csv row; each
later accepted frame advances the row by its alive-counter step). Status: FaultOdomTimeout, FaultOdomE2E
(latched), FaultCanBusOff (latched on a failed send). Prints counters at exit.

AGV_FAKE_FAULT=bad-crc,skip-counter,no-timeout,half-rate (any subset) makes it misbehave on
purpose.
"""
import argparse
import math
import os
import socket
import struct
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import hil_dbc  # noqa: E402
from hil_common import as_bool, as_int, read_odom, yaml_scalars  # noqa: E402

FMT = "=IB3x8s"
EFF, RTR, ERR = 0x80000000, 0x40000000, 0x20000000
FAULT = set(os.environ.get("AGV_FAKE_FAULT", "").split(","))


def next_due(due, now, period_s):
    """The due time one period on; one period from now if the loop fell behind it."""
    due += period_s
    return due if due >= now else now + period_s


def integrate(rows):
    """Poses at each odometry row: midpoint integration with the previous row's v, omega."""
    x = y = th = 0.0
    out = [(rows[0][0], x, y, th)]
    for (t0, v, w), (t1, _, _) in zip(rows, rows[1:]):
        dt = (t1 - t0) / 1e9
        thm = th + w * dt / 2
        x += v * dt * math.cos(thm) * 1000.0
        y += v * dt * math.sin(thm) * 1000.0
        th = math.remainder(th + w * dt, 2 * math.pi)
        out.append((t1, x, y, th))
    return out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("cmd", choices=["replay"])
    ap.add_argument("recording")
    ap.add_argument("--out", required=True)
    ap.add_argument("--config", required=True)
    ap.add_argument("--can", help="CAN interface: send output frames there")
    ap.add_argument("--odom-from-can", action="store_true")
    ap.add_argument("--realtime", action="store_true")
    ap.add_argument("--speed", type=float, default=1.0)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rows = read_odom(a.recording)
    poses = integrate(rows)
    with open(os.path.join(a.out, "poses.csv"), "w") as f:
        f.write("t_ns,x_mm,y_mm,theta_rad,valid\n")
        for t, x, y, th in poses:
            f.write(f"{t},{x!r},{y!r},{th!r},1\n")
    if not a.can:
        return 0
    return bus(a, rows)


def bus(a, rows) -> int:
    cfg = yaml_scalars(open(a.config).read())
    g = lambda *k, d: cfg.get(tuple(k), d)  # noqa: E731
    dbc = hil_dbc.Dbc(os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                   "../../can/agvloc.dbc"))
    base = as_int(g("can", "base_id", d="0x300"))
    mode = g("can", "odometry", "mode", d="v_omega")
    om = dbc.by_name("MC_OdomWheels" if mode == "wheels" else "MC_OdomTwist")
    oid = as_int(g("can", "odometry", "id", d="0")) or base + om.frame_id - 0x300
    track = float(g("can", "odometry", "track_width_mm", d="500"))
    protected = as_bool(g("can", "odometry", "protected", d="true"))
    timeout = float(g("can", "odometry", "timeout_ms", d="100")) / 1000.0
    # Rates are on the replay clock, like the localizer's: wall periods are 1/speed longer.
    rate = float(g("loop", "output_rate_hz", d="100")) * a.speed
    if "half-rate" in FAULT:
        rate /= 2
    msgs = {n: dbc.by_name(n) for n in ("AGV_PoseXY", "AGV_PoseHeading", "AGV_Velocity",
                                         "AGV_Quality", "AGV_Status", "AGV_Heartbeat")}
    ids = {n: base + m.frame_id - 0x300 for n, m in msgs.items()}
    counters = {n: 0 for n in msgs}
    stats = {"odom_accepted": 0, "odom_rejected": 0, "tx_frames": 0, "tx_failed": 0}

    s = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    s.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FILTER,
                 struct.pack("=II", oid, 0x7FF | EFF | RTR))
    s.bind((a.can,))
    s.settimeout(0.002)

    def send(name, fill):
        d = bytearray(8)
        fill(msgs[name], d)
        c = counters[name]
        if name == "AGV_PoseXY":
            state["n_pose"] += 1
            if "skip-counter" in FAULT and state["n_pose"] == 50:
                counters["AGV_PoseXY"] = counters["AGV_PoseHeading"] = c = (c + 1) % 15
        hil_dbc.e2e_protect(msgs[name].data_id, c, d)
        if "bad-crc" in FAULT and name == "AGV_PoseXY" and stats["tx_frames"] % 97 == 0:
            d[0] ^= 0x01
        try:
            s.send(struct.pack(FMT, ids[name], 8, bytes(d)))
            stats["tx_frames"] += 1
        except OSError:
            state["busoff"] = True
            stats["tx_failed"] += 1

    state = {"busoff": False, "e2e": False, "n_pose": 0}
    ticks = []  # what was sent, like the localizer's own --out DIR/poses.csv
    received = []  # accepted odometry, like its --out DIR/odom_received.csv
    last_ctr = None
    t_wall0 = None
    last_ok = None
    idx = 0
    est = (rows[0][0], 0.0, 0.0, 0.0)
    x = y = th = 0.0
    v_prev = w_prev = 0.0
    t_prev = rows[0][0]
    next_pose = next_status = next_hb = time.monotonic()
    t_start = time.monotonic()
    end_rec = rows[-1][0] + int(0.3e9)
    while True:
        now = time.monotonic()
        try:
            raw = s.recv(16)
            cid, dlc, data = struct.unpack(FMT, raw)
            data = data[:dlc]
            ok = dlc == 8 and (not protected or hil_dbc.e2e_ok(om.data_id, data))
            delta = 1
            if ok and protected and last_ctr is not None:
                delta = (hil_dbc.alive_counter(data) - last_ctr) % 15
                ok = 1 <= delta <= 3
                if not ok:
                    last_ctr = hil_dbc.alive_counter(data)  # resynchronise, costs one frame
            if not ok:
                stats["odom_rejected"] += 1
                state["e2e"] = True
            else:
                last_ctr = hil_dbc.alive_counter(data)
                stats["odom_accepted"] += 1
                if t_wall0 is None:
                    t_wall0 = now
                    idx = 0
                else:
                    # The alive counter says which recorded row this is (receive times jitter
                    # by tens of ms in the emulated guest; the sequence does not).
                    idx = min(idx + delta, len(rows) - 1)
                t_row = rows[idx][0]
                sig = om.decode(data)
                if "V" in sig:
                    v, w = sig["V"], sig["Omega"]
                else:
                    v = (sig["LeftSpeed"] + sig["RightSpeed"]) / 2
                    w = (sig["RightSpeed"] - sig["LeftSpeed"]) * 1000.0 / track
                dt = (t_row - t_prev) / 1e9
                thm = th + w_prev * dt / 2
                x += v_prev * dt * math.cos(thm) * 1000.0
                y += v_prev * dt * math.sin(thm) * 1000.0
                th = math.remainder(th + w_prev * dt, 2 * math.pi)
                t_prev, v_prev, w_prev = t_row, v, w
                received.append((t_row, v, w))
                est = (t_row, x, y, th)
                last_ok = now
        except socket.timeout:
            pass
        except OSError:
            state["busoff"] = True  # interface down: reported in the next status frame
            time.sleep(0.01)
        if t_wall0 is None:
            if now - t_start > 120:
                print("no odometry within 120 s", file=sys.stderr)
                return 1
            continue
        t_rec_now = rows[0][0] + (now - t_wall0) * a.speed * 1e9
        if now >= next_pose:
            next_pose = next_due(next_pose, now, 1.0 / rate)
            lat_ms = (t_rec_now - est[0]) / 1e6 / a.speed

            def xy(m, d):
                m.signals["PoseValid"].encode(d, 1)
                m.signals["X"].encode(d, est[1])
                m.signals["Y"].encode(d, est[2])

            def hd(m, d):
                m.signals["PoseValid"].encode(d, 1)
                m.signals["Theta"].encode(d, est[3])
                m.signals["Latency"].encode(d, lat_ms)

            def vel(m, d):
                m.signals["VelocityValid"].encode(d, 1)
                m.signals["V"].encode(d, v_prev)
                m.signals["Omega"].encode(d, w_prev)
            ticks.append(est)
            send("AGV_PoseXY", xy)
            send("AGV_PoseHeading", hd)
            counters["AGV_PoseXY"] = counters["AGV_PoseHeading"] = (counters["AGV_PoseXY"] + 1) % 15
            send("AGV_Velocity", vel)
            counters["AGV_Velocity"] = (counters["AGV_Velocity"] + 1) % 15
        if now >= next_status:
            next_status = next_due(next_status, now, 0.1 / a.speed)
            tmo = last_ok is None or now - last_ok > timeout
            if "no-timeout" in FAULT:
                tmo = False

            def st(m, d):
                m.signals["Health"].encode(d, 1 if tmo else 0)
                m.signals["TimeSinceFix"].encode(d, 65535)
                m.signals["FaultOdomTimeout"].encode(d, int(tmo))
                m.signals["FaultOdomE2E"].encode(d, int(state["e2e"]))
                m.signals["FaultCanBusOff"].encode(d, int(state["busoff"]))

            def q(m, d):
                m.signals["QualityValid"].encode(d, 0)
            busoff_before = stats["tx_failed"]
            send("AGV_Status", st)
            if stats["tx_failed"] == busoff_before:
                state["e2e"] = state["busoff"] = False
            counters["AGV_Status"] = (counters["AGV_Status"] + 1) % 15
            send("AGV_Quality", q)
            counters["AGV_Quality"] = (counters["AGV_Quality"] + 1) % 15
        if now >= next_hb:
            next_hb = next_due(next_hb, now, 1.0 / a.speed)

            def hb(m, d):
                m.signals["ProtocolVersion"].encode(d, 1)
                m.signals["Uptime"].encode(d, now - t_start)
            send("AGV_Heartbeat", hb)
            counters["AGV_Heartbeat"] = (counters["AGV_Heartbeat"] + 1) % 15
        if t_rec_now > end_rec:
            break
    with open(os.path.join(a.out, "poses.csv"), "w") as f:
        f.write("t_ns,x_mm,y_mm,theta_rad,valid\n")
        for t, x, y, th in ticks:
            f.write(f"{t},{x!r},{y!r},{th!r},1\n")
    if a.odom_from_can:
        with open(os.path.join(a.out, "odom_received.csv"), "w") as f:
            f.write("t_ns,v_mps,omega_radps\n")
            for t, v, w in received:
                f.write(f"{t},{v!r},{w!r}\n")
    print("can: " + " ".join(f"{k}={v}" for k, v in stats.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())

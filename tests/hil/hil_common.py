"""Shared parts of the HIL harness (hil.py): constants, config patching, recordings and CAN
logs, the report. Split out of hil.py unchanged."""
from __future__ import annotations

import csv
import math
import os
import re
import shlex
import shutil
import statistics
import subprocess
import sys
from dataclasses import dataclass, field

# python3-can is imported lazily (read_capture): fake_agvloc.py reuses this module inside the
# TCG guest, where importing python-can costs ~45 s of 9p file lookups.

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import hil_dbc  # noqa: E402

SKIP = 77
OFFLINE_MEDIAN_MM = 2.0  # bus vs offline replay, see compare_poses
OFFLINE_P90_MM = 10.0
# The received-odometry reference is like for like only while the guest keeps up with real time:
# beyond the comparison window (+-250 ms) its frames and odometry sit on clocks that drifted apart.
RX_LAG_LIMIT_MS = 250.0
MAX_POSE_GAP_S = 0.5  # longest tolerated pose-frame gap while nothing is injected
# The SocketCAN driver's restart time: its reopen backoff is capped at 100 ms
# (SocketCanConfig::reopen_backoff_max_ns, docs/guide/can.md), so the first pose after the link comes
# back must be on the bus within that plus one output period. The guest logs "link up" after
# `ip link set up` returned; emulation adds scheduling delay on top, bounded here.
CAN_RESTART_S = 0.1
EMULATION_SLACK_S = 0.25
SOURCE_DIR = os.path.dirname(os.path.dirname(HERE))


class HilError(Exception):
    """A precondition or preparation step failed (reported, not a crash)."""


# ----------------------------------------------------------------------------------------------
# Minimal YAML subset for the localizer's config: nested "key: value" maps, comments. We only
# patch values of existing keys and read scalars; we never rewrite the user's structure.
def yaml_scalars(text: str) -> dict[tuple[str, ...], str]:
    out, stack = {}, []  # stack of (indent, key)
    for line in text.splitlines():
        body = line.split(" #", 1)[0].rstrip() if not line.lstrip().startswith("#") else ""
        if not body.strip():
            continue
        indent = len(body) - len(body.lstrip())
        m = re.match(r"\s*([\w.-]+)\s*:\s*(.*)$", body)
        if not m:
            continue
        while stack and stack[-1][0] >= indent:
            stack.pop()
        key, value = m.group(1), m.group(2).strip()
        path = tuple(k for _, k in stack) + (key,)
        if value:
            out[path] = value.strip('"').strip("'")
        else:
            stack.append((indent, key))
    return out


def yaml_patch(text: str, values: dict[tuple[str, ...], str]) -> str:
    lines, stack, done = text.splitlines(), [], set()
    for i, line in enumerate(lines):
        if line.lstrip().startswith("#") or not line.strip():
            continue
        indent = len(line) - len(line.lstrip())
        m = re.match(r"(\s*)([\w.-]+)(\s*:\s*)([^#]*?)(\s*#.*)?$", line)
        if not m:
            continue
        while stack and stack[-1][0] >= indent:
            stack.pop()
        path = tuple(k for _, k in stack) + (m.group(2),)
        if m.group(4).strip() == "":
            stack.append((indent, m.group(2)))
            continue
        if path in values:
            lines[i] = f"{m.group(1)}{m.group(2)}{m.group(3)}{values[path]}{m.group(5) or ''}"
            done.add(path)
    missing = set(values) - done
    if missing:
        raise HilError("config has no key(s) " + ", ".join(".".join(p) for p in sorted(missing)))
    return "\n".join(lines) + "\n"


def as_int(s: str) -> int:
    return int(s, 0)


def as_bool(s: str) -> bool:
    return s.lower() in ("true", "yes", "on", "1")


# ----------------------------------------------------------------------------------------------
@dataclass
class Setup:
    scenario: str
    results: str
    agvloc: str
    recording: str
    config: str
    speed: float
    dbc: hil_dbc.Dbc
    iface: str = "vcan0"
    base_id: int = 0x300
    extended: bool = False
    odom_msg: str = "MC_OdomTwist"
    odom_id: int = 0x311
    odom_ext: bool = False
    odom_protected: bool = True
    odom_timeout_ms: float = 100.0
    track_width_mm: float = 500.0
    output_rate_hz: float = 100.0
    heartbeat_rate_hz: float = 1.0
    odom: list[tuple[int, float, float]] = field(default_factory=list)


def prepare_config(args, results: str) -> tuple[str, dict]:
    src = os.path.abspath(args.config)
    text = open(src, encoding="utf-8").read()
    vals = yaml_scalars(text)
    patch = {("can", "interface"): args.iface, ("camera", "driver"): "replay"}
    # Fix-triggered pose pairs have no row in the localizer's poses.csv (one row per tick), which
    # the bus poses are matched against; and under TCG emulation a landmark frame takes many times
    # longer, which at SCHED_FIFO would hold a guest CPU from everything else for that long.
    for key, value in ((("loop", "pose_on_fix"), "false"), (("loop", "vision_priority"), "0")):
        if key in vals:
            patch[key] = value
    # Under TCG emulation on a loaded host the guest's replay camera hands frames to vision
    # seconds late (exposure -> vision start p50 1.5 s, max 4.8 s in the garbage scenario with a
    # build beside it). The vehicle's 500 ms fusion.max_fix_delay_ms then dropped 10 of 12 fixes
    # as too old, and the bus track no longer followed the offline reference, which fused them.
    # That lateness is the emulator's, not behaviour under test (the fault replays check the
    # too-old rule), so the HIL configuration accepts fixes up to the key's limit, with the
    # history to re-propagate them (100 Hz odometry x 10 s plus the fixes, twice over).
    fusion_keys = {("fusion", "max_fix_delay_ms"): "10000", ("fusion", "history_capacity"): "2048"}
    if not any(k[0] == "fusion" for k in vals):
        text += "\nfusion:\n" + "".join(f"  {k[1]}: {v}\n" for k, v in fusion_keys.items())
    else:
        patch.update({k: v for k, v in fusion_keys.items() if k in vals})
    if ("landmark", "map") in vals and not os.path.isabs(vals[("landmark", "map")]):
        patch[("landmark", "map")] = os.path.normpath(
            os.path.join(os.path.dirname(src), vals[("landmark", "map")]))
    for kv in args.set or []:
        k, v = kv.split("=", 1)
        patch[tuple(k.split("."))] = v
    out = os.path.join(results, "hil-config.yaml")
    patched = yaml_patch(text, patch)
    with open(out, "w", encoding="utf-8") as f:
        f.write(f"# generated by tests/hil/hil.py from {src}\n" + patched)
    return out, yaml_scalars(patched)


def read_odom(rec: str) -> list[tuple[int, float, float]]:
    path = os.path.join(rec, "odom.csv")
    rows = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            rows.append((int(r["t_ns"]), float(r["v_mps"]), float(r["omega_radps"])))
    if len(rows) < 10:
        raise HilError(f"{path}: only {len(rows)} odometry rows")
    return rows


def received_recording(rec: str, odom_received: str, out: str) -> str:
    """The recording's frames (symlinks) with the odometry the localizer decoded from the bus
    (its --out odom_received.csv, receive times on the replay clock) as odom.csv: replayed
    offline it is what the localizer on the bus computed from what it actually received, apart
    from when each fix arrived (compare_poses leaves those windows out)."""
    if os.path.isdir(out):
        shutil.rmtree(out)
    os.makedirs(out)
    for name in os.listdir(rec):
        if name not in ("odom.csv", "truth.csv"):
            os.symlink(os.path.realpath(os.path.join(rec, name)), os.path.join(out, name))
    shutil.copyfile(odom_received, os.path.join(out, "odom.csv"))
    return out


def quantize_recording(s: Setup, out: str, drop: tuple[int, int] | None = None) -> str:
    """A copy of the recording (symlinks) whose odom.csv holds exactly the values the bus can
    carry (DBC resolution), so the offline replay and the localizer on the bus see identical
    odometry and their poses can be compared within the pose signals' resolution. Rows with
    drop[0] <= t_ns < drop[1] are left out (the odometry-timeout scenario's gap), so the offline
    reference sees the same gap as the localizer on the bus.

    The recording's gyro (imu.csv) is left out: the bus carries no gyro in these scenarios, and
    the localizer on it (--odom-from-can) ignores imu.csv, so it runs wheels only. A reference
    that fused the gyro drifted apart from it between fixes by up to the gyro's correction
    (1.8 mm and 0.2 deg after a fix fused 1.7 s late under load: ci9's hil_garbage, median
    2.196 mm against the 2.0 mm limit)."""
    os.makedirs(out, exist_ok=True)
    for name in os.listdir(s.recording):
        if name not in ("odom.csv", "imu.csv"):
            os.symlink(os.path.join(s.recording, name), os.path.join(out, name))
    msg = s.dbc.by_name(s.odom_msg)
    q = []
    for t, v, w in s.odom:
        if drop and drop[0] <= t < drop[1]:
            continue
        d = bytearray(8)
        if s.odom_msg == "MC_OdomTwist":
            msg.signals["V"].encode(d, v)
            msg.signals["Omega"].encode(d, w)
            v, w = msg.signals["V"].decode(d), msg.signals["Omega"].decode(d)
        else:
            half = w * s.track_width_mm / 2000.0
            msg.signals["LeftSpeed"].encode(d, v - half)
            msg.signals["RightSpeed"].encode(d, v + half)
            left, right = msg.signals["LeftSpeed"].decode(d), msg.signals["RightSpeed"].decode(d)
            v, w = (left + right) / 2.0, (right - left) * 1000.0 / s.track_width_mm
        q.append((t, v, w))
    with open(os.path.join(out, "odom.csv"), "w") as f:
        f.write("t_ns,v_mps,omega_radps\n")
        for t, v, w in q:
            f.write(f"{t},{v!r},{w!r}\n")
    s.odom = q
    return out


def synthetic_recording(out: str, seconds: float) -> str:
    """Odometry-only recording for the harness self-test (fake_agvloc.py needs no images):
    100 Hz, a slalom at up to 1 m/s."""
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "odom.csv"), "w") as f:
        f.write("t_ns,v_mps,omega_radps\n")
        for k in range(int(seconds * 100) + 1):
            t = k / 100.0
            f.write(f"{1_000_000_000 + k * 10_000_000},{0.8 + 0.2 * math.sin(t):.9g},"
                    f"{0.5 * math.sin(0.7 * t):.9g}\n")
    with open(os.path.join(out, "frames.csv"), "w") as f:
        f.write("t_ns,file\n")
    return out


def odom_frames(s: Setup) -> list[tuple[int, bytes]]:
    """(recording t_ns, payload) of the motor controller's odometry frames, E2E protected with
    our own CRC implementation (so a localizer/DBC disagreement shows as rejected odometry)."""
    msg = s.dbc.by_name(s.odom_msg)
    out = []
    for k, (t, v, w) in enumerate(s.odom):
        d = bytearray(8)
        if s.odom_msg == "MC_OdomTwist":
            msg.signals["V"].encode(d, v)
            msg.signals["Omega"].encode(d, w)
        else:
            half = w * s.track_width_mm / 2000.0
            msg.signals["LeftSpeed"].encode(d, v - half)
            msg.signals["RightSpeed"].encode(d, v + half)
        hil_dbc.e2e_protect(msg.data_id, k % 15, d)
        out.append((t, bytes(d)))
    return out


def fmt_id(can_id: int, ext: bool) -> str:
    return f"{can_id:08X}" if ext else f"{can_id:03X}"


def write_canplayer_log(path: str, iface: str, frames: list[tuple[float, int, bool, bytes]]):
    """frames: (seconds, id, extended, data). Same format as `candump -l`."""
    with open(path, "w") as f:
        for t, cid, ext, data in frames:
            f.write(f"({t:.6f}) {iface} {fmt_id(cid, ext)}#{data.hex().upper()}\n")


# ----------------------------------------------------------------------------------------------
@dataclass
class Frame:
    t: float
    can_id: int
    ext: bool
    data: bytes
    rtr: bool = False


def read_capture(path: str) -> list[Frame]:
    import can  # python3-can: candump log parsing only

    out = []
    for m in can.CanutilsLogReader(path):
        if m.is_error_frame:
            continue
        out.append(Frame(m.timestamp, m.arbitration_id, m.is_extended_id, bytes(m.data),
                         m.is_remote_frame))
    return out


def read_cangen_logs(results: str) -> list[tuple[int, bool, bytes, bool]]:
    """Frames cangen -v -v reported as sent: '  vcan0  1A2   [3]  01 02 03' or '... remote request'."""
    out = []
    for name in ("cangen.log", "cangen_eff.log", "cangen_rtr.log"):
        p = os.path.join(results, name)
        if not os.path.exists(p):
            continue
        for line in open(p, errors="replace"):
            m = re.match(r"\s*\S+\s+([0-9A-F]+)\s+\[(\d+)\]\s*(.*)$", line)
            if not m:
                continue
            cid = int(m.group(1), 16)
            ext = len(m.group(1)) == 8
            rest = m.group(3)
            rtr = "remote" in rest
            data = b"" if rtr else bytes.fromhex("".join(re.findall(r"\b[0-9A-F]{2}\b", rest)))
            out.append((cid, ext, data, rtr))
    return out


def read_pose_csv(out_dir: str) -> tuple[str, list[dict]]:
    """The replay's pose output: the CSV in out_dir with t_ns, x_mm, y_mm and a theta column."""
    cands = []
    for root, _, files in os.walk(out_dir):
        for fn in files:
            if fn.endswith(".csv"):
                p = os.path.join(root, fn)
                with open(p, newline="") as f:
                    header = next(csv.reader(f), [])
                if {"t_ns", "x_mm", "y_mm"} <= set(header) and (
                        "theta_rad" in header or "theta_deg" in header):
                    cands.append(p)
    if not cands:
        raise HilError(f"no pose CSV (t_ns,x_mm,y_mm,theta_rad|theta_deg) in {out_dir}")
    cands.sort(key=lambda p: (0 if "pose" in os.path.basename(p) else 1, p))
    rows = []
    with open(cands[0], newline="") as f:
        for r in csv.DictReader(f):
            th = float(r["theta_rad"]) if "theta_rad" in r else math.radians(float(r["theta_deg"]))
            valid = (r.get("valid") or "1").strip().lower() not in ("0", "false")
            tsf = r.get("time_since_fix_ms")
            rows.append({"t_ns": int(r["t_ns"]), "x": float(r["x_mm"]), "y": float(r["y_mm"]),
                         "th": th, "valid": valid,
                         "tsf_ms": float(tsf) if tsf not in (None, "") else None})
    rows.sort(key=lambda r: r["t_ns"])
    return cands[0], rows


def wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


# ----------------------------------------------------------------------------------------------
class Report:
    def __init__(self, path: str):
        self.path, self.lines, self.failed = path, [], []

    def info(self, msg: str):
        self.lines.append("  " + msg)

    def check(self, ok: bool, name: str, detail: str = ""):
        self.lines.append(f"{'PASS' if ok else 'FAIL'} {name}" + (f": {detail}" if detail else ""))
        if not ok:
            self.failed.append(name)
        return ok

    def write(self):
        with open(self.path, "w") as f:
            f.write("\n".join(self.lines) + "\n")


def period_stats(ts: list[float]) -> dict:
    d = [b - a for a, b in zip(ts, ts[1:])]
    if len(d) < 2:
        return {"n": len(ts)}
    ds = sorted(d)
    return {"n": len(ts), "median": statistics.median(d), "mean": statistics.fmean(d),
            "p05": ds[int(0.05 * (len(ds) - 1))], "p95": ds[int(0.95 * (len(ds) - 1))],
            "max": ds[-1], "min": ds[0]}


def fmt_ms(st: dict) -> str:
    if "median" not in st:
        return f"n={st['n']}"
    return (f"n={st['n']} median={st['median']*1e3:.2f}ms mean={st['mean']*1e3:.2f}ms "
            f"p05={st['p05']*1e3:.2f}ms p95={st['p95']*1e3:.2f}ms max={st['max']*1e3:.2f}ms")


def t0_plus(t0: float, dt: float) -> float:
    return t0 + dt


def parse_counters(log: str) -> dict[str, int]:
    """key=value integer pairs the localizer prints (last occurrence wins), and the replay
    summary's "CAN E2E rejected N" as odom_rejected."""
    out = {}
    if os.path.exists(log):
        for line in open(log, errors="replace"):
            for k, v in re.findall(r"\b([a-z][a-z0-9_]*)=(\d+)\b", line):
                out[k] = int(v)
            m = re.search(r"CAN E2E rejected (\d+)", line)
            if m:
                out["odom_rejected"] = int(m.group(1))
    return out


# ----------------------------------------------------------------------------------------------
def run(cmd: list[str], log: str, timeout: float) -> int:
    with open(log, "w") as f:
        f.write("$ " + " ".join(shlex.quote(c) for c in cmd) + "\n")
        f.flush()
        try:
            return subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, timeout=timeout).returncode
        except subprocess.TimeoutExpired:
            f.write(f"\nTIMEOUT after {timeout} s\n")
            return 124

#!/usr/bin/python3
"""Hardware-in-the-loop scenarios on a real kernel CAN bus (vcan0 in the VM), see docs/design/hil.md.

  hil.py SCENARIO --agvloc BIN --results DIR [--recording REC | --sim-args "..."]
         [--agvloc-desk BIN] [--config CFG] [--speed S] [--dbc can/agvloc.dbc]

SCENARIO: nominal | odom_timeout | garbage | link_flap

On the host: prepare (HIL config, offline replay, odometry as a canplayer log, garbage), boot the
VM (vm/run-in-vm.sh) running guest/scenario.sh, then decode the capture with an independent DBC
reader (hil_dbc.py, python-can for the log) and check it. Every check is listed in
DIR/report.txt; on failure the paths of the capture, the localizer log and the guest console are
printed. Exit 0 pass, 1 fail, 77 skipped (the localizer's replay CLI is not there yet).
"""
from __future__ import annotations

import argparse
import os
import random
import re
import shlex
import shutil
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import hil_dbc  # noqa: E402
from hil_common import (  # noqa: E402
    HERE, HilError, Report, SKIP, SOURCE_DIR, Setup, as_bool, as_int, odom_frames, prepare_config,
    quantize_recording, read_capture, read_odom, read_pose_csv, received_recording, run,
    synthetic_recording,
    write_canplayer_log,
)
from hil_analysis import analyse  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("scenario", choices=["nominal", "odom_timeout", "garbage", "link_flap"])
    ap.add_argument("--agvloc", required=True)
    ap.add_argument("--results", required=True)
    ap.add_argument("--agvloc-desk",
                    help="desk tool for the simulated recording (default: agvloc-desk beside BIN)")
    ap.add_argument("--recording",
                    help="recording directory (default: generate with agvloc-desk sim)")
    ap.add_argument("--sim-args", default="",
                    help="arguments for `agvloc-desk sim` after --out DIR")
    ap.add_argument("--recording-cache", help="where the generated recording is kept between runs")
    ap.add_argument("--config", default=os.path.join(SOURCE_DIR, "firmware/config/agvloc.yaml"))
    ap.add_argument("--set", action="append", help="extra config override key.sub=value")
    ap.add_argument("--dbc", default=os.path.join(SOURCE_DIR, "can/agvloc.dbc"))
    ap.add_argument("--speed", type=float, default=float(os.environ.get("AGV_HIL_SPEED", "0.5")),
                    help="replay pace (1 = real time); the TCG VM is slow (docs/design/hil.md)")
    ap.add_argument("--iface", default="vcan0", help="bus interface (can0 with --no-vm)")
    ap.add_argument("--no-vm", action="store_true",
                    help="run on this machine's own interface (a real bench bus; needs root)")
    ap.add_argument("--match-window-ms", type=float, default=250.0,
                    help="search window (recording time) around the estimate time; poses must\n"
                         "still be equal within the signal resolution")
    ap.add_argument("--vm-timeout", type=float, default=0, help="0 = from the recording length")
    ap.add_argument("--analyse-only", action="store_true",
                    help="re-run only the checks on an existing results dir (same arguments)")
    a = ap.parse_args()

    res = os.path.abspath(a.results)
    if not a.analyse_only:
        shutil.rmtree(res, ignore_errors=True)
    os.makedirs(res, exist_ok=True)
    rep = Report(os.path.join(res, "report.txt"))
    rep.lines.append(f"HIL scenario {a.scenario}  ({time.strftime('%Y-%m-%d %H:%M:%S')})")
    try:
        rc = scenario(a, res, rep)
    except HilError as e:
        rep.check(False, "preparation", str(e))
        rc = 1
    rep.write()
    print("\n".join(rep.lines))
    if rc == SKIP:
        return SKIP
    if rep.failed or rc:
        print(f"\nFAIL: {a.scenario}: {', '.join(rep.failed) or 'see above'}")
        for what, p in (("report", "report.txt"), ("capture (candump -l format)", "capture.log"),
                        ("localizer log", "localizer.log"), ("guest console", ".vm/console.log"),
                        ("guest events", "events.log"), ("offline replay log", "offline.log")):
            if os.path.exists(os.path.join(res, p)):
                print(f"  {what}: {os.path.join(res, p)}")
        return 1
    print(f"\nPASS: {a.scenario}")
    return 0


def make_recording(desk: str, rec: str, sim_args: str, res: str) -> str | None:
    """`agvloc-desk sim --out REC SIM_ARGS`, reused while the binary and the arguments are the
    same (the scenarios run one after the other and share it)."""
    if not os.access(desk, os.X_OK):
        raise HilError(f"{desk} is not an executable (build the agvloc-desk target)")
    stamp = f"{desk} {os.stat(desk).st_mtime_ns} {sim_args}\n"
    stamp_path = os.path.join(rec, ".hil-stamp")
    if os.path.exists(stamp_path) and open(stamp_path).read() == stamp:
        return rec
    shutil.rmtree(rec, ignore_errors=True)
    cmd = [desk, "sim", "--out", rec] + shlex.split(sim_args)
    log = os.path.join(res, "sim.log")
    if run(cmd, log, 150) != 0:
        if "not implemented" in open(log).read():
            print(f"SKIP: `agvloc-desk sim` is not implemented yet ({log})")
            return None
        raise HilError(f"`{' '.join(cmd)}` failed, see {log}")
    with open(stamp_path, "w") as f:
        f.write(stamp)
    return rec


def scenario(a, res: str, rep: Report) -> int:
    agvloc = os.path.abspath(a.agvloc)
    if not os.access(agvloc, os.X_OK):
        raise HilError(f"{agvloc} is not an executable (build the agvloc target)")
    probe = subprocess.run([agvloc, "replay", "--help"], capture_output=True, text=True, timeout=60)
    help_text = probe.stdout + probe.stderr
    if "not implemented" in help_text:
        print(f"SKIP: `agvloc replay` is not implemented yet ({help_text.strip()})")
        return SKIP
    missing = [f for f in ("--can", "--odom-from-can", "--realtime", "--speed", "--out", "--config")
               if f not in help_text]
    if missing:
        raise HilError(f"`agvloc replay --help` does not mention {' '.join(missing)}: the HIL "
                       f"harness needs them (docs/design/hil.md, 'What the localizer must provide')")

    # Recording.
    rec = a.recording
    if rec and rec.startswith("synthetic:"):
        rec = synthetic_recording(os.path.join(res, "recording"), float(rec.split(":", 1)[1]))
    if not rec:
        rec = a.recording_cache or os.path.join(res, "recording")
        desk = os.path.abspath(a.agvloc_desk or
                               os.path.join(os.path.dirname(agvloc), "agvloc-desk"))
        rec = make_recording(desk, rec, a.sim_args, res)
        if rec is None:
            return SKIP
    rec = os.path.realpath(rec)
    # The guest mounts its own tmpfs on /tmp, /run, /var/tmp and /dev/shm; run-in-vm.sh keeps
    # the host directories named here (and the working directory, checkout, results) visible.
    os.environ["AGV_VM_KEEP_EXTRA"] = " ".join(
        p for p in (rec, os.path.dirname(os.path.realpath(agvloc)))
        if re.match(r"^/(tmp|run|var/tmp|dev/shm)/", p))

    cfg_path, cfg = prepare_config(a, res)
    dbc = hil_dbc.Dbc(a.dbc)
    s = Setup(a.scenario, res, agvloc, rec, cfg_path, a.speed, dbc, a.iface)
    g = lambda *k, d=None: cfg.get(tuple(k), d)  # noqa: E731
    s.base_id = as_int(g("can", "base_id", d="0x300"))
    s.extended = as_bool(g("can", "extended_ids", d="false"))
    mode = g("can", "odometry", "mode", d="v_omega")
    s.odom_msg = "MC_OdomWheels" if mode == "wheels" else "MC_OdomTwist"
    default_odom = s.base_id + (0x10 if mode == "wheels" else 0x11)
    s.odom_id = as_int(g("can", "odometry", "id", d="0")) or default_odom  # 0 = DBC default
    s.odom_ext = as_bool(g("can", "odometry", "extended_id", d="false"))
    s.odom_protected = as_bool(g("can", "odometry", "protected", d="true"))
    s.odom_timeout_ms = float(g("can", "odometry", "timeout_ms", d="100"))
    s.track_width_mm = float(g("can", "odometry", "track_width_mm", d="500"))
    s.output_rate_hz = float(g("loop", "output_rate_hz", d="100"))
    s.heartbeat_rate_hz = float(g("loop", "heartbeat_rate_hz", d="1"))
    s.odom = read_odom(rec)
    dur_rec_ns = s.odom[-1][0] - s.odom[0][0]
    drop = None
    if s.scenario == "odom_timeout":
        # Drop the odometry of a window in the middle: 10 timeouts long, at least 1 s wall.
        gap_ns = int(max(1.0 * s.speed, 10 * s.odom_timeout_ms / 1000.0) * 1e9)
        g0_ns = s.odom[0][0] + int(0.4 * dur_rec_ns)
        drop = (g0_ns, g0_ns + gap_ns)
        rep.info(f"odometry gap: recording {(g0_ns - s.odom[0][0]) / 1e9:.2f} s + "
                 f"{gap_ns / 1e9:.2f} s")
    if a.analyse_only:
        s.recording = os.path.join(res, "recording-q")
        s.odom = read_odom(s.recording)
        rec = s.recording
    else:
        rec = s.recording = quantize_recording(s, os.path.join(res, "recording-q"), drop)
    rep.info(f"recording {rec}: {len(s.odom)} odometry rows, "
             f"{(s.odom[-1][0]-s.odom[0][0])/1e9:.2f} s; speed {s.speed} (wall = recording / "
             f"{s.speed})")
    rep.info(f"config {cfg_path}: base 0x{s.base_id:X}, odometry {s.odom_msg} on "
             f"0x{s.odom_id:X}, timeout {s.odom_timeout_ms} ms, output {s.output_rate_hz} Hz")

    # Offline replay on the host: the reference.
    off_dir = os.path.join(res, "offline")
    cmd = [agvloc, "replay", rec, "--out", off_dir, "--config", cfg_path]
    t = time.monotonic()
    if not a.analyse_only and run(cmd, os.path.join(res, "offline.log"), 150) != 0:
        raise HilError(f"offline replay `{' '.join(cmd)}` failed, see {res}/offline.log")
    rep.info(f"offline replay {time.monotonic() - t:.1f} s")
    sc = {"offline": read_pose_csv(off_dir), "match_window_ms": a.match_window_ms}

    # Odometry as the motor controller sends it, paced by 1/speed.
    frames = odom_frames(s)
    sc["odom_payloads"] = frames
    t0 = frames[0][0]
    wall = lambda t_ns: (t_ns - t0) / 1e9 / s.speed  # noqa: E731
    dur = wall(frames[-1][0])
    part1, part2 = frames, []
    env = {"SCENARIO": s.scenario, "AGVLOC": agvloc, "RECORDING": rec, "CONFIG": cfg_path,
           "SPEED": str(s.speed), "IFACE": s.iface, "ODOM_LOG_2": "", "GARBAGE_LOG": "",
           "CANGEN_COUNT": "0", "CANGEN_GAP_MS": "5", "CANGEN_START_S": "0",
           "LINK_DOWN_S": "1", "LOCALIZER_LIMIT_S": "30", "EXTRA_ARGS": ""}
    if s.scenario == "odom_timeout":
        sc["gap_wall"] = True  # the gap is in the (quantized) recording itself
    elif s.scenario == "link_flap":
        cut = dur * 0.4
        part1 = [f for f in frames if wall(f[0]) < cut]
        # Resume with the odometry that belongs to the time after the outage (the outage is
        # LINK_DOWN_S wall seconds; the shell's own delays make this approximate, so poses are
        # compared with the offline replay only before the outage).
        resume = cut + float(env["LINK_DOWN_S"])
        part2 = [f for f in frames if wall(f[0]) >= resume]
    elif s.scenario == "garbage":
        gdur = dur * 0.5
        start = dur * 0.25
        rnd = random.Random(7)
        gf, gl = [], []
        odom_msg = dbc.by_name(s.odom_msg)
        n = int(gdur / 0.02)
        for i in range(n):
            d = bytearray(rnd.randbytes(8))
            d[1] = (d[1] & 0xF0) | rnd.randrange(15)
            good = hil_dbc.e2e_crc(odom_msg.data_id, d)
            d[0] = (good + 1 + rnd.randrange(255)) & 0xFF  # guaranteed wrong CRC
            if i % 5 == 4:
                d = d[: rnd.randrange(8)]  # wrong length
            gl.append((i * 0.02, s.odom_id, s.odom_ext, bytes(d)))
            gf.append((s.odom_id, s.odom_ext, bytes(d), False))
        glog = os.path.join(res, "garbage_odom.log")
        write_canplayer_log(glog, s.iface, gl)
        sc["garbage_frames"] = gf
        env.update(GARBAGE_LOG=glog, CANGEN_COUNT=str(int(gdur / 0.01)), CANGEN_GAP_MS="10",
                   CANGEN_START_S=f"{start:.3f}")
        sc["expect_garbage"] = True
        sc["garbage_window_wall"] = (start, start + gdur)
    log1 = os.path.join(res, "odom_part1.log")
    write_canplayer_log(log1, s.iface, [(wall(t) + 1000.0, s.odom_id, s.odom_ext, d)
                                        for t, d in part1])
    env["ODOM_LOG_1"] = log1
    if part2:
        log2 = os.path.join(res, "odom_part2.log")
        write_canplayer_log(log2, s.iface, [(wall(t) + 1000.0, s.odom_id, s.odom_ext, d)
                                            for t, d in part2])
        env["ODOM_LOG_2"] = log2
    sc["odom_sent"] = len(part1) + len(part2)
    with open(os.path.join(res, "scenario.env"), "w") as f:
        for k, v in env.items():
            f.write(f"{k}={shlex.quote(v)}\n")

    # The VM. vm_timeout bounds the scenario from its start in the guest; the boot has its own
    # limit (run-in-vm.sh --boot-timeout, 300 s), so a boot slowed by a loaded host does not eat it.
    vm_timeout = a.vm_timeout or (90 + dur * 1.5 + int(env["LOCALIZER_LIMIT_S"]) +
                                  float(env["LINK_DOWN_S"]))
    t = time.monotonic()
    guest = [os.path.join(HERE, "guest/scenario.sh"), res]
    if a.analyse_only:
        vm_rc = 0
    elif a.no_vm:
        # A real bus (docs/design/hil.md, "On a real bus"): the same guest script, on this machine.
        try:
            vm_rc = subprocess.run(guest, timeout=vm_timeout).returncode
        except subprocess.TimeoutExpired:
            rep.check(False, "scenario run", f"still running after {vm_timeout:.0f} s")
            return 1
    else:
        vm_rc = subprocess.run([os.path.join(HERE, "vm/run-in-vm.sh"), "--quiet", "--share", res,
                                "--timeout", str(int(vm_timeout)), "--"] + guest).returncode
    rep.info(f"VM run {time.monotonic() - t:.1f} s (" +
             open(os.path.join(res, ".vm/timing")).read().replace("\n", " ").strip() + ")"
             if os.path.exists(os.path.join(res, ".vm/timing")) else "no timing")
    if vm_rc != 0:
        rep.check(False, "VM run", f"run-in-vm.sh exited {vm_rc}; guest console "
                  f"{res}/.vm/console.log")
        return 1
    if not os.path.exists(os.path.join(res, "capture.log")):
        rep.check(False, "capture", "the guest wrote no capture.log; see events.log/console")
        return 1

    # Wall windows -> capture times (relative to the first odometry frame on the bus).
    ev = {}
    for line in open(os.path.join(res, "events.log")):
        tt, _, what = line.strip().partition(" ")
        ev.setdefault(what, float(tt))
    cap = read_capture(os.path.join(res, "capture.log"))
    payloads = set(d for _, d in frames)
    ours = [f for f in cap if (f.can_id, f.ext) == (s.odom_id, s.odom_ext) and f.data in payloads]
    if len(ours) >= 2:
        tc0 = ours[0].t
        if "gap_wall" in sc:
            # The real gap on the bus: the largest inter-frame gap of our odometry frames.
            gap = max((b.t - a_.t, a_.t, b.t) for a_, b in zip(ours, ours[1:]))
            sc["gap_capture"] = (gap[1], gap[2])
        sc["loc_exit"] = next((v for k, v in ev.items() if k.startswith("localizer exited")),
                              float("inf"))
        if "garbage_window_wall" in sc:
            w0 = ev.get("garbage start", tc0)
            w1 = ev.get("garbage end", w0 + sc["garbage_window_wall"][1])
            sc["garbage_window"] = (w0, w1)
        if s.scenario == "link_flap":
            d0, d1 = ev.get("link down"), ev.get("link up")
            if d0 is None or d1 is None:
                rep.check(False, "link flap performed", "events.log has no link down/up")
                return 1
            sc["outage"] = (ev.get("link down requested", d0), d1)
            sc["link_down_done"] = d0
            sc["compare_until"] = d0
    # The reference for what the localizer made of what it received: the recording's frames with
    # the odometry it decoded from the bus, replayed offline. Under TCG on a loaded host the
    # guest's receive times drift by milliseconds from the recording's (5.9 mm along the track at
    # 0.5 m/s in one run) and odometry arrives in bursts; against this replay only the fixes'
    # arrival times differ.
    rx_csv = os.path.join(res, "run", "odom_received.csv")
    if os.path.exists(rx_csv):
        rx_rec = received_recording(rec, rx_csv, os.path.join(res, "recording-rx"))
        rx_dir = os.path.join(res, "offline-rx")
        cmd = [agvloc, "replay", rx_rec, "--out", rx_dir, "--config", cfg_path]
        if run(cmd, os.path.join(res, "offline-rx.log"), 150) != 0:
            rep.check(False, "offline replay of the received odometry",
                      f"`{' '.join(cmd)}` failed, see {res}/offline-rx.log")
            return 1
        sc["received"] = read_pose_csv(rx_dir)
        sc["odom_received"] = read_odom(rx_rec)
    analyse(s, sc, rep)
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Scores an `agvloc replay` output against the recording's truth.csv: how well the reported sigma
tracks the error (docs/design/fusion.md, "A slip inside an arc is not flagged").

Usage: score_replay.py RECORDING_DIR REPLAY_OUT_DIR [...more pairs]

Per pair, over the valid ticks after the first fix (poses.csv):
  RMS of e/sigma in position (x and y pooled) and heading, 3-sigma coverage (x, y and theta all
  inside), between-landmark p95 position error and heading error (valid ticks >= 200 ms after the
  last fused fix), fixes rejected by the gate and re-initialisations (summary.txt).
"""
import bisect
import csv
import math
import os
import re
import sys


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def p95(xs):
    if not xs:
        return float("nan")
    s = sorted(xs)
    return s[min(len(s) - 1, int(math.ceil(0.95 * len(s))) - 1)]


def score(rec, out):
    tr = read_csv(os.path.join(rec, "truth.csv"))
    tt = [int(r["t_ns"]) for r in tr]
    tx = [float(r["x_mm"]) for r in tr]
    ty = [float(r["y_mm"]) for r in tr]
    tth = [float(r["theta_deg"]) for r in tr]

    def truth_at(t):
        if t < tt[0] or t > tt[-1]:
            return None
        i = bisect.bisect_right(tt, t) - 1
        j = min(i + 1, len(tt) - 1)
        f = 0.0 if tt[j] == tt[i] else (t - tt[i]) / (tt[j] - tt[i])
        dth = (tth[j] - tth[i] + 180.0) % 360.0 - 180.0
        return tx[i] + f * (tx[j] - tx[i]), ty[i] + f * (ty[j] - ty[i]), tth[i] + f * dth

    n = n_cov = 0
    sq_pos = sq_th = 0.0
    btw, btw_th = [], []
    for p in read_csv(os.path.join(out, "poses.csv")):
        if p["valid"] != "1" or float(p["time_since_fix_ms"]) < 0:
            continue
        g = truth_at(int(p["t_ns"]))
        if g is None:
            continue
        ex, ey = float(p["x_mm"]) - g[0], float(p["y_mm"]) - g[1]
        eth = (float(p["theta_deg"]) - g[2] + 180.0) % 360.0 - 180.0
        sx, sy, sth = (float(p[k]) for k in ("sigma_x_mm", "sigma_y_mm", "sigma_theta_deg"))
        n += 1
        sq_pos += (ex / sx) ** 2 + (ey / sy) ** 2
        sq_th += (eth / sth) ** 2
        if abs(ex) <= 3 * sx and abs(ey) <= 3 * sy and abs(eth) <= 3 * sth:
            n_cov += 1
        if float(p["time_since_fix_ms"]) >= 200.0:
            btw.append(math.hypot(ex, ey))
            btw_th.append(abs(eth))
    gated = reinit = "?"
    summary = os.path.join(out, "summary.txt")
    if os.path.exists(summary):
        m = re.search(r"gated (\d+),.* re-initialisations (\d+)", open(summary).read())
        if m:
            gated, reinit = int(m.group(1)), int(m.group(2))
    return {
        "ticks": n,
        "pos_rms": math.sqrt(sq_pos / (2 * n)) if n else float("nan"),
        "th_rms": math.sqrt(sq_th / n) if n else float("nan"),
        "cov": 100.0 * n_cov / n if n else float("nan"),
        "btw_p95_mm": p95(btw),
        "btw_th_p95_deg": p95(btw_th),
        "gated": gated,
        "reinit": reinit,
    }


def main(argv):
    if len(argv) < 2 or len(argv) % 2:
        print(__doc__, file=sys.stderr)
        return 2
    print("| run | ticks | e/σ RMS pos / heading | 3σ cov. % | between p95 mm / ° | gated | re-init |")
    print("|---|---|---|---|---|---|---|")
    for rec, out in zip(argv[0::2], argv[1::2]):
        r = score(rec, out)
        print(f"| {out} | {r['ticks']} | {r['pos_rms']:.2f} / {r['th_rms']:.2f} | {r['cov']:.2f} | "
              f"{r['btw_p95_mm']:.2f} / {r['btw_th_p95_deg']:.3f} | {r['gated']} | {r['reinit']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

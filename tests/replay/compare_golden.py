#!/usr/bin/env python3
"""Compares a replay's poses.csv and fixes.csv with golden files and with truth.csv.

Tolerances: a golden comparison must survive compiler and CPU differences (x86-64 vs aarch64
floating point contraction), so positions agree to 0.2 mm and headings to 0.02 deg, not bit for
bit; the frame statuses and the validity of every output tick must be identical.
"""
import csv
import math
import sys

POS_TOL_MM = 0.2
HEAD_TOL_DEG = 0.02
TRUTH_MAX_MM = 10.0  # every valid fused pose within 10 mm of the truth on this short run
TRUTH_MAX_DEG = 0.5


def load(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def angdiff(a, b):
    return abs((a - b + 180.0) % 360.0 - 180.0)


def truth_at(truth, t):
    lo, hi = 0, len(truth) - 1
    if t < truth[0][0] or t > truth[-1][0]:
        return None
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if truth[mid][0] <= t:
            lo = mid
        else:
            hi = mid
    a, b = truth[lo], truth[hi]
    f = 0.0 if b[0] == a[0] else (t - a[0]) / (b[0] - a[0])
    dth = (b[3] - a[3] + 180.0) % 360.0 - 180.0
    return a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]), a[3] + f * dth


def main():
    golden_dir, out_dir, truth_path = sys.argv[1:4]
    errors = []
    gp, op = load(f"{golden_dir}/poses.csv"), load(f"{out_dir}/poses.csv")
    if len(gp) != len(op):
        errors.append(f"poses.csv: {len(op)} rows, golden has {len(gp)}")
    for g, o in zip(gp, op):
        if g["t_ns"] != o["t_ns"] or g["valid"] != o["valid"] or g["health"] != o["health"]:
            errors.append(f"poses.csv t={o['t_ns']}: valid/health {o['valid']}/{o['health']}, "
                          f"golden t={g['t_ns']} {g['valid']}/{g['health']}")
            continue
        d = math.hypot(float(g["x_mm"]) - float(o["x_mm"]), float(g["y_mm"]) - float(o["y_mm"]))
        h = angdiff(float(g["theta_deg"]), float(o["theta_deg"]))
        if d > POS_TOL_MM or h > HEAD_TOL_DEG:
            errors.append(f"poses.csv t={o['t_ns']}: differs from golden by {d:.3f} mm / {h:.4f} deg")
    gf, of = load(f"{golden_dir}/fixes.csv"), load(f"{out_dir}/fixes.csv")
    if [r["status"] for r in gf] != [r["status"] for r in of]:
        errors.append("fixes.csv: frame statuses differ from golden: "
                      f"{[r['status'] for r in of]} vs {[r['status'] for r in gf]}")
    else:
        # Columns added later (search, identity) are compared once the golden files carry them.
        for col in ("search", "identity"):
            if gf and col in gf[0] and [r[col] for r in gf] != [r.get(col) for r in of]:
                errors.append(f"fixes.csv: column {col} differs from golden")
        for g, o in zip(gf, of):
            if o["status"] != "ok":
                continue
            d = math.hypot(float(g["e_x_mm"]) - float(o["e_x_mm"]), float(g["e_y_mm"]) - float(o["e_y_mm"]))
            if d > POS_TOL_MM or angdiff(float(g["e_phi_deg"]), float(o["e_phi_deg"])) > HEAD_TOL_DEG:
                errors.append(f"fixes.csv t={o['t_ns']}: deviation differs from golden by {d:.3f} mm")
    truth = [(int(r["t_ns"]), float(r["x_mm"]), float(r["y_mm"]), float(r["theta_deg"]))
             for r in load(truth_path)]
    n_valid = 0
    worst = (0.0, 0.0)
    for o in op:
        if o["valid"] != "1":
            continue
        tr = truth_at(truth, int(o["t_ns"]))
        if tr is None:
            continue
        n_valid += 1
        d = math.hypot(float(o["x_mm"]) - tr[0], float(o["y_mm"]) - tr[1])
        h = angdiff(float(o["theta_deg"]), tr[2])
        worst = (max(worst[0], d), max(worst[1], h))
    if n_valid < 100:
        errors.append(f"only {n_valid} valid fused poses (expected >= 100)")
    if worst[0] > TRUTH_MAX_MM or worst[1] > TRUTH_MAX_DEG:
        errors.append(f"fused pose vs truth: worst {worst[0]:.2f} mm / {worst[1]:.3f} deg "
                      f"(limits {TRUTH_MAX_MM} mm / {TRUTH_MAX_DEG} deg)")
    for e in errors[:20]:
        print("FAIL:", e)
    if errors:
        print(f"{len(errors)} problem(s)")
        return 1
    print(f"golden replay OK: {len(op)} ticks, {n_valid} valid, worst vs truth "
          f"{worst[0]:.2f} mm / {worst[1]:.3f} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())

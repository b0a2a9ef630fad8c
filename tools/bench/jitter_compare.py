#!/usr/bin/env python3
"""Compares the modes of tools/bench/mqtt_jitter.sh or tests/diag/diag_jitter.sh (their stdout,
one line per run) against the first mode (off): per mode, the median over its runs of the run's
output-period jitter p99 and end-to-end p99, their ratio to off's, and a bootstrap 90 % interval
of that ratio (runs resampled within each mode). A target "within 10 %" is met when the upper
bound is at most 1.10, missed when the lower bound is above it, and not resolved by these runs
otherwise (the machine's run-to-run spread is wider than the target): more runs narrow it.

  jitter_compare.py [--limit 1.10] < runs.txt"""
import argparse
import random
import re
import statistics
import sys


def parse(lines):
    runs = {}
    order = []
    for line in lines:
        m = re.match(r"(\S+) (\d+) .*?output period jitter p50 ([\d.]+) ms p99 ([\d.]+) ms", line)
        e = re.search(r"end to end \(exposure->CAN\) p50 [\d.]+ ms p99 ([\d.]+) ms", line)
        if not m:
            continue
        mode = m.group(1)
        if mode not in runs:
            runs[mode] = []
            order.append(mode)
        runs[mode].append((float(m.group(4)), float(e.group(1)) if e else float("nan")))
    return order, runs


def interval(a, b, rng, n=4000):
    """90 % bootstrap interval of median(a) / median(b)."""
    r = sorted(statistics.median(rng.choices(a, k=len(a))) /
               statistics.median(rng.choices(b, k=len(b))) for _ in range(n))
    return r[int(0.05 * n)], r[int(0.95 * n) - 1]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--limit", type=float, default=1.10)
    a = ap.parse_args()
    order, runs = parse(sys.stdin)
    if len(order) < 2:
        print("jitter_compare: fewer than two modes in the input", file=sys.stderr)
        return 2
    rng = random.Random(1)
    base = order[0]
    print(f"{'mode':8s} {'runs':>4s} {'jitter p99 ms':>14s} {'ratio':>6s} {'90 % interval':>15s} "
          f"{'verdict':14s} {'e2e p99 ms':>11s} {'ratio':>6s} {'90 % interval':>15s} verdict")
    for mode in order:
        cols = []
        for k in (0, 1):
            v = [r[k] for r in runs[mode] if r[k] == r[k]]
            b = [r[k] for r in runs[base] if r[k] == r[k]]
            if not v or not b:
                cols.append(f"{'-':>14s} {'':>6s} {'':>15s} {'':14s}")
                continue
            med = statistics.median(v)
            if mode == base:
                cols.append(f"{med:14.3f} {'':>6s} {'':>15s} {'(reference)':14s}")
                continue
            lo, hi = interval(v, b, rng)
            verdict = ("met" if hi <= a.limit else "missed" if lo > a.limit else "not resolved")
            cols.append(f"{med:14.3f} {med / statistics.median(b):6.2f} "
                        f"{f'{lo:.2f}-{hi:.2f}':>15s} {verdict:14s}")
        print(f"{mode:8s} {len(runs[mode]):4d} {cols[0]} {cols[1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

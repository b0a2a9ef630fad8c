"""Helpers of agvloc-overhead's script tests (tests/overhead/binary.cmake): commands given as one
string each (an emulator may precede the binary), a recording rendered by agvloc-desk
render-site, CSV reading and truth lookup."""
import csv, os, shlex, shutil, subprocess, sys

SKIP = 77

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "vda5050"))
from mqtt_replay import load_schema  # noqa: E402


def vda5050_schema(jsonschema, topic):
    """VDA 5050 2.1.0's schema of `topic` (tests/vda5050/schemas), or None without the caller's
    jsonschema module (the messages' fields are then checked by hand only)."""
    return None if jsonschema is None else load_schema("2.1.0", topic)


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


def run(cmd, args, timeout=120):
    """Runs `cmd` (a command string) with args; returns (rc, stdout, stderr)."""
    p = subprocess.run(shlex.split(cmd) + [str(a) for a in args], capture_output=True, text=True,
                       timeout=timeout)
    if p.returncode < 0 or p.returncode > 2:
        fail("%s %s crashed or failed (rc %d):\n%s\n%s" % (cmd, " ".join(map(str, args)),
                                                          p.returncode, p.stdout, p.stderr))
    return p.returncode, p.stdout, p.stderr


def render(desk, site, out, frames, fps=15.0, seed=3):
    """The site's ceiling cameras, one recording folder each under `out`."""
    shutil.rmtree(out, ignore_errors=True)
    rc, so, se = run(desk, ["render-site", "--site", site, "--out", out, "--frames", frames,
                            "--fps", fps, "--start-s", 2, "--clutter", 0,
                            "--parcel-fraction", 0, "--seed", seed])
    if rc != 0:
        fail("render-site failed:\n" + so + se)
    return sorted(os.path.join(out, d) for d in os.listdir(out)
                  if os.path.isdir(os.path.join(out, d)))


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        fail(path + " is empty")
    return rows[0], rows[1:]


def agv_truth(recording_dirs):
    """{agv id: [(t_ns, x, y, theta, best visible fraction over the cameras)]} sorted by time."""
    by = {}
    for d in recording_dirs:
        _, rows = read_csv(os.path.join(d, "site_truth.csv"))
        for r in rows:
            if r[1] != "agv":
                continue
            key = (r[2], int(r[0]))
            vis = float(r[14])
            old = by.get(key)
            by[key] = (float(r[3]), float(r[4]), float(r[5]), max(vis, old[3] if old else 0.0))
    out = {}
    for (agv, t), v in by.items():
        out.setdefault(agv, []).append((t,) + v)
    for v in out.values():
        v.sort()
    return out

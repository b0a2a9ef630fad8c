"""agvloc-overhead on bad input (tests/overhead/binary.cmake): every case a named error with
exit code 2 or a counted, skipped frame, never a crash. Usage:
test_overhead_bad_input.py OVERHEAD_CMD DESK_CMD SITE WORK"""
import os, shutil, sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from test_overhead_util import fail, render, run


def expect(overhead, args, rc, *parts):
    got, so, se = run(overhead, args)
    text = so + se
    if got != rc or any(p not in text for p in parts):
        fail("%s: expected rc %d with %s, got rc %d:\n%s" % (" ".join(map(str, args)), rc, parts,
                                                             got, text))
    return text


def write(path, text, mode="w"):
    with open(path, mode) as f:
        f.write(text)


def main():
    overhead, desk, site, work = sys.argv[1:5]
    recs = render(desk, site, os.path.join(work, "rec"), frames=3)
    site_text = open(site).read()

    def replay(*args, recordings=None, site_path=site):
        return ["replay", "--site", site_path, "--recordings"] + (recordings or recs) + \
               ["--fast"] + list(args)

    # Site and configuration.
    expect(overhead, replay(site_path=os.path.join(work, "none.yaml")), 2, "none.yaml")
    write(os.path.join(work, "corrupt.yaml"), "name: [unclosed\n")
    expect(overhead, replay(site_path=os.path.join(work, "corrupt.yaml")), 2, "corrupt.yaml")
    write(os.path.join(work, "same_tag.yaml"), site_text.replace("tag_id: 22", "tag_id: 21"))
    expect(overhead, replay(site_path=os.path.join(work, "same_tag.yaml")), 2, "fleet[1].tag_id", "duplicate tag_id")
    expect(overhead, replay("--config", os.path.join(work, "none.yml")), 2, "none.yml")
    write(os.path.join(work, "bad.yml"), "tracker:\n  gate_chi2: 16\n  gate: 3\n")
    expect(overhead, replay("--config", os.path.join(work, "bad.yml")), 2, "line 3",
           "tracker.gate", "unknown key")
    expect(overhead, ["check-config", os.path.join(work, "bad.yml")], 2, "tracker.gate")
    write(os.path.join(work, "lat.yml"), "cameras:\n  cam-north:\n    latency_ms: 20\n")
    expect(overhead, ["check-config", os.path.join(work, "lat.yml")], 0, "OK")
    expect(overhead, ["check-config", os.path.join(work, "lat.yml"), "--site", site], 2,
           "cameras.cam-north: no camera 'cam-north'")
    expect(overhead, replay("--config", os.path.join(work, "lat.yml")), 2, "cam-north")
    write(os.path.join(work, "nobroker.yml"), "output:\n  mqtt: {enabled: true, broker_host: 127.0.0.1, port: 1}\n")
    expect(overhead, replay("--config", os.path.join(work, "nobroker.yml")), 1,
           "output.mqtt: broker 127.0.0.1:1: ")
    expect(overhead, ["run", "--config", os.path.join(work, "lat.yml")], 2, "--site is required")
    expect(overhead, ["run", "--config", os.path.join(work, "lat.yml"), "--site", site], 2,
           "no camera 'cam-north'")
    write(os.path.join(work, "nodev.yml"), "cameras:\n  cam-west:\n    fps: 25\n")
    expect(overhead, ["run", "--config", os.path.join(work, "nodev.yml"), "--site", site], 2,
           "no camera to open")
    expect(overhead, ["run", "--config", os.path.join(work, "nodev.yml"), "--site", site,
                      "--duration-s", "-1"], 2, "--duration-s")
    expect(overhead, ["replay", "--site", site], 2, "--recordings")
    expect(overhead, replay("--bogus"), 2, "--bogus")
    expect(overhead, ["record", "--config", os.path.join(work, "lat.yml"), "--site", site], 2,
           "--out is required")
    expect(overhead, ["detect", "--config", os.path.join(work, "nodev.yml"), "--site", site,
                      "--camera", "cam-west"], 2, "no camera to open")
    expect(overhead, ["detect", "--site", site, "--camera", "cam-west", "--replay", recs[0],
                      "--duration-s", "1"], 2, "--duration-s")
    expect(overhead, [], 2, "subcommand")
    expect(overhead, ["--help"], 0, "check-config", "replay", "detect")

    # Recordings.
    expect(overhead, replay(recordings=[os.path.join(work, "no_such_rec")]), 2,
           "no_such_rec: no such recording folder")
    bad = os.path.join(work, "bad_rec")

    def fresh():
        shutil.rmtree(bad, ignore_errors=True)
        shutil.copytree(recs[0], bad)

    fresh()
    write(os.path.join(bad, "camera.yaml"), "id: cam-north\n")
    expect(overhead, replay(recordings=[bad]), 2, "camera 'cam-north' is not in the site")
    fresh()
    expect(overhead, replay(recordings=[recs[0], bad]), 2, "given twice")
    fresh()
    frames = open(os.path.join(bad, "frames.csv")).read()
    write(os.path.join(bad, "frames.csv"), frames[:-12])  # the last row cut by a power loss
    text = expect(overhead, replay(recordings=[bad]), 0, "frames.csv", "2 frames")
    fresh()
    lines = frames.splitlines(True)
    write(os.path.join(bad, "frames.csv"), "".join(lines[:2]) + lines[2][:12] + "\n" + "".join(lines[3:]))
    expect(overhead, replay(recordings=[bad]), 2, "frames.csv:3")
    fresh()
    write(os.path.join(bad, "frames", "000001.png"), b"\x89PNG\r\n\x1a\n" + b"garbage" * 40, "wb")
    text = expect(overhead, replay(recordings=[bad]), 0, "frame skipped", "1 unreadable")
    print("PASS: every bad input refused or counted")


if __name__ == "__main__":
    main()

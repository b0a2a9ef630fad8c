#!/usr/bin/env python3
"""The diagnostics page in a real browser (docs/guide/diagnostics.md): headless Chromium loads the page
of `agvloc replay --serve`, the test waits until the page says it has drawn the live camera frame
and the map (body data-frame="ok" and data-map="ok", set by the page's own JS after an image
loaded and a map with landmarks was drawn), then keeps a screenshot as a test artefact:
WORKDIR/diag_page.png.
usage: diag_chromium.py AGVLOC WORKDIR   (exit 77 = skipped: no chromium)
"""
import os, shutil, subprocess, sys, time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from diag_common import Served, fail, make_recording


def chromium():
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def run_chromium(browser, work, url, *args):
    # --no-sandbox: CI runs as root, where Chromium's sandbox refuses to start. A throw-away
    # profile; virtual time lets the page's timers and fetches run for the budget, then it dumps.
    profile = os.path.join(work, "chromium-profile")
    cmd = [browser, "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
           "--no-first-run", "--user-data-dir=" + profile, "--window-size=1280,1000",
           "--hide-scrollbars", "--virtual-time-budget=6000"] + list(args) + [url]
    return subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=180)


def main():
    agvloc, work = sys.argv[1], sys.argv[2]
    browser = chromium()
    if not browser:
        print("SKIP: no chromium (tools/install-deps.sh installs it)")
        sys.exit(77)
    os.makedirs(work, exist_ok=True)
    rec = os.path.join(work, "rec")
    make_recording(agvloc, rec)
    srv = Served(agvloc, rec, os.path.join(work, "served"), "diag:\n  port: 0\n")
    if not srv.port:
        fail("no 'diag: serving' line:\n" + srv.output())
    try:
        srv.wait_finished()
        url = "http://127.0.0.1:%d/" % srv.port
        deadline = time.monotonic() + 300
        dom = ""
        while time.monotonic() < deadline:
            r = run_chromium(browser, work, url, "--dump-dom")
            dom = r.stdout.decode(errors="replace")
            if 'data-frame="ok"' in dom and 'data-map="ok"' in dom:
                break
            time.sleep(1)
        else:
            fail("the page did not draw the frame and the map; last DOM:\n" + dom[:2000])
        if "LOST" in dom.split("</header>")[0] and "OK" not in dom.split("</header>")[0]:
            print("note: the final health is LOST")
        shot = os.path.join(work, "diag_page.png")
        if os.path.exists(shot):
            os.remove(shot)
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            run_chromium(browser, work, url, "--screenshot=" + shot)
            if os.path.exists(shot) and os.path.getsize(shot) > 20000:
                break
            time.sleep(1)
        else:
            fail("no screenshot")
        print("screenshot: %s (%d bytes)" % (shot, os.path.getsize(shot)))
    finally:
        rc = srv.stop()
    if rc != 0:
        fail("agvloc replay --serve ended with %d" % rc)
    print("PASS", flush=True)


if __name__ == "__main__":
    main()

"""Helpers of the diagnostics page tests (docs/guide/diagnostics.md): the recording, a served replay,
HTTP requests with deadlines. Every wait polls a condition against a generous deadline: the tests
run on a loaded 2-core machine."""
import atexit, http.client, os, re, shutil, signal, subprocess, sys, threading, time


def fail(msg):
    print("FAIL: " + msg, flush=True)
    sys.exit(1)


def make_recording(agvloc, rec):
    """The 8 s simulated recording the MQTT test uses (line, 15 fps), with the simulator's map as
    map.csv (replay takes it from there: fixes map-verified, landmarks on the page's map)."""
    if os.path.exists(os.path.join(rec, "map.csv")):
        return
    desk = os.path.join(os.path.dirname(agvloc), "agvloc-desk")  # beside agvloc in the build
    subprocess.run([desk, "sim", "--out", rec, "--trajectory", "line", "--duration-s", "8",
                    "--fps", "15", "--seed", "7", "--speed-mps", "0.5", "--force"], check=True,
                   stdout=subprocess.DEVNULL)
    here = os.path.dirname(os.path.abspath(__file__))
    shutil.copy(os.path.join(here, "..", "..", "tools", "maps", "default_grid.csv"),
                os.path.join(rec, "map.csv"))


class Served:
    """`agvloc replay REC --serve` in the background; .port once it serves."""

    def __init__(self, agvloc, rec, out, config_text, extra=(), deadline_s=120):
        os.makedirs(out, exist_ok=True)
        self.config = os.path.join(out, "diag.yaml")
        open(self.config, "w").write(config_text)
        self.log_path = os.path.join(out, "stdout.txt")
        self.log = open(self.log_path, "w")
        self.proc = subprocess.Popen([agvloc, "replay", rec, "--out", out, "--config", self.config,
                                      "--quiet", "--serve"] + list(extra),
                                     stdout=self.log, stderr=subprocess.STDOUT)
        # A failing check exits at once: the served replay must not outlive the test.
        atexit.register(self._kill)
        self.port = None
        end = time.monotonic() + deadline_s
        while time.monotonic() < end:
            m = re.search(r"diag: serving http://[^ ]*:(\d+)/", open(self.log_path).read())
            if m:
                self.port = int(m.group(1))
                return
            if self.proc.poll() is not None:
                return
            time.sleep(0.05)

    def _kill(self):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()

    def output(self):
        return open(self.log_path).read()

    def wait_finished(self, deadline_s=180):
        """Polls the status until the replay's final state is served."""
        end = time.monotonic() + deadline_s
        while time.monotonic() < end:
            status, body, _ = get(self.port, "/api/status.json", timeout=30)
            if status == 200:
                import json
                s = json.loads(body)
                if s["finished"]:
                    return s
            if self.proc.poll() is not None:
                fail("replay ended while serving:\n" + self.output())
            time.sleep(0.2)
        fail("the replay did not finish within %d s" % deadline_s)

    def stop(self, deadline_s=30):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(timeout=deadline_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            fail("agvloc did not stop within %d s of SIGTERM" % deadline_s)


def get(port, path, timeout=30, method="GET", headers=None):
    """(status, body bytes, headers dict); status 0 when the connection failed."""
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=timeout)
    try:
        c.request(method, path, headers=headers or {})
        r = c.getresponse()
        return r.status, r.read(), dict(r.getheaders())
    except (OSError, http.client.HTTPException) as e:
        return 0, str(e).encode(), {}
    finally:
        c.close()


def read_poses(path):
    lines = open(path).read().splitlines()
    head = lines[0].split(",")
    return [dict(zip(head, l.split(","))) for l in lines[1:]]

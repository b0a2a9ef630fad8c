"""The diagnostics page under hostile clients (docs/design/security.md "Diagnostics page"): 500
idle sockets, a client sending its header line one byte a second, floods of oversized header
sections, request lines and bodies, all at once; meanwhile normal GETs must get their 200 within 1 s
and the server's RSS must stay within +16 MB of what it was before the attack. Runs the page alone
(diag_serve: no loop, no camera). The bounds are generous for a loaded 2-core machine: the figures
measured are printed.

The attackers run in a process of their own: sharing the interpreter lock with them, the normal
client could be held for many milliseconds between its connect and its request, a silence no real
client shows and one the server rightly treats as idle once the flood has turned its table over."""
import multiprocessing, os, resource, socket, subprocess, sys, threading, time

IDLE = 500
RSS_BUDGET_KB = 16 * 1024
GET_DEADLINE_S = 1.0


def fail(msg):
    print("FAIL: " + msg, flush=True)
    sys.exit(1)


def rss_kb(pid):
    for line in open("/proc/%d/status" % pid):
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def connect(port, timeout=5.0):
    s = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\0" * 8)
    return s


def get(port):
    """One normal GET /metrics: (status, seconds), status 0 when no answer came."""
    t0 = time.monotonic()
    try:
        s = connect(port, timeout=10)
        s.sendall(b"GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n")
        data = b""
        while True:
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
        s.close()
        status = int(data[9:12]) if data.startswith(b"HTTP/1.1 ") else 0
    except OSError as e:
        print("GET failed: %r" % e, flush=True)
        status = 0
    return status, time.monotonic() - t0


class Attack:
    def __init__(self, port):
        self.port, self.stop, self.threads = port, threading.Event(), []
        self.slow_cut_s, self.refusals = None, {}

    def spawn(self, fn):
        t = threading.Thread(target=fn, daemon=True)
        t.start()
        self.threads.append(t)

    def count(self, what):
        self.refusals[what] = self.refusals.get(what, 0) + 1

    def idle(self):
        """IDLE sockets that never send a byte, reopened when the server drops them."""
        socks = []
        while not self.stop.is_set():
            socks = [s for s in socks if s.fileno() >= 0]
            while len(socks) < IDLE and not self.stop.is_set():
                try:
                    socks.append(connect(self.port))
                except OSError:
                    break
            for s in list(socks):
                s.setblocking(False)
                try:
                    if s.recv(1) == b"":
                        s.close()
                except BlockingIOError:
                    pass
                except OSError:
                    s.close()
            time.sleep(0.2)
        for s in socks:
            s.close()

    def slow_header(self):
        """A header line one byte a second: it must be cut off, never answered."""
        s = connect(self.port)
        t0 = time.monotonic()
        s.sendall(b"GET /metrics HTTP/1.1\r\nX-Slow: ")
        s.settimeout(1.0)
        while not self.stop.is_set() and time.monotonic() - t0 < 30:
            try:
                s.sendall(b"a")
                if s.recv(1024) == b"":
                    break
            except socket.timeout:
                continue
            except OSError:
                break
        else:
            return
        self.slow_cut_s = time.monotonic() - t0
        s.close()

    def flood(self, head, chunk, total):
        """Sends head, then chunk until total bytes or the server closes; counts the answer."""
        while not self.stop.is_set():
            try:
                s = connect(self.port)
                s.sendall(head)
                sent = 0
                while sent < total and not self.stop.is_set():
                    s.sendall(chunk)
                    sent += len(chunk)
                s.settimeout(5)
                answer = s.recv(64)
                self.count(answer[9:12].decode() if answer.startswith(b"HTTP/1.1 ") else "closed")
            except OSError:
                self.count("closed")
            finally:
                s.close()


def attack_process(port, stop, results):
    """The whole attack, until stop is set: its slow-header cut and flood answers go to results."""
    a = Attack(port)
    a.spawn(a.idle)
    a.spawn(a.slow_header)
    many_headers = b"GET / HTTP/1.1\r\nHost: x\r\n"
    a.spawn(lambda: a.flood(many_headers, b"X-a: b\r\n" * 8192, 10 << 20))
    a.spawn(lambda: a.flood(b"GET /", b"a" * 65536, 20 << 20))  # one huge request line
    a.spawn(lambda: a.flood(b"POST / HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n",
                            b"10000\r\n" + b"c" * 65536 + b"\r\n", 10 << 20))
    a.spawn(lambda: a.flood(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n", b"d" * 65536, 10 << 20))
    stop.wait()
    a.stop.set()
    for t in a.threads:
        t.join(timeout=40)
    results.put((a.slow_cut_s, a.refusals))


def main():
    serve = sys.argv[1]
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < IDLE + 200:
        resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, 4096), hard))
    proc = subprocess.Popen([serve], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    if proc.poll() == 77 or not line.startswith("diag:"):
        proc.wait()
        if proc.returncode == 77:
            print("SKIP: built without the diagnostics page")
            sys.exit(77)
    while not line.startswith("port "):
        line = proc.stdout.readline()
        if not line:
            fail("diag_serve printed no port")
    port = int(line.split()[1])
    try:
        for _ in range(20):
            if get(port)[0] != 200:
                fail("no 200 before the attack")
        # Alone first: the request deadline, not the eviction of idle sockets, cuts it.
        alone = Attack(port)
        alone.slow_header()
        if alone.slow_cut_s is None or alone.slow_cut_s > 10:
            fail("a header sent one byte a second was not cut off within 10 s: %s"
                 % alone.slow_cut_s)
        print("slow header alone: cut after %.1f s" % alone.slow_cut_s)
        time.sleep(0.5)
        base = rss_kb(proc.pid)
        ctx = multiprocessing.get_context("fork")
        stop, results = ctx.Event(), ctx.Queue()
        attacker = ctx.Process(target=attack_process, args=(port, stop, results), daemon=True)
        attacker.start()
        time.sleep(3)  # the idle sockets are in, the floods running
        peak, latencies, statuses = base, [], []
        t_end = time.monotonic() + 12
        while time.monotonic() < t_end:
            status, dt = get(port)
            statuses.append(status)
            latencies.append(dt)
            peak = max(peak, rss_kb(proc.pid))
            time.sleep(0.2)
        peak = max(peak, rss_kb(proc.pid))
        stop.set()
        slow_cut_s, refusals = results.get(timeout=60)
        attacker.join(timeout=10)
    finally:
        proc.stdin.close()
        proc.wait(timeout=30)
    latencies.sort()
    print("during the attack: %d GETs, statuses %s, latency median %.3f s, max %.3f s"
          % (len(statuses), sorted(set(statuses)), latencies[len(latencies) // 2], latencies[-1]))
    print("RSS before %d kB, peak %d kB (+%d kB); slow header cut after %s s; flood answers %s"
          % (base, peak, peak - base, slow_cut_s and round(slow_cut_s, 1), refusals))
    print(proc.stdout.read().strip())
    if any(s != 200 for s in statuses):
        fail("a normal GET was not answered 200 during the attack: %s" % statuses)
    if latencies[-1] > GET_DEADLINE_S:
        fail("a normal GET took %.3f s (> %.1f s)" % (latencies[-1], GET_DEADLINE_S))
    if peak - base > RSS_BUDGET_KB:
        fail("RSS grew by %d kB (> %d kB)" % (peak - base, RSS_BUDGET_KB))
    if slow_cut_s is None or slow_cut_s > 10:
        fail("the one-byte-a-second header was not cut off within 10 s: %s" % slow_cut_s)
    print("PASS")


if __name__ == "__main__":
    main()

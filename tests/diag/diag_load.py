#!/usr/bin/env python3
"""N clients on the diagnostics page until SIGTERM / SIGINT; prints the answer counts at exit.
  page:  each client polls as the page does (status every 0.5 s, map and frame every 1 s,
         i.e. 4 requests a second a client: 200 a second for 50)
  flood: each client requests status, map, metrics, frame, page in turn as fast as answered
usage: diag_load.py PORT [CLIENTS] [page|flood]   (tests/diag/diag_jitter.sh)"""
import os, signal, sys, threading, time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from diag_common import get

port = int(sys.argv[1])
n = int(sys.argv[2]) if len(sys.argv) > 2 else 50
mode = sys.argv[3] if len(sys.argv) > 3 else "page"
stop = threading.Event()
counts = {}
lock = threading.Lock()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
signal.signal(signal.SIGINT, lambda *_: stop.set())


def count(status):
    with lock:
        counts[status] = counts.get(status, 0) + 1


def flood(i):
    paths = ["/api/status.json", "/api/map.json", "/metrics", "/frame.png", "/"]
    k = i
    while not stop.is_set():
        count(get(port, paths[k % len(paths)], timeout=10)[0])
        k += 1


def page(i):
    stop.wait(0.5 * i / n)  # spread the clients over a period, as browsers opened at random
    k = 0
    while not stop.is_set():
        t0 = time.monotonic()
        count(get(port, "/api/status.json", timeout=10)[0])
        if k % 2 == 0:
            count(get(port, "/api/map.json", timeout=10)[0])
            count(get(port, "/frame.png", timeout=10)[0])
        k += 1
        stop.wait(max(0.0, 0.5 - (time.monotonic() - t0)))


threads = [threading.Thread(target=flood if mode == "flood" else page, args=(i,), daemon=True)
           for i in range(n)]
for t in threads:
    t.start()
while not stop.is_set():
    stop.wait(0.5)
print("load: %d clients (%s), answers by status %s" % (n, mode, dict(sorted(counts.items()))),
      flush=True)

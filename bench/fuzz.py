#!/usr/bin/env python3
"""Malformed and random requests: COUNT connections to HOST:PORT, each sending
one request built from random bytes, a mutated valid request, an absurd
header, or a mutated scene, then half-closing and reading the answer. Checks
/healthz every 1000 requests. Prints counts of answers by status line.

usage: fuzz.py HOST PORT COUNT [THREADS] [SEED]
"""
import random
import socket
import sys
import threading
import time
from collections import Counter

SCENE = (b"NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 8 8\n"
         b"SPHERE s 0 0 -5 1 2 1 1 0 0 1 1 0.5 0.3 20\nLIGHT l 3 3 0 1 1 1\n"
         b"BACK 0 0 1\nAMBIENT 0.2 0.2 0.2\nOUTPUT x.ppm\n")
VALID = [
    b"GET /healthz HTTP/1.1\r\nHost: f\r\n\r\n",
    b"GET /scenes/testSample.txt HTTP/1.1\r\nHost: f\r\n\r\n",
    b"HEAD / HTTP/1.1\r\nHost: f\r\nConnection: close\r\n\r\n",
    b"POST /render?spp=1 HTTP/1.1\r\nHost: f\r\nContent-Length: %d\r\n\r\n" % len(SCENE) + SCENE,
]
ABSURD = [
    b"POST /render HTTP/1.1\r\nHost: f\r\nContent-Length: 99999999999999999999\r\n\r\n",
    b"POST /render HTTP/1.1\r\nHost: f\r\nContent-Length: -5\r\n\r\nabc",
    b"POST /render HTTP/1.1\r\nHost: f\r\nTransfer-Encoding: chunked\r\n\r\n4\r\nNEAR\r\n0\r\n\r\n",
    b"POST /render HTTP/1.1\r\nHost: f\r\nContent-Length: 3\r\nContent-Length: 4\r\n\r\nabcd",
    b"GET /" + b"a" * 20000 + b" HTTP/1.1\r\nHost: f\r\n\r\n",
    b"GET / HTTP/1.1\r\n" + b"X: y\r\n" * 200 + b"\r\n",
    b"GET / HTTP/9.9\r\nHost: f\r\n\r\n",
    b"\x00\x01\x02\r\n\r\n",
    b"POST /render?spp=99999&depth=-1&format=gif HTTP/1.1\r\nHost: f\r\nContent-Length: 0\r\n\r\n",
    b"GET /scenes/..%2f..%2fetc%2fpasswd HTTP/1.1\r\nHost: f\r\n\r\n",
]


def mutate(rng, data):
    data = bytearray(data)
    for _ in range(rng.randint(1, 8)):
        op = rng.randrange(3)
        i = rng.randrange(len(data) + 1)
        if op == 0 and data:
            data[min(i, len(data) - 1)] = rng.randrange(256)
        elif op == 1:
            data[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
        elif data:
            del data[i:i + rng.randint(1, 16)]
    return bytes(data)


def scene_request(rng):
    body = mutate(rng, SCENE)
    return b"POST /render HTTP/1.1\r\nHost: f\r\nContent-Length: %d\r\n\r\n" % len(body) + body


def build(rng):
    kind = rng.randrange(4)
    if kind == 0:
        return bytes(rng.randrange(256) for _ in range(rng.randint(0, 2000)))
    if kind == 1:
        return mutate(rng, rng.choice(VALID))
    if kind == 2:
        return rng.choice(ABSURD)
    return scene_request(rng)


def exchange(host, port, data, timeout=15.0):
    with socket.create_connection((host, port), timeout=timeout) as s:
        try:
            s.sendall(data)
            s.shutdown(socket.SHUT_WR)
        except OSError:
            pass
        reply = b""
        try:
            while True:
                chunk = s.recv(65536)
                if not chunk:
                    break
                reply += chunk
        except ConnectionResetError:
            pass
        return reply


def main():
    host, port, count = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    threads = int(sys.argv[4]) if len(sys.argv) > 4 else 8
    seed = int(sys.argv[5]) if len(sys.argv) > 5 else 1
    counts = Counter()
    health_failures = []
    lock = threading.Lock()
    next_index = [0]

    def work(tid):
        rng = random.Random(seed * 1000 + tid)
        while True:
            with lock:
                i = next_index[0]
                next_index[0] += 1
            if i >= count:
                return
            if i % 1000 == 0:
                started = time.monotonic()
                try:
                    ok = exchange(host, port, VALID[0], timeout=5).startswith(b"HTTP/1.1 200")
                except OSError as e:
                    ok = False
                if not ok or time.monotonic() - started > 2:
                    with lock:
                        health_failures.append(i)
            try:
                reply = exchange(host, port, build(rng))
                # A half-closed render is told 100 Continue first: count the final answer.
                while reply.startswith(b"HTTP/1.1 1") and b"\r\n\r\n" in reply:
                    reply = reply.split(b"\r\n\r\n", 1)[1]
                status = reply.split(b"\r\n", 1)[0].decode("latin-1")[:12] or "(closed)"
            except socket.timeout:
                status = "(timeout)"
            except OSError as e:
                status = "(" + type(e).__name__ + ")"
            with lock:
                counts[status] += 1

    started = time.monotonic()
    workers = [threading.Thread(target=work, args=(t,)) for t in range(threads)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    elapsed = time.monotonic() - started
    print(f"fuzz: {count} requests in {elapsed:.1f} s, {len(health_failures)} failed /healthz checks")
    for status, n in counts.most_common():
        print(f"  {n:7d}  {status}")
    sys.exit(1 if health_failures else 0)


if __name__ == "__main__":
    main()

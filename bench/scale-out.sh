#!/usr/bin/env bash
# Scale-out figures: renders/s through nginx with 1 and 2 workers (and to
# one worker directly, without nginx), and one 4096 × 4096 frame tiled over
# 1 and 2 workers against a local render with the same total threads.
# Every worker has --threads 1. Configurations are interleaved, REPS times
# each; the table gives medians and the spread (min–max).
#
#   bench/scale-out.sh [REPS] [LOAD-SECONDS]     (defaults 3 and 15)
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BIN="$ROOT/target/release/voxtrace"
REPS="${1:-3}"
SECONDS_PER_LOAD="${2:-15}"
WORK="$(mktemp -d)"
export VOXTRACE_BIN="$BIN"
cleanup() {
  VOXTRACE_CLUSTER_DIR="$WORK/c1" "$ROOT/deploy/cluster.sh" down || true
  VOXTRACE_CLUSTER_DIR="$WORK/c2" "$ROOT/deploy/cluster.sh" down || true
  rm -rf "$WORK"
}
trap cleanup EXIT

[ -x "$BIN" ] || (cd "$ROOT" && cargo build --release --bin voxtrace)
SMALL="$ROOT/scenes/testSample.txt"
sed 's/^RES .*/RES 4096 4096/' "$SMALL" > "$WORK/big.txt"
SPP=4
TILES=16

c1="$(VOXTRACE_CLUSTER_DIR="$WORK/c1" "$ROOT/deploy/cluster.sh" up 1 -- --threads 1)"
c2="$(VOXTRACE_CLUSTER_DIR="$WORK/c2" "$ROOT/deploy/cluster.sh" up 2 -- --threads 1)"
front1="$(head -n 1 <<<"$c1")"
front2="$(head -n 1 <<<"$c2")"
direct1="$(sed -n 2p <<<"$c1" | cut -d' ' -f3)"
"$BIN" render "$WORK/big.txt" --spp $SPP --threads 2 -o "$WORK/reference.png"

# renders/s of `voxtrace load`, 4 connections, testSample (600 × 600).
load() {
  "$BIN" load --url "$1/render" --scene "$SMALL" -c 4 -d "${SECONDS_PER_LOAD}s" --json |
    python3 -c 'import json,sys; r=json.load(sys.stdin); assert r["status"]=={"200": r["requests"]}, r["status"]; print(r["renders_per_s"])'
}

# CPU seconds (user + system) the processes PIDS… have used so far.
cpu_of() {
  local ticks=0 pid
  for pid in "$@"; do
    # Fields 14 and 15 of /proc/PID/stat, counted after the command name.
    ticks=$((ticks + $(sed 's/.*) //' "/proc/$pid/stat" | awk '{print $12 + $13}')))
  done
  echo "$ticks $(getconf CLK_TCK)" | awk '{printf "%.2f", $1 / $2}'
}

# The processes of cluster directory $1: its workers, nginx and nginx's workers.
cluster_pids() {
  local nginx; nginx="$(cat "$1/nginx.pid")"
  cut -d' ' -f1 "$1/workers"
  echo "$nginx"
  for child in $(cat "/proc/$nginx/task/$nginx/children"); do echo "$child"; done
}

# A render of the big frame: whole-process wall seconds, and CPU seconds of
# the client and (for a tiled one, cluster directory $1) every process of
# the cluster; and a check that it wrote the local bytes.
frame() {
  local cluster="$1"; shift
  local out="$WORK/out.png" pids=() before=0 after=0
  [ -z "$cluster" ] || { mapfile -t pids < <(cluster_pids "$cluster"); before="$(cpu_of "${pids[@]}")"; }
  # In a session of its own, as each worker is (cluster.sh starts them
  # with setsid): with autogroup scheduling, a contended CPU is shared out
  # per session first.
  /usr/bin/time -f "%e %U %S" -o "$WORK/time" setsid -w "$BIN" render "$WORK/big.txt" --spp $SPP -o "$out" "$@" 2>/dev/null
  [ -z "$cluster" ] || after="$(cpu_of "${pids[@]}")"
  cmp -s "$out" "$WORK/reference.png" || { echo "scale-out.sh: $* wrote other bytes" >&2; exit 1; }
  awk -v b="$before" -v a="$after" '{printf "%s %.2f\n", $1, $2 + $3 + a - b}' "$WORK/time"
}

: > "$WORK/results"
for rep in $(seq 1 "$REPS"); do
  echo "rep $rep/$REPS (load average $(cut -d' ' -f1 /proc/loadavg))" >&2
  echo "load_direct_1 $(load "$direct1")" >> "$WORK/results"
  echo "load_nginx_1 $(load "$front1")" >> "$WORK/results"
  echo "load_nginx_2 $(load "$front2")" >> "$WORK/results"
  for run in "local_t1||--threads 1" "tiled_w1|$WORK/c1|--remote $front1 --tiles $TILES" \
             "local_t2||--threads 2" "tiled_w2|$WORK/c2|--remote $front2 --tiles $TILES"; do
    IFS='|' read -r name cluster args <<<"$run"
    # shellcheck disable=SC2086 # the arguments are words
    read -r wall cpu <<<"$(frame "$cluster" $args)"
    echo "frame_$name $wall" >> "$WORK/results"
    echo "cpu_$name $cpu" >> "$WORK/results"
  done
done

python3 - "$WORK/results" <<'PY'
import statistics, sys
runs = {}
for line in open(sys.argv[1]):
    name, value = line.split()
    runs.setdefault(name, []).append(float(value))
med = {k: statistics.median(v) for k, v in runs.items()}
def row(label, key, unit):
    v = runs[key]
    print(f"| {label} | {med[key]:.2f} {unit} | {min(v):.2f}–{max(v):.2f} |")
print("| configuration | median | spread |\n|---|---:|---:|")
row("renders/s, one worker directly", "load_direct_1", "/s")
row("renders/s, nginx + 1 worker", "load_nginx_1", "/s")
row("renders/s, nginx + 2 workers", "load_nginx_2", "/s")
row("4096² frame, local --threads 1", "frame_local_t1", "s")
row("4096² frame, 16 tiles, nginx + 1 worker", "frame_tiled_w1", "s")
row("4096² frame, local --threads 2", "frame_local_t2", "s")
row("4096² frame, 16 tiles, nginx + 2 workers", "frame_tiled_w2", "s")
row("CPU of the 4096² frame, local --threads 1", "cpu_local_t1", "s")
row("CPU of the 4096² frame, tiled, 1 worker (client + nginx + worker)", "cpu_tiled_w1", "s")
row("CPU of the 4096² frame, local --threads 2", "cpu_local_t2", "s")
row("CPU of the 4096² frame, tiled, 2 workers (client + nginx + workers)", "cpu_tiled_w2", "s")
print()
print(f"nginx overhead (renders/s direct / through nginx, 1 worker): {med['load_direct_1']/med['load_nginx_1']:.3f}")
print(f"throughput scaling, 2 workers / 1 worker: {med['load_nginx_2']/med['load_nginx_1']:.2f}")
print(f"tiling overhead, 1 worker (tiled / local, 1 thread): {med['frame_tiled_w1']/med['frame_local_t1']:.3f}")
print(f"tiling overhead, 2 workers (tiled / local, 2 threads): {med['frame_tiled_w2']/med['frame_local_t2']:.3f}")
print(f"frame speed-up, 2 workers / 1 worker: {med['frame_tiled_w1']/med['frame_tiled_w2']:.2f}")
print(f"CPU overhead of tiling, 1 worker (tiled / local): {med['cpu_tiled_w1']/med['cpu_local_t1']:.3f}")
print(f"CPU overhead of tiling, 2 workers (tiled / local): {med['cpu_tiled_w2']/med['cpu_local_t2']:.3f}")
PY

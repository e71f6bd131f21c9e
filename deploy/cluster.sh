#!/usr/bin/env bash
# A local render cluster: N `voxtrace serve` workers behind nginx, all
# unprivileged on loopback ports, under one prefix directory.
#
#   deploy/cluster.sh up N [-- SERVE-ARGS…]   start; prints the front URL, then `worker PID URL` per worker
#   deploy/cluster.sh down                    stop everything it started (SIGTERM: workers drain first)
#
# Environment: VOXTRACE_CLUSTER_DIR (the prefix; default
# ${TMPDIR:-/tmp}/voxtrace-cluster-$UID), VOXTRACE_BIN (default
# target/release/voxtrace, built if missing), VOXTRACE_FRONT_PORT (nginx's
# port; default a free one).
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
DIR="${VOXTRACE_CLUSTER_DIR:-${TMPDIR:-/tmp}/voxtrace-cluster-$(id -u)}"
BIN="${VOXTRACE_BIN:-$ROOT/target/release/voxtrace}"
# Every wait below ends by then, or the command fails saying what it waited for.
START_SECONDS=20
STOP_SECONDS=100

die() { echo "cluster.sh: $*" >&2; exit 1; }

# Whether PID is a live process (a zombie waiting to be reaped is not).
alive() {
  local state
  state="$(awk '{print $3}' "/proc/$1/stat" 2>/dev/null)" || return 1
  [ -n "$state" ] && [ "$state" != Z ]
}

find_nginx() {
  NGINX="$(command -v nginx || true)"
  [ -n "$NGINX" ] || { [ -x /usr/sbin/nginx ] && NGINX=/usr/sbin/nginx; } || true
  if [ -z "$NGINX" ]; then
    echo "cluster.sh: installing nginx (Debian package)" >&2
    local sudo=""; [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get update -qq >&2
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq nginx >&2
    NGINX="$(command -v nginx || echo /usr/sbin/nginx)"
  fi
  [ -x "$NGINX" ] || die "no nginx"
}

# The URL a worker printed on its first line ("listening on http://ADDR").
worker_url() {
  local log="$1" pid="$2" deadline=$((SECONDS + START_SECONDS)) line
  while [ $SECONDS -lt $deadline ]; do
    line="$(head -n 1 "$log" 2>/dev/null || true)"
    case "$line" in
      "listening on http://"*) echo "${line#listening on }"; return 0 ;;
    esac
    alive "$pid" || die "worker $pid exited: $(cat "$log")"
    sleep 0.05
  done
  die "worker $pid did not start within ${START_SECONDS}s"
}

up() {
  local n="$1"; shift
  [[ "$n" =~ ^[1-9][0-9]*$ ]] || die "up N: N must be a whole number of workers, at least 1"
  [ "${1:-}" = "--" ] && shift
  [ ! -e "$DIR/workers" ] || die "a cluster is already up in $DIR (deploy/cluster.sh down first)"
  find_nginx
  if [ ! -x "$BIN" ]; then
    (cd "$ROOT" && cargo build --release --bin voxtrace >&2)
  fi
  mkdir -p "$DIR/temp" "$DIR/logs"
  : > "$DIR/workers"
  local servers="" i pid url
  for i in $(seq 1 "$n"); do
    setsid "$BIN" serve --addr 127.0.0.1:0 --worker-name "worker-$i" "$@" \
      </dev/null >"$DIR/logs/worker-$i.log" 2>&1 &
    pid=$!
    url="$(worker_url "$DIR/logs/worker-$i.log" "$pid")"
    echo "$pid $url" >> "$DIR/workers"
    servers+="        server ${url#http://} max_fails=1 fail_timeout=5s;"$'\n'
  done
  local user="" port tries=0
  # As root, nginx would hand its workers to `nobody`, who cannot write
  # the prefix; unprivileged, the directive means nothing and is left out.
  [ "$(id -u)" -ne 0 ] || user="user root;"
  while :; do
    port="${VOXTRACE_FRONT_PORT:-$((20000 + RANDOM % 40000))}"
    sed -e "s|@PREFIX@|$DIR|g" -e "s|@PORT@|$port|g" -e "s|@USER@|$user|" \
        -e "/@SERVERS@/{r /dev/stdin" -e "d}" "$ROOT/deploy/nginx.conf" \
        > "$DIR/nginx.conf" <<<"${servers%$'\n'}"
    if "$NGINX" -p "$DIR" -c "$DIR/nginx.conf" -e "$DIR/error.log" 2>>"$DIR/error.log"; then
      break
    fi
    tries=$((tries + 1))
    [ -z "${VOXTRACE_FRONT_PORT:-}" ] && [ $tries -lt 20 ] \
      || { down >/dev/null 2>&1; die "nginx did not start: $(tail -n 3 "$DIR/error.log")"; }
  done
  local deadline=$((SECONDS + START_SECONDS))
  until [ -s "$DIR/nginx.pid" ] && alive "$(cat "$DIR/nginx.pid")"; do
    [ $SECONDS -lt $deadline ] || die "nginx wrote no pid file within ${START_SECONDS}s"
    sleep 0.05
  done
  echo "http://127.0.0.1:$port" > "$DIR/front"
  cat "$DIR/front"
  sed 's/^/worker /' "$DIR/workers"
}

down() {
  [ -d "$DIR" ] || return 0
  local pids=()
  if [ -s "$DIR/nginx.pid" ]; then
    pids+=("$(cat "$DIR/nginx.pid")")
    # Its worker processes are its children; QUIT lets them finish.
    pids+=($(cat "/proc/${pids[0]}/task/${pids[0]}/children" 2>/dev/null || true))
    kill -QUIT "${pids[0]}" 2>/dev/null || true
  fi
  if [ -s "$DIR/workers" ]; then
    local pid url
    while read -r pid url; do
      pids+=("$pid")
      kill -TERM "$pid" 2>/dev/null || true
    done < "$DIR/workers"
  fi
  local deadline=$((SECONDS + STOP_SECONDS)) pid left
  while :; do
    left=()
    for pid in "${pids[@]}"; do alive "$pid" && left+=("$pid"); done
    [ ${#left[@]} -gt 0 ] || break
    if [ $SECONDS -ge $deadline ]; then
      echo "cluster.sh: still running after ${STOP_SECONDS}s, killing: ${left[*]}" >&2
      kill -KILL "${left[@]}" 2>/dev/null || true
    fi
    sleep 0.05
  done
  rm -rf "$DIR"
}

case "${1:-}" in
  up) shift; [ $# -ge 1 ] || die "usage: cluster.sh up N [-- SERVE-ARGS…]"; up "$@" ;;
  down) down ;;
  *) die "usage: cluster.sh up N [-- SERVE-ARGS…] | cluster.sh down" ;;
esac

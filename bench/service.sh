#!/usr/bin/env bash
# Benchmarks of `voxtrace serve`, measured with `voxtrace load` (and Debian's
# wrk for comparison). Prints markdown tables.
#
#   cargo build --release
#   bench/service.sh [throughput|saturation|instructions|overload|slowloris|fuzz|wrk|all]
#
# Environment: DUR (per run, default 10s; DUR_HEAVY 40s for the heavy scene), REPS (interleaved
# repetitions, default 5; REPS_HEAVY 3), SCENES (throughput and saturation cases, default
# "small heavy"), CONCURRENCY (throughput, default "1 2 8 64"),
# SAT_C (saturation: connections, default 8), SAT_REPS / SAT_REPS_HEAVY (saturation: pairs of
# runs, default 30 / 12), SAT_N / SAT_N_HEAVY (saturation: requests per run, default 300 / 16),
# OVERLOAD_DUR (default 60s), OVERLOAD_RUNS (runs after one another on one server, default 1),
# FUZZ_COUNT (default 100000), SERVE_ARGS (more `voxtrace serve` options, e.g. "--renders 4"),
# VOXTRACE_BIN.
# Needs python3 (slowloris, fuzz, JSON), wrk (apt-get install -y wrk) and, for
# instructions, valgrind (apt-get install -y valgrind).
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${VOXTRACE_BIN:-target/release/voxtrace}
DUR=${DUR:-10s}
DUR_HEAVY=${DUR_HEAVY:-40s}
REPS=${REPS:-5}
REPS_HEAVY=${REPS_HEAVY:-3}
SCENES=${SCENES:-small heavy}
CONCURRENCY=${CONCURRENCY:-1 2 8 64}
SAT_C=${SAT_C:-8}
SAT_REPS=${SAT_REPS:-30}
SAT_REPS_HEAVY=${SAT_REPS_HEAVY:-12}
SAT_N=${SAT_N:-300}
SAT_N_HEAVY=${SAT_N_HEAVY:-16}
OVERLOAD_DUR=${OVERLOAD_DUR:-60s}
OVERLOAD_RUNS=${OVERLOAD_RUNS:-1}
FUZZ_COUNT=${FUZZ_COUNT:-100000}
SERVE_ARGS=${SERVE_ARGS:-}
WORK=$(mktemp -d)
SERVER=
cleanup() {
    [ -n "$SERVER" ] && kill "$SERVER" 2>/dev/null || true
    rm -rf "$WORK"
}
trap cleanup EXIT

# testSample at 256x256 (the standard case), and 10^5 spheres at 512x512 (heavy, 9.6 MB of text).
sed 's/RES 600 600/RES 256 256/' scenes/testSample.txt > "$WORK/sample256.txt"
"$BIN" gen --spheres 100000 --dist uniform --seed 1 --res 512 512 -o "$WORK/heavy.txt" > /dev/null

start_server() {
    # shellcheck disable=SC2086 # SERVE_ARGS is a list of options
    "$BIN" serve --addr 127.0.0.1:0 "$@" $SERVE_ARGS > "$WORK/serve.out" 2> "$WORK/serve.err" &
    SERVER=$!
    for _ in $(seq 100); do
        ADDR=$(sed -n 's|^listening on http://||p' "$WORK/serve.out")
        [ -n "$ADDR" ] && return
        sleep 0.05
    done
    echo "the server did not start" >&2
    exit 1
}
stop_server() {
    kill "$SERVER"
    wait "$SERVER" 2>/dev/null || true
    SERVER=
}
# field EXPR: evaluates a Python expression over the JSON object `d` on stdin.
field() { python3 -c "import json,sys; d=json.load(sys.stdin); print($1)"; }
median() { sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
proc() { awk -v k="$1:" '$1 == k {print $2}' "/proc/$SERVER/status"; }
metric() { curl -s "http://$ADDR/metrics" | awk -v m="$1" '$1 == m {print $2}'; }

# cpu_of FILE: the user + system seconds GNU time wrote to FILE.
cpu_of() { awk '{print $1 + $2}' "$1"; }
# server_cpu: the server's user + system seconds so far.
server_cpu() { awk -v t="$(getconf CLK_TCK)" '{print ($14 + $15) / t}' "/proc/$SERVER/stat"; }

# run_in_process SCENE C ARGS…: one `voxtrace load --in-process` run (ARGS: -d or -n)
# into $WORK/run.json; sets `cpu` to its CPU seconds.
run_in_process() {
    local scene=$1 c=$2
    shift 2
    /usr/bin/time -f "%U %S" -o "$WORK/time" \
        "$BIN" load --in-process --url "http://x/render" --scene "$WORK/$scene" -c "$c" "$@" --json > "$WORK/run.json"
    cpu=$(cpu_of "$WORK/time")
}
# run_service SCENE C ARGS…: the same run against the server; sets `cpu` to the CPU
# seconds of the server and the load client together.
run_service() {
    local scene=$1 c=$2 before
    shift 2
    before=$(server_cpu)
    /usr/bin/time -f "%U %S" -o "$WORK/time" \
        "$BIN" load --url "http://$ADDR/render" --scene "$WORK/$scene" -c "$c" "$@" --timeout 300s --json > "$WORK/run.json"
    # Let the renders still in flight finish before reading the server's CPU.
    while [ "$(metric voxtrace_renders_in_flight)" != 0 ] || [ "$(metric voxtrace_render_queue_depth)" != 0 ]; do sleep 0.1; done
    cpu=$(echo "$(server_cpu) - $before + $(cpu_of "$WORK/time")" | bc -l)
}
# record_not_200 WHAT: notes in $WORK/not_200 a run whose answers were not all 200.
record_not_200() {
    field '"" if d["status"].get("200") == d["requests"] and not d["errors"] else "%s: status %s, errors %s" % ("'"$1"'", d["status"], d["errors"])' < "$WORK/run.json" >> "$WORK/not_200"
}

throughput() {
    echo "### Throughput: service vs in-process, interleaved"
    echo
    echo "Renders/s by wall clock (median over the repetitions), the median of the per-repetition"
    echo "ratios (each service run against the in-process run next to it, the order alternating),"
    echo "and CPU milliseconds per render (in-process: the whole process; service: server + load"
    echo "client; both divided by renders answered in the window plus those still in flight)."
    echo
    echo "| scene | concurrency | in-process renders/s | service renders/s | ratio of medians | median of paired ratios | in-process CPU ms/render | service CPU ms/render | CPU ratio |"
    echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|"
    # Room for 64 heavy scenes arriving at once (64 x 9.6 MB), and for 62 of
    # them waiting in the queue (about a minute): with the defaults (256 MiB of
    # bodies, 30 s in the queue) the service would rightly answer some 503.
    start_server --body-memory 1073741824 --render-timeout-ms 120000
    : > "$WORK/saturation_lines"
    : > "$WORK/not_200"
    for case in "small|sample256.txt|testSample 256×256|$DUR|$REPS" "heavy|heavy.txt|10⁵ spheres 512×512|$DUR_HEAVY|$REPS_HEAVY"; do
        IFS='|' read -r name scene label dur reps <<< "$case"
        [[ " $SCENES " == *" $name "* ]] || continue
        rows=()
        for c in $CONCURRENCY; do
            : > "$WORK/in"; : > "$WORK/svc"; : > "$WORK/in_cpu"; : > "$WORK/svc_cpu"; : > "$WORK/pair"
            for rep in $(seq "$reps"); do
                order="in svc"
                [ $((rep % 2)) = 0 ] && order="svc in"
                for mode in $order; do
                    if [ "$mode" = in ]; then
                        run_in_process "$scene" "$c" -d "$dur"
                        in=$(field 'd["renders_per_s"]' < "$WORK/run.json")
                        echo "$in" >> "$WORK/in"
                        n=$(field 'd["renders"] + d["unfinished"]' < "$WORK/run.json")
                        echo "$cpu * 1000 / $n" | bc -l >> "$WORK/in_cpu"
                    else
                        run_service "$scene" "$c" -d "$dur"
                        svc=$(field 'd["renders_per_s"]' < "$WORK/run.json")
                        record_not_200 "$label c=$c"
                        echo "$svc" >> "$WORK/svc"
                        n=$(field 'd["renders"] + d["unfinished"]' < "$WORK/run.json")
                        echo "$cpu * 1000 / $n" | bc -l >> "$WORK/svc_cpu"
                    fi
                done
                echo "$svc / $in" | bc -l >> "$WORK/pair"
            done
            rows+=("$c $(median < "$WORK/in") $(median < "$WORK/svc") $(median < "$WORK/pair") $(median < "$WORK/in_cpu") $(median < "$WORK/svc_cpu")")
            [ "$c" = 8 ] && [ "$scene" = sample256.txt ] && median < "$WORK/svc" > "$WORK/saturation"
        done
        for row in "${rows[@]}"; do
            read -r c in svc pair in_cpu svc_cpu <<< "$row"
            printf '| %s | %d | %.2f | %.2f | %.3f | %.3f | %.1f | %.1f | %.3f |\n' "$label" "$c" "$in" "$svc" \
                "$(echo "$svc / $in" | bc -l)" "$pair" "$in_cpu" "$svc_cpu" "$(echo "$svc_cpu / $in_cpu" | bc -l)"
        done
        # Saturation: each side's best throughput at any concurrency.
        best_in=$(printf '%s\n' "${rows[@]}" | sort -k2 -g | tail -1)
        best_svc=$(printf '%s\n' "${rows[@]}" | sort -k3 -g | tail -1)
        read -r c_in in _ <<< "$best_in"
        read -r c_svc _ svc _ <<< "$best_svc"
        printf '%s: saturation in-process %.2f renders/s (c=%s), service %.2f (c=%s), ratio %.3f\n' "$label" "$in" "$c_in" "$svc" "$c_svc" \
            "$(echo "$svc / $in" | bc -l)" >> "$WORK/saturation_lines"
    done
    stop_server
    echo
    cat "$WORK/saturation_lines"
    grep . "$WORK/not_200" | sed 's/^/not all 200: /' || true
    echo
}

# load1: the 1-minute load average now.
load1() { cut -d' ' -f1 /proc/loadavg; }

# Many short runs at one saturating concurrency, in-process and service in
# pairs (the order alternating), so that the machine's slow swings hit both
# sides of a pair alike; then the distribution of the paired ratios.
saturation() {
    echo "### Throughput at saturation: $SAT_C connections, paired short runs"
    echo
    echo "Each pair is one in-process run and one service run of the same number of requests,"
    echo "back to back, the order alternating; renders/s = requests / wall time of the run."
    echo "Paired ratio = service / in-process within a pair. Interval: the 2.5th and 97.5th"
    echo "percentiles of the median paired ratio over 10,000 bootstrap resamples of the pairs."
    echo "CPU ms/render: in-process, the whole process; service, server + load client."
    echo
    echo "| scene | pairs × requests | in-process renders/s | service renders/s | median paired ratio | IQR of paired ratios | 95% bootstrap interval | pairs ≥ 0.95 | median CPU ratio | its 95% interval | load average |"
    echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    start_server --body-memory 1073741824 --render-timeout-ms 120000
    for case in "small|sample256.txt|testSample 256×256|$SAT_N|$SAT_REPS" "heavy|heavy.txt|10⁵ spheres 512×512|$SAT_N_HEAVY|$SAT_REPS_HEAVY"; do
        IFS='|' read -r name scene label n reps <<< "$case"
        [[ " $SCENES " == *" $name "* ]] || continue
        : > "$WORK/pairs"
        : > "$WORK/not_200"
        for rep in $(seq "$reps"); do
            order="in svc"
            [ $((rep % 2)) = 0 ] && order="svc in"
            load_before=$(load1)
            for mode in $order; do
                if [ "$mode" = in ]; then
                    run_in_process "$scene" "$SAT_C" -n "$n"
                    in=$(field 'd["renders"] / d["elapsed_s"]' < "$WORK/run.json")
                    in_cpu=$(echo "$cpu * 1000 / $n" | bc -l)
                else
                    run_service "$scene" "$SAT_C" -n "$n"
                    svc=$(field 'd["renders"] / d["elapsed_s"]' < "$WORK/run.json")
                    svc_cpu=$(echo "$cpu * 1000 / $n" | bc -l)
                    record_not_200 "$label"
                fi
            done
            echo "${order%% *} $in $svc $in_cpu $svc_cpu $load_before $(load1)" >> "$WORK/pairs"
        done
        cp "$WORK/pairs" "$WORK/pairs.$name"
        python3 - "$WORK/pairs" "$label" "$reps" "$n" <<'PY'
import random, statistics, sys
rows = [line.split() for line in open(sys.argv[1])]
first = [r[0] for r in rows]
inp, svc, in_cpu, svc_cpu = ([float(r[i]) for r in rows] for i in (1, 2, 3, 4))
loads = [float(x) for r in rows for x in r[5:7]]
ratio = [s / i for s, i in zip(svc, inp)]
cpu = [s / i for s, i in zip(svc_cpu, in_cpu)]
def q(xs, p):
    xs = sorted(xs)
    k = (len(xs) - 1) * p
    lo = int(k)
    hi = min(lo + 1, len(xs) - 1)
    return xs[lo] + (xs[hi] - xs[lo]) * (k - lo)
def boot(xs):
    rng = random.Random(1)
    meds = sorted(statistics.median(rng.choices(xs, k=len(xs))) for _ in range(10000))
    return q(meds, 0.025), q(meds, 0.975)
lo, hi = boot(ratio)
clo, chi = boot(cpu)
print("| %s | %s × %s | %.2f | %.2f | %.3f | %.3f–%.3f | %.3f–%.3f | %d of %d | %.3f | %.3f–%.3f | %.1f–%.1f (median %.1f) |" % (
    sys.argv[2], sys.argv[3], sys.argv[4], statistics.median(inp), statistics.median(svc),
    statistics.median(ratio), q(ratio, 0.25), q(ratio, 0.75), lo, hi,
    sum(r >= 0.95 for r in ratio), len(ratio), statistics.median(cpu), clo, chi,
    min(loads), max(loads), statistics.median(loads)))
by_first = {k: statistics.median([r for r, f in zip(ratio, first) if f == k]) for k in ("in", "svc") if k in first}
print("%s: median paired ratio with in-process first %.3f, with the service first %.3f; paired ratios %s" % (
    sys.argv[2], by_first.get("in", float("nan")), by_first.get("svc", float("nan")),
    " ".join("%.3f" % r for r in ratio)), file=sys.stderr)
PY
        grep . "$WORK/not_200" | sed 's/^/not all 200: /' >&2 || true
    done 2> "$WORK/sat_notes"
    stop_server
    echo
    cat "$WORK/sat_notes"
    echo
}

# collected FILE: the instruction count valgrind reported in FILE.
collected() { sed -n 's/.*Collected : //p' "$1"; }

instructions() {
    echo "### Instructions per render: service vs in-process (callgrind, one render thread)"
    echo
    echo "| scene | in-process | service (server) | load client per request | service / in-process |"
    echo "|---|---:|---:|---:|---:|"
    export RAYON_NUM_THREADS=1
    for case in "sample256.txt|testSample 256×256|2|12" "heavy.txt|10⁵ spheres 512×512|1|2"; do
        IFS='|' read -r scene label few many <<< "$case"
        # In process: the difference between two runs is the cost of the renders between them.
        for n in "$few" "$many"; do
            valgrind --tool=callgrind --callgrind-out-file="$WORK/cg.in.$n" \
                "$BIN" load --in-process --url "http://x/render" --scene "$WORK/$scene" -c 1 --requests "$n" --json > /dev/null 2> "$WORK/vg.in.$n"
        done
        in=$(( ($(collected "$WORK/vg.in.$many") - $(collected "$WORK/vg.in.$few")) / (many - few) ))
        # The server under callgrind: dump after a warm-up, then after the measured requests,
        # sent by two clients (under callgrind too) whose difference is a request's cost.
        valgrind --tool=callgrind --callgrind-out-file="$WORK/cg.svc" "$BIN" serve --addr 127.0.0.1:0 > "$WORK/serve.out" 2> "$WORK/vg.svc" &
        SERVER=$!
        for _ in $(seq 200); do
            ADDR=$(sed -n 's|^listening on http://||p' "$WORK/serve.out")
            [ -n "$ADDR" ] && break
            sleep 0.1
        done
        "$BIN" load --url "http://$ADDR/render" --scene "$WORK/$scene" -c 1 --requests "$few" --json > /dev/null
        callgrind_control -d "$SERVER" > /dev/null 2>&1
        for n in "$few" "$many"; do
            valgrind --tool=callgrind --callgrind-out-file="$WORK/cg.client.$n" \
                "$BIN" load --url "http://$ADDR/render" --scene "$WORK/$scene" -c 1 --requests "$n" --json > /dev/null 2> "$WORK/vg.client.$n"
        done
        callgrind_control -d "$SERVER" > /dev/null 2>&1
        svc=$(( $(sed -n 's/^summary: //p' "$WORK/cg.svc.2") / (few + many) ))
        client=$(( ($(collected "$WORK/vg.client.$many") - $(collected "$WORK/vg.client.$few")) / (many - few) ))
        kill "$SERVER"; wait "$SERVER" 2>/dev/null || true; SERVER=
        rm -f "$WORK"/cg.*
        printf '| %s | %d | %d | %d | %.4f |\n' "$label" "$in" "$svc" "$client" "$(echo "($svc + $client) / $in" | bc -l)"
    done
    unset RAYON_NUM_THREADS
    echo
}

# settle: waits for the renders still queued or running when a load run ended,
# then 2 s (the server gives free memory back within a second of going quiet).
settle() {
    while [ "$(metric voxtrace_renders_in_flight)" != 0 ] || [ "$(metric voxtrace_render_queue_depth)" != 0 ]; do sleep 0.1; done
    sleep 2
}

overload() {
    [ -f "$WORK/saturation" ] || {
        start_server
        "$BIN" load --url "http://$ADDR/render" --scene "$WORK/sample256.txt" -c 8 -d "$DUR" --json \
            | field 'd["renders_per_s"]' > "$WORK/saturation"
        stop_server
    }
    sat=$(cat "$WORK/saturation")
    rate=$(echo "4 * $sat" | bc -l)
    echo "### Overload: open loop at 4× saturation ($(printf %.0f "$rate") req/s vs $(printf %.1f "$sat") renders/s), $OVERLOAD_DUR, testSample 256×256"
    echo
    start_server
    sleep 0.3
    rss_cold=$(proc VmRSS)
    # Warm-up: the same load for 10 s. Before any render the render pool's
    # threads have done nothing and no connection thread has run, so the
    # resident memory of a fresh server is not what it settles at; the
    # baseline is taken after this, once its connections have closed.
    "$BIN" load --url "http://$ADDR/render" --scene "$WORK/sample256.txt" -c 400 -d 10s --rate "$rate" --json > "$WORK/warm.json"
    settle
    rss0=$(proc VmRSS)
    threads0=$(proc Threads)
    # Peak resident memory from here on (clear_refs 5 resets VmHWM).
    echo 5 > "/proc/$SERVER/clear_refs" 2>/dev/null || true
    for run in $(seq "$OVERLOAD_RUNS"); do
        [ "$OVERLOAD_RUNS" = 1 ] || echo "    run $run of $OVERLOAD_RUNS on the same server:"
        echo "    load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
        "$BIN" load --url "http://$ADDR/render" --scene "$WORK/sample256.txt" -c 400 -d "$OVERLOAD_DUR" --rate "$rate" --timeout 120s --json > "$WORK/overload.json" &
        LOAD=$!
        samples=""
        while kill -0 "$LOAD" 2>/dev/null; do
            sleep 5
            samples="$samples $(proc VmRSS)"
        done
        wait "$LOAD"
        echo "    load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
        settle
        rss1=$(proc VmRSS)
        field '"requests %d in %.1f s, status %s, transport errors %s, unfinished %d\n200: %s\n503: %s\naccepted renders/s: %.1f" % (d["requests"], d["elapsed_s"], d["status"], d["errors"], d["unfinished"], d["latency_ms_by_status"].get("200"), d["latency_ms_by_status"].get("503"), d["status"].get("200", 0) / d["elapsed_s"])' < "$WORK/overload.json" | sed 's/^/    /'
        field '"503 without Retry-After: %d" % d["503_without_retry_after"]' < "$WORK/overload.json" | sed 's/^/    /'
        echo "    server RSS (KiB): fresh $rss_cold; after the 10 s warm-up (baseline) $rss0; every 5 s during:$samples; peak since the warm-up $(proc VmHWM); after $rss1 ($(echo "100 * ($rss1 - $rss0) / $rss0" | bc -l | xargs printf '%+.1f')% of the baseline)"
        echo "    threads: after the warm-up $threads0, after the run $(proc Threads); abandoned renders $(metric voxtrace_renders_abandoned_total), write timeouts $(metric voxtrace_write_timeouts_total)"
    done
    stop_server
    echo
}

slowloris() {
    echo "### Slow clients: 500 connections (250 trickling their heads, 250 idle) for 30 s; a normal client at 5 renders/s, testSample 256×256"
    echo
    start_server
    normal() {
        "$BIN" load --url "http://$ADDR/render" --scene "$WORK/sample256.txt" -c 4 -d 20s --rate 5 --json
    }
    summary='"status %s, errors %s, latency ms p50 %.1f p90 %.1f p99 %.1f max %.1f" % (d["status"], d["errors"], d["latency_ms"]["p50"], d["latency_ms"]["p90"], d["latency_ms"]["p99"], d["latency_ms"]["max"])'
    normal > "$WORK/unloaded.json"
    python3 bench/slowloris.py 127.0.0.1 "${ADDR##*:}" 500 30 2 > "$WORK/slow.txt" &
    SLOW=$!
    sleep 3
    echo "    server threads with the slow connections open: $(proc Threads), open connections: $(metric voxtrace_open_connections)"
    normal > "$WORK/normal.json"
    wait "$SLOW"
    sleep 0.5
    sed 's/^/    /' "$WORK/slow.txt"
    echo "    normal client alone:                 $(field "$summary" < "$WORK/unloaded.json")"
    echo "    normal client beside the slow ones:  $(field "$summary" < "$WORK/normal.json")"
    echo "    p50 ratio $(field 'd["latency_ms"]["p50"]' < "$WORK/normal.json") / $(field 'd["latency_ms"]["p50"]' < "$WORK/unloaded.json"), p99 ratio $(field 'd["latency_ms"]["p99"]' < "$WORK/normal.json") / $(field 'd["latency_ms"]["p99"]' < "$WORK/unloaded.json")"
    echo "    408s answered by the server: $(curl -s "http://$ADDR/metrics" | awk '/route="other",status="408"/ {print $2}'); afterwards open connections (counting the /metrics request): $(metric voxtrace_open_connections), threads: $(proc Threads)"
    stop_server
    echo
}

fuzz() {
    echo "### $FUZZ_COUNT malformed and random requests"
    echo
    start_server
    threads0=$(proc Threads)
    python3 bench/fuzz.py 127.0.0.1 "${ADDR##*:}" "$FUZZ_COUNT" 8 1 | sed 's/^/    /'
    sleep 1.5
    echo "    server alive: $(kill -0 "$SERVER" && echo yes); threads before $threads0, after $(proc Threads)"
    echo "    /healthz: $(curl -s "http://$ADDR/healthz"); open connections after (counting the /metrics request itself): $(metric voxtrace_open_connections); panics: $(curl -s "http://$ADDR/metrics" | grep -c 'route="panic"' || true)"
    stop_server
    echo
}

wrk_compare() {
    echo "### voxtrace load vs wrk (req/s, median of $REPS × $DUR, interleaved)"
    echo
    printf 'wrk.method = "POST"\nwrk.body = io.open("%s"):read("*a")\nwrk.headers["Content-Type"] = "text/plain"\n' "$WORK/sample256.txt" > "$WORK/post.lua"
    echo "| target | connections | wrk | voxtrace load | load / wrk |"
    echo "|---|---:|---:|---:|---:|"
    start_server
    for case in "render|8" "healthz|8"; do
        IFS='|' read -r path c <<< "$case"
        : > "$WORK/wrk"; : > "$WORK/load"
        for _ in $(seq "$REPS"); do
            if [ "$path" = render ]; then
                wrk -t2 -c"$c" -d"$DUR" -s "$WORK/post.lua" "http://$ADDR/render" | awk '/Requests\/sec/ {print $2}' >> "$WORK/wrk"
                "$BIN" load --url "http://$ADDR/render" --scene "$WORK/sample256.txt" -c "$c" -d "$DUR" --json | field 'd["requests_per_s"]' >> "$WORK/load"
            else
                wrk -t2 -c"$c" -d"$DUR" "http://$ADDR/healthz" | awk '/Requests\/sec/ {print $2}' >> "$WORK/wrk"
                "$BIN" load --url "http://$ADDR/healthz" -c "$c" -d "$DUR" --json | field 'd["requests_per_s"]' >> "$WORK/load"
            fi
        done
        w=$(median < "$WORK/wrk"); l=$(median < "$WORK/load")
        printf '| /%s | %d | %.1f | %.1f | %.3f |\n' "$path" "$c" "$w" "$l" "$(echo "$l / $w" | bc -l)"
    done
    stop_server
    echo
}

what=${1:-all}
case "$what" in
    throughput) throughput ;;
    saturation) saturation ;;
    instructions) instructions ;;
    overload) overload ;;
    slowloris) slowloris ;;
    fuzz) fuzz ;;
    wrk) wrk_compare ;;
    all) throughput; saturation; instructions; overload; slowloris; fuzz; wrk_compare ;;
    *) echo "usage: $0 [throughput|saturation|instructions|overload|slowloris|fuzz|wrk|all]" >&2; exit 2 ;;
esac

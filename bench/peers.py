#!/usr/bin/python3
"""voxtrace's index against Embree 3 on the same scene files, interleaved.

    bench/peers.py SCENE... [--reps 3] [--threads 2] [--voxtrace BIN] [--embree BIN]

For each scene and repetition, in turn: `voxtrace bench --scene FILE --json
--no-baselines`, then Embree's benchmark with its built-in sphere primitive,
then with user-geometry spheres (`--user-spheres`); Embree's better figure of
the two counts for each column, as its README advises. Prints, per scene and
column, voxtrace's and Embree's medians and the ratio voxtrace / Embree of each
repetition's pair: median, min and max. voxtrace's build is the grid's plus
its light buffers' (`build_s + light_buffer_s`), and its bytes a sphere are
given as the grid's plus the buffers' (`index_bytes_per_sphere +
light_buffer_bytes_per_sphere`). Embree's benchmark is built from
`../shared/peers` (see its README) into target/peers/embree_bench.
"""
import argparse
import json
import statistics
import subprocess
import sys

COLUMNS = [
    # (name, voxtrace JSON key, Embree key)
    ("packets", "primary_mrays_s", "primary16_Mrays_s"),
    ("single rays", "primary_single_mrays_s", "primary1_Mrays_s"),
    ("shadow rays", "shadow_mrays_s", "shadow_Mrays_s"),
    ("shadow rays, grid walked (no light buffers)", "shadow_walk_mrays_s", "shadow_Mrays_s"),
]


def voxtrace(binary, scene, threads):
    out = subprocess.run(
        [binary, "bench", "--scene", scene, "--json", "--no-baselines", "--threads", str(threads)],
        check=True, capture_output=True, text=True).stdout
    return json.loads(out)[0]


def embree(binary, scene, threads, user):
    args = [binary, scene, "--threads", str(threads), "--repeat", "3"]
    if user:
        args.append("--user-spheres")
    out = subprocess.run(args, check=True, capture_output=True, text=True).stdout
    figures = {}
    for line in out.splitlines():
        for token in line.split():
            key, _, value = token.partition("=")
            try:
                figures[key] = float(value)
            except ValueError:
                pass
    return figures


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--voxtrace", default="target/release/voxtrace")
    ap.add_argument("--embree", default="target/peers/embree_bench")
    a = ap.parse_args()
    print("| scene | spheres | build s (voxtrace / Embree) | voxtrace bytes a sphere (grid + buffers) "
          "| column | voxtrace Mrays/s | Embree Mrays/s | ratio median | ratio min–max |")
    print("|---|---:|---:|---:|---|---:|---:|---:|---:|")
    for scene in a.scenes:
        runs = []
        for _ in range(a.reps):
            v = voxtrace(a.voxtrace, scene, a.threads)
            e1 = embree(a.embree, scene, a.threads, False)
            e2 = embree(a.embree, scene, a.threads, True)
            best = {k: max(e1.get(k, 0.0), e2.get(k, 0.0)) for k in set(e1) | set(e2)}
            best["build_s"] = min(e1.get("build_s", 1e9), e2.get("build_s", 1e9))
            runs.append((v, best))
            print(f"  {scene}: " + " ".join(
                f"{n}={v[vk]:.2f}/{best[ek]:.2f}" for n, vk, ek in COLUMNS), file=sys.stderr)
        spheres = runs[0][0]["spheres"]
        build = f"{statistics.median(r[0]['build_s'] + r[0]['light_buffer_s'] for r in runs):.3f} / " \
                f"{statistics.median(r[1]['build_s'] for r in runs):.3f}"
        first = runs[0][0]
        size = f"{first['index_bytes_per_sphere']:.1f} + {first['light_buffer_bytes_per_sphere']:.1f}"
        for name, vk, ek in COLUMNS:
            ours = [r[0][vk] for r in runs]
            theirs = [r[1][ek] for r in runs]
            ratios = [o / t for o, t in zip(ours, theirs)]
            print(f"| {scene} | {spheres} | {build} | {size} | {name} | {statistics.median(ours):.2f} | "
                  f"{statistics.median(theirs):.2f} | **{statistics.median(ratios):.2f}** | "
                  f"{min(ratios):.2f}–{max(ratios):.2f} |")
            sys.stdout.flush()


if __name__ == "__main__":
    main()

#!/usr/bin/python3
"""Whole renders: voxtrace against POV-Ray 3.7 on the same picture, interleaved.

    bench/povray.py SCENE... [--reps 3] [--voxtrace BIN] [--peers ../shared/peers]

For each scene, converts it once with the peers' `to_povray.py`, then for
each repetition runs, in turn, `voxtrace render SCENE` and `povray +WT2 -A`
(the peers' README command) under `/usr/bin/time -v`, and prints per scene the
wall-time medians with their range, the peak resident sets, and the ratio
POV-Ray / voxtrace of each pair: median, min and max. Whole processes: parse,
index or bounding, trace and write.
"""
import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile


def timed(args):
    """(wall seconds, peak KiB) of one process under /usr/bin/time -v."""
    out = subprocess.run(["/usr/bin/time", "-v", *args], capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"{args[0]} failed ({out.returncode}):\n{out.stderr[-2000:]}")
    wall = re.search(r"Elapsed \(wall clock\) time.*: (?:(\d+):)?(\d+):([\d.]+)", out.stderr)
    hours, minutes, seconds = (float(g or 0) for g in wall.groups())
    peak = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", out.stderr).group(1))
    return hours * 3600 + minutes * 60 + seconds, peak


def resolution(scene):
    with open(scene) as f:
        for line in f:
            words = line.split()
            if words and words[0] == "RES":
                return words[1], words[2]
    sys.exit(f"{scene}: no RES line")


def spread(values, fmt="{:.2f}"):
    return f"{fmt.format(statistics.median(values))} ({fmt.format(min(values))}–{fmt.format(max(values))})"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--voxtrace", default="target/release/voxtrace")
    ap.add_argument("--peers", default="../shared/peers")
    a = ap.parse_args()
    work = tempfile.mkdtemp(prefix="voxtrace-povray-")
    print("| scene | voxtrace s | POV-Ray s | ratio median | ratio min–max | peak MB voxtrace / POV-Ray |")
    print("|---|---:|---:|---:|---:|---:|")
    for scene in a.scenes:
        pov = os.path.join(work, "scene.pov")
        subprocess.run([sys.executable, os.path.join(a.peers, "to_povray.py"), scene, "-o", pov], check=True)
        w, h = resolution(scene)
        ours_cmd = [a.voxtrace, "render", scene, "-o", os.path.join(work, "voxtrace.png")]
        theirs_cmd = ["povray", f"+I{pov}", f"+O{os.path.join(work, 'povray.ppm')}", "+FP16",
                      f"+W{w}", f"+H{h}", "-D", "-P", "-A", "+WT2", "File_Gamma=1.0"]
        ours, theirs, ratios, peaks = [], [], [], [[], []]
        for _ in range(a.reps):
            (t_ours, p_ours), (t_theirs, p_theirs) = timed(ours_cmd), timed(theirs_cmd)
            ours.append(t_ours)
            theirs.append(t_theirs)
            ratios.append(t_theirs / t_ours)
            peaks[0].append(p_ours / 1024)
            peaks[1].append(p_theirs / 1024)
            print(f"  {scene}: voxtrace {t_ours:.2f} s, POV-Ray {t_theirs:.2f} s", file=sys.stderr)
        print(f"| {scene} | {spread(ours)} | {spread(theirs)} | **{statistics.median(ratios):.1f}×** | "
              f"{min(ratios):.1f}–{max(ratios):.1f} | {max(peaks[0]):.0f} / {max(peaks[1]):.0f} |")
        os.remove(pov)


if __name__ == "__main__":
    main()

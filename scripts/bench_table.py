#!/usr/bin/env python3
"""The before/after table of docs/performance.md from the JSON lines that
scripts/bench_compare.sh appends (one `polydem bench` report per run, with its label and round):
per scene and precision, particles, contacts per particle, particle-steps/s before and after
(every round, min–max), the ratio of the means, the pair stage in ms/step and device bytes per
particle after.

    python3 scripts/bench_table.py runs.jsonl
"""
import json
import os
import sys
from statistics import mean


def fmt(xs):
    lo, hi = min(xs), max(xs)
    return f"{lo:.3g}" if abs(hi - lo) <= 0.005 * hi else f"{lo:.3g}–{hi:.3g}"


def main(path):
    rows = {}
    for line in open(path):
        if not line.strip():
            continue
        r = json.loads(line)
        key = (os.path.basename(r["scene"]).removesuffix(".toml"), r.get("precision", "?"))
        rows.setdefault(key, {"before": [], "after": [], "failed": []})
        if r.get("failed"):
            rows[key]["failed"].append(r["label"])
        else:
            rows[key][r["label"]].append(r)
    print("| scene | precision | particles | contacts per particle | particle-steps/s before "
          "| after | after / before | pairs ms/step after | device bytes/particle |")
    print("|---|---|---|---|---|---|---|---|---|")
    for (scene, precision), runs in sorted(rows.items()):
        before = [r["particle_steps_per_second"] for r in runs["before"]]
        after = [r["particle_steps_per_second"] for r in runs["after"]]
        last = (runs["after"] or runs["before"] or [None])[-1]
        if last is None:
            print(f"| {scene} | {precision} | | | failed | failed | | | |")
            continue
        steps = last["steps"]
        pairs = mean(r["stage_seconds"]["pairs"] / steps * 1e3 for r in runs["after"]) if after else None
        ratio = f"{mean(after) / mean(before):.2f}" if before and after else ""
        bpp = last.get("device_bytes_per_particle")
        print(
            f"| {scene} | {precision} | {last['particles']} | {last['contacts_per_particle']:.2f} "
            f"| {fmt(before) if before else 'failed'} | {fmt(after) if after else 'failed'} | {ratio} "
            f"| {f'{pairs:.2f}' if pairs is not None else ''} | {f'{bpp:.0f}' if bpp else ''} |"
        )


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "runs.jsonl")

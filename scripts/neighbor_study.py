#!/usr/bin/env python3
"""The neighbour-mode study of docs/performance.md ("Who builds the pair list"): reads the
`polydem bench` reports collected in docs/data/neighbor_study.jsonl (one JSON object per run:
the scene, the mode, seconds per step, the `neighbor` report) and prints the table, and writes
docs/neighbor_study.svg: seconds per step of each mode per scene, and the hybrid gain G against
the seed's G_max (Skorych & Dosta, docs/design.md §10; Eq. 7 and 9).

    python3 scripts/neighbor_study.py [data.jsonl] [out.svg]
"""
import json
import math
import os
import sys
from statistics import mean

MODES = ["gpu", "cpu", "hybrid", "auto"]
COLOURS = {"gpu": "#1f77b4", "cpu": "#d62728", "hybrid": "#2ca02c", "auto": "#9467bd"}


def load(path):
    runs = [json.loads(line) for line in open(path) if line.strip()]
    scenes = {}
    for r in runs:
        s = scenes.setdefault(os.path.basename(r["scene"]).removesuffix(".toml"), {"runs": []})
        s["runs"].append(r)
    return scenes


def g_max(q):
    """Seed Eq. 9."""
    return q if q <= 0.5 else (1 - q) / (2 * q)


def summarise(scenes):
    out = []
    for name, s in scenes.items():
        by = {m: [r for r in s["runs"] if r["mode"] == m] for m in MODES}
        # gpu against auto from the same batch (one start of the machine): starts differ by a few %.
        batch = by["auto"][-1]["batch"]
        by["gpu"] = [r for r in by["gpu"] if r["batch"] == batch]
        t = {m: mean(r["seconds_per_step"] for r in by[m]) for m in MODES if by[m]}
        worst_auto = max(r["seconds_per_step"] for r in by["auto"])
        cpu = by["cpu"][0]["neighbor"]
        q = cpu["tau_cpu_s"] / cpu["tau_gpu_s"]
        gain = t["cpu"] / t["hybrid"] - 1
        best = min(("gpu", "cpu", "hybrid"), key=lambda m: t[m])
        first = s["runs"][0]
        picks = sorted({sw["to"] for r in by["auto"] for sw in r["neighbor"]["switches"]})
        out.append({
            "scene": name, "particles": first["particles"], "precision": first["precision"],
            "contacts": first["contacts_per_particle"], "t": t, "best": best,
            "auto_vs_best": t[best] / t["auto"] - 1, "worst_auto_vs_best": t[best] / worst_auto - 1,
            "tau_cpu": cpu["tau_cpu_s"], "tau_gpu": cpu["tau_gpu_s"], "q": q, "G": gain,
            "G_max": g_max(q), "auto_final": by["auto"][-1]["neighbor"]["builder"],
            "auto_tried": picks, "runs": {m: len(by[m]) for m in MODES},
        })
    return out


def table(rows):
    lines = [
        "| scene | particles | precision | contacts / particle | gpu µs/step | cpu | hybrid | auto | "
        "auto vs best fixed (mean; worst run) | τ_CPU ms | τ_GPU ms | q | G | G_max | auto runs |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        t = r["t"]
        us = lambda m: f"{1e6 * t[m]:.1f}"
        tried = ", ".join(r["auto_tried"]) if r["auto_tried"] else "no trial"
        lines.append(
            f"| {r['scene']} | {r['particles']} | {r['precision']} | {r['contacts']:.2f} | {us('gpu')} | "
            f"{us('cpu')} | {us('hybrid')} | {us('auto')} | {100 * r['auto_vs_best']:+.1f} %; "
            f"{100 * r['worst_auto_vs_best']:+.1f} % | {1e3 * r['tau_cpu']:.1f} | {1e3 * r['tau_gpu']:.1f} | "
            f"{r['q']:.2f} | {100 * r['G']:+.1f} % | {100 * r['G_max']:+.1f} % | {r['auto_final']} ({tried}) |"
        )
    return "\n".join(lines)


def svg(rows, path):
    w, h = 980, 420
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
             '<rect width="100%" height="100%" fill="white"/>']
    # Left: seconds per step per mode, log scale.
    x0, y0, pw, ph = 70, 40, 520, 320
    lo, hi = -6.0, -1.0
    y = lambda v: y0 + ph - (math.log10(v) - lo) / (hi - lo) * ph
    parts.append(f'<text x="{x0}" y="22" font-size="14">Seconds per step by who builds the pair list (H200, 16 cores)</text>')
    for e in range(int(lo), int(hi) + 1):
        yy = y(10.0 ** e)
        parts.append(f'<line x1="{x0}" x2="{x0 + pw}" y1="{yy:.1f}" y2="{yy:.1f}" stroke="#ddd"/>')
        parts.append(f'<text x="{x0 - 8}" y="{yy + 4:.1f}" text-anchor="end">1e{e}</text>')
    gw = pw / len(rows)
    bw = gw / (len(MODES) + 1)
    for i, r in enumerate(rows):
        for k, m in enumerate(MODES):
            v = r["t"][m]
            xx = x0 + i * gw + (k + 0.5) * bw
            parts.append(f'<rect x="{xx:.1f}" y="{y(v):.1f}" width="{bw * 0.9:.1f}" height="{y0 + ph - y(v):.1f}" fill="{COLOURS[m]}"/>')
        parts.append(f'<text x="{x0 + (i + 0.5) * gw:.1f}" y="{y0 + ph + 16}" text-anchor="middle">{r["scene"]}</text>')
    parts.append(f'<line x1="{x0}" x2="{x0}" y1="{y0}" y2="{y0 + ph}" stroke="black"/>')
    parts.append(f'<line x1="{x0}" x2="{x0 + pw}" y1="{y0 + ph}" y2="{y0 + ph}" stroke="black"/>')
    for k, m in enumerate(MODES):
        parts.append(f'<rect x="{x0 + 10 + 80 * k}" y="{y0 + ph + 30}" width="12" height="12" fill="{COLOURS[m]}"/>')
        parts.append(f'<text x="{x0 + 26 + 80 * k}" y="{y0 + ph + 41}">{m}</text>')
    # Right: G against G_max.
    x1, pw2 = 680, 260
    glo, ghi = -0.6, 0.6
    gx = lambda v: x1 + (v - glo) / (ghi - glo) * pw2
    gy = lambda v: y0 + ph - (v - glo) / (ghi - glo) * ph
    parts.append(f'<text x="{x1}" y="22" font-size="14">Hybrid gain G against G_max</text>')
    for v in (-0.5, -0.25, 0.0, 0.25, 0.5):
        parts.append(f'<line x1="{gx(glo):.1f}" x2="{gx(ghi):.1f}" y1="{gy(v):.1f}" y2="{gy(v):.1f}" stroke="#ddd"/>')
        parts.append(f'<text x="{x1 - 6}" y="{gy(v) + 4:.1f}" text-anchor="end">{v:+.2f}</text>')
        parts.append(f'<text x="{gx(v):.1f}" y="{y0 + ph + 16}" text-anchor="middle">{v:+.2f}</text>')
    parts.append(f'<line x1="{gx(glo):.1f}" y1="{gy(glo):.1f}" x2="{gx(ghi):.1f}" y2="{gy(ghi):.1f}" stroke="#888" stroke-dasharray="4 3"/>')
    parts.append(f'<rect x="{x1}" y="{y0}" width="{pw2}" height="{ph}" fill="none" stroke="black"/>')
    for r in rows:
        gm = max(glo, min(ghi, r["G_max"]))
        parts.append(f'<circle cx="{gx(gm):.1f}" cy="{gy(r["G"]):.1f}" r="5" fill="#2ca02c"/>')
        parts.append(f'<text x="{gx(gm) + 7:.1f}" y="{gy(r["G"]) - 6:.1f}" font-size="10">{r["scene"]} (q {r["q"]:.2g})</text>')
    parts.append(f'<text x="{x1 + pw2 / 2}" y="{y0 + ph + 34}" text-anchor="middle">G_max (seed Eq. 9; clipped at −0.6)</text>')
    parts.append(f'<text x="{x1 - 44}" y="{y0 + ph / 2}" transform="rotate(-90 {x1 - 44} {y0 + ph / 2})" text-anchor="middle">G = t_cpu / t_hybrid − 1</text>')
    parts.append("</svg>")
    open(path, "w").write("\n".join(parts) + "\n")


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    data = sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "docs/data/neighbor_study.jsonl")
    out = sys.argv[2] if len(sys.argv) > 2 else os.path.join(root, "docs/neighbor_study.svg")
    rows = summarise(load(data))
    print(table(rows))
    svg(rows, out)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Case 1 (docs/production.md §1): the fill height of the dodecahedra over several pours.

  python3 launch/production/fill_heights.py OUT.svg SCENE:CHECKPOINT ... | RESULT.json ...

Runs `polydem analyze fill-height` (target/release/polydem, or $POLYDEM) on each pour's final
checkpoint (each with the scene file of its seed), or reads its output saved as JSON (what
`run_on_gpu.sh` writes for the ten pours of one scene), prints the table of
docs/production.md and draws each pour's highest point and mean top surface against the
experiment's 16 cm.
"""
import json
import math
import os
import subprocess
import sys

EXPERIMENT = 0.16  # m, seed paper Sec. 3.3 ("approximately 16 cm")
RADIUS = 0.05      # m, the cylinder's inner radius


def analyze(scene, checkpoint):
    exe = os.environ.get("POLYDEM", "target/release/polydem")
    out = subprocess.run([exe, "analyze", "fill-height", scene, checkpoint, "--radius", str(RADIUS)],
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def stats(xs):
    m = sum(xs) / len(xs)
    s = math.sqrt(sum((x - m) ** 2 for x in xs) / (len(xs) - 1)) if len(xs) > 1 else 0.0
    return m, s


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    svg, runs = sys.argv[1], sys.argv[2:]
    rows = [json.load(open(r)) if r.endswith(".json") else analyze(*r.split(":", 1)) for r in runs]
    print("| pour | highest point (cm) | mean top surface (cm) | bulk solid fraction |")
    print("|---|---|---|---|")
    for k, r in enumerate(rows):
        print(f"| {k} | {100 * r['highest']:.2f} | {100 * r['mean_surface']:.2f} | {r['solid_fraction']:.3f} |")
    for key, name, scale in (("highest", "highest point (cm)", 100), ("mean_surface", "mean top surface (cm)", 100),
                             ("solid_fraction", "bulk solid fraction", 1)):
        m, s = stats([r[key] * scale for r in rows])
        print(f"{name}: mean {m:.3g}, standard deviation {s:.2g} over {len(rows)} pours")
    w, h, x0, y0, pw, ph = 560, 360, 70, 30, 420, 280
    lo, hi = 0.10, 0.20
    py = lambda z: y0 + ph - (z - lo) / (hi - lo) * ph
    px = lambda k: x0 + (k + 0.5) / len(rows) * pw
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
             '<rect width="100%" height="100%" fill="white"/>',
             f'<text x="{x0}" y="18" font-size="13">63 dodecahedra in a 10 cm cylinder: fill height of each pour</text>']
    for z in (0.10, 0.12, 0.14, 0.16, 0.18, 0.20):
        parts.append(f'<line x1="{x0}" x2="{x0 + pw}" y1="{py(z):.1f}" y2="{py(z):.1f}" stroke="#ddd"/>')
        parts.append(f'<text x="{x0 - 6}" y="{py(z) + 4:.1f}" text-anchor="end">{100 * z:.0f} cm</text>')
    parts.append(f'<line x1="{x0}" x2="{x0 + pw}" y1="{py(EXPERIMENT):.1f}" y2="{py(EXPERIMENT):.1f}" stroke="black" stroke-dasharray="6 3"/>')
    parts.append(f'<text x="{x0 + pw + 4}" y="{py(EXPERIMENT) + 4:.1f}">experiment</text>')
    for k, r in enumerate(rows):
        parts.append(f'<circle cx="{px(k):.1f}" cy="{py(r["highest"]):.1f}" r="4" fill="#d62728"/>')
        parts.append(f'<circle cx="{px(k):.1f}" cy="{py(r["mean_surface"]):.1f}" r="4" fill="#1f77b4"/>')
        parts.append(f'<text x="{px(k):.1f}" y="{y0 + ph + 16}" text-anchor="middle">{k}</text>')
    parts.append(f'<rect x="{x0}" y="{y0}" width="{pw}" height="{ph}" fill="none" stroke="black"/>')
    parts.append(f'<text x="{x0 + pw / 2}" y="{y0 + ph + 34}" text-anchor="middle">pour (seed)</text>')
    parts.append(f'<circle cx="{x0 + pw + 10}" cy="{y0 + 10}" r="4" fill="#d62728"/><text x="{x0 + pw + 18}" y="{y0 + 14}">highest</text>')
    parts.append(f'<circle cx="{x0 + pw + 10}" cy="{y0 + 28}" r="4" fill="#1f77b4"/><text x="{x0 + pw + 18}" y="{y0 + 32}">mean top</text>')
    parts.append("</svg>")
    with open(svg, "w") as f:
        f.write("\n".join(parts) + "\n")


if __name__ == "__main__":
    main()

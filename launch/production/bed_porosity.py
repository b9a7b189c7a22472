#!/usr/bin/env python3
"""Case 3 (docs/production.md §3): the fixed bed's radial porosity profile against the mean
porosity correlation for cylinders in tubes.

  python3 launch/production/bed_porosity.py OUT.svg POROSITY.json [--d 0.0055] [--tube 0.025]

POROSITY.json is what `polydem analyze porosity SCENE CHECKPOINT --radius R --z ... --annuli N`
prints. Prints the profile as a table (distance from the wall in mm and in pellet diameters d)
with its extrema, and the mean against Benyahia and O'Neill's correlation for solid cylinders,
eps = 0.373 + 1.703 / (D/d_pe + 0.611)^2 (Particulate Sci. Technol. 23 (2005) 169-177; d_pe the
volume-equivalent sphere diameter, (3 d^2 L / 2)^(1/3)), and draws the profile.
"""
import argparse
import json


def benyahia_oneil(tube, d, length):
    d_pe = (1.5 * d * d * length) ** (1.0 / 3.0)
    return 0.373 + 1.703 / (tube / d_pe + 0.611) ** 2, tube / d_pe


def extrema(xs, ys):
    """Interior local minima and maxima: (kind, x, y)."""
    out = []
    for k in range(1, len(ys) - 1):
        if ys[k] < ys[k - 1] and ys[k] <= ys[k + 1]:
            out.append(("min", xs[k], ys[k]))
        elif ys[k] > ys[k - 1] and ys[k] >= ys[k + 1]:
            out.append(("max", xs[k], ys[k]))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("svg")
    ap.add_argument("porosity")
    ap.add_argument("--d", type=float, default=0.0055, help="pellet diameter (m)")
    ap.add_argument("--length", type=float, default=0.0055, help="pellet length (m)")
    ap.add_argument("--tube", type=float, default=0.025, help="tube inner diameter (m)")
    a = ap.parse_args()
    r = json.load(open(a.porosity))
    xs = [w / a.d for w in r["wall_distance"]]
    ys = r["porosity"]
    eps, ratio = benyahia_oneil(a.tube, a.d, a.length)
    print("| from the wall (mm) | (d) | porosity |")
    print("|---|---|---|")
    for w, x, y in zip(r["wall_distance"], xs, ys):
        print(f"| {1000 * w:.2f} | {x:.2f} | {y:.3f} |")
    print()
    for kind, x, y in extrema(xs, ys):
        print(f"{kind} {y:.3f} at {x:.2f} d ({1000 * x * a.d:.2f} mm)")
    print(f"mean porosity {r['mean']:.4f}; Benyahia and O'Neill: {eps:.4f} at D/d_pe = {ratio:.3f} "
          f"({(r['mean'] - eps) / eps:+.1%})")

    w, h, m = 640, 360, 56
    x1 = max(xs)
    px = lambda x: m + (w - 1.5 * m) * x / x1
    py = lambda y: h - m + (h - 1.5 * m) * -y
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
             f'<rect width="{w}" height="{h}" fill="white"/>',
             f'<line x1="{m}" y1="{h - m}" x2="{w - m / 2}" y2="{h - m}" stroke="black"/>',
             f'<line x1="{m}" y1="{h - m}" x2="{m}" y2="{m / 2}" stroke="black"/>']
    for k in range(0, 11, 2):
        y = k / 10
        parts.append(f'<text x="{m - 6}" y="{py(y) + 4:.1f}" text-anchor="end">{y:.1f}</text>')
        parts.append(f'<line x1="{m}" y1="{py(y):.1f}" x2="{w - m / 2}" y2="{py(y):.1f}" stroke="#eee"/>')
    for k in range(0, int(x1 * 2) + 1):
        x = k / 2
        parts.append(f'<text x="{px(x):.1f}" y="{h - m + 16}" text-anchor="middle">{x:g}</text>')
    parts.append(f'<text x="{(w + m) / 2}" y="{h - 12}" text-anchor="middle">distance from the tube wall (pellet diameters; the axis at {x1:.2f})</text>')
    parts.append(f'<text x="14" y="{h / 2}" transform="rotate(-90 14 {h / 2})" text-anchor="middle">porosity of the annulus</text>')
    parts.append(f'<line x1="{m}" y1="{py(eps):.1f}" x2="{w - m / 2}" y2="{py(eps):.1f}" stroke="#d95f02" stroke-dasharray="6 4"/>')
    parts.append(f'<text x="{w - m / 2 - 4}" y="{py(eps) - 6:.1f}" text-anchor="end" fill="#d95f02">Benyahia and O\'Neill, mean {eps:.3f}</text>')
    parts.append(f'<line x1="{m}" y1="{py(r["mean"]):.1f}" x2="{w - m / 2}" y2="{py(r["mean"]):.1f}" stroke="#1b9e77" stroke-dasharray="2 3"/>')
    parts.append(f'<text x="{w - m / 2 - 4}" y="{py(r["mean"]) + 14:.1f}" text-anchor="end" fill="#1b9e77">bed mean {r["mean"]:.3f}</text>')
    pts = " ".join(f"{px(x):.1f},{py(y):.1f}" for x, y in zip(xs, ys))
    parts.append(f'<polyline points="{pts}" fill="none" stroke="#1f4e9c" stroke-width="2"/>')
    parts.append("</svg>")
    with open(a.svg, "w") as f:
        f.write("\n".join(parts) + "\n")


if __name__ == "__main__":
    main()

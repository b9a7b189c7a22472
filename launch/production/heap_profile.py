#!/usr/bin/env python3
"""Case 4 (docs/production.md §4b): a poured heap's profile and its angle of repose.

  python3 launch/production/heap_profile.py OUT.svg HEAP.json [--range 30,45]

HEAP.json is what `polydem analyze heap SCENE CHECKPOINT --radius R ... --fit A,B` prints: the
mean height of the top surface on rings from the axis out (`radii`, `heights`) and the cone
fitted to the rings between A R and B R (`fit`, in m; `line`, z = a + b r; `angle_deg`). Prints
the rings as a table, refits the cone by least squares over the same rings as a check of the
analysis (the two angles agree to the printed digits), and draws the profile at true scale
(equal units on both axes, so the drawn slope is the angle) with the fitted cone and, through
its middle, the cones of the range's angles (default 30° and 45°: the static angle of repose
of crushed angular rock).
"""
import argparse
import json
import math


def fitted_angle(radii, heights, r0, r1):
    """Angle (degrees, positive for a heap) of the least-squares line through the rings whose
    radius lies in [r0, r1], and its intercept and slope."""
    pts = [(r, z) for r, z in zip(radii, heights) if r0 <= r <= r1]
    if len(pts) < 2:
        raise SystemExit(f"fewer than two rings between {r0} and {r1} m")
    mr = sum(r for r, _ in pts) / len(pts)
    mz = sum(z for _, z in pts) / len(pts)
    b = sum((r - mr) * (z - mz) for r, z in pts) / sum((r - mr) ** 2 for r, _ in pts)
    return math.degrees(math.atan(-b)), mz - b * mr, b


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("svg")
    ap.add_argument("heap")
    ap.add_argument("--range", default="30,45", help="reference angles drawn (degrees)")
    a = ap.parse_args()
    h = json.load(open(a.heap))
    radii, heights = h["radii"], h["heights"]
    r0, r1 = h["fit"]
    angle, icpt, b = fitted_angle(radii, heights, r0, r1)
    print("| ring radius (mm) | top surface (mm) |")
    print("|---|---|")
    for r, z in zip(radii, heights):
        print(f"| {1000 * r:.1f} | {1000 * z:.1f} |")
    print()
    print(f"cone fitted between {1000 * r0:.0f} and {1000 * r1:.0f} mm: {angle:.2f} deg "
          f"(analysis: {h['angle_deg']:.2f} deg); apex of the fitted cone {1000 * icpt:.1f} mm, "
          f"highest ring {1000 * max(heights):.1f} mm")

    x1 = max(radii) + 0.5 * (radii[1] - radii[0]) if len(radii) > 1 else max(radii)
    y1 = max(max(heights), icpt) * 1.15
    w, m = 720, 56
    scale = (w - 1.5 * m) / x1
    hgt = int(y1 * scale + 1.5 * m)
    px = lambda x: m + scale * x
    py = lambda y: hgt - m - scale * y
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{hgt}" font-family="sans-serif" font-size="12">',
             f'<rect width="{w}" height="{hgt}" fill="white"/>',
             f'<line x1="{m}" y1="{py(0)}" x2="{px(x1):.1f}" y2="{py(0)}" stroke="black"/>',
             f'<line x1="{m}" y1="{py(0)}" x2="{m}" y2="{py(y1):.1f}" stroke="black"/>',
             f'<rect x="{px(r0):.1f}" y="{py(y1):.1f}" width="{px(r1) - px(r0):.1f}" height="{py(0) - py(y1):.1f}" fill="#f4f4f4"/>']
    step = 0.02 if x1 > 0.1 else 0.01
    for k in range(0, int(x1 / step + 1e-9) + 1):
        x = k * step
        parts.append(f'<text x="{px(x):.1f}" y="{py(0) + 16:.1f}" text-anchor="middle">{1000 * x:.0f}</text>')
    for k in range(0, int(y1 / step + 1e-9) + 1):
        y = k * step
        parts.append(f'<text x="{m - 6}" y="{py(y) + 4:.1f}" text-anchor="end">{1000 * y:.0f}</text>')
    parts.append(f'<text x="{(w + m) / 2}" y="{hgt - 12}" text-anchor="middle">distance from the axis (mm); the cone fitted over the shaded rings</text>')
    parts.append(f'<text x="14" y="{hgt / 2}" transform="rotate(-90 14 {hgt / 2})" text-anchor="middle">top surface (mm)</text>')
    rm = 0.5 * (r0 + r1)
    zm = icpt + b * rm
    for ref in (float(x) for x in a.range.split(",")):
        t = math.tan(math.radians(ref))
        # The reference cone through the fitted one's middle, clipped to the plot.
        xa, xb = max(0.0, rm - (y1 - zm) / t), min(x1, rm + zm / t)
        parts.append(f'<line x1="{px(xa):.1f}" y1="{py(zm + t * (rm - xa)):.1f}" x2="{px(xb):.1f}" '
                     f'y2="{py(zm - t * (xb - rm)):.1f}" stroke="#999" stroke-dasharray="3 3"/>')
        parts.append(f'<text x="{px(xa) + 4:.1f}" y="{py(zm + t * (rm - xa)) + 12:.1f}" fill="#777">{ref:g}°</text>')
    xe = min(x1, -icpt / b) if b < 0 else x1
    parts.append(f'<line x1="{px(0):.1f}" y1="{py(icpt):.1f}" x2="{px(xe):.1f}" y2="{py(icpt + b * xe):.1f}" '
                 f'stroke="#d95f02" stroke-width="1.5"/>')
    parts.append(f'<text x="{px(rm) + 10:.1f}" y="{py(zm) - 10:.1f}" fill="#d95f02">fitted cone {angle:.1f}°</text>')
    pts = " ".join(f"{px(r):.1f},{py(z):.1f}" for r, z in zip(radii, heights))
    parts.append(f'<polyline points="{pts}" fill="none" stroke="#1f4e9c" stroke-width="2"/>')
    parts += [f'<circle cx="{px(r):.1f}" cy="{py(z):.1f}" r="3" fill="#1f4e9c"/>' for r, z in zip(radii, heights)]
    parts.append("</svg>")
    with open(a.svg, "w") as f:
        f.write("\n".join(parts) + "\n")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Case 2 (docs/production.md §2): the drum's time-averaged velocity field, as the seed's
Fig. 15 draws it, one panel per drum.

  python3 launch/production/drum_field.py OUT.svg LABEL:FIELD.csv:FLOW.json ...

FIELD.csv and FLOW.json are what `polydem analyze drum ... --field FIELD.csv > FLOW.json`
writes. Each panel shows the cells' mean velocity as arrows coloured by speed (cells with fewer
than 0.02 centres per frame, the flying grains, are left out), the drum's rim, the fitted free
surface and the depth of the flowing layer below its middle.
"""
import csv
import json
import math
import sys


def colour(f):
    """Blue (slow) to red (fast), f in [0, 1]."""
    f = min(max(f, 0.0), 1.0)
    stops = [(0.0, (49, 54, 149)), (0.35, (116, 173, 209)), (0.65, (253, 174, 97)), (1.0, (165, 0, 38))]
    for (f0, c0), (f1, c1) in zip(stops, stops[1:]):
        if f <= f1:
            t = (f - f0) / (f1 - f0)
            return "rgb({},{},{})".format(*(round(a + t * (b - a)) for a, b in zip(c0, c1)))
    return "rgb(165,0,38)"


def panel(label, cells, flow, x0, y0, size, vmax):
    r = max(math.hypot(c["x"], c["z"]) for c in cells) if cells else 0.15
    r = flow.get("radius", r)
    s = size / (2.2 * r)
    cx, cy = x0 + size / 2, y0 + size / 2
    px = lambda x, z: (cx + s * x, cy - s * z)
    out = [f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="{s * r:.1f}" fill="none" stroke="black"/>']
    h = flow["cell"]
    arrow = 0.9 * h * s / vmax  # a cell's width at the fastest speed
    for c in cells:
        if c["occupancy"] < 0.02:
            continue
        sp = math.hypot(c["vx"], c["vz"])
        (ax, ay) = px(c["x"], c["z"])
        bx, by = ax + arrow * c["vx"], ay - arrow * c["vz"]
        col = colour(sp / vmax)
        out.append(f'<line x1="{ax:.1f}" y1="{ay:.1f}" x2="{bx:.1f}" y2="{by:.1f}" stroke="{col}" stroke-width="1.2"/>')
        out.append(f'<circle cx="{bx:.1f}" cy="{by:.1f}" r="1.1" fill="{col}"/>')
    if flow.get("surface_line"):
        a, b = flow["surface_line"]
        xs = [-0.5 * r, 0.5 * r]
        (x1, y1), (x2, y2) = (px(x, a + b * x) for x in xs)
        out.append(f'<line x1="{x1:.1f}" y1="{y1:.1f}" x2="{x2:.1f}" y2="{y2:.1f}" stroke="black" stroke-dasharray="5 3" stroke-width="1.5"/>')
        if flow.get("surface_middle") and flow.get("flowing_layer_depth"):
            mx, mz = flow["surface_middle"]
            d = flow["flowing_layer_depth"]
            n = (b / math.hypot(1, b), -1 / math.hypot(1, b))
            (p1x, p1y), (p2x, p2y) = px(mx, mz), px(mx + d * n[0], mz + d * n[1])
            out.append(f'<line x1="{p1x:.1f}" y1="{p1y:.1f}" x2="{p2x:.1f}" y2="{p2y:.1f}" stroke="black" stroke-width="3"/>')
    angle = flow.get("angle_of_repose_deg")
    depth = flow.get("flowing_layer_depth")
    text = f"{label}: θ = {angle:.1f}°" if angle is not None else f"{label}"
    if depth is not None:
        text += f", layer {1000 * depth:.0f} mm"
    out.append(f'<text x="{cx:.1f}" y="{y0 + size + 16:.1f}" text-anchor="middle">{text}</text>')
    return out


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    svg, specs = sys.argv[1], sys.argv[2:]
    panels = []
    for spec in specs:
        label, field, flow = spec.split(":", 2)
        with open(field) as f:
            cells = [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]
        with open(flow) as f:
            panels.append((label, cells, json.load(f)))
    vmax = max((math.hypot(c["vx"], c["vz"]) for _, cells, _ in panels for c in cells if c["occupancy"] >= 0.02),
               default=1.0)
    size, pad = 320, 20
    w, h = len(panels) * (size + pad) + pad + 60, size + 70
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
             '<rect width="100%" height="100%" fill="white"/>']
    for k, (label, cells, flow) in enumerate(panels):
        parts += panel(label, cells, flow, pad + k * (size + pad), 20, size, vmax)
    # The colour bar.
    bx = pad + len(panels) * (size + pad)
    for j in range(50):
        f = j / 49
        parts.append(f'<rect x="{bx}" y="{20 + size - (j + 1) * size / 50:.1f}" width="12" height="{size / 50 + 0.5:.1f}" fill="{colour(f)}"/>')
    parts.append(f'<text x="{bx + 16}" y="{20 + size:.0f}">0</text>')
    parts.append(f'<text x="{bx + 16}" y="28">{vmax:.2f} m/s</text>')
    parts.append("</svg>")
    with open(svg, "w") as f:
        f.write("\n".join(parts) + "\n")
    for label, _, flow in panels:
        print(f"{label}: angle {flow.get('angle_of_repose_deg')}, layer {flow.get('flowing_layer_depth')}, "
              f"surface speed {flow.get('surface_speed')}")


if __name__ == "__main__":
    main()

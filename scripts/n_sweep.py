#!/usr/bin/env python3
"""Particle-steps per second against the number of particles, GPU against CPU
(docs/performance.md, "Speed against size").

  python3 scripts/n_sweep.py scenes DIR
      writes the sweep's scenes into DIR (from the repository root): the settled packings of
      launch/bench/packings/ (dodecahedra, spheres) tiled k x k x k for 4000 k^3 particles, and
      small simple cubic lattices of the lattice benches' spacing below one cell (1000 particles
      and fewer); prints one line per scene: its path and particle count.
  python3 scripts/n_sweep.py plot DATA.jsonl OUT.svg
      DATA holds one `polydem bench` report per line (scripts/n_sweep.sh writes it); prints the
      table and draws particle-steps/s against N, one line per shape, backend and precision.
"""
import json
import math
import os
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))
from settled_benches import bench_scene, read_packing  # noqa: E402

# name: (type name, particle type lines (paths relative to the sweep folder's scenes, which
# the caller places two levels below the root), lattice spacing)
SHAPES = {
    "dodecahedra": ("dodecahedron", 'mesh = "{root}/meshes/particles/dodecahedron.stl"\nscale = 0.001', 0.00087),
    "spheres": ("sphere", 'generator = {{ kind = "sphere", size = 0.001 }}', 0.00099),
}
TILES = [1, 2, 3, 5, 8, 13, 20, 29]
LATTICES = [5, 10]



def scenes(folder):
    folder = pathlib.Path(folder).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    for shape, (type_name, type_lines, spacing) in SHAPES.items():
        lines = type_lines.format(root=ROOT)
        for m in LATTICES:
            n = m ** 3
            b = [repr(m * spacing)] * 3
            how = f"lattice = [{spacing}, {spacing}, {spacing}]\norientation = \"random\""
            path = folder / f"{shape}_lattice_{n}.toml"
            path.write_text(bench_scene(b, type_name, lines, n, how, folder / "out"))
            print(path, n)
        packing = ROOT / f"launch/bench/packings/{shape}.packing"
        cell, count, _ = read_packing(packing)
        for k in TILES:
            n = count * k ** 3
            b = [repr(c * k) for c in cell]
            how = f'packing = "{packing}"'
            path = folder / f"{shape}_settled_{n}.toml"
            path.write_text(bench_scene(b, type_name, lines, n, how, folder / "out"))
            print(path, n)


def series_of(r):
    name = os.path.basename(r["scene"])
    # lattices below one settled cell (1000 particles and fewer) and tiled settled cells
    # above it: one line per shape, the lattice points drawn hollow
    label = name.split("_")[0]
    if r["backend"] == "cpu":
        return f"{label}, CPU {r['device'].split(',')[-1].strip()}"
    return f"{label}, GPU {r['precision']}"


COLOURS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f"]


def plot(data, out):
    rows = [json.loads(line) for line in open(data) if line.strip()]
    rows = [r for r in rows if "particle_steps_per_second" in r]
    series = {}
    for r in rows:
        kind = os.path.basename(r["scene"]).split("_")[1]
        series.setdefault(series_of(r), []).append((r["particles"], r["particle_steps_per_second"], kind))
    print("| series | packing | particles | particle-steps/s |")
    print("|---|---|---|---|")
    for name, pts in sorted(series.items()):
        for n, v, kind in sorted(pts):
            print(f"| {name} | {kind} | {n} | {v:.3g} |")
    w, h = 900, 560
    x0, y0, pw, ph = 80, 40, 520, 440
    xlo, xhi, ylo, yhi = 2.0, 8.0, 4.0, 10.0
    px = lambda n: x0 + (math.log10(n) - xlo) / (xhi - xlo) * pw
    py = lambda v: y0 + ph - (math.log10(v) - ylo) / (yhi - ylo) * ph
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
             '<rect width="100%" height="100%" fill="white"/>',
             f'<text x="{x0}" y="22" font-size="14">Particle-steps per second against particles (H200; CPU: its 16 cores; hollow: lattices)</text>']
    for e in range(int(xlo), int(xhi) + 1):
        xx = px(10.0 ** e)
        parts.append(f'<line x1="{xx:.1f}" x2="{xx:.1f}" y1="{y0}" y2="{y0 + ph}" stroke="#ddd"/>')
        parts.append(f'<text x="{xx:.1f}" y="{y0 + ph + 16}" text-anchor="middle">1e{e}</text>')
    for e in range(int(ylo), int(yhi) + 1):
        yy = py(10.0 ** e)
        parts.append(f'<line x1="{x0}" x2="{x0 + pw}" y1="{yy:.1f}" y2="{yy:.1f}" stroke="#ddd"/>')
        parts.append(f'<text x="{x0 - 8}" y="{yy + 4:.1f}" text-anchor="end">1e{e}</text>')
    parts.append(f'<rect x="{x0}" y="{y0}" width="{pw}" height="{ph}" fill="none" stroke="black"/>')
    parts.append(f'<text x="{x0 + pw / 2}" y="{y0 + ph + 36}" text-anchor="middle">particles</text>')
    for i, (name, pts) in enumerate(sorted(series.items())):
        c = COLOURS[i % len(COLOURS)]
        dash = ' stroke-dasharray="5 3"' if "CPU" in name else ""
        pts = sorted(pts)
        path = " ".join(f"{'M' if k == 0 else 'L'}{px(n):.1f},{py(v):.1f}" for k, (n, v, _) in enumerate(pts))
        parts.append(f'<path d="{path}" fill="none" stroke="{c}" stroke-width="2"{dash}/>')
        for n, v, kind in pts:
            fill = "white" if kind == "lattice" else c
            parts.append(f'<circle cx="{px(n):.1f}" cy="{py(v):.1f}" r="3" fill="{fill}" stroke="{c}"/>')
        parts.append(f'<line x1="{x0 + pw + 20}" x2="{x0 + pw + 44}" y1="{y0 + 10 + 18 * i}" y2="{y0 + 10 + 18 * i}" stroke="{c}" stroke-width="2"{dash}/>')
        parts.append(f'<text x="{x0 + pw + 50}" y="{y0 + 14 + 18 * i}">{name}</text>')
    parts.append("</svg>")
    open(out, "w").write("\n".join(parts) + "\n")


def main():
    if len(sys.argv) == 3 and sys.argv[1] == "scenes":
        scenes(sys.argv[2])
    elif len(sys.argv) == 4 and sys.argv[1] == "plot":
        plot(sys.argv[2], sys.argv[3])
    else:
        print(__doc__, file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Writes launch/bench/settled/<shape>_<size>.toml: each packing of launch/bench/packings/
(made by `polydem pack`, see scripts/make_packings.sh) tiled to about 1e5, 1e6 and 1e7
particles in a fully periodic box without gravity, with the material of the lattice benches.

Usage: python3 scripts/settled_benches.py   (from the repository root; reads the packings'
cell sizes, so run it after the packings change)."""
import pathlib

ROOT = pathlib.Path(__file__).resolve().parent.parent
PACKINGS = ROOT / "launch/bench/packings"
OUT = ROOT / "launch/bench/settled"

# Particle type lines, as in the packing scenes.
SHAPES = {
    "dodecahedra": ("dodecahedron", 'mesh = "../../../meshes/particles/dodecahedron.stl"\nscale = 0.001',
                    "dodecahedra of 1 mm (circumscribed diameter)"),
    "mineral_grains": ("mineral_grain", 'mesh = "../../../meshes/particles/mineral_grain.stl"\nscale = 1.0',
                       "mineral grains (18 vertices, 32 faces, about 2 mm)"),
    "cylinders": ("cylinder", 'mesh = "../../../meshes/particles/catalyst_cylinder.stl"\nscale = 1.0',
                  "catalyst cylinders (24-gon prisms, 5.5 mm x 5.5 mm)"),
    "spheres": ("sphere", 'generator = { kind = "sphere", size = 0.001 }', "spheres of 1 mm"),
}
# Copies of the cell along x, y, z for each size (a cell holds 4000 particles).
TILINGS = {"1e5": (3, 3, 3), "1e6": (6, 6, 7), "1e7": (13, 14, 14)}


def read_packing(path):
    cell, count, comments = None, None, []
    with open(path) as f:
        for line in f:
            if line.startswith("# ") and not line.startswith("# polydem"):
                comments.append(line[2:].strip())
            elif line.startswith("cell"):
                cell = [float(x) for x in line.split()[1:]]
            elif line.startswith("particles"):
                count = int(line.split()[1])
                break
    return cell, count, comments


def bench_scene(box, type_name, type_lines, count, how, out):
    """The text of a benchmark scene: the lattice benches' material, fully periodic, no gravity,
    `count` particles of one type filling the box `box` (three coordinates as strings), placed
    as the insertion line(s) `how` say; output into `out`."""
    return f"""gravity = [0.0, 0.0, 0.0]

[simulation]
dt_fraction = 0.025
end_time = 1.0
seed = 9

[domain]
min = [0.0, 0.0, 0.0]
max = [{box[0]}, {box[1]}, {box[2]}]
periodic = [true, true, true]

[[materials]]
name = "grain"
youngs_modulus = 1.0e7
poisson_ratio = 0.3
density = 2500.0

[[material_pairs]]
materials = ["grain", "grain"]
restitution = 0.5
friction = 0.5

[[particle_types]]
name = "{type_name}"
material = "grain"
{type_lines}

[[insertions]]
type = "{type_name}"
region = {{ kind = "box", min = [0.0, 0.0, 0.0], max = [{box[0]}, {box[1]}, {box[2]}] }}
count = {count}
{how}

[output]
dir = "{out}"
"""


def main():
    OUT.mkdir(exist_ok=True)
    for shape, (type_name, type_lines, what) in SHAPES.items():
        packing = PACKINGS / f"{shape}.packing"
        if not packing.exists():
            print(f"{packing} missing: run scripts/make_packings.sh first; {shape} skipped")
            continue
        cell, count, comments = read_packing(packing)
        for size, tiles in TILINGS.items():
            n = count * tiles[0] * tiles[1] * tiles[2]
            box = [repr(c * t) for c, t in zip(cell, tiles)]
            made = "\n".join(f"#   {c}" for c in comments)
            header = f"""# Benchmark: {n} {what} in a settled random packing: the periodic cell of
# launch/bench/packings/{shape}.packing ({count} particles) tiled {tiles[0]} x {tiles[1]} x {tiles[2]} in a fully periodic
# box without gravity. The cell was made by compression:
{made}
# Written by scripts/settled_benches.py; run with
# `polydem bench launch/bench/settled/{shape}_{size}.toml` (docs/performance.md).

"""
            text = header + bench_scene(box, type_name, type_lines, n, f'packing = "../packings/{shape}.packing"',
                                        f"../../../out/bench_settled_{shape}_{size}")
            (OUT / f"{shape}_{size}.toml").write_text(text)
            print(OUT / f"{shape}_{size}.toml", n)


if __name__ == "__main__":
    main()

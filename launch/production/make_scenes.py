#!/usr/bin/env python3
"""Writes the production scenes that hold several copies of one experiment side by side
(launch/production/*.toml listed in SCENES below).

  python3 launch/production/make_scenes.py            # all of them
  python3 launch/production/make_scenes.py NAME ...   # only these

A small scene keeps a GPU latency-bound (docs/performance.md, speed against size): 63 dice
step no faster than 630 do. So the ten pours of case 1 run as ten cylinders in one scene, and
the drum's three speeds as three drums, each with its own walls and insertion; the copies do
not touch (their walls are closed and 2 cm or more apart), so each is the experiment alone,
with its own random placements. `polydem analyze` takes one copy at a time (`--centre`, `--y`).
"""
import pathlib
import sys

HERE = pathlib.Path(__file__).resolve().parent

PLA = """[[materials]]
name = "pla"                         # the 3D-printed dodecahedra (seed Sec. 3.2, Table 2)
youngs_modulus = 1.0e6
poisson_ratio = 0.1
density = 1500.0

[[materials]]
name = "acrylic"                     # the container: same elastic data, it is not resolved
youngs_modulus = 1.0e6
poisson_ratio = 0.1
density = 1500.0
"""


def pairs(restitution, friction):
    return "".join(f"""
[[material_pairs]]
materials = ["pla", "{other}"]
restitution = {restitution}
friction = {friction}
""" for other in ("pla", "acrylic"))


# --- case 1: ten pours -------------------------------------------------------------------------

POURS, ROW, PITCH = 10, 5, 0.12   # cylinders of r 0.05 m, 2 cm apart


def pour_centre(k):
    return (PITCH * (k % ROW), PITCH * (k // ROW))


def dodecahedra_cylinder_x10():
    rows = (POURS + ROW - 1) // ROW
    out = [f"""# Ten pours of ../dodecahedra_cylinder.toml (seed paper Sec. 3.3) in one scene, written by
# make_scenes.py: the same cylinder ({POURS} copies, {ROW} to a row, axes {PITCH} m apart, the first
# on the z axis), the same dice and the same feed, 63 dodecahedra of 30.8 mm one by one into
# each. The pours differ by their random placements and orientations (one stream for the
# scene). Pour k's cylinder has its axis at x = {PITCH} (k mod {ROW}), y = {PITCH} (k div {ROW}):
#   polydem analyze fill-height dodecahedra_cylinder_x10.toml CKPT --radius 0.05 --centre X,Y

gravity = [0.0, 0.0, -9.81]

[simulation]
dt_fraction = 0.05
end_time = 10.0
seed = 0

[domain]
min = [-0.06, -0.06, -0.01]
max = [{PITCH * (ROW - 1) + 0.06:.2f}, {PITCH * (rows - 1) + 0.06:.2f}, 0.27]
on_leaving = "error"

{PLA}{pairs(0.1, 0.8)}
[[particle_types]]
name = "dodecahedron"
material = "pla"
mesh = "../../meshes/particles/dodecahedron.stl"   # unit circumscribed diameter
scale = 0.0308
"""]
    for k in range(POURS):
        x, y = pour_centre(k)
        out.append(f"""
[[insertions]]                       # pour {k}
type = "dodecahedron"
region = {{ kind = "cylinder", base = [{x:.2f}, {y:.2f}, 0.205], axis = [0.0, 0.0, 1.0], radius = 0.031, height = 0.035 }}
rate = 8.0
total = 63
orientation = "random"
""")
    for k in range(POURS):
        x, y = pour_centre(k)
        out.append(f"""
[[walls]]
name = "cylinder_{k}"
mesh = "meshes/dodecahedra_cylinder.stl"
material = "acrylic"
translate = [{x:.2f}, {y:.2f}, 0.0]
""")
    out.append("""
[output]
dir = "out/dodecahedra_cylinder_x10"
checkpoint_interval = 2.5
series_interval = 0.05
""")
    return "".join(out)


# --- case 2: the drum at three speeds ----------------------------------------------------------

DRUM_RPM = (30.0, 45.0, 60.0)   # the seed's 45 rpm between a slower and a faster speed
DRUM_PITCH = 0.03               # m between the drums' mid-planes (each is 11 mm deep)
DRUM_FILL = 330                 # dodecahedra per drum: about 40 % of its cross-section


def drum_y(k):
    return DRUM_PITCH * (k - (len(DRUM_RPM) - 1) / 2)


def drum_speeds():
    n = len(DRUM_RPM)
    out = [f"""# Seed paper Sec. 3.4, Table 3: the quasi-2D rotating drum (D = 0.30 m, 11 mm deep) with
# regular dodecahedra of 1 cm circumscribed diameter, the dice material of Sec. 3.2 and the
# friction of 0.7 the seed fitted to its experiment; written by make_scenes.py. Three drums
# side by side along y ({DRUM_PITCH} m apart), turning at {", ".join(f"{r:g}" for r in DRUM_RPM)} rpm, each with
# {DRUM_FILL} dodecahedra (about 40 % of its cross-section: the seed does not give its fill).
# The particles are placed at random in each drum at t = 0, fall and are carried up; the flow
# is steady after about one turn. Drum k's mid-plane is at y = {drum_y(0):g} + {DRUM_PITCH} k:
#   polydem analyze drum out/drum_speeds/particles --radius 0.15 --y Y-0.0055,Y+0.0055 --from 2

gravity = [0.0, 0.0, -9.81]

[simulation]
dt_fraction = 0.05
end_time = 6.0
seed = 0

[domain]
min = [-0.16, {drum_y(0) - 0.01:.4f}, -0.16]
max = [0.16, {drum_y(n - 1) + 0.01:.4f}, 0.16]
on_leaving = "error"

{PLA}{pairs(0.1, 0.7)}
[[particle_types]]
name = "dodecahedron"
material = "pla"
mesh = "../../meshes/particles/dodecahedron.stl"   # unit circumscribed diameter
scale = 0.01
"""]
    for k, rpm in enumerate(DRUM_RPM):
        y = drum_y(k)
        out.append(f"""
[[insertions]]                       # drum {k}, {rpm:g} rpm
type = "dodecahedron"
region = {{ kind = "cylinder", base = [0.0, {y - 0.0055:.4f}, 0.0], axis = [0.0, 1.0, 0.0], radius = 0.149, height = 0.011 }}
count = {DRUM_FILL}
orientation = "random"
""")
    for k, rpm in enumerate(DRUM_RPM):
        y = drum_y(k)
        out.append(f"""
[[walls]]
name = "drum_{rpm:g}rpm"
mesh = "meshes/drum.stl"             # make_meshes.py: D 0.30 m, 11 mm deep, axis y
material = "acrylic"
translate = [0.0, {y:.4f}, 0.0]
motion = {{ kind = "rotate", axis = [0.0, 1.0, 0.0], rpm = {rpm:g}, origin = [0.0, {y:.4f}, 0.0] }}
""")
    out.append("""
[output]
dir = "out/drum_speeds"
frame_interval = 0.01
formats = ["csv"]
checkpoint_interval = 1.0
series_interval = 0.01
""")
    return "".join(out)


SCENES = {
    "dodecahedra_cylinder_x10": dodecahedra_cylinder_x10,
    "drum_speeds": drum_speeds,
}


def main(names):
    for name in names or SCENES:
        if name not in SCENES:
            sys.exit(f"unknown scene {name!r}: one of {', '.join(SCENES)}")
        path = HERE / f"{name}.toml"
        tmp = path.with_suffix(".toml.tmp")
        tmp.write_text(SCENES[name]())
        tmp.replace(path)
        print(path)


if __name__ == "__main__":
    main(sys.argv[1:])

#!/usr/bin/env python3
"""Writes the production scenes built from parameters (launch/production/*.toml and twins/
listed in SCENES below): those that hold several copies of one experiment side by side, the
silo's fills, discharges and heap, and their twins.

  python3 launch/production/make_scenes.py            # all of them
  python3 launch/production/make_scenes.py NAME ...   # only these
  python3 launch/production/make_scenes.py --discharge-count N silo_discharge_75mm ...
  python3 launch/production/make_scenes.py --discharge-outlets   # prints "NAME D0 Z" per outlet
  python3 launch/production/make_scenes.py --check    # writes nothing: exits 1 naming every
                                                      # scene file that differs from its parameters

A small scene keeps a GPU latency-bound (docs/performance.md, speed against size): 63 dice
step no faster than 630 do. So the ten pours of case 1 run as ten cylinders in one scene, and
the drum's three speeds as three drums, each with its own walls and insertion; the copies do
not touch (their walls are closed and 2 cm or more apart), so each is the experiment alone,
with its own random placements. `polydem analyze` takes one copy at a time (`--centre`, `--y`).
"""
import math
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
face_window = "secant"               # as docs/production.md's runs were made (the default is "trajectory")
end_time = 5.0                       # s: averaged from 2 s on, 300 frames (1.5 turns at 30 rpm)
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


# --- case 4: the silo ---------------------------------------------------------------------------

GRAIN = "../../meshes/particles/mineral_grain.stl"   # 18 vertices, 32 faces, d_c = 2.152 mm
GRAIN_DC = 2 * 0.0010760251611716461                  # circumscribed diameter at scale 1 (m)
GRAIN_V = 1.0128777552160202e-09                      # volume at scale 1 (m³)
BENCH_PACKING = HERE.parent / "bench" / "packings" / "mineral_grains.packing"


def scaled_packing(factor, out):
    """The benchmarks' settled packing of 4000 mineral grains (launch/bench/packings/, 7
    contacts per particle, solid fraction 0.559) enlarged `factor` times: positions, cell and
    scale, the same packing at another size."""
    lines = BENCH_PACKING.read_text().splitlines()
    res = [lines[0], f"# the packing of {BENCH_PACKING.relative_to(HERE.parent.parent)} enlarged {factor!r} times "
           "(launch/production/make_scenes.py)"]
    for line in lines[1:]:
        if line.startswith("#") or line.startswith("particles"):
            res.append(line)
        elif line.startswith("cell"):
            res.append("cell " + " ".join(repr(float(x) * factor) for x in line.split()[1:]))
        else:
            v = [float(x) for x in line.split()]
            res.append(" ".join([repr(x * factor) for x in v[:3]] + line.split()[3:7] + [repr(v[7] * factor)]))
    (HERE / "packings").mkdir(exist_ok=True)
    path = HERE / "packings" / out
    tmp = path.with_suffix(".tmp")
    tmp.write_text("\n".join(res) + "\n")
    tmp.replace(path)
    return path


GRAIN_MATERIALS = """[[materials]]
name = "ore"                         # a mineral ore; the seed gives no material for its silo
youngs_modulus = {e}
poisson_ratio = 0.3
density = 2500.0

[[materials]]
name = "steel"
youngs_modulus = 2.0e11
poisson_ratio = 0.3
density = 7800.0

[[material_pairs]]
materials = ["ore", "ore"]
restitution = 0.5
friction = 0.5

[[material_pairs]]
materials = ["ore", "steel"]
restitution = 0.5
friction = 0.3
"""

def grain_head(end, lo, hi, on_leaving, e, scale, up=""):
    """The head of every mineral-grain scene: gravity, the step and the end time (`end`, a number
    or the text after `end_time = `), the domain box (`lo`, `hi`: TOML arrays), what happens to
    grains that leave it, the ore and steel materials with the grains' E (`e`, Pa, as text) and
    the grain type at `scale` (`up`: the path from the scene's folder to launch/production/)."""
    return f"""gravity = [0.0, 0.0, -9.81]

[simulation]
dt_fraction = 0.05
face_window = "secant"               # as docs/production.md's runs were made (the default is "trajectory")
end_time = {end if isinstance(end, str) else repr(end)}
seed = 0

[domain]
min = {lo}
max = {hi}
on_leaving = "{on_leaving}"

{GRAIN_MATERIALS.format(e=e)}
[[particle_types]]
name = "grain"
material = "ore"
mesh = "{up}{GRAIN}"
scale = {scale!r}
"""



def silo_walls(prefix, bands, up=""):
    names = ["hopper"] + (["side"] if bands == 0 else ["side_west"] + [f"band_{b:02d}" for b in range(bands)])
    out = []
    for n in names:
        out.append(f"""
[[walls]]
name = "{n}"
mesh = "{up}meshes/{prefix}_{n}.stl"
material = "steel"
""")
    return "".join(out)


def kept_in_cylinder(packing, radius, height, bound):
    """How many particles of `packing` tiled over the square prism around a cylinder have their
    bounding sphere (radius `bound`) inside it: the count `[[insertions]] packing` keeps in a
    cylinder region (docs/scene.md). Distances from the axis do not depend on the frame's
    turn about it, so this needs only the cell and the positions."""
    cell, pts = None, []
    for line in packing.read_text().splitlines():
        if line.startswith("cell"):
            cell = [float(x) for x in line.split()[1:]]
        elif line and not line.startswith(("#", "particles")):
            pts.append([float(x) for x in line.split()[:3]])
    tiles = [math.ceil(2 * radius / cell[0]), math.ceil(2 * radius / cell[1]), math.ceil(height / cell[2])]
    n = 0
    for k in range(tiles[2]):
        for j in range(tiles[1]):
            for i in range(tiles[0]):
                ox, oy, oz = -radius + i * cell[0], -radius + j * cell[1], k * cell[2]
                for x, y, z in pts:
                    lx, ly, lz = ox + x, oy + y, oz + z
                    if math.hypot(lx, ly) <= radius - bound and bound <= lz <= height - bound:
                        n += 1
    return n


def hopper_steps(r, r0, z_h, steps, margin, bound):
    """Cylinders stacked inside the cone (radius r0 at z = 0 to r at z_h), each as wide as the
    cone at its bottom less `margin`, `steps` of them: regions that fill the hopper without
    touching it. Returns (base z, radius, height) per step; steps narrower than a grain are
    left out."""
    out = []
    for k in range(steps):
        z0, z1 = z_h * k / steps, z_h * (k + 1) / steps
        rad = r0 + (r - r0) * z0 / z_h - margin
        if rad > 1.5 * bound:
            out.append((z0, rad, z1 - z0))
    return out


SILO_SCALE = 23.0       # d_c = 49.5 mm: 1e6 grains fill the seed's silo to about 7 m
SILO_GRAINS = 1_000_000


def silo_filled():
    """Case 4a: the seed's silo (make_meshes.py silo, 151 504 facets) holding 1e6 grains from
    the start: the scaled settled packing tiled in the hopper (stacked cylinders) and the
    cylinder above it, then a short settle. For measuring the filled state, not for its
    physics."""
    packing = scaled_packing(SILO_SCALE, "mineral_grains_silo.packing")
    r, r0, a = 1.05, 0.335, 0.0065
    z_h = (r - r0) / math.tan(math.radians(30.0))
    bound = GRAIN_DC / 2 * SILO_SCALE
    steps = hopper_steps(r, r0, z_h, 8, 0.01, bound)
    out = [f"""# Case 4a (docs/production.md §4): the seed's silo (Sec. 4.1, Fig. 19-20; 2.1 m across, 10.6 m,
# 0.67 m outlet, corrugated side, 151 504 facets) filled with 1e6 of its mineral grains (18
# vertices, 32 faces) of 49.5 mm circumscribed diameter, for measuring what a filled silo costs
# on one GPU. Built without a fill: the settled packing of the benchmarks, enlarged to this
# grain (packings/mineral_grains_silo.packing), tiled in {len(steps)} stacked cylinders inside the hopper
# and in the cylinder above it up to the count; {SILO_GRAINS} grains. Written by make_scenes.py.
# The side wall's mesh is not committed (7.5 MB): first run
#   python3 launch/production/make_meshes.py silo

{grain_head('0.05                      # s: a short settle; the bench is the point', '[-1.1, -1.1, -0.05]', '[1.1, 1.1, 10.65]', 'error', "1.0e7", SILO_SCALE)}"""]
    # The hopper's steps, then the cylinder: fill counts are checked by `polydem check`.
    rest = SILO_GRAINS
    for z0, rad, h in steps:
        n = kept_in_cylinder(packing, rad, h, bound)
        out.append(f"""
[[insertions]]                       # hopper step at z = {z0:.3f} m
type = "grain"
region = {{ kind = "cylinder", base = [0.0, 0.0, {z0!r}], axis = [0.0, 0.0, 1.0], radius = {rad!r}, height = {h!r} }}
packing = "packings/mineral_grains_silo.packing"
count = {n}
""")
        rest -= n
    if rest > kept_in_cylinder(packing, r - a - 0.005, 8.0, bound):
        sys.exit("silo_filled: the cylinder cannot hold the rest of the grains")
    out.append(f"""
[[insertions]]                       # the cylinder above the hopper
type = "grain"
region = {{ kind = "cylinder", base = [0.0, 0.0, {z_h!r}], axis = [0.0, 0.0, 1.0], radius = {r - a - 0.005!r}, height = 8.0 }}
packing = "packings/mineral_grains_silo.packing"
count = {rest}
""")
    out.append(silo_walls("silo", 0))
    out.append("""
[[walls]]
name = "gate"
mesh = "meshes/silo_gate.stl"        # closes the outlet from below
material = "steel"

[output]
dir = "out/silo_filled"
checkpoint_interval = 0.05
series_interval = 0.005
""")
    return "".join(out)


QUARTER_SCALE = 15.0    # d_c = 32.3 mm, d_eq = 18.7 mm: the 1:4 silo is 16 grains across
QUARTER_GRAINS = 40_000 # about 1.1 m of bed above the hopper
QUARTER_END = 3.8       # s: the fill (the last grain lands near 2.8 s) and its settling
QUARTER_E = "1.0e6"     # Pa: the fill's and the discharges' grains


def silo_fill(name, prefix, d, height, outlet, scale, grains, rate, e, bands, end, inlet, doc, up="",
              speed=2.0, feed=6, batch=None):
    """A silo filled from a central inlet at its top (case 4b and its twin): grains placed at
    random in a cylinder of radius `inlet` d/2 and `feed` grain radii tall just below the rim,
    thrown down at `speed` so the inlet clears quickly, onto a gate closing the outlet; fed in
    batches `batch` seconds apart when given. The side's east half is cut into `bands` walls
    for the wall stress."""
    r = d / 2
    bound = GRAIN_DC / 2 * scale
    top = height - 2.5 * bound
    feed_h = feed * bound
    batched = f"interval = {batch!r}\n" if batch else ""
    return f"""{doc}
{grain_head(end, f"[{-r - 0.02!r}, {-r - 0.02!r}, -0.05]", f"[{r + 0.02!r}, {r + 0.02!r}, {height + 0.05!r}]", "error", e, scale, up)}
[[insertions]]                       # the inlet: a central stream from the top
type = "grain"
region = {{ kind = "cylinder", base = [0.0, 0.0, {top - feed_h!r}], axis = [0.0, 0.0, 1.0], radius = {inlet * r!r}, height = {feed_h!r} }}
rate = {rate!r}
total = {grains}
{batched}velocity = [0.0, 0.0, {-speed!r}]
orientation = "random"
{silo_walls(prefix, bands, up)}
[[walls]]
name = "gate"
mesh = "{up}meshes/{prefix}_gate.stl"
material = "steel"

[output]
dir = "out/{name}"
frame_interval = 0.25
formats = ["vtu"]
fields = ["id", "type", "velocity", "orientation"]
checkpoint_interval = 0.5
series_interval = 0.005
"""


def silo_quarter_fill():
    bound = GRAIN_DC / 2 * QUARTER_SCALE
    # the inlet: a column from just above the hopper (0.35 m) to the rim
    feed = round((2.65 - 2.5 * bound - 0.35) / bound, 1)
    return silo_fill(
        "silo_quarter_fill", "silo_quarter", 0.525, 2.65, 0.1675, QUARTER_SCALE, QUARTER_GRAINS,
        24000.0, QUARTER_E, 6, QUARTER_END, 0.6, speed=1.0, feed=feed, batch=0.005,
        doc=f"""# Case 4b (docs/production.md §4): the seed's silo at 1:4 (make_meshes.py silo_quarter: 0.525 m
# across, 2.65 m, 0.1675 m outlet, 30 degree hopper, corrugated side whose east half is six
# height bands for the wall stress) filled to completion from a central inlet with
# {QUARTER_GRAINS} mineral grains of 32.3 mm (circumscribed; 18.7 mm volume-equivalent), onto a gate
# closing the outlet. The inlet is a central column of 60 % of the radius from just above the
# hopper to the rim: grains are placed at random free spots in it (above the heap as it rises)
# and thrown down at 1 m/s, a stream falling onto the centre of the heap; fed at up to 24 000 per
# second in batches every 5 ms (each GPU step that inserts takes the state through the host),
# it takes about 20 000 per second, so the last grain comes at about 2.2 s and lands by 2.8 s;
# then settling to {QUARTER_END} s. E softened to 1 MPa (the bed's wall stress saturates near
# 14 kPa, a strain of about 1.5 %). Compared with Janssen's law (the bands' forces in series.csv), its packing
# fraction and the heap's angle of repose (`polydem analyze porosity` and `heap`). Written by
# make_scenes.py.""")


def silo_twin():
    return silo_fill(
        "silo_twin", "silo_twin", 0.10, 0.45, 0.06, 11.6, 160, 2000.0, "1.0e6", 2, 0.7, 0.7,
        """# Twin of ../silo_quarter_fill.toml for `make test` (tests/production.rs): a narrow silo
# (make_meshes.py silo_twin: 0.10 m across, 0.45 m, a flat 60 degree hopper, two wall bands)
# fed from the central inlet with 160 grains of 25 mm (circumscribed), E = 1 MPa, settled by
# 0.7 s: a bed about one diameter deep, where the wall already carries part of the weight. Written by make_scenes.py.""", up="../")


def silo_twin_discharge():
    """Case 5's twin: the silo twin's settled state (committed as twins/silo_filled.ckpt, the
    end of twins/silo.toml) discharged through its hopper's own 60 mm outlet."""
    return f"""# Twin of the discharge scenes for `make test` (tests/production.rs): the silo twin's settled
# bed of 160 grains (silo_filled.ckpt: twins/silo.toml run to its end on the CPU) without its
# gate, discharging through the 60 mm outlet (4.1 volume-equivalent grain diameters of
# 14.5 mm) for 0.4 s. Written by make_scenes.py.

{grain_head(0.4, '[-0.07, -0.07, -0.1]', '[0.07, 0.07, 0.5]', 'remove', "1.0e6", 11.6, up='../')}
[[insertions]]
type = "grain"
region = {{ kind = "cylinder", base = [0.0, 0.0, -0.01], axis = [0.0, 0.0, 1.0], radius = 0.06, height = 0.46 }}
state = "silo_filled.ckpt"
count = 160
{silo_walls("silo_twin", 2, "../")}"""


DISCHARGE_HOLES = [round(k * 0.0187, 4) for k in (4, 5, 6, 7, 8)]   # as make_meshes.py
DISCHARGE_OUTLET = 0.1675   # m: the hopper's own outlet, 9.0 d, discharged open (no plate)
DISCHARGE_CUT = round(10 * 0.0187, 4)   # m: 10 d, the hopper cut where it is that wide (as make_meshes.py)
# m: the grains below are discharged, the hopper (0.31 m) and 0.4 m of bed above it: a head
# of 0.71 m over the orifice, 1.35 silo diameters, above which the rate no longer depends on
# the height (22 345 grains of the fill's final state; the 0.91 m of before kept 0.2 m more
# bed, work in every step that does not change the rate)
DISCHARGE_TOP = 0.71
DISCHARGE_END = 0.7     # s: the rate is fitted over 0.25-0.7 s (run_on_gpu.sh)
# Grains of the fill's final state below DISCHARGE_TOP: those of the state kept in
# restart/silo_quarter_fill.final.ckpt.gz; a new fill has its own (`polydem check` on a
# discharge scene gives it, and run_on_gpu.sh passes it as --discharge-count).
DISCHARGE_COUNT = [22_345]


def outlet_height(hole):
    """Where case 5 counts a grain out (m): the plate and the hopper's own outlet lie at z = 0;
    an outlet wider than the hopper's is the cone cut where it is that wide, higher up."""
    return max(hole - DISCHARGE_OUTLET, 0.0) / 2 / math.tan(math.radians(30.0))


DISCHARGES = DISCHARGE_HOLES + [DISCHARGE_OUTLET, DISCHARGE_CUT]


def silo_discharge(hole):
    """Case 5: the filled 1:4 silo (case 4b's final state) discharged from t = 0 through an
    orifice plate of `hole` under its hopper; through the hopper's own outlet when `hole` is
    that outlet (no plate); through the hopper cut where it is `hole` wide when wider."""
    mm = round(1000 * hole)
    walls = silo_walls("silo_quarter", 6)
    d = f"{hole / 0.0187:.{1 if hole == DISCHARGE_OUTLET else 0}f}"
    if hole < DISCHARGE_OUTLET:
        what = f"""through an orifice of {mm} mm ({d} volume-equivalent grain diameters) in a plate under
# its hopper"""
        opened = "the plate's hole is open"
        counted = "the plate (silo_discharge.py\n# --above 0"
        walls += f"""
[[walls]]
name = "orifice"
mesh = "meshes/silo_quarter_orifice_{mm}mm.stl"
material = "steel"
"""
    elif hole == DISCHARGE_OUTLET:
        what = f"""through its hopper's own outlet, {mm} mm ({d} volume-equivalent grain diameters),
# with no plate"""
        opened = "the outlet is open"
        counted = "the outlet (silo_discharge.py\n# --above 0"
    else:
        z = outlet_height(hole)
        what = f"""through an outlet of {mm} mm ({d} volume-equivalent grain diameters),
# its hopper cut {1000 * z:.1f} mm above its own outlet, where the cone is that wide
# (make_meshes.py silo_quarter_hopper)"""
        opened = "the outlet is open"
        counted = f"the cut (silo_discharge.py\n# {hole}@{z:.4f}"
        walls = walls.replace("meshes/silo_quarter_hopper.stl", f"meshes/silo_quarter_hopper_{mm}mm.stl")
    return f"""# Case 5 (docs/production.md §5): the 1:4 silo filled by silo_quarter_fill.toml discharged
# {what}. The grains are the fill's final state below {DISCHARGE_TOP} m, the hopper and {DISCHARGE_TOP - 0.31:.1f} m of
# the bed above it, a head at which the rate no longer depends on the height (`state`:
# run_on_gpu.sh copies the fill's last checkpoint to out/silo_quarter_fill/final.ckpt); the gate
# is gone, {opened} from t = 0, and grains that fall below the domain are
# removed; particle tables every 0.05 s count the grains left above {counted}: mass against time and Beverloo's law). Written by make_scenes.py.

{grain_head(DISCHARGE_END, '[-0.2825, -0.2825, -0.3]', '[0.2825, 0.2825, 2.7]', 'remove', QUARTER_E, QUARTER_SCALE)}
[[insertions]]
type = "grain"
region = {{ kind = "cylinder", base = [0.0, 0.0, -0.01], axis = [0.0, 0.0, 1.0], radius = 0.28, height = {DISCHARGE_TOP + 0.01!r} }}
state = "out/silo_quarter_fill/final.ckpt"
count = {DISCHARGE_COUNT[0]}
{walls}
[output]
dir = "out/silo_discharge_{mm}mm"
frame_interval = 0.05
formats = ["csv"]
checkpoint_interval = 0.5
series_interval = 0.01
"""


def silo_grain_heap():
    """Case 4's angle of repose: the 1:4 silo's grains poured from a narrow inlet onto a round
    base until the heap spills over its rim (the fixed-base method)."""
    bound = GRAIN_DC / 2 * QUARTER_SCALE
    r = 0.2                 # as make_meshes.py HEAP_BASE
    inlet_r, base, height = 0.065, 0.22, 0.3
    return f"""# Case 4 (docs/production.md §4): the angle of repose of the 1:4 silo's grains (mineral grains
# of 32.3 mm circumscribed, 18.7 mm volume-equivalent, the fill's material), which the silo's fill
# cannot give: its feed is 60 % of the silo's radius wide and leaves the top nearly flat. Here
# the grains are poured from an inlet of {inlet_r * 1000:.0f} mm radius (a column from {base} m to
# {base + height:.2f} m, thrown down at 1 m/s: about 540 grains per second on the CPU over the
# first 1.4 s) onto the centre of a round base of {r} m radius (make_meshes.py
# silo_grain_heap_base) whose friction is the grains' own (a rough base), until the heap spills
# over the rim: a fixed-base heap, whose flank's slope is the angle of repose (`polydem analyze
# heap --radius {r} --floor 0`). The stream is slow and lands low: thrown at 3 m/s from 0.35 m
# and more, the grains landed at 4 m/s and spread in a flat layer over the whole base, a third of
# them bouncing off it. Grains that roll off the rim fall out of the domain and are removed.
# 1800 grains by about 3.4 s, then 0.8 s of settling. The stream lands over the inlet's width
# and leaves a flat top out to about half the base's radius (0.09 m on the H200), so the
# flank is fitted between 0.5 and 0.95 of it. Written by make_scenes.py.

{grain_head(4.2, '[-0.25, -0.25, -0.1]', f'[0.25, 0.25, {base + height + 0.05!r}]', 'remove', QUARTER_E, QUARTER_SCALE)}
[[insertions]]                       # the inlet: a narrow stream onto the heap's apex
type = "grain"
region = {{ kind = "cylinder", base = [0.0, 0.0, {base!r}], axis = [0.0, 0.0, 1.0], radius = {inlet_r!r}, height = {height!r} }}
rate = 2000.0
total = 1800
interval = 0.01
velocity = [0.0, 0.0, -1.0]
orientation = "random"

[[walls]]
name = "base"
mesh = "meshes/silo_grain_heap_base.stl"
material = "ore"                     # a rough base: the grains' friction, 0.5

[output]
dir = "out/silo_grain_heap"
frame_interval = 0.25
formats = ["vtu"]
fields = ["id", "type", "velocity", "orientation"]
checkpoint_interval = 0.5
series_interval = 0.005
"""


SCENES = {
    "dodecahedra_cylinder_x10": dodecahedra_cylinder_x10,
    "drum_speeds": drum_speeds,
    "silo_filled": silo_filled,
    "silo_quarter_fill": silo_quarter_fill,
    "silo_grain_heap": silo_grain_heap,
    "twins/silo": silo_twin,
    "twins/silo_discharge": silo_twin_discharge,
    **{f"silo_discharge_{round(1000 * h)}mm": (lambda h=h: silo_discharge(h))
       for h in DISCHARGES},
}


def main(names):
    check = names[:1] == ["--check"]
    if check:
        names = names[1:]
    if names == ["--discharge-outlets"]:
        # For run_on_gpu.sh: each discharge scene, its outlet and the height it counts at.
        for h in DISCHARGES:
            print(f"silo_discharge_{round(1000 * h)}mm {h} {outlet_height(h):.4f}")
        return
    if names[:1] == ["--discharge-count"]:
        DISCHARGE_COUNT[0] = int(names[1])
        names = names[2:]
    stale = []
    for name in names or SCENES:
        if name not in SCENES:
            sys.exit(f"unknown scene {name!r}: one of {', '.join(SCENES)}")
        path = HERE / f"{name}.toml"
        if check:
            if not path.is_file() or path.read_text() != SCENES[name]():
                stale.append(str(path))
            continue
        tmp = path.with_suffix(".toml.tmp")
        tmp.write_text(SCENES[name]())
        tmp.replace(path)
        print(path)
    if stale:
        sys.exit("not what make_scenes.py writes from its parameters (run it to rewrite them):\n  "
                 + "\n  ".join(stale))


if __name__ == "__main__":
    main(sys.argv[1:])

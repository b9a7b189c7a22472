#!/usr/bin/env python3
"""Writes the wall meshes of the production scenes (launch/production/meshes/*.stl).

  python3 launch/production/make_meshes.py            # all of them but the large (LARGE below)
  python3 launch/production/make_meshes.py NAME ...   # only these (names as in MESHES below)

A mesh of several parts (a silo's hopper, side and bands) is written as NAME_PART.stl each.

Binary STL in metres. Every triangle is wound counter-clockwise seen from the particles' side,
so that its normal (b - a) x (c - a) points at the particles (docs/scene.md, [[walls]]).
Each mesh's parameters are the constants of its entry in MESHES; tests/production.rs checks
the committed files against them (triangle counts, extent, orientation).
"""
import math
import pathlib
import struct
import sys

HERE = pathlib.Path(__file__).resolve().parent


def ring(r, z, segments, phase=0.0):
    """Points of a regular polygon of circumradius r at height z, counter-clockwise from +x."""
    return [(r * math.cos(phase + 2 * math.pi * k / segments),
             r * math.sin(phase + 2 * math.pi * k / segments), z) for k in range(segments)]


def band(lower, upper):
    """Triangles joining two rings (lists of points, same length, counter-clockwise seen from
    +z), facing the axis: (up the wall) x (around) points inwards."""
    n = len(lower)
    tris = []
    for k in range(n):
        a, b = lower[k], lower[(k + 1) % n]
        c, d = upper[(k + 1) % n], upper[k]
        tris.append((a, d, c))
        tris.append((a, c, b))
    return tris


def ring_counts(r, size):
    """Points on each ring of `ring_disk`: ring k of m = ceil(r / size) has chords of about
    `size`, and at least 6 points."""
    m = max(1, math.ceil(r / size))
    return [max(6, round(2 * math.pi * r * k / m / size)) for k in range(1, m + 1)]


def join_rings(inner, outer):
    """Triangles between two concentric rings of any point counts, walking both by angle and
    always closing the triangle whose new point comes first (winding fixed by the caller)."""
    a, b = len(inner), len(outer)
    i = j = 0
    tris = []
    while i < a or j < b:
        if j == b or (i < a and (i + 1) / a < (j + 1) / b):
            tris.append((inner[i], inner[(i + 1) % a], outer[j % b]))
            i += 1
        else:
            tris.append((inner[i % a], outer[(j + 1) % b], outer[j]))
            j += 1
    return tris


def facing(tris, up):
    """The triangles wound so that their normals point up (+z) if `up`, else down."""
    out = []
    for t in tris:
        u = [t[1][k] - t[0][k] for k in range(3)]
        v = [t[2][k] - t[0][k] for k in range(3)]
        nz = u[0] * v[1] - u[1] * v[0]
        out.append(t if (nz > 0) == up else (t[0], t[2], t[1]))
    return out


def orifice_plate(outlet, hole, size):
    """An annular plate at z = 0, facing up, closing a hopper's outlet (diameter `outlet`; its
    outer polygon circumscribes 1.1 times the outlet's circle) but for a central hole of
    diameter `hole` (an inscribed polygon of chords about `size`: its area is within 1 % of
    the circle's), cut into triangles of about `size` by concentric rings."""
    r_in, r_out = hole / 2, 0.55 * outlet
    m = max(1, math.ceil((r_out - r_in) / size))
    radii = [r_in + (r_out - r_in) * k / m for k in range(m + 1)]
    counts = [max(24, round(2 * math.pi * rk / size)) for rk in radii]
    radii[-1] = radii[-1] / math.cos(math.pi / counts[-1]) * (1 + 1e-6)
    rings = [ring(rk, 0.0, n) for rk, n in zip(radii, counts)]
    tris = []
    for inner, outer in zip(rings, rings[1:]):
        tris += join_rings(inner, outer)
    return facing(tris, True)


def ring_disk(r, z, size, up=True):
    """A disk covering the circle of radius r at height z, cut into triangles of about `size`
    by concentric rings; the outermost ring's polygon circumscribes the circle, so the disk
    closes the polygon of any wall of radius r standing on it (a fan of that wall's segments
    would be slivers meeting at the centre, and a particle resting near it would touch dozens).
    Normal +z if `up`."""
    counts = ring_counts(r, size)
    m = len(counts)
    radii = [r * (k + 1) / m for k in range(m)]
    # 1e-6 beyond the circumscribing radius: the STL's single precision moves a vertex by up to
    # 6e-8 of its distance from the axis, and must not open a gap at the wall.
    radii[-1] = r / math.cos(math.pi / counts[-1]) * (1 + 1e-6)
    rings = [ring(rk, z, n) for rk, n in zip(radii, counts)]
    centre = (0.0, 0.0, z)
    tris = [(centre, rings[0][j], rings[0][(j + 1) % counts[0]]) for j in range(counts[0])]
    for inner, outer in zip(rings, rings[1:]):
        tris += join_rings(inner, outer)
    return facing(tris, up)


def tube(r, z0, z1, segments, rings):
    """Cylinder side of radius r from z0 to z1 in `rings` bands, facing the axis."""
    zs = [z0 + (z1 - z0) * i / rings for i in range(rings + 1)]
    tris = []
    for za, zb in zip(zs, zs[1:]):
        tris += band(ring(r, za, segments), ring(r, zb, segments))
    return tris


def rotate_x(tris, degrees):
    """Rotates about the x axis (right-handed): used to lay a z-axis drum along y."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    rot = lambda p: (p[0], c * p[1] - s * p[2], s * p[1] + c * p[2])
    return [tuple(rot(p) for p in t) for t in tris]


def translate(tris, d):
    return [tuple((p[0] + d[0], p[1] + d[1], p[2] + d[2]) for p in t) for t in tris]


# --- the meshes --------------------------------------------------------------------------------

def dodecahedra_cylinder():
    """Seed Sec. 3.3: a transparent cylinder of 10 cm inner diameter and 20 cm height, closed at
    the bottom (z = 0), open at the top; axis z. 96 segments: the flats lie within 54 um of the
    circle (r (1 - cos(pi/96))), 1/570 of the particle size. The floor is cut into triangles of
    about the dice's size (30 mm)."""
    r, h, n = 0.05, 0.20, 96
    return ring_disk(r, 0.0, 0.03, up=True) + tube(r, 0.0, h, n, 4)


def drum():
    """Seed Sec. 3.4, Table 3: a quasi-2D drum of diameter 0.30 m and thickness 11 mm, axis y
    through the origin, closed by its two end plates (y = -5.5 mm and +5.5 mm). 192 segments:
    the flats lie within 20 um of the circle and are 4.9 mm wide, half a particle. The end
    plates, on which every particle slides, are cut into triangles of about the particle's size
    (10 mm)."""
    r, w, n = 0.15, 0.011, 192
    # Built along z from -w/2 to w/2 (the side faces the axis, the plates face each other),
    # then turned -90 degrees about x, which takes +z to +y.
    side = tube(r, -w / 2, w / 2, n, 1)
    plates = ring_disk(r, -w / 2, 0.01, up=True) + ring_disk(r, w / 2, 0.01, up=False)
    return rotate_x(side + plates, -90.0)


def drum_twin():
    """The drum twin's drum (twins/drum.toml): the same 11 mm depth and 10 mm plate triangles,
    D = 0.10 m with 64 segments (flats 4.9 mm wide, as in the full drum)."""
    r, w, n = 0.05, 0.011, 64
    side = tube(r, -w / 2, w / 2, n, 1)
    plates = ring_disk(r, -w / 2, 0.01, up=True) + ring_disk(r, w / 2, 0.01, up=False)
    return rotate_x(side + plates, -90.0)


def fixed_bed_tube():
    """Seed Sec. 4.2: a reactor tube of 25 mm inner diameter and 1.80 m height, closed at the
    bottom (z = 0); axis z. 64 segments: the flats lie within 15 um of the circle (1/370 of the
    5.5 mm catalyst), 1.2 mm wide; 90 bands of 20 mm, so that a facet is no taller than about
    four particles. The floor is cut into triangles of about the pellet's size (5.5 mm)."""
    r, h, n = 0.0125, 1.80, 64
    return ring_disk(r, 0.0, 0.0055, up=True) + tube(r, 0.0, h, n, 90)


def fixed_bed_tube_twin():
    """The fixed-bed twin's tube (twins/fixed_bed.toml): the same 25 mm bore, 10 cm tall, with
    24 segments (flats 3.3 mm wide, within 0.1 mm of the circle) so that a pellet on the wall
    touches a few facets instead of a dozen: the twin runs in seconds."""
    r, h, n = 0.0125, 0.10, 24
    return ring_disk(r, 0.0, 0.0055, up=True) + tube(r, 0.0, h, n, 5)


def corrugated_silo(d, height, outlet, hopper_deg, pitch, depth, segments, per_pitch, hopper_rings,
                    bands=0):
    """Seed Sec. 4.1, Fig. 19: a silo of diameter d whose cylindrical side wall is corrugated
    horizontally (radius R + (depth/2) sin(2 pi (z - z_h) / pitch), a whole number of pitches,
    `per_pitch` rings each), above a conical hopper of half-angle `hopper_deg` from the vertical
    down to the outlet of diameter `outlet` at z = 0, which is open. Axis z; `segments` around.

    Returns the parts as walls: "hopper" and "side"; with `bands` > 0 the side's x > 0 half is
    cut into that many bands of equal height (whole pitches each), "band_00" from the bottom up,
    and the rest is "side_west" (x < 0): the net force on a half band is its normal load times
    2 R h whatever the corrugation (Janssen's wall stress, docs/production.md §4)."""
    r, r0 = d / 2, outlet / 2
    z_h = (r - r0) / math.tan(math.radians(hopper_deg))
    pitches = round((height - z_h) / pitch)
    a = depth / 2
    rings = pitches * per_pitch
    zs = [z_h + pitch * k / per_pitch for k in range(rings + 1)]
    radius = lambda z: r + a * math.sin(2 * math.pi * (z - z_h) / pitch)
    hopper = []
    for k in range(hopper_rings):
        f0, f1 = k / hopper_rings, (k + 1) / hopper_rings
        hopper += band(ring(r0 + (r - r0) * f0, z_h * f0, segments), ring(r0 + (r - r0) * f1, z_h * f1, segments))
    side = []
    for za, zb in zip(zs, zs[1:]):
        side.append(band(ring(radius(za), za, segments), ring(radius(zb), zb, segments)))
    if bands <= 0:
        return {"hopper": hopper, "side": [t for ring_tris in side for t in ring_tris]}
    assert segments % 4 == 0 and pitches % bands == 0, "halves on segment edges, bands on whole pitches"
    east = lambda t: sum(p[0] for p in t) > 0
    parts = {"hopper": hopper, "side_west": [t for rt in side for t in rt if not east(t)]}
    per_band = rings // bands
    for b in range(bands):
        parts[f"band_{b:02d}"] = [t for rt in side[b * per_band:(b + 1) * per_band] for t in rt if east(t)]
    return parts


# The seed's silo: 2.1 m across, 0.67 m outlet, 10.6 m tall. The hopper angle and the
# corrugation are not given: a 30 degree hopper (from the vertical) and the common corrugated
# silo sheet of 68 mm pitch and 13 mm depth, 8 rings per pitch and 68 segments, about 150 000
# facets as the seed's model has.
SILO = dict(d=2.1, height=10.6, outlet=0.67, hopper_deg=30.0, pitch=0.068, depth=0.013, segments=68,
            per_pitch=8, hopper_rings=10)
# The same silo at 1:4 (case 4b), its corrugation scaled with the grain instead (the grains are
# 0.64 of the seed's, so 43.5 mm pitch, 8.3 mm deep), its east half in 6 bands for Janssen.
SILO_QUARTER = dict(d=0.525, height=2.65, outlet=0.1675, hopper_deg=30.0, pitch=0.0435, depth=0.0083,
                    segments=48, per_pitch=6, hopper_rings=8, bands=6)
# The twin's silo: a narrow column (0.10 m, four grains across) on a flat 60 degree hopper
# with a 60 mm outlet (4 volume-equivalent grain diameters, so that it discharges), 0.45 m tall, corrugated at the twin grain's scale, its east half in 2 bands; small enough for
# a few hundred grains to stand 1.5 diameters deep, where the wall already carries weight.
SILO_TWIN = dict(d=0.10, height=0.45, outlet=0.06, hopper_deg=60.0, pitch=0.02, depth=0.004,
                 segments=24, per_pitch=4, hopper_rings=2, bands=2)


# Case 5: orifice plates under the 1:4 silo's hopper (outlet 0.1675 m) with holes of 4 ... 8
# volume-equivalent grain diameters (18.7 mm): Beverloo's law over outlet sizes. The hopper's
# own outlet is 9.0 d (open, no plate), and 10 d is the same hopper cut where it is that wide.
DISCHARGE_HOLES = [round(k * 0.0187, 4) for k in (4, 5, 6, 7, 8)]
DISCHARGE_CUT = round(10 * 0.0187, 4)


def cut_hopper(d, outlet, hopper_deg, segments, hopper_rings, cut, **_):
    """The conical hopper of `corrugated_silo` (same arguments) cut where it is `cut` wide: the
    same rings above that height, below it a first band from the cut up to the next ring. The
    silo's outlet widened without changing the cone the grains rest on (case 5's 10 d outlet)."""
    r, r0, rc = d / 2, outlet / 2, cut / 2
    assert r0 < rc < r, "the cut lies on the cone"
    t = math.tan(math.radians(hopper_deg))
    z_h = (r - r0) / t
    levels = [(rc, (rc - r0) / t)]
    levels += [(r0 + (r - r0) * k / hopper_rings, z_h * k / hopper_rings) for k in range(1, hopper_rings + 1)
               if z_h * k / hopper_rings > levels[0][1] + 1e-9]
    tris = []
    for (ra, za), (rb, zb) in zip(levels, levels[1:]):
        tris += band(ring(ra, za, segments), ring(rb, zb, segments))
    return tris


def silo_gate(outlet):
    """A disk closing the outlet at z = 0 from below, facing up: 10 % wider than the outlet."""
    return ring_disk(0.55 * outlet, 0.0, outlet / 8, up=True)


def heap_base(r, size):
    """A round base of radius r at z = 0, facing up, for a heap poured onto it (a fixed-base
    angle of repose: the heap grows until grains roll off the rim)."""
    return ring_disk(r, 0.0, size, up=True)


# m: the base of the 1:4 silo's grains' heap (make_scenes.py silo_grain_heap): 21 volume-
# equivalent grain diameters across; a cone of 40 degrees on it holds about 1 200 grains, so the
# 1 800 poured (make_scenes.py) fill it and spill over its rim.
HEAP_BASE = 0.2


MESHES = {
    "dodecahedra_cylinder": dodecahedra_cylinder,
    "drum": drum,
    "drum_twin": drum_twin,
    "fixed_bed_tube": fixed_bed_tube,
    "fixed_bed_tube_twin": fixed_bed_tube_twin,
    "silo": lambda: corrugated_silo(**SILO),
    "silo_gate": lambda: silo_gate(SILO["outlet"]),
    "silo_quarter": lambda: corrugated_silo(**SILO_QUARTER),
    "silo_quarter_gate": lambda: silo_gate(SILO_QUARTER["outlet"]),
    "silo_twin": lambda: corrugated_silo(**SILO_TWIN),
    "silo_twin_gate": lambda: silo_gate(SILO_TWIN["outlet"]),
    "silo_grain_heap_base": lambda: heap_base(HEAP_BASE, 0.02),
    "silo_quarter_orifice": lambda: {f"{round(1000 * h)}mm": orifice_plate(SILO_QUARTER["outlet"], h, 0.01)
                                     for h in DISCHARGE_HOLES},
    "silo_quarter_hopper": lambda: {f"{round(1000 * DISCHARGE_CUT)}mm": cut_hopper(cut=DISCHARGE_CUT, **SILO_QUARTER)},
}
# Written only when named: 7.6 MB, regenerated on demand (`make_meshes.py silo`).
LARGE = {"silo"}


def write_stl(path, tris, name):
    """Binary STL: 80-byte header, u32 count, then per triangle the normal, three vertices (f32)
    and a zero attribute word."""
    out = bytearray(name.encode()[:80].ljust(80, b" "))
    out += struct.pack("<I", len(tris))
    for a, b, c in tris:
        u = [b[i] - a[i] for i in range(3)]
        v = [c[i] - a[i] for i in range(3)]
        n = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
        ln = math.sqrt(sum(x * x for x in n)) or 1.0
        out += struct.pack("<3f", *(x / ln for x in n))
        for p in (a, b, c):
            out += struct.pack("<3f", *p)
        out += struct.pack("<H", 0)
    tmp = path.with_suffix(".stl.tmp")
    tmp.write_bytes(out)
    tmp.replace(path)


def main(names):
    folder = HERE / "meshes"
    folder.mkdir(exist_ok=True)
    for name in names or [m for m in MESHES if m not in LARGE]:
        if name not in MESHES:
            sys.exit(f"unknown mesh {name!r}: one of {', '.join(MESHES)}")
        made = MESHES[name]()
        parts = made.items() if isinstance(made, dict) else [(None, made)]
        for part, tris in parts:
            stem = f"{name}_{part}" if part else name
            write_stl(folder / f"{stem}.stl", tris, f"polydem {stem} (launch/production/make_meshes.py)")
            print(f"{folder / stem}.stl: {len(tris)} triangles")


if __name__ == "__main__":
    main(sys.argv[1:])

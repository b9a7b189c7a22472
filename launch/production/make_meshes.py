#!/usr/bin/env python3
"""Writes the wall meshes of the production scenes (launch/production/meshes/*.stl).

  python3 launch/production/make_meshes.py            # all of them
  python3 launch/production/make_meshes.py NAME ...   # only these (names as in MESHES below)

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


def disk(r, z, segments, up=True):
    """A fan of triangles closing the ring of radius r at height z; normal +z if `up`."""
    pts = ring(r, z, segments)
    centre = (0.0, 0.0, z)
    tris = []
    for k in range(segments):
        a, b = pts[k], pts[(k + 1) % segments]
        tris.append((centre, a, b) if up else (centre, b, a))
    return tris


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
    circle (r (1 - cos(pi/96))), 1/570 of the particle size."""
    r, h, n = 0.05, 0.20, 96
    return disk(r, 0.0, n, up=True) + tube(r, 0.0, h, n, 4)


def drum():
    """Seed Sec. 3.4, Table 3: a quasi-2D drum of diameter 0.30 m and thickness 11 mm, axis y
    through the origin, closed by its two end plates (y = -5.5 mm and +5.5 mm). 192 segments:
    the flats lie within 20 um of the circle and are 4.9 mm wide, half a particle."""
    r, w, n = 0.15, 0.011, 192
    # Built along z from -w/2 to w/2 (the side faces the axis, the plates face each other),
    # then turned -90 degrees about x, which takes +z to +y.
    side = tube(r, -w / 2, w / 2, n, 1)
    plates = disk(r, -w / 2, n, up=True) + disk(r, w / 2, n, up=False)
    return rotate_x(side + plates, -90.0)


def fixed_bed_tube():
    """Seed Sec. 4.2: a reactor tube of 25 mm inner diameter and 1.80 m height, closed at the
    bottom (z = 0); axis z. 64 segments: the flats lie within 15 um of the circle (1/370 of the
    5.5 mm catalyst), 1.2 mm wide; 90 bands of 20 mm, so that a facet is no taller than about
    four particles."""
    r, h, n = 0.0125, 1.80, 64
    return disk(r, 0.0, n, up=True) + tube(r, 0.0, h, n, 90)


def fixed_bed_tube_twin():
    """The fixed-bed twin's tube (twins/fixed_bed.toml): the same 25 mm bore, 10 cm tall, with
    24 segments (flats 3.3 mm wide, within 0.1 mm of the circle) so that a pellet on the wall
    touches a few facets instead of a dozen: the twin runs in seconds."""
    r, h, n = 0.0125, 0.10, 24
    return disk(r, 0.0, n, up=True) + tube(r, 0.0, h, n, 5)


MESHES = {
    "dodecahedra_cylinder": dodecahedra_cylinder,
    "drum": drum,
    "fixed_bed_tube": fixed_bed_tube,
    "fixed_bed_tube_twin": fixed_bed_tube_twin,
}


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
    for name in names or MESHES:
        if name not in MESHES:
            sys.exit(f"unknown mesh {name!r}: one of {', '.join(MESHES)}")
        tris = MESHES[name]()
        write_stl(folder / f"{name}.stl", tris, f"polydem {name} (launch/production/make_meshes.py)")
        print(f"{folder / name}.stl: {len(tris)} triangles")


if __name__ == "__main__":
    main(sys.argv[1:])

#!/usr/bin/env python3
"""Independent oracle for `polydem probe overlap`: the overlap volume (and centroid) of each pair
by Manifold's exact mesh Booleans on the two convex hulls.

    manifold_overlap.py INPUT.json > REFERENCE.jsonl

INPUT.json is a `polydem probe overlap` input file (see src/probe.rs). Every shape is turned into
points in its input coordinates *here*, without polydem: "vertices" lists as given, "mesh" files
(binary/ASCII STL, OBJ; relative paths are relative to INPUT.json's folder) read with numpy, and
"generator" solids built from their documented definitions (src/shape/generators.rs: golden-ratio
coordinates scaled to the circumscribed diameter `size`). A pair's world points are
`R(q) v + position` (q = [w, x, y, z], normalised), with no re-centring, and the reference is

    V = (Manifold.hull_points(A) ^ Manifold.hull_points(B)).volume()

One JSON line per pair, in input order:
    {"volume": V, "volume_a": |A|, "volume_b": |B|, "centroid": [x, y, z] or null,
     "area": surface area of A ∩ B, "extent": diagonal of its bounding box}
The centroid is that of the intersection mesh (signed tetrahedra on Manifold's f64 mesh).
"""

import json
import os
import struct
import sys

import numpy as np

try:
    import manifold3d
except ImportError as e:  # pragma: no cover - the message is the point
    sys.exit(
        f"manifold_overlap.py: {e}. This oracle needs the packages of python/requirements.txt; "
        "run `make test` (it creates .venv), or set POLYDEM_PYTHON to a Python that has them."
    )

PHI = (1.0 + 5.0**0.5) / 2.0


def _signs3(a, b, c):
    return [[sx * a, sy * b, sz * c] for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)]


def _cyclic(a, b, c):
    out = []
    for sb in (1, -1):
        for sc in (1, -1):
            p = [a, sb * b, sc * c]
            out += [p, [p[2], p[0], p[1]], [p[1], p[2], p[0]]]
    return out


def generator_points(name, size):
    """The regular solid `name` with circumscribed diameter `size`, in polydem's orientation."""
    name = name.strip().lower()
    if name == "tetrahedron":
        pts = [[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]
    elif name == "cube":
        pts = _signs3(1, 1, 1)
    elif name == "octahedron":
        pts = [[s if k == j else 0 for j in range(3)] for k in range(3) for s in (1, -1)]
    elif name == "dodecahedron":
        pts = _signs3(1, 1, 1) + _cyclic(0.0, 1.0 / PHI, PHI)
    elif name == "icosahedron":
        pts = _cyclic(0.0, 1.0, PHI)
    else:
        raise ValueError(f"unknown generator {name!r}")
    pts = np.array(pts, dtype=float)
    # Scale so that the circumscribed radius (all vertices are equidistant) is size / 2.
    return pts * (size / 2.0 / np.linalg.norm(pts[0]))


def mesh_points(path):
    """Vertex coordinates of an STL (binary or ASCII) or OBJ file, as float64."""
    with open(path, "rb") as f:
        data = f.read()
    if path.lower().endswith(".obj"):
        rows = [
            line.split()[1:4]
            for line in data.decode("utf-8", "replace").splitlines()
            if line.startswith("v ")
        ]
        return np.array(rows, dtype=float)
    if len(data) >= 84:
        (n,) = struct.unpack_from("<I", data, 80)
        if len(data) == 84 + 50 * n:
            rec = np.frombuffer(data, dtype=np.uint8, count=50 * n, offset=84).reshape(n, 50)
            tri = rec[:, 12:48].copy().view("<f4").reshape(n * 3, 3)
            return tri.astype(np.float64)
    rows = [
        line.split()[1:4]
        for line in data.decode("ascii", "replace").splitlines()
        if line.strip().startswith("vertex")
    ]
    if not rows:
        raise ValueError(f"{path}: neither binary nor ASCII STL")
    return np.array(rows, dtype=float)


def shape_points(spec, base):
    if "vertices" in spec:
        return np.array(spec["vertices"], dtype=float)
    if "mesh" in spec:
        return mesh_points(os.path.join(base, spec["mesh"]))
    if "generator" in spec:
        return generator_points(spec["generator"], float(spec["size"]))
    raise ValueError(f"unknown shape spec {spec}")


def rotation(q):
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def world(points, pose):
    return points @ rotation(pose["orientation"]).T + np.asarray(pose["position"], dtype=float)


def centroid(m):
    """Volume centroid of a closed manifold, from its f64 mesh by signed tetrahedra."""
    mesh = m.to_mesh64()
    v = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    t = np.asarray(mesh.tri_verts, dtype=np.int64)
    if len(t) == 0:
        return None
    o = v.mean(axis=0)  # reference point inside: keeps the tetrahedra well conditioned
    a, b, c = v[t[:, 0]] - o, v[t[:, 1]] - o, v[t[:, 2]] - o
    vol = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    total = vol.sum()
    if total <= 0.0:
        return None
    return ((a + b + c) * (vol / 4.0)[:, None]).sum(axis=0) / total + o


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    path = sys.argv[1]
    with open(path) as f:
        inp = json.load(f)
    base = os.path.dirname(os.path.abspath(path))
    points = {name: shape_points(spec, base) for name, spec in inp["shapes"].items()}
    out = sys.stdout
    for pair in inp["pairs"]:
        a = manifold3d.Manifold.hull_points(world(points[pair["a"]], pair["pose_a"]))
        b = manifold3d.Manifold.hull_points(world(points[pair["b"]], pair["pose_b"]))
        inter = a ^ b
        vol = inter.volume()
        c = centroid(inter) if vol > 0.0 else None
        box = np.asarray(inter.bounding_box(), dtype=float) if vol > 0.0 else np.zeros(6)
        row = {
            "volume": vol,
            "volume_a": a.volume(),
            "volume_b": b.volume(),
            "centroid": None if c is None else [float(x) for x in c],
            "area": inter.surface_area() if vol > 0.0 else 0.0,
            "extent": float(np.linalg.norm(box[3:] - box[:3])),
        }
        out.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()

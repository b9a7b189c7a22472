#!/usr/bin/env python3
"""Independent oracle for `polydem probe wall`: per triangle facet, the area and centroid of the
particle's section by the facet plane clipped to the triangle (shapely), and the penetrating
volume, the particle ∩ the half-infinite prism behind the triangle (Manifold).

    shapely_wall.py INPUT.json > REFERENCE.jsonl

INPUT.json is a `polydem probe wall` input file (see src/probe.rs); shapes are read and placed as
in manifold_overlap.py (`R(q) v + position`, no polydem involved). For each facet with corners
a, b, c (counter-clockwise seen from the particle's side, so n = (b − a) × (c − a) / |…| points
towards the particle):

- section: the plane n·x = n·a cuts the hull of the world points P in the convex polygon
  conv{ p + s (q − p) : p, q in P on opposite sides, s = the crossing parameter } (every point of
  a segment between two points of a convex set lies in it, and the polygon's corners lie on
  hull edges, which are such segments). It is expressed in 2D plane coordinates and intersected
  with the triangle by shapely.
- volume: (Manifold.hull_points(P) ^ Manifold.hull_points(triangle ∪ (triangle − L n))).volume(),
  L long enough for the prism to reach through the particle.

One JSON line per case, in input order:
    {"volume_shape": |P|, "facets": [{"area": a, "centroid": [x, y, z] or null, "volume": v}, ...]}
"""

import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from manifold_overlap import manifold3d, shape_points, world  # noqa: E402

try:
    from shapely.geometry import MultiPoint, Polygon
except ImportError as e:  # pragma: no cover
    sys.exit(
        f"shapely_wall.py: {e}. Run `make test` (it creates .venv), or set POLYDEM_PYTHON to a "
        "Python with python/requirements.txt installed."
    )


def plane_basis(n):
    """Unit vectors u, w with u × w = n."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(helper, n)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def section(points, n, h):
    """Corners (3D) of the polygon {x in hull(points) : n·x = h}, possibly empty."""
    d = points @ n - h
    above, below = points[d > 0], points[d < 0]
    da, db = d[d > 0], d[d < 0]
    on = [points[d == 0]]
    if len(above) and len(below):
        # For every pair (p above, q below): p + s (q - p) with s = d_p / (d_p - d_q).
        s = da[:, None] / (da[:, None] - db[None, :])
        x = above[:, None, :] + s[:, :, None] * (below[None, :, :] - above[:, None, :])
        on.append(x.reshape(-1, 3))
    return np.concatenate(on)


def facet(points, hull_m, tri):
    a, b, c = (np.asarray(p, dtype=float) for p in tri)
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n)
    u, w = plane_basis(n)
    to2d = lambda x: np.stack([(x - a) @ u, (x - a) @ w], axis=-1)  # noqa: E731
    triangle = Polygon(to2d(np.array([a, b, c])))
    corners = section(points, n, n @ a)
    area, cen = 0.0, None
    if len(corners) >= 3:
        poly = MultiPoint([tuple(p) for p in to2d(corners)]).convex_hull
        clipped = poly.intersection(triangle)
        area = clipped.area
        if area > 0.0:
            cx, cy = clipped.centroid.x, clipped.centroid.y
            cen = [float(v) for v in a + cx * u + cy * w]
    # Long enough to reach through the particle's far side: distance to the plane + diameter.
    centre = points.mean(axis=0)
    length = abs(n @ (a - centre)) + 2.5 * np.max(np.linalg.norm(points - centre, axis=1))
    prism = manifold3d.Manifold.hull_points(np.array([a, b, c, a - length * n, b - length * n, c - length * n]))
    vol = (hull_m ^ prism).volume()
    return {"area": area, "centroid": cen, "volume": vol}


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    path = sys.argv[1]
    with open(path) as f:
        inp = json.load(f)
    base = os.path.dirname(os.path.abspath(path))
    points = {name: shape_points(spec, base) for name, spec in inp["shapes"].items()}
    for case in inp["cases"]:
        p = world(points[case["shape"]], case["pose"])
        p = np.unique(p, axis=0)  # STL files repeat each corner in every triangle
        hull_m = manifold3d.Manifold.hull_points(p)
        facets = [facet(p, hull_m, t) for t in case["triangles"]]
        print(json.dumps({"volume_shape": hull_m.volume(), "facets": facets}))


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Independent reader for polydem's VTK output (src/io/vtk.rs), used by tests/io_output.rs.

    read_vtu.py mesh FILE.vtu          one piece, read with meshio
    read_vtu.py collection FILE.pvd    a collection: its DataSets, and each .pvtu's pieces

Prints one JSON object. Floats of cell data are given as their IEEE-754 bit patterns (uint64)
so that the test can compare them exactly; points are given as floats (Python's repr
round-trips, but the test compares them to its own rotation with a tolerance anyway).

mesh:
    {"points": [[x, y, z], ...],
     "blocks": [{"type": "polyhedron20", "cells": [[[p, ...] per face] per cell]}, ...],
     "cell_data": {name: [[value or [components]] per cell, concatenated over blocks]}}
collection:
    {"datasets": [{"timestep": t, "file": f, "pieces": [source, ...] or null,
                   "cell_arrays": [name, ...] or null, "cells": total cells read by meshio}]}
"""

import json
import os
import sys
import xml.etree.ElementTree as ET

import numpy as np

try:
    import meshio
except ImportError as e:  # pragma: no cover - the message is the point
    sys.exit(f"read_vtu.py needs meshio (python/requirements.txt; `make test` installs it): {e}")


def exact(a):
    """Cell data as JSON-exact values: float bits as uint64, integers as ints."""
    a = np.asarray(a)
    if a.dtype.kind == "f":
        a = np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)
    return a.tolist()


def declared_cells(path):
    """NumberOfCells summed over the file's pieces."""
    root = ET.parse(path).getroot()
    return sum(int(p.get("NumberOfCells")) for p in root.iter("Piece"))


def mesh(path):
    if declared_cells(path) == 0:
        # meshio 5.3.5 cannot read a grid without cells (IndexError in vtk_cells_from_data);
        # an empty rank piece is valid VTK, so report it as the empty mesh it declares.
        return {"points": [], "blocks": [], "cell_data": {}}
    m = meshio.read(path)
    blocks = []
    for b in m.cells:
        if b.type.startswith("polyhedron"):
            cells = [[np.asarray(f).tolist() for f in cell] for cell in b.data]
        else:
            cells = np.asarray(b.data).tolist()
        blocks.append({"type": b.type, "cells": cells})
    cell_data = {}
    for name, per_block in m.cell_data.items():
        values = []
        for d in per_block:
            values.extend(exact(d))
        cell_data[name] = values
    return {"points": m.points.tolist(), "blocks": blocks, "cell_data": cell_data}


def cell_count(path):
    if declared_cells(path) == 0:
        return 0  # see mesh()
    return sum(len(b.data) for b in meshio.read(path).cells)


def collection(path):
    root = ET.parse(path).getroot()
    assert root.tag == "VTKFile" and root.get("type") == "Collection", root.attrib
    base = os.path.dirname(path)
    out = []
    for ds in root.iter("DataSet"):
        f = ds.get("file")
        full = os.path.join(base, f)
        entry = {"timestep": float(ds.get("timestep")), "file": f}
        if f.endswith(".pvtu"):
            p = ET.parse(full).getroot()
            assert p.get("type") == "PUnstructuredGrid", p.attrib
            grid = p.find("PUnstructuredGrid")
            pieces = [piece.get("Source") for piece in grid.findall("Piece")]
            entry["pieces"] = pieces
            entry["cell_arrays"] = [a.get("Name") for a in grid.find("PCellData")]
            pdir = os.path.dirname(full)
            entry["cells"] = sum(cell_count(os.path.join(pdir, s)) for s in pieces)
        else:
            entry["pieces"] = None
            entry["cell_arrays"] = None
            entry["cells"] = cell_count(full)
        out.append(entry)
    return {"datasets": out}


def main():
    if len(sys.argv) != 3 or sys.argv[1] not in ("mesh", "collection"):
        sys.exit(__doc__)
    mode, path = sys.argv[1], sys.argv[2]
    result = mesh(path) if mode == "mesh" else collection(path)
    json.dump(result, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()

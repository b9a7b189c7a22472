#!/usr/bin/env python3
"""Readable summary of `polydem probe` output, for `make run`.

    probe_report.py overlap INPUT.json OUTPUT.jsonl
    probe_report.py wall    INPUT.json OUTPUT.jsonl

INPUT.json is the file given to `polydem probe`, OUTPUT.jsonl what it printed (one JSON object
per pair or case, in input order). Uses only the standard library.
"""

import json
import sys


def vec(v, fmt="{:+.4f}"):
    if v is None:
        return "-"
    return "(" + ", ".join(fmt.format(x) for x in v) + ")"


def shape_label(shapes, name):
    spec = shapes[name]
    if "generator" in spec:
        return f"{name} [{spec['generator']} {spec['size']:g}]"
    if "mesh" in spec:
        return f"{name} [{spec['mesh'].rsplit('/', 1)[-1]}]"
    return f"{name} [{len(spec['vertices'])} vertices]"


def overlap(inp, results):
    for i, (pair, r) in enumerate(zip(inp["pairs"], results)):
        a = shape_label(inp["shapes"], pair["a"])
        b = shape_label(inp["shapes"], pair["b"])
        print(f"  pair {i}: A = {a}, B = {b}")
        if r["volume"] > 0:
            print(
                f"    overlap volume {r['volume']:.6e}, contact area {r['area']:.6e},"
                f" normal A->B {vec(r['normal'])}"
            )
            print(f"    dV/dx_B {vec(r['dv_dxb'], '{:+.4e}')}, centroid {vec(r['centroid'], '{:+.6g}')}")
        else:
            state = "touching" if r["intersects"] else "separated"
            print(f"    no overlap ({state})")


def wall(inp, results):
    for i, (case, r) in enumerate(zip(inp["cases"], results)):
        s = shape_label(inp["shapes"], case["shape"])
        print(f"  case {i}: {s} on {len(case['triangles'])} triangles")
        print(f"    section area {r['area']:.6e}, penetrating volume {r['volume']:.6e}")
        areas = ", ".join(f"{f['area']:.4g}" for f in r["facets"])
        print(f"    per-triangle areas: {areas}")
        grad = [sum((f["dv_dx"] or [0, 0, 0])[k] for f in r["facets"]) for k in range(3)]
        print(f"    dV/dx summed over the wall {vec(grad, '{:+.4e}')}")


def main():
    if len(sys.argv) != 4 or sys.argv[1] not in ("overlap", "wall"):
        sys.exit(__doc__)
    with open(sys.argv[2]) as f:
        inp = json.load(f)
    with open(sys.argv[3]) as f:
        results = [json.loads(line) for line in f if line.strip()]
    n = len(inp["pairs" if sys.argv[1] == "overlap" else "cases"])
    if len(results) != n:
        sys.exit(f"{sys.argv[3]}: {len(results)} results for {n} inputs")
    (overlap if sys.argv[1] == "overlap" else wall)(inp, results)


if __name__ == "__main__":
    main()

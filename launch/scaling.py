#!/usr/bin/env python3
"""Strong and weak scaling of polydem over MPI ranks: runs `polydem bench` under mpirun for
each rank count, writes one CSV row per run and an SVG plot of speed-up and efficiency.

    launch/scaling.py SCENE --ranks 1 2 4 [--weak] [--steps 50] [--warmup 10] [--out DIR]

Strong scaling runs SCENE as it is on every rank count. Weak scaling (--weak) gives each rank
the work of SCENE: the domain, the insertion regions and their counts are repeated N times
along x (meant for lattice scenes such as launch/bench/*.toml, whose lattice then continues
unchanged), written to DIR/weak_N.toml.

CSV columns: mode, ranks, particles, steps, wall_seconds, particle_steps_per_second, speedup,
efficiency, and per rank the largest halo exchange, migration, balancing and waiting seconds
(waiting at the step's first collective is the load imbalance), and the particle imbalance
(most particles on one rank / mean). Needs only Python's standard library, mpirun and the
built binary (POLYDEM_BIN, default target/release/polydem).
"""

import argparse
import csv
import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {v!r} as TOML")


def toml_dump(doc):
    """A scene as TOML: top-level keys, then tables (one level of sub-tables), then arrays of
    tables; nested values inline."""
    out = [f"{k} = {toml_value(v)}" for k, v in doc.items() if not isinstance(v, (dict, list))
           or (isinstance(v, list) and not (v and isinstance(v[0], dict)))]
    for k, v in doc.items():
        if isinstance(v, dict):
            out.append(f"\n[{k}]")
            subs = []
            for kk, vv in v.items():
                if isinstance(vv, dict):
                    subs.append((kk, vv))
                else:
                    out.append(f"{kk} = {toml_value(vv)}")
            for kk, vv in subs:
                out.append(f"\n[{k}.{kk}]")
                out.extend(f"{a} = {toml_value(b)}" for a, b in vv.items())
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for item in v:
                out.append(f"\n[[{k}]]")
                out.extend(f"{a} = {toml_value(b)}" for a, b in item.items())
    return "\n".join(out) + "\n"


def weak_scene(base: Path, n: int, out: Path) -> Path:
    doc = tomllib.loads(base.read_text())
    here = base.parent
    lx = doc["domain"]["max"][0] - doc["domain"]["min"][0]
    doc["domain"]["max"][0] = doc["domain"]["min"][0] + n * lx
    for ins in doc.get("insertions", []):
        r = ins["region"]
        if r.get("kind") != "box":
            sys.exit(f"{base}: weak scaling repeats box regions only")
        r["max"][0] = r["min"][0] + n * (r["max"][0] - r["min"][0])
        if "count" in ins:
            ins["count"] *= n
        if "total" in ins:
            ins["total"] *= n
    for t in doc.get("particle_types", []) + doc.get("walls", []):
        if "mesh" in t:
            t["mesh"] = str((here / t["mesh"]).resolve())
    doc.setdefault("output", {})["dir"] = str(out / f"weak_{n}_out")
    path = out / f"weak_{n}.toml"
    path.write_text(toml_dump(doc))
    return path


def bench(scene: Path, ranks: int, steps: int, warmup: int, cores: int) -> dict:
    binary = os.environ.get("POLYDEM_BIN", str(ROOT / "target/release/polydem"))
    env = dict(os.environ)
    env.setdefault("RAYON_NUM_THREADS", str(max(1, cores // ranks)))
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    env.setdefault("RUST_LOG", "warn")
    cmd = ["mpirun", "--oversubscribe", "-n", str(ranks), "-x", "RAYON_NUM_THREADS",
           binary, "bench", str(scene), "--backend", env.get("POLYDEM_BACKEND", "cpu"),
           "--steps", str(steps), "--warmup", str(warmup)]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{done.stderr}")
    return json.loads(done.stdout)


def row(mode, ranks, report, base_rate, base_ranks):
    rate = report["particle_steps_per_second"]
    per_rank = (report.get("parallel") or {}).get("per_rank") or []

    def worst(key):
        return max((r["decomposition_seconds"][key] for r in per_rank), default=0.0)

    counts = [r["particles"] for r in per_rank] or [report["particles"]]
    # Particle-steps per second against the first run's: ideally in proportion to the ranks,
    # in strong scaling (same particles) and weak scaling (same particles per rank) alike.
    speedup = rate / base_rate
    eff = speedup * base_ranks / ranks
    return {
        "mode": mode, "ranks": ranks, "particles": report["particles"],
        "steps": report["steps"], "wall_seconds": report["wall_seconds"],
        "particle_steps_per_second": rate, "speedup": speedup, "efficiency": eff,
        "halo_seconds": worst("halo"), "migrate_seconds": worst("migrate"),
        "balance_seconds": worst("balance"), "wait_seconds": worst("wait"),
        "particle_imbalance": max(counts) / (sum(counts) / len(counts)),
    }


def svg_plot(rows, path: Path):
    """Speed-up against ranks (ideal dashed) and efficiency, one panel each."""
    W, H, M = 720, 320, 50
    ranks = sorted({r["ranks"] for r in rows})
    rmax = max(ranks)
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" '
             f'font-family="sans-serif" font-size="12">']
    for panel, (key, ymax, title) in enumerate(
            [("speedup", max([rmax] + [r["speedup"] for r in rows]) * 1.1, "speed-up"),
             ("efficiency", 1.2, "parallel efficiency")]):
        x0 = panel * W / 2 + M
        w, h = W / 2 - 1.5 * M, H - 2 * M

        def X(r):
            return x0 + (r - 1) / max(rmax - 1, 1) * w

        def Y(v):
            return M + h - v / ymax * h

        parts.append(f'<rect x="{x0}" y="{M}" width="{w}" height="{h}" fill="none" stroke="#444"/>')
        parts.append(f'<text x="{x0 + w / 2}" y="{M - 12}" text-anchor="middle">{title}</text>')
        parts.append(f'<text x="{x0 + w / 2}" y="{H - 12}" text-anchor="middle">ranks</text>')
        for r in ranks:
            parts.append(f'<text x="{X(r)}" y="{M + h + 15}" text-anchor="middle">{r}</text>')
        for k in range(5):
            v = ymax * k / 4
            parts.append(f'<text x="{x0 - 6}" y="{Y(v) + 4}" text-anchor="end">{v:.2g}</text>')
        ideal = [(1, 1), (rmax, rmax)] if key == "speedup" else [(1, 1), (rmax, 1)]
        parts.append(f'<line x1="{X(ideal[0][0])}" y1="{Y(ideal[0][1])}" x2="{X(ideal[1][0])}" '
                     f'y2="{Y(ideal[1][1])}" stroke="#999" stroke-dasharray="4 3"/>')
        for mode, colour in [("strong", "#1f77b4"), ("weak", "#d62728")]:
            pts = sorted((r["ranks"], r[key]) for r in rows if r["mode"] == mode)
            if not pts:
                continue
            d = " ".join(f"{X(a):.1f},{Y(b):.1f}" for a, b in pts)
            parts.append(f'<polyline points="{d}" fill="none" stroke="{colour}" stroke-width="2"/>')
            for a, b in pts:
                parts.append(f'<circle cx="{X(a):.1f}" cy="{Y(b):.1f}" r="3" fill="{colour}"/>')
            parts.append(f'<text x="{x0 + 8}" y="{M + 16 + 14 * (mode == "weak")}" '
                         f'fill="{colour}">{mode}</text>')
    parts.append("</svg>")
    path.write_text("\n".join(parts) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", type=Path)
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--weak", action="store_true")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--warmup", type=int, default=10)
    ap.add_argument("--out", type=Path, default=ROOT / "out/scaling")
    ap.add_argument("--cores", type=int, default=os.cpu_count())
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    mode = "weak" if a.weak else "strong"
    rows, base = [], None
    for n in a.ranks:
        scene = weak_scene(a.scene.resolve(), n, a.out.resolve()) if a.weak else a.scene
        report = bench(scene, n, a.steps, a.warmup, a.cores)
        if base is None:
            base = (report["particle_steps_per_second"], n)
        rows.append(row(mode, n, report, *base))
        print(json.dumps(rows[-1]), flush=True)
    csv_path = a.out / f"{mode}.csv"
    with open(csv_path, "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=list(rows[0]))
        wr.writeheader()
        wr.writerows(rows)
    svg_plot(rows, a.out / f"{mode}.svg")
    print(f"wrote {csv_path} and {a.out / (mode + '.svg')}")


if __name__ == "__main__":
    main()

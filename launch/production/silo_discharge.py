#!/usr/bin/env python3
"""Case 5 (docs/production.md §5): silo discharge through orifices of several sizes, mass
against time and Beverloo's law.

  python3 launch/production/silo_discharge.py OUT.svg D0[@Z]:FRAMES ... --grain-mass M
      --bulk-density RHO_B --d D [--window auto | T0,T1] [--above Z] [--fit-max D0]

Each FRAMES is a run's particle tables (`<output.dir>/particles`, step_<step>[_r<rank>].csv),
the grains left at each frame being its rows whose centre lies above Z (default: every row; the
orifice plate's height counts a grain out as it passes the hole, not when it falls out of the
domain; `D0@Z` sets that run's own Z, for an outlet at another height), or a text file of "time
grains" lines already counted (Z does not apply). Several runs of one D0 (starts from different
beds) are several points of the fit and are also summarised together.

The steady window of each run is found from its data (`--window auto`, the default): the flow
out between frames is a series whose start-up is a transient, and the window starts where the
Marginal Standard Error Rule puts the end of that transient (White, Simulation 69 (1997)
323-334): at the frame d, among the first half, that minimises the squared standard error of the
mean of the increments after it, sum((x_i - mean)^2) / (n - d)^2. `--window T0,T1` fixes it
instead. The discharge rate W (kg/s) is the least-squares slope of the mass left over the window;
its standard error is that of the mean flow per frame over the window (the frames' scatter, which
carries the flow's bursts), and at least one grain over the window. An orifice with no flow
(jammed) is reported and left out of the fit, and so are those wider than --fit-max (tabled
against the law fitted to the others). Beverloo's law

  W = C rho_b sqrt(g) (D0 - k d)^(5/2)

is fitted as the straight line W^(2/5) = (C rho_b sqrt(g))^(2/5) (D0 - k d), weighted by each
rate's error: C from its slope and k from where it crosses zero, with 68 % and 95 % intervals
from a parametric bootstrap (each W redrawn from its error, 20 000 times, fixed seed; the errors
first scaled by the root of chi^2 per degree of freedom where the rates scatter about the law by
more than they allow). d is the
law's grain size as given (state which: the scenes use the volume-equivalent diameter). Prints
the table and the fit, and plots the mass discharged against time and W against D0 with the
fitted law.
"""
import argparse
import collections
import math
import os
import random
import sys

G = 9.81


def counts(frames, above=-math.inf):
    """(time, grains) per frame, in time order: rows of every rank's table of a step whose z
    (the table's fifth column) exceeds `above`."""
    if os.path.isfile(frames):
        with open(frames) as fh:
            return sorted((float(t), int(n)) for t, n in (line.split() for line in fh if line.strip()))
    by_step = collections.defaultdict(list)
    for name in os.listdir(frames):
        if name.startswith("step_") and name.endswith(".csv"):
            by_step[name[5:-4].split("_r")[0]].append(os.path.join(frames, name))
    out = []
    for step, files in by_step.items():
        n, t = 0, None
        for f in files:
            with open(f) as fh:
                next(fh)
                for line in fh:
                    if line.strip():
                        cols = line.split(",", 5)
                        if float(cols[4]) > above:
                            n += 1
                        if t is None:
                            t = float(cols[0])
        if t is not None:
            out.append((t, n))
    return sorted(out)


def slope(xs, ys):
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    sxx = sum((x - mx) ** 2 for x in xs)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx, my - mx * sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx


def steady_start(series):
    """Index of the first frame of the steady window of `series` ((time, grains) in time order):
    the Marginal Standard Error Rule on the grains out between frames, over the first half."""
    flow = [n0 - n1 for (_, n0), (_, n1) in zip(series, series[1:])]
    best, start = math.inf, 0
    for d in range(len(flow) // 2 + 1):
        rest = flow[d:]
        mean = sum(rest) / len(rest)
        mser = sum((x - mean) ** 2 for x in rest) / len(rest) ** 2
        if mser < best:
            best, start = mser, d
    return start


def rate_error(win, grain_mass):
    """Standard error (kg/s) of the rate over the frames `win` ((time, mass left) in order): that
    of the mean flow per frame, and at least one grain over the window."""
    flows = [(m0 - m1) / (t1 - t0) for (t0, m0), (t1, m1) in zip(win, win[1:])]
    n = len(flows)
    mean = sum(flows) / n
    sd = math.sqrt(sum((f - mean) ** 2 for f in flows) / (n - 1)) if n > 1 else 0.0
    return max(sd / math.sqrt(n), grain_mass / (win[-1][0] - win[0][0]))


def weighted_line(xs, ys, sigmas):
    """Weighted least-squares line y = s x + b: (s, b)."""
    w = [1.0 / (e * e) for e in sigmas]
    sw = sum(w)
    mx = sum(wi * x for wi, x in zip(w, xs)) / sw
    my = sum(wi * y for wi, y in zip(w, ys)) / sw
    sxx = sum(wi * (x - mx) ** 2 for wi, x in zip(w, xs))
    s = sum(wi * (x - mx) * (y - my) for wi, x, y in zip(w, xs, ys)) / sxx
    return s, my - s * mx


def beverloo_fit(rows, rho_b, d, draws=0):
    """C and k of the rows' (d0, w, err) by the weighted line of W^(2/5) on D0; with `draws`,
    also the bootstrap samples of (C, k), each W redrawn from its error (seeded)."""
    def fit(ws):
        xs = [r["d0"] for r in rows]
        ys = [max(w, 0.0) ** 0.4 for w in ws]
        es = [0.4 * max(w, 1e-12) ** -0.6 * r["err"] for w, r in zip(ws, rows)]
        s, b = weighted_line(xs, ys, es)
        if s <= 0:
            return None
        return s ** 2.5 / (rho_b * math.sqrt(G)), -b / s / d
    c, k = fit([r["w"] for r in rows])
    # Rates that scatter about the law by more than their errors say (chi^2 per degree of
    # freedom above 1) have errors too small for the fit: they are scaled up by its root (the
    # Birge ratio) before the bootstrap, so that the intervals carry the scatter too.
    law = lambda d0: c * rho_b * math.sqrt(G) * max(d0 - k * d, 0.0) ** 2.5
    chi2 = sum(((r["w"] ** 0.4 - law(r["d0"]) ** 0.4) / (0.4 * r["w"] ** -0.6 * r["err"])) ** 2
               for r in rows)
    dof = len(rows) - 2
    birge = math.sqrt(chi2 / dof) if dof > 0 and chi2 > dof else 1.0
    rng = random.Random(2024)
    samples = []
    for _ in range(draws):
        one = fit([max(rng.gauss(r["w"], birge * r["err"]), 1e-9) for r in rows])
        if one:
            samples.append(one)
    return c, k, samples, chi2, dof, birge


def interval(values, level):
    v = sorted(values)
    lo = v[int((1 - level) / 2 * (len(v) - 1))]
    hi = v[int((1 + level) / 2 * (len(v) - 1))]
    return lo, hi


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("svg")
    ap.add_argument("runs", nargs="+", help="D0[@Z]:FRAMES")
    ap.add_argument("--grain-mass", type=float, required=True)
    ap.add_argument("--bulk-density", type=float, required=True)
    ap.add_argument("--d", type=float, required=True, help="grain diameter of the law (m)")
    ap.add_argument("--window", default="auto",
                    help="auto (the steady window found from each run) or T0,T1 (s)")
    ap.add_argument("--above", type=float, default=-math.inf,
                    help="count a grain while its centre is above this height (m)")
    ap.add_argument("--fit-max", type=float, default=math.inf,
                    help="fit the law to the outlets up to this D0 (m) only")
    a = ap.parse_args()
    auto = a.window == "auto"
    if not auto:
        t0, t1 = (float(x) for x in a.window.split(","))
    rows = []
    for spec in a.runs:
        d0, frames = spec.split(":", 1)
        d0, _, z = d0.partition("@")
        series = counts(frames, float(z) if z else a.above)
        if not series:
            sys.exit(f"{frames}: no particle tables")
        if auto:
            t0, t1 = series[steady_start(series)][0], math.inf
        # Frame times are stored in f64 sums of steps (0.2499996 for 0.25): a frame within a
        # thousandth of the frame interval of a bound is inside it.
        tol = 1e-3 * min((b[0] - f[0] for f, b in zip(series, series[1:])), default=0.0)
        win = [(t, n * a.grain_mass) for t, n in series if t0 - tol <= t <= t1 + tol]
        if len(win) < 3:
            print(f"D0 = {float(d0):.4f} m ({frames}): fewer than 3 frames in the window "
                  f"{t0} … {t1} s, left out")
            continue
        w = -slope([t for t, _ in win], [m for _, m in win])[0] + 0.0  # no -0.000
        out = round((win[0][1] - win[-1][1]) / a.grain_mass)
        rows.append(dict(d0=float(d0), w=w, err=rate_error(win, a.grain_mass), start=win[0][0],
                         grains=out, series=series, fitted=w > 0 and out > 0 and float(d0) <= a.fit_max))
    if not rows:
        sys.exit("no run has 3 frames in its window")
    print(f"d = {a.d} m (the law's grain size), rho_b = {a.bulk_density} kg/m3, "
          f"window {'found from each run (MSER)' if auto else a.window + ' s'}")
    print("| D0 (m) | D0 / d | W (kg/s) | standard error | steady from (s) | grains out in the window |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['d0']:.4f} | {r['d0'] / a.d:.2f} | {r['w']:.3f} | {r['err']:.3f} | "
              f"{r['start']:.3f} | {r['grains']} |")
    # Several starts of one outlet: their mean and spread beside the standard errors.
    by_d0 = collections.defaultdict(list)
    for r in rows:
        by_d0[round(r["d0"], 6)].append(r["w"])
    for d0, ws in sorted(by_d0.items()):
        if len(ws) > 1:
            mean = sum(ws) / len(ws)
            sd = math.sqrt(sum((w - mean) ** 2 for w in ws) / (len(ws) - 1))
            print(f"D0 = {d0:.4f} m: {len(ws)} runs, W {mean:.3f} ± {sd:.3f} kg/s (standard deviation)")
    fit = None
    # An outlet that jammed (no grain out over the window) has no place on the law's line:
    # the fit takes the outlets that flow, and says which it left out.
    flowing = [r for r in rows if r["fitted"]]
    for r in rows:
        if r["w"] <= 0:
            print(f"D0 = {r['d0']:.4f} m: no flow over the window (jammed), left out of the fit")
        elif r["d0"] > a.fit_max:
            print(f"D0 = {r['d0']:.4f} m: wider than --fit-max, left out of the fit")
    if len(flowing) >= 2:
        c, k, samples, chi2, dof, birge = beverloo_fit(flowing, a.bulk_density, a.d, draws=20000)
        fit = lambda d0: c * a.bulk_density * math.sqrt(G) * max(d0 - k * a.d, 0.0) ** 2.5
        print(f"Beverloo: C = {c:.3f}, k = {k:.2f} (d = {a.d} m, rho_b = {a.bulk_density} kg/m3)")
        if samples:
            (c1, c2), (k1, k2) = (interval([x[0] for x in samples], 0.68),
                                  interval([x[1] for x in samples], 0.68))
            (c3, c4), (k3, k4) = (interval([x[0] for x in samples], 0.95),
                                  interval([x[1] for x in samples], 0.95))
            print(f"chi^2 = {chi2:.1f} over {dof} degrees of freedom: the rates' errors "
                  f"{'scaled by ' + format(birge, '.2f') if birge > 1 else 'as measured'}")
            print(f"intervals (bootstrap of the rates' errors, {len(samples)} fits): "
                  f"C 68 % [{c1:.3f}, {c2:.3f}], 95 % [{c3:.3f}, {c4:.3f}]; "
                  f"k 68 % [{k1:.2f}, {k2:.2f}], 95 % [{k3:.2f}, {k4:.2f}]")
        for r in rows:
            law = fit(r["d0"])
            if law > 0:
                # Rounded first: a deviation below half a percent prints as +0%, never -0%.
                dev = round(r["w"] / law - 1, 2) + 0.0
                print(f"D0 = {r['d0']:.4f} m: W {r['w']:.3f} kg/s, the law {law:.3f} ({dev:+.0%})")
    # Two panels: mass discharged against time (a silo's few kilograms out of its whole charge
    # would be a flat line on a scale of what is left); W against D0 with the law.
    w, h = 900, 380
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
             '<rect width="100%" height="100%" fill="white"/>']
    colours = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f"]
    x0, y0, pw, ph = 70, 30, 340, 290
    tmax = max(t for r in rows for t, _ in r["series"])
    for r in rows:
        n0 = r["series"][0][1]
        r["out"] = [(t, (n0 - n) * a.grain_mass) for t, n in r["series"]]
    mmax = max(max(m for r in rows for _, m in r["out"]), 1e-9)
    parts.append(f'<rect x="{x0}" y="{y0}" width="{pw}" height="{ph}" fill="none" stroke="black"/>')
    parts.append(f'<text x="{x0 + pw / 2}" y="{y0 + ph + 30}" text-anchor="middle">time (s)</text>')
    parts.append(f'<text x="{x0}" y="20">mass discharged (kg, 0 … {mmax:.2g})</text>')
    for i, r in enumerate(rows):
        pts = " ".join(f"{x0 + t / tmax * pw:.1f},{y0 + ph - m / mmax * ph:.1f}" for t, m in r["out"])
        parts.append(f'<polyline points="{pts}" fill="none" stroke="{colours[i % len(colours)]}" stroke-width="1.5"/>')
        parts.append(f'<text x="{x0 + pw - 4}" y="{y0 + 16 + 14 * i}" text-anchor="end" fill="{colours[i % len(colours)]}">D0 = {1000 * r["d0"]:.0f} mm</text>')
    for j in range(5):
        parts.append(f'<text x="{x0 + pw * j / 4:.0f}" y="{y0 + ph + 14}" text-anchor="middle">{tmax * j / 4:.1f}</text>')
    x1 = x0 + pw + 90
    dmax = max(r["d0"] for r in rows) * 1.1
    wmax = max(max(r["w"] for r in rows) * 1.2, 1e-9)   # all jammed: an empty panel
    parts.append(f'<rect x="{x1}" y="{y0}" width="{pw}" height="{ph}" fill="none" stroke="black"/>')
    parts.append(f'<text x="{x1 + pw / 2}" y="{y0 + ph + 30}" text-anchor="middle">outlet D0 (m)</text>')
    parts.append(f'<text x="{x1}" y="20">discharge rate W (kg/s, 0 … {wmax:.1f})</text>')
    for j in range(5):
        parts.append(f'<text x="{x1 + pw * j / 4:.0f}" y="{y0 + ph + 14}" text-anchor="middle">{dmax * j / 4:.3f}</text>')
    if fit:
        curve = []
        for j in range(101):
            d0 = dmax * j / 100
            wv = fit(d0)
            curve.append(f"{x1 + d0 / dmax * pw:.1f},{y0 + ph - min(wv, wmax) / wmax * ph:.1f}")
        parts.append(f'<polyline points="{" ".join(curve)}" fill="none" stroke="#1f77b4" stroke-width="2"/>')
        parts.append(f'<text x="{x1 + 8}" y="{y0 + 16}" fill="#1f77b4">Beverloo: C = {c:.2f}, k = {k:.2f}</text>')
    # Filled: the outlets the law was fitted to; hollow: those left out (wider than --fit-max).
    for r in rows:
        fill = "#d62728" if r["d0"] <= a.fit_max else "white"
        parts.append(f'<circle cx="{x1 + r["d0"] / dmax * pw:.1f}" cy="{y0 + ph - max(r["w"], 0.0) / wmax * ph:.1f}" r="4" fill="{fill}" stroke="#d62728" stroke-width="1.5"/>')
    if any(r["d0"] > a.fit_max for r in rows):
        parts.append(f'<text x="{x1 + 8}" y="{y0 + 32}" fill="#d62728">hollow: D0 &gt; {a.fit_max:g} m, not fitted</text>')
    parts.append("</svg>")
    with open(a.svg, "w") as f:
        f.write("\n".join(parts) + "\n")


if __name__ == "__main__":
    main()

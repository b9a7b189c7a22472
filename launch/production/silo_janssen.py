#!/usr/bin/env python3
"""Case 4 (docs/production.md §4): the silo's wall stress against depth, fitted with Janssen's
law.

  python3 launch/production/silo_janssen.py SERIES.csv OUT.svg --radius R --hopper-top Z_H
      --band-height H --fill-top Z_F --bulk-density RHO_B [--from T]

SERIES.csv is the run's series (one force column triple per wall, `band_00_fx` ... from the
bottom up, as make_meshes.py cuts the side's east half). The forces are averaged over the rows
from time T on. For a pressure p uniform around the axis the net force on a half band of
height h is p times its projected area, |F_x| = 2 R h p, whatever the corrugation, so

  sigma_n = |F_x| / (2 R h),   tau = |F_z| / (pi R h)   (the half band's lateral area),

at the band's middle depth below the fill's top Z_F. Janssen's law for a cylinder (hydraulic
radius R_h = R / 2) with wall friction mu_w and lateral stress ratio K:

  sigma_n(d) = (rho_b g R_h / mu_w) (1 - exp(-mu_w K d / R_h)),

saturating at rho_b g R_h / mu_w with depth, against K rho_b g d without the wall's support.
mu_w is taken as the mobilised friction tau / sigma_n (the mean over the loaded bands), then K
is fitted by least squares; a two-parameter fit is printed too. Prints the table and writes
the plot.
"""
import argparse
import csv
import math
import sys

G = 9.81


def janssen(d, rho_b, rh, mu, k):
    return rho_b * G * rh / mu * (1 - math.exp(-mu * k * d / rh))


def fit_k(depths, sig, rho_b, rh, mu):
    """Least-squares K for a fixed mu (golden-section search on (0, 3))."""
    err = lambda k: sum((janssen(d, rho_b, rh, mu, k) - s) ** 2 for d, s in zip(depths, sig))
    a, b = 1e-4, 3.0
    for _ in range(200):
        c, e = b - (b - a) / 1.618, a + (b - a) / 1.618
        if err(c) < err(e):
            b = e
        else:
            a = c
    return (a + b) / 2, err((a + b) / 2)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("series")
    ap.add_argument("svg")
    ap.add_argument("--radius", type=float, required=True)
    ap.add_argument("--hopper-top", type=float, required=True)
    ap.add_argument("--band-height", type=float, required=True)
    ap.add_argument("--fill-top", type=float, required=True)
    ap.add_argument("--bulk-density", type=float, required=True)
    ap.add_argument("--from", dest="t0", type=float, default=0.0)
    a = ap.parse_args()
    with open(a.series) as f:
        rows = [r for r in csv.DictReader(f) if float(r["time"]) >= a.t0]
    if not rows:
        sys.exit(f"{a.series}: no rows from t = {a.t0} s on")
    bands = sorted({k[:-3] for k in rows[0] if k.startswith("band_") and k.endswith("_fx")})
    R, h, rh = a.radius, a.band_height, a.radius / 2
    table = []
    for b, name in enumerate(bands):
        fx = sum(float(r[name + "_fx"]) for r in rows) / len(rows)
        fz = sum(float(r[name + "_fz"]) for r in rows) / len(rows)
        z_mid = a.hopper_top + (b + 0.5) * h
        depth = a.fill_top - z_mid
        table.append(dict(band=name, z=z_mid, depth=depth, sigma=abs(fx) / (2 * R * h), tau=abs(fz) / (math.pi * R * h)))
    loaded = [t for t in table if t["depth"] > 0.5 * h and t["sigma"] > 0]
    print(f"{len(rows)} rows from t = {float(rows[0]['time']):.3f} s to {float(rows[-1]['time']):.3f} s")
    print("| band | middle z (m) | depth (m) | sigma_n (Pa) | tau (Pa) | tau / sigma_n |")
    print("|---|---|---|---|---|---|")
    for t in table:
        ratio = t["tau"] / t["sigma"] if t["sigma"] > 0 else float("nan")
        print(f"| {t['band']} | {t['z']:.3f} | {t['depth']:.3f} | {t['sigma']:.1f} | {t['tau']:.1f} | {ratio:.2f} |")
    result = {}
    if len(loaded) >= 2:
        depths = [t["depth"] for t in loaded]
        sig = [t["sigma"] for t in loaded]
        mu = sum(t["tau"] / t["sigma"] for t in loaded) / len(loaded)
        k, e = fit_k(depths, sig, a.bulk_density, rh, mu)
        best = min(((m / 100, *fit_k(depths, sig, a.bulk_density, rh, m / 100)) for m in range(5, 101)),
                   key=lambda x: x[2])
        result = dict(mu_mobilised=mu, k=k, rms=math.sqrt(e / len(loaded)), mu2=best[0], k2=best[1],
                      saturation=a.bulk_density * G * rh / mu)
        print(f"mobilised wall friction mu_w = {mu:.3f}; fitted K = {k:.3f} (rms {result['rms']:.1f} Pa); "
              f"saturation rho_b g R_h / mu_w = {result['saturation']:.0f} Pa")
        print(f"two-parameter fit: mu_w = {best[0]:.2f}, K = {best[1]:.3f}")
    # The plot: sigma_n against depth, the Janssen curve and the hydrostatic line K rho_b g d.
    w, hh, x0, y0, pw, ph = 600, 400, 70, 30, 480, 320
    dmax = max([t["depth"] for t in table] + [0.1])
    smax = max([t["sigma"] for t in table] + [1.0]) * 1.3
    px = lambda s: x0 + s / smax * pw
    py = lambda d: y0 + d / dmax * ph
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{hh}" font-family="sans-serif" font-size="12">',
             '<rect width="100%" height="100%" fill="white"/>',
             f'<rect x="{x0}" y="{y0}" width="{pw}" height="{ph}" fill="none" stroke="black"/>',
             f'<text x="{x0 + pw / 2}" y="{y0 + ph + 32}" text-anchor="middle">wall normal stress (Pa)</text>',
             f'<text x="18" y="{y0 + ph / 2}" transform="rotate(-90 18 {y0 + ph / 2})" text-anchor="middle">depth below the fill (m)</text>']
    for j in range(5):
        s, d = smax * j / 4, dmax * j / 4
        parts.append(f'<text x="{px(s):.0f}" y="{y0 + ph + 14}" text-anchor="middle">{s:.0f}</text>')
        parts.append(f'<text x="{x0 - 4}" y="{py(d) + 4:.0f}" text-anchor="end">{d:.2f}</text>')
    if result:
        mu, k = result["mu_mobilised"], result["k"]
        curve = " ".join(f"{px(janssen(dmax * j / 60, a.bulk_density, rh, mu, k)):.1f},{py(dmax * j / 60):.1f}" for j in range(61))
        parts.append(f'<polyline points="{curve}" fill="none" stroke="#1f77b4" stroke-width="2"/>')
        dl = min(dmax, smax / (k * a.bulk_density * G))
        parts.append(f'<line x1="{px(0)}" y1="{py(0)}" x2="{px(k * a.bulk_density * G * dl):.1f}" y2="{py(dl):.1f}" stroke="#999" stroke-dasharray="5 3"/>')
        parts.append(f'<text x="{x0 + 8}" y="{y0 + ph - 24}" fill="#1f77b4">Janssen, mu_w = {mu:.2f}, K = {k:.2f}</text>')
        parts.append(f'<text x="{x0 + 8}" y="{y0 + ph - 8}" fill="#666">without wall support, K rho_b g d</text>')
    for t in table:
        parts.append(f'<circle cx="{px(t["sigma"]):.1f}" cy="{py(max(t["depth"], 0)):.1f}" r="4" fill="#d62728"/>')
    parts.append("</svg>")
    with open(a.svg, "w") as f:
        f.write("\n".join(parts) + "\n")


if __name__ == "__main__":
    main()

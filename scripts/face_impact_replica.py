#!/usr/bin/env python3
"""A one-dimensional replica of the normal contact law for a face on a face (docs/contact.md §1).

Dimensionless: unit effective mass, area and stiffness, so that the seed's face law is
`X'' = -X^{1/3}` for the depth X > 0, with the regularized potential below V* (σ = 1/2), the
kick window where the swept volume exceeds half the volume, the entry and the exit, stepped by
velocity Verlet as `src/contact/law.rs` does (e = 1: no damping). Prints, for dt_fraction =
dt/t_c from 0.1 to 0.0125:

- the largest energy gain and loss of an elastic impact at 1 (unit speed) over 32 phases of
  first touch (docs/validation.md §3 compares them with the 3-D cubes);
- the exit alone: started from an exact state in contact (integrated finely from the deepest
  point for a fraction of a step), the energy change through the separation.

With `--variants`, also the largest gain with two changes tried at the first and last touch
(docs/validation.md §3): the entry's and the exit's constant-speed impulses `U/v` replaced by
the energy-exact `2U/(v + sqrt(v² + 2U))`, and the first and last kicks given the exact impulse
of the contact's one-dimensional motion from the moment of touch, or up to separation (RK4).

Usage: python3 scripts/face_impact_replica.py [--variants]
"""

import math
import sys

SIGMA = 0.5  # potential::RESOLVED_STEP


def cbrt(x):
    return math.copysign(abs(x) ** (1.0 / 3.0), x)


def w(v, vs):
    """The regularized potential W(V) (potential::resolved_potential, c = 1)."""
    if v <= 0.0:
        return 0.0
    if v < vs:
        r = cbrt(vs)
        return 0.5 * v * v / (r * r)
    return 0.75 * v * cbrt(v) - 0.25 * vs * cbrt(vs)


def w_slope(v, vs):
    if v <= 0.0:
        return 0.0
    if v < vs:
        r = cbrt(vs)
        return v / (r * r)
    return cbrt(v)


def w_mean(lo, hi, vs):
    return w_slope(hi, vs) if hi <= lo else (w(hi, vs) - w(lo, vs)) / (hi - lo)


# The variant of the entry and exit impulses: "law" (as src/contact/law.rs), "energy" (the
# energy-exact impulse in place of U/v) or "exact" (the contact's own 1-D motion, RK4).
VARIANT = "law"


def end_factor(u, speed):
    """What multiplies the constant-speed impulse U/v of the entry or the exit."""
    if VARIANT != "energy":
        return 1.0
    return 2.0 * speed / (speed + math.sqrt(speed * speed + 2.0 * u))


def force(depth, vn, dt, first, vs):
    """The law's normal force for a face (exponent 1), vn > 0 separating."""
    sweep = 0.5 * abs(vn) * dt
    p = w_mean(depth - sweep, depth + sweep, vs) if sweep > 0.5 * depth else w_slope(depth, vs)
    if first and sweep > 0.0 and depth - 2.0 * sweep <= 0.0 < depth - sweep:
        u = w(depth - sweep, vs)
        p += end_factor(u, abs(vn)) * u / (2.0 * sweep)
    if vn > 0.0:
        exit_ = 0.5 * (vn + p * dt) * dt
        if depth - 2.0 * exit_ <= 0.0 < depth - exit_:
            u = w(depth - exit_, vs)
            p += end_factor(u, vn + p * dt) * u / (2.0 * exit_)
    return p


def rk4(depth, rate, span, vs, steps):
    """The contact's 1-D motion (depth, its rate) over `span`; stops once apart when `steps`
    is None (then `span` is the sub-step)."""
    acc = lambda x: -w_slope(x, vs)  # noqa: E731
    n, h = (steps, span / steps) if steps else (None, span)
    k = 0
    while (k < n) if n else depth > 0.0:
        k1d, k1r = rate, acc(depth)
        k2d, k2r = rate + 0.5 * h * k1r, acc(depth + 0.5 * h * k1d)
        k3d, k3r = rate + 0.5 * h * k2r, acc(depth + 0.5 * h * k2d)
        k4d, k4r = rate + h * k3r, acc(depth + h * k3d)
        depth += h / 6.0 * (k1d + 2.0 * k2d + 2.0 * k3d + k4d)
        rate += h / 6.0 * (k1r + 2.0 * k2r + 2.0 * k3r + k4r)
        k += 1
    return depth, rate


def exact_ends_gain(dt, phase):
    """An elastic impact whose first and last kicks carry the exact 1-D impulse."""
    vs = (dt / SIGMA) ** 3
    depth, rate, f, touched, first = -phase * dt, 1.0, 0.0, False, True
    while True:
        rate -= 0.5 * f * dt
        depth += rate * dt
        if depth > 0.0:
            if first and depth - rate * dt <= 0.0:
                _, end = rk4(0.0, rate, depth / rate + 0.5 * dt, vs, 400)
                f = -(end - rate) / dt
            else:
                f = force(depth, -rate, dt, first, vs)
                if rate < 0.0 and depth + (rate - f * dt) * dt <= 0.0:
                    _, end = rk4(depth - 0.5 * rate * dt, rate, dt / 400.0, vs, None)
                    f = -(end - rate) / dt
            first, touched = False, True
        else:
            f = 0.0
            if touched:
                return rate * rate - 1.0
        rate -= 0.5 * f * dt


def step_until_apart(depth, vn, force_now, dt, vs, first):
    """Velocity Verlet until the bodies separate; returns the final normal speed."""
    f, touched = force_now, force_now > 0.0
    while True:
        vn += 0.5 * f * dt
        depth -= vn * dt
        if depth > 0.0:
            f = force(depth, vn, dt, first, vs)
            first, touched = False, True
        else:
            f = 0.0
            if touched:
                return vn
        vn += 0.5 * f * dt


def impact_gain(dt, phase):
    vs = (dt / SIGMA) ** 3
    v = step_until_apart(-phase * dt, -1.0, 0.0, dt, vs, True)
    return v * v - 1.0


def contact_time():
    """t_c of X'' = -X^{1/3} at unit speed: 2 ∫ dX / sqrt(1 - 1.5 X^{4/3})."""
    top, n = (2.0 / 3.0) ** 0.75, 200000
    return 2.0 * sum(
        top / n / math.sqrt(max(1.0 - 1.5 * ((i + 0.5) / n * top) ** (4.0 / 3.0), 1e-300))
        for i in range(n)
    )


def exit_gain(dt, phase):
    vs = (dt / SIGMA) ** 3
    depth, v, sub = (2.0 / 3.0) ** 0.75 * (1.0 - 1e-12), 0.0, 2000
    h = phase * dt / sub
    for _ in range(sub):  # exact (fine midpoint) motion for phase × dt from the deepest point
        a = w_slope(depth, vs)
        dm, vm = depth - v * h / 2.0, v + a * h / 2.0
        depth, v = depth - vm * h, v + w_slope(dm, vs) * h
    e0 = 0.5 * v * v + w(depth, vs)
    out = step_until_apart(depth, v, force(depth, v, dt, False, vs), dt, vs, False)
    return 0.5 * out * out / e0 - 1.0


def main():
    global VARIANT
    tc = contact_time()
    print(f"t_c = {tc:.6f}")
    for frac in (0.1, 0.05, 0.025, 0.0125):
        dt = frac * tc
        g = [impact_gain(dt, (k + 0.5) / 32) for k in range(32)]
        x = [exit_gain(dt, (k + 0.5) / 16) for k in range(16)]
        print(
            f"dt_fraction {frac}: impact gain {max(g):.3e}, loss {min(g):.3e}; "
            f"exit alone {min(x):.2e} … {max(x):.2e}"
        )
    if "--variants" in sys.argv[1:]:
        for frac in (0.1, 0.05, 0.025, 0.0125):
            dt = frac * tc
            VARIANT = "energy"
            energy = max(impact_gain(dt, (k + 0.5) / 32) for k in range(32))
            VARIANT = "law"
            exact = max(exact_ends_gain(dt, (k + 0.5) / 16) for k in range(16))
            print(
                f"dt_fraction {frac}: largest gain with energy-exact ends {energy:.3e}, "
                f"with exact first and last kicks {exact:.3e}"
            )


if __name__ == "__main__":
    main()

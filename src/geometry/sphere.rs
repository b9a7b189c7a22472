//! The sphere fast path (docs/design.md §1: "all spheres → stages 4–5 are the sphere formula"): the
//! overlap of two spheres and of a sphere with a wall facet in closed form, as the same
//! [`Overlap`] record the polyhedral stages produce, so the volume-based contact law applies
//! unchanged. The GPU twins are in `cuda/sphere.cuh`.
//!
//! **Two spheres** (radii `r_A`, `r_B`, centres `d` apart): the lens `A ∩ B` is two spherical caps
//! on either side of the radical plane at `d_A = (d² + r_A² − r_B²)/(2d)` from A's centre. A cap
//! of height `h` on a sphere of radius `r` has volume `πh²(3r − h)/3` and its centroid
//! `3(2r − h)²/(4(3r − h))` from the sphere's centre. Moving B away by `dd` removes the lens's
//! cross-section `πa²` (`a² = r_A² − d_A²`) times `dd`, so `S = dV/dx_B = −πa² û` with
//! `û = (x_B − x_A)/d`. B's part of the lens surface is a cap of B whose normals all pass
//! through `x_B`, so its moment about the lens centroid (on the axis) is zero.
//!
//! **A sphere and a wall facet** (wall.rs: the facet owns the part of space behind it within its
//! three side planes): the cap of the sphere behind the facet's plane, height `h = r − s` for a
//! centre `s` in front of the plane, is apportioned to the facet by the exact area of the cap's
//! base disk (radius `a = √(r² − s²)`) that lies on the facet's triangle, [`disk_polygon`]. The
//! facets of a flat wall tile its plane, so their shares sum to the whole cap, its volume and
//! `S = πa² n` exactly, whatever the triangulation; at a convex edge each facet contributes its
//! own cap over its own triangle.

use super::Overlap;
use nalgebra::{Vector2, Vector3};
use std::f64::consts::PI;

/// Volume of a cap of height `h` (0 ≤ h ≤ 2r) of a sphere of radius `r`: `πh²(3r − h)/3`.
pub fn cap_volume(r: f64, h: f64) -> f64 {
    PI * h * h * (3.0 * r - h) / 3.0
}

/// Distance from the sphere's centre to the centroid of a cap of height `h`:
/// `3(2r − h)²/(4(3r − h))`.
pub fn cap_centroid_distance(r: f64, h: f64) -> f64 {
    let t = 2.0 * r - h;
    3.0 * t * t / (4.0 * (3.0 * r - h))
}

/// The overlap of sphere A (radius `r_a`, centre at the origin of the pair frame) with sphere B
/// (radius `r_b`, centre at `d`), in the pair frame. No overlap (volume 0) when the spheres are
/// apart or touch; when one holds the other the lens is the smaller sphere and `S = 0` (no
/// direction: the contact law then gives no force, as for nested polyhedra).
pub fn sphere_lens(r_a: f64, r_b: f64, d: &Vector3<f64>) -> Overlap<f64> {
    let dist = d.norm();
    let delta = r_a + r_b - dist;
    if delta <= 0.0 {
        return Overlap {
            depth: 0.5 * delta,
            thickness: delta,
            ..Overlap::default()
        };
    }
    if dist <= (r_a - r_b).abs() {
        let (r, c) = if r_a <= r_b {
            (r_a, Vector3::zeros())
        } else {
            (r_b, *d)
        };
        return Overlap {
            volume: 4.0 / 3.0 * PI * r * r * r,
            centroid: c,
            depth: r,
            thickness: 2.0 * r,
            ..Overlap::default()
        };
    }
    let u = d / dist;
    // Radical plane at d_a from A's centre; the caps of A (height h_a) and of B (height h_b).
    let d_a = (dist * dist + r_a * r_a - r_b * r_b) / (2.0 * dist);
    let (h_a, h_b) = (r_a - d_a, r_b - (dist - d_a));
    let (v_a, v_b) = (cap_volume(r_a, h_a), cap_volume(r_b, h_b));
    let volume = v_a + v_b;
    // Cap centroids on the axis, measured from A's centre.
    let z_a = cap_centroid_distance(r_a, h_a);
    let z_b = dist - cap_centroid_distance(r_b, h_b);
    let z = (v_a * z_a + v_b * z_b) / volume;
    let a2 = (r_a * r_a - d_a * d_a).max(0.0);
    Overlap {
        volume,
        centroid: u * z,
        dv_dxb: u * (-PI * a2),
        moment_b: Vector3::zeros(),
        depth: 0.5 * delta,
        thickness: delta,
    }
}

/// Area and first moment (about the disk's centre) of the part of the disk of radius `a`
/// centred at the origin that lies inside the polygon `poly` (counter-clockwise), exactly: the
/// sum over the polygon's edges PQ of the signed disk ∩ triangle (O, P, Q), each a triangle
/// where the edge runs inside the circle and a circular sector where it runs outside.
pub fn disk_polygon(a: f64, poly: &[Vector2<f64>]) -> (f64, Vector2<f64>) {
    let n = poly.len();
    // The common case, a disk clear of every edge (on the inner side of each by at least a):
    // the whole disk, exactly.
    if (0..n).all(|k| {
        let (p, q) = (poly[k], poly[(k + 1) % n]);
        let e = q - p;
        cross2(&e, &(-p)) >= a * e.norm()
    }) {
        return (PI * a * a, Vector2::zeros());
    }
    let mut area = 0.0;
    let mut moment = Vector2::zeros();
    for k in 0..n {
        let (p, q) = (poly[k], poly[(k + 1) % n]);
        let e = q - p;
        let ee = e.dot(&e);
        // |p + t e|² = a²: t = (−p·e ∓ √disc)/(e·e), disc = (p·e)² − e·e (p·p − a²).
        let pe = p.dot(&e);
        let disc = pe * pe - ee * (p.dot(&p) - a * a);
        let (t1, t2) = if disc > 0.0 && ee > 0.0 {
            let root = disc.sqrt();
            (
                ((-pe - root) / ee).clamp(0.0, 1.0),
                ((-pe + root) / ee).clamp(0.0, 1.0),
            )
        } else {
            (1.0, 1.0) // the whole edge is outside the circle (or degenerate)
        };
        let (s1, s2) = (p + e * t1, p + e * t2);
        let (ar, mo) = sector(a, &p, &s1);
        area += ar;
        moment += mo;
        let tri = 0.5 * cross2(&s1, &s2);
        area += tri;
        moment += (s1 + s2) * (tri / 3.0);
        let (ar, mo) = sector(a, &s2, &q);
        area += ar;
        moment += mo;
    }
    (area, moment)
}

/// The signed circular sector of radius `a` from the direction of `s` to that of `e`
/// (counter-clockwise positive): area `a²θ/2` and first moment `(2/3) a³ sin(θ/2) b̂`, with
/// `b̂` the bisecting direction. Only `+ − × ÷ √` and [`atan2`] (this module's, not libm's):
/// the GPU twin then rounds identically, and double-precision runs stay bitwise equal.
fn sector(a: f64, s: &Vector2<f64>, e: &Vector2<f64>) -> (f64, Vector2<f64>) {
    let (sin, cos) = (cross2(s, e), s.dot(e));
    let theta = atan2(sin, cos);
    if theta == 0.0 {
        return (0.0, Vector2::zeros());
    }
    let ns = s.norm();
    let u = s / ns;
    let perp = Vector2::new(-u.y, u.x);
    // Half-angle sine and cosine from the unnormalised sin θ, cos θ (length ρ): cos(θ/2) =
    // √((1 + cos θ)/2) and sin(θ/2) = sin θ / (2 cos(θ/2)) while θ is within ±120°; beyond,
    // sin(θ/2) = ±√((1 − cos θ)/2) first, which avoids the cancellation in 1 + cos θ.
    let rho = (sin * sin + cos * cos).sqrt();
    let (c, sn) = (cos / rho, sin / rho);
    let (sh, ch) = if c > -0.5 {
        let ch = (0.5 * (1.0 + c)).sqrt();
        (sn / (2.0 * ch), ch)
    } else {
        let sh = (0.5 * (1.0 - c)).sqrt().copysign(sn);
        (sh, sn / (2.0 * sh))
    };
    let bisector = u * ch + perp * sh;
    (0.5 * a * a * theta, bisector * (2.0 / 3.0 * a * a * a * sh))
}

/// `atan2(y, x)` in (−π, π] from `+ − × ÷` only, within a few ulp of libm's, so that the CPU and
/// the GPU (cuda/sphere.cuh `portable_atan2`) compute it identically. The ratio `t ≤ 1` is
/// reduced by `atan t = π/6 + atan((√3 t − 1)/(√3 + t))` to `|t| ≤ tan(π/12)` ≈ 0.268, where 15
/// terms of the alternating series `t − t³/3 + …` leave a truncation error below 1e-18.
pub fn atan2(y: f64, x: f64) -> f64 {
    const PI_2: f64 = std::f64::consts::FRAC_PI_2;
    const PI_6: f64 = std::f64::consts::FRAC_PI_6;
    const SQRT3: f64 = 1.732_050_807_568_877_2;
    const TAN_PI_12: f64 = 0.267_949_192_431_122_7;
    if y == 0.0 && x >= 0.0 {
        return 0.0;
    }
    if x == 0.0 && y == 0.0 {
        return if x.is_sign_negative() {
            PI.copysign(y)
        } else {
            0.0
        };
    }
    let (ax, ay) = (x.abs(), y.abs());
    let swap = ay > ax;
    let t = if swap { ax / ay } else { ay / ax };
    let (t, base) = if t > TAN_PI_12 {
        ((SQRT3 * t - 1.0) / (SQRT3 + t), PI_6)
    } else {
        (t, 0.0)
    };
    let t2 = t * t;
    let mut series = 0.0;
    for k in (0..15).rev() {
        let term = 1.0 / (2 * k + 1) as f64;
        series = if k % 2 == 0 { term } else { -term } + t2 * series;
    }
    let mut angle = base + t * series;
    if swap {
        angle = PI_2 - angle;
    }
    if x < 0.0 {
        angle = PI - angle;
    }
    if y < 0.0 { -angle } else { angle }
}

fn cross2(a: &Vector2<f64>, b: &Vector2<f64>) -> f64 {
    a.x * b.y - a.y * b.x
}

/// The part of the sphere (centre `c`, radius `r`) behind the facet `t` (counter-clockwise seen
/// from its front, unit normal `n` towards the front) that the facet owns: the cap behind the
/// plane times the share of its base disk on the triangle (module docs). `S = dV/dx_wall` points
/// along `n`; the wall's surface in the overlap is flat under the cap's centroid, so its moment
/// is zero.
pub fn sphere_facet(
    c: &Vector3<f64>,
    r: f64,
    t: &[Vector3<f64>; 3],
    n: &Vector3<f64>,
) -> Overlap<f64> {
    let s = n.dot(&(c - t[0]));
    let h = r - s;
    if h <= 0.0 {
        return Overlap::default();
    }
    let h = h.min(2.0 * r);
    let a = (r * r - s * s).max(0.0).sqrt();
    // In-plane frame (e1, e2, n), right-handed, centred on the disk's centre.
    let e1 = (t[1] - t[0]).normalize();
    let e2 = n.cross(&e1);
    let foot = c - n * s;
    let poly = t.map(|v| {
        let w = v - foot;
        Vector2::new(w.dot(&e1), w.dot(&e2))
    });
    let (area, moment) = if a > 0.0 {
        disk_polygon(a, &poly)
    } else {
        (0.0, Vector2::zeros())
    };
    if area <= 0.0 {
        return Overlap::default();
    }
    let share = area / (PI * a * a);
    let lateral = (e1 * moment.x + e2 * moment.y) / area;
    Overlap {
        volume: share * cap_volume(r, h),
        centroid: foot + lateral + n * (s - cap_centroid_distance(r, h)),
        dv_dxb: n * area,
        moment_b: Vector3::zeros(),
        depth: 0.5 * h,
        thickness: h,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn portable_atan2_is_within_a_few_ulp_of_libm() {
        let mut rng = crate::rng::Rng::new(3);
        let mut worst = 0.0f64;
        for k in 0..200_000 {
            let scale = 10f64.powi(k % 13 - 6);
            let (y, x) = (rng.range(-1.0, 1.0) * scale, rng.range(-1.0, 1.0));
            let (a, b) = (atan2(y, x), y.atan2(x));
            worst = worst.max((a - b).abs() / (b.abs() * f64::EPSILON).max(f64::MIN_POSITIVE));
        }
        println!("portable atan2: worst {worst:.2} ulp of libm");
        assert!(worst <= 4.0, "worst {worst} ulp");
        for (y, x) in [
            (0.0, 1.0),
            (1.0, 0.0),
            (0.0, -1.0),
            (-1.0, 0.0),
            (1.0, 1.0),
            (-1.0, -1.0),
        ] {
            assert!(
                (atan2(y, x) - f64::atan2(y, x)).abs() <= 4.0 * f64::EPSILON,
                "{y} {x}"
            );
        }
    }

    /// The lens volume by integrating the cross-section area along the axis (Simpson, 20 000
    /// intervals): an oracle that uses neither cap formula.
    fn lens_by_slices(r_a: f64, r_b: f64, d: f64) -> (f64, f64) {
        let (lo, hi) = (d - r_b, r_a);
        let n = 20_000;
        let hstep = (hi - lo) / n as f64;
        let area = |x: f64| {
            let ra2 = (r_a * r_a - x * x).max(0.0);
            let rb2 = (r_b * r_b - (x - d) * (x - d)).max(0.0);
            PI * ra2.min(rb2)
        };
        let (mut v, mut m) = (0.0, 0.0);
        for k in 0..=n {
            let x = lo + hstep * k as f64;
            let w = if k == 0 || k == n {
                1.0
            } else if k % 2 == 1 {
                4.0
            } else {
                2.0
            };
            v += w * area(x);
            m += w * area(x) * x;
        }
        (v * hstep / 3.0, m * hstep / 3.0)
    }

    #[test]
    fn lens_matches_slices_and_its_gradient_is_the_cross_section() {
        for &(r_a, r_b, d) in &[
            (1.0, 1.0, 1.9),
            (1.0, 1.0, 1.2),
            (0.5, 2.0, 2.3),
            (2.0, 0.5, 2.45),
            (1.0, 0.3, 0.9),
        ] {
            let dir = Vector3::new(0.3, -0.5, 0.8).normalize();
            let o = sphere_lens(r_a, r_b, &(dir * d));
            let (v, m) = lens_by_slices(r_a, r_b, d);
            assert!(
                (o.volume - v).abs() <= 1e-8 * v,
                "{r_a} {r_b} {d}: {} vs {v}",
                o.volume
            );
            let z = m / v;
            assert!((o.centroid - dir * z).norm() <= 1e-7 * r_a, "centroid");
            // S = dV/dx_B by central differences along the axis.
            let h = 1e-6;
            let dv = (sphere_lens(r_a, r_b, &(dir * (d + h))).volume
                - sphere_lens(r_a, r_b, &(dir * (d - h))).volume)
                / (2.0 * h);
            assert!((o.dv_dxb - dir * dv).norm() <= 1e-6 * dv.abs(), "S");
            assert_eq!(o.thickness, r_a + r_b - d);
        }
        let apart = sphere_lens(1.0, 1.0, &Vector3::new(2.5, 0.0, 0.0));
        assert_eq!(apart.volume, 0.0);
        assert!(apart.thickness < 0.0);
    }

    #[test]
    fn disk_polygon_matches_a_clipped_4096_gon() {
        let a = 1.0;
        let n = 4096;
        // An n-gon of the disk's area (its circumradius a/√(sin(2π/n)/(2π/n))), so that only
        // the O(n⁻²) error of the chords cut by the triangle's edges remains.
        let ratio = (2.0 * PI / n as f64).sin() / (2.0 * PI / n as f64);
        let rho = a / ratio.sqrt();
        let ngon: Vec<Vector2<f64>> = (0..n)
            .map(|k| {
                let t = 2.0 * PI * k as f64 / n as f64;
                Vector2::new(rho * t.cos(), rho * t.sin())
            })
            .collect();
        for tri in [
            [[-3.0, -3.0], [3.0, -3.0], [0.0, 4.0]], // holds the disk
            [[0.2, -2.0], [2.0, 0.1], [0.3, 1.5]],   // cuts off a side
            [[-0.4, -0.3], [0.5, -0.2], [0.1, 0.6]], // inside the disk
            [[0.5, 0.5], [3.0, 0.7], [0.6, 3.0]],    // one corner inside
            [[1.5, 1.5], [3.0, 1.7], [1.6, 3.0]],    // apart
        ] {
            let poly: Vec<Vector2<f64>> = tri.iter().map(|p| Vector2::new(p[0], p[1])).collect();
            let (area, moment) = disk_polygon(a, &poly);
            // Oracle: the n-gon clipped by the triangle's three edge half-planes.
            let mut clipped = ngon.clone();
            for k in 0..3 {
                let (p, q) = (poly[k], poly[(k + 1) % 3]);
                let side = |x: &Vector2<f64>| cross2(&(q - p), &(x - p));
                let mut out = Vec::new();
                for j in 0..clipped.len() {
                    let (u, w) = (clipped[j], clipped[(j + 1) % clipped.len()]);
                    let (su, sw) = (side(&u), side(&w));
                    if su >= 0.0 {
                        out.push(u);
                    }
                    if (su >= 0.0) != (sw >= 0.0) {
                        out.push(u + (w - u) * (su / (su - sw)));
                    }
                }
                clipped = out;
            }
            let (mut ref_area, mut ref_moment) = (0.0, Vector2::zeros());
            for k in 1..clipped.len().saturating_sub(1) {
                let (p, q, s) = (clipped[0], clipped[k], clipped[k + 1]);
                let t = 0.5 * cross2(&(q - p), &(s - p));
                ref_area += t;
                ref_moment += (p + q + s) * (t / 3.0);
            }
            // The chords' error: below a (2π/n)² ≈ 2.4e-6 a² per cut arc.
            assert!(
                (area - ref_area).abs() <= 1e-6,
                "{tri:?}: {area} vs {ref_area}"
            );
            assert!((moment - ref_moment).norm() <= 1e-6, "{tri:?}: moment");
        }
    }

    #[test]
    fn a_flat_wall_of_any_triangulation_carries_the_whole_cap() {
        let (r, c) = (0.5, Vector3::new(0.13, -0.21, 0.4));
        let n = Vector3::z();
        // A square of side 2 around the contact, cut into triangles two ways.
        let corners = [
            Vector3::new(-1.0, -1.0, 0.0),
            Vector3::new(1.0, -1.0, 0.0),
            Vector3::new(1.0, 1.0, 0.0),
            Vector3::new(-1.0, 1.0, 0.0),
        ];
        let centre = Vector3::new(0.1, 0.05, 0.0);
        let fan: Vec<[Vector3<f64>; 3]> = (0..4)
            .map(|k| [centre, corners[k], corners[(k + 1) % 4]])
            .collect();
        let split = vec![
            [corners[0], corners[1], corners[2]],
            [corners[0], corners[2], corners[3]],
        ];
        let h = r - 0.4;
        let a2 = r * r - 0.16;
        for mesh in [fan, split] {
            let mut v = 0.0;
            let mut s = Vector3::zeros();
            let mut m = Vector3::zeros();
            for t in &mesh {
                let o = sphere_facet(&c, r, t, &n);
                v += o.volume;
                s += o.dv_dxb;
                m += o.centroid * o.volume;
            }
            let vc = cap_volume(r, h);
            assert!((v - vc).abs() <= 1e-14 * vc, "{v} vs {vc}");
            assert!((s - n * (PI * a2)).norm() <= 1e-14, "{s}");
            let centroid = m / v;
            let expect = Vector3::new(c.x, c.y, 0.4 - cap_centroid_distance(r, h));
            assert!(
                (centroid - expect).norm() <= 1e-14,
                "{centroid} vs {expect}"
            );
        }
    }
}

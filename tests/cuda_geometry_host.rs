//! Parity of the CUDA contact-geometry headers (`cuda/gjk.cuh`, `interior.cuh`, `quickhull.cuh`,
//! `overlap.cuh`, `pair.cuh`, `polytope.cuh`, `prism.cuh`) with the Rust reference, on a machine without a
//! GPU: the headers compile as plain host C++17, `cuda/host/geometry_harness.cpp` runs them on
//! cases written by this test, and the results are compared with
//! `geometry::pair::{overlap_pair, axis_separates}` and
//! `geometry::clip::{facet_prism, prism_overlap_culled}` in f64 and f32.
//!
//! The headers replay the Rust code operation for operation (nalgebra's orders of summation
//! included) and every build disables floating-point contraction (`-ffp-contract=off` here,
//! `--fmad=false` under NVRTC), so the results are expected to be bitwise equal; the tolerances
//! below leave room only for a compiler that evaluates some expression differently.

mod common;

use common::*;
use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use polydem::geometry::Real;
use polydem::geometry::clip::{facet_prism, prism_overlap_culled};
use polydem::geometry::gjk_intersect;
use polydem::geometry::overlap::{Overlap, OverlapError, OverlapWorkspace};
use polydem::geometry::pair::{PairGeometry, PairWorkspace, axis_separates, overlap_pair};
use polydem::geometry::polytope::{PosedPolytope, cast};
use polydem::geometry::quickhull::HullError;
use polydem::rng::Rng;
use polydem::shape::ConvexTemplate;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Double precision: 1e-12 relative to the natural scale of each quantity ([`Scales`]), far
/// above the last-bit level of a well-conditioned result and far below anything physical. The
/// volume of a barely touching pair is ill-conditioned (its round-off is ε × size × area, not
/// ε × V), so for those only a port that reproduces the Rust operations exactly passes: that is
/// deliberate, the headers are meant to be bitwise twins of the Rust code.
const TOL_F64: f64 = 1e-12;

/// Single precision: the C++ float path must reproduce the Rust f32 path, not merely approximate
/// the exact overlap (tests/overlap_oracle.rs allows 1e-4 between f32 and the exact volume).
/// 1e-5 relative is an order of magnitude below that, so a computation done in a different
/// precision anywhere shows up, yet a last-bit difference in a well-conditioned result passes.
const TOL_F32: f64 = 1e-5;

/// Least fraction of results that must be bitwise identical to the Rust reference. Every
/// operation involved (+, −, ×, ÷, √) is correctly rounded in IEEE 754 and none is contracted, so
/// all of them are expected to be; a change of the order of operations that stays within the
/// tolerances (a reordered sum in a well-conditioned place) shows up here. The margin leaves room
/// for a compiler that evaluates a rare expression differently.
const MIN_BITWISE: f64 = 0.99;

/// Cases: 2640 pairs (every ordered pair of the 11 test shapes 21 or 22 times, in five kinds of
/// contact, see [`pair_cases`]) and 660 body–facet cases.
const N_PAIRS: usize = 2640;
const N_FACETS: usize = 660;

/// One pair case: shapes, scales, poses, and an axis and margin for `axis_separates`.
struct PairCase {
    a: usize,
    b: usize,
    sa: f64,
    sb: f64,
    pose_a: Isometry3<f64>,
    pose_b: Isometry3<f64>,
    axis: Vector3<f64>,
    margin: f64,
    kind: &'static str,
}

/// One facet case: a body, a triangle (relative to `origin`) and the pair-frame origin.
struct FacetCase {
    t: usize,
    s: f64,
    pose: Isometry3<f64>,
    origin: Vector3<f64>,
    tri: [Vector3<f64>; 3],
}

fn scaled_world_vertices(t: &ConvexTemplate, s: f64, pose: &Isometry3<f64>) -> Vec<Vector3<f64>> {
    t.vertices
        .iter()
        .map(|v| pose.rotation * (v.coords * s) + pose.translation.vector)
        .collect()
}

/// Centre distance along `dir` at which A and B (B moving along `dir` from A's centre) stop
/// intersecting, by bisection on the f64 GJK verdict.
fn touching_distance(shapes: &[Shape], c: &PairCase, dir: &Vector3<f64>) -> f64 {
    let (ta, tb) = (&shapes[c.a].template, &shapes[c.b].template);
    let va = scaled_world_vertices(ta, c.sa, &c.pose_a);
    let (mut lo, mut hi) = (
        0.0,
        1.01 * (ta.circumscribed_radius * c.sa + tb.circumscribed_radius * c.sb),
    );
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        let pb = pose(c.pose_a.translation.vector + dir * mid, c.pose_b.rotation);
        let vb = scaled_world_vertices(tb, c.sb, &pb);
        if gjk_intersect(&va, &vb, dir * mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// `n` pairs cycling through every ordered pair of shapes, in five kinds: deep (centre distance
/// up to 0.6 (r_A + r_B)), uniform (up to 1.05 (r_A + r_B)), near-touching (the touching distance
/// times 1 ± 10^-e, e in [3, 13]: shallow, barely touching and barely apart), touching (the
/// bisected touching distance itself) and aligned (both bodies with the same rotation, offset
/// along a body axis: face-to-face contacts with coincident planes). Some bodies are scaled, some
/// pairs sit far from the world origin.
fn pair_cases(shapes: &[Shape], n: usize, seed: u64) -> Vec<PairCase> {
    let mut rng = Rng::new(seed);
    let k = shapes.len();
    let mut cases = Vec::with_capacity(n);
    for i in 0..n {
        let (a, b) = (i % k, (i / k) % k);
        let sa = if i % 7 == 3 { rng.range(0.5, 2.0) } else { 1.0 };
        let sb = if i % 5 == 1 { rng.range(0.5, 2.0) } else { 1.0 };
        let ra = shapes[a].template.circumscribed_radius * sa;
        let rb = shapes[b].template.circumscribed_radius * sb;
        let far = if i % 9 == 4 { 100.0 } else { 2.0 };
        let pa = Vector3::new(
            rng.range(-far, far),
            rng.range(-far, far),
            rng.range(-far, far),
        );
        let qa = random_rotation(&mut rng);
        let kind = ["deep", "uniform", "near-touching", "touching", "aligned"][i % 5];
        let (qb, dir) = if kind == "aligned" {
            let q = if rng.uniform() < 0.3 {
                UnitQuaternion::identity()
            } else {
                qa
            };
            let axis = [Vector3::x(), Vector3::y(), Vector3::z()][(i / 5) % 3];
            let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
            (q, q * (axis * sign))
        } else {
            (random_rotation(&mut rng), Vector3::from(rng.unit_vector()))
        };
        let mut c = PairCase {
            a,
            b,
            sa,
            sb,
            pose_a: pose(pa, qa),
            pose_b: pose(pa, qb),
            axis: Vector3::zeros(),
            margin: 0.0,
            kind,
        };
        let dist = match kind {
            "deep" => rng.uniform() * 0.6 * (ra + rb),
            "uniform" => rng.uniform() * 1.05 * (ra + rb),
            "near-touching" => {
                let e = rng.range(3.0, 13.0);
                let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
                touching_distance(shapes, &c, &dir) * (1.0 + sign * 10f64.powf(-e))
            }
            "touching" => touching_distance(shapes, &c, &dir),
            _ => {
                let d = touching_distance(shapes, &c, &dir);
                if rng.uniform() < 0.5 {
                    d * (1.0 - rng.range(0.0, 0.2))
                } else {
                    d
                }
            }
        };
        c.pose_b = pose(pa + dir * dist, qb);
        cases.push(c);
    }
    cases
}

/// `n` bodies against a triangle: the facet plane at a signed distance in [−0.5, 1.1] r from the
/// body's centre (deep to missed), the triangle from 0.2 to 3 r across and shifted in its plane by
/// up to r (so the prism's side planes cut the body too); every 40th triangle is degenerate. The
/// pair-frame origin is the facet's foot under the body or the world origin.
fn facet_cases(shapes: &[Shape], n: usize, seed: u64) -> Vec<FacetCase> {
    let mut rng = Rng::new(seed);
    let k = shapes.len();
    (0..n)
        .map(|i| {
            let t = i % k;
            let s = if i % 3 == 2 { rng.range(0.5, 2.0) } else { 1.0 };
            let r = shapes[t].template.circumscribed_radius * s;
            let p = Vector3::new(
                rng.range(-2.0, 2.0),
                rng.range(-2.0, 2.0),
                rng.range(-2.0, 2.0),
            );
            let q = random_rotation(&mut rng);
            let nrm = Vector3::from(rng.unit_vector());
            let h = r * rng.range(-0.5, 1.1);
            let foot = p - nrm * h;
            let helper = if nrm.x.abs() < 0.9 {
                Vector3::x()
            } else {
                Vector3::y()
            };
            let e1 = nrm.cross(&helper).normalize();
            let e2 = nrm.cross(&e1);
            let centre = foot + e1 * (r * rng.range(-1.0, 1.0)) + e2 * (r * rng.range(-1.0, 1.0));
            let size = r * rng.range(0.2, 3.0);
            let theta0 = rng.range(0.0, std::f64::consts::TAU);
            let mut tri = [Vector3::zeros(); 3];
            for (j, v) in tri.iter_mut().enumerate() {
                let th = theta0 + j as f64 * std::f64::consts::TAU / 3.0 + rng.range(-0.4, 0.4);
                let rad = size * rng.range(0.5, 1.0);
                *v = centre + e1 * (rad * th.cos()) + e2 * (rad * th.sin());
            }
            if i % 40 == 7 {
                tri[2] = tri[1]; // degenerate: facet_prism returns None
            }
            if i % 6 == 5 {
                // A face resting on the facet's plane, tilted by round-off and 1e-9 … 1e-5 of
                // the size deep: the thin slab of a packing's wall contacts, where the
                // interior-point LP and the plane culling take their rarer branches.
                let f = &shapes[t].template.faces[i % shapes[t].template.faces.len()];
                let down = UnitQuaternion::rotation_between(&f.normal, &-nrm)
                    .unwrap_or_else(UnitQuaternion::identity);
                let q = UnitQuaternion::from_scaled_axis(e1 * 1e-12 + e2 * 3e-13) * down;
                let depth = r * 10f64.powf(rng.range(-9.0, -5.0));
                let low = shapes[t]
                    .template
                    .vertices
                    .iter()
                    .map(|v| nrm.dot(&(q * v.coords)) * s)
                    .fold(f64::MAX, f64::min);
                let p = foot + nrm * (-low - depth);
                let origin = if i % 2 == 0 { foot } else { Vector3::zeros() };
                return FacetCase {
                    t,
                    s,
                    pose: pose(p, q),
                    origin,
                    tri: tri.map(|v| v - origin),
                };
            }
            let origin = if i % 2 == 0 { foot } else { Vector3::zeros() };
            FacetCase {
                t,
                s,
                pose: pose(p, q),
                origin,
                tri: tri.map(|v| v - origin),
            }
        })
        .collect()
}

fn hex(out: &mut String, x: f64) {
    write!(out, " {:016x}", x.to_bits()).unwrap();
}

fn hex3(out: &mut String, v: &Vector3<f64>) {
    hex(out, v.x);
    hex(out, v.y);
    hex(out, v.z);
}

fn hex_pose(out: &mut String, p: &Isometry3<f64>) {
    hex3(out, &p.translation.vector);
    let q = p.rotation;
    hex(out, q.w);
    hex(out, q.i);
    hex(out, q.j);
    hex(out, q.k);
}

/// The case file read by the harness (format in cuda/host/geometry_harness.cpp).
fn case_file(shapes: &[Shape], pairs: &[PairCase], facets: &[FacetCase]) -> String {
    let mut out = String::new();
    writeln!(out, "templates {}", shapes.len()).unwrap();
    for s in shapes {
        let t = &s.template;
        write!(out, "{}", t.vertices.len()).unwrap();
        for v in &t.vertices {
            hex3(&mut out, &v.coords);
        }
        write!(out, "\n{}", t.faces.len()).unwrap();
        for f in &t.faces {
            hex3(&mut out, &f.normal);
            hex(&mut out, f.offset);
            write!(out, " {}", f.vertices.len()).unwrap();
            for v in &f.vertices {
                write!(out, " {v}").unwrap();
            }
        }
        out.push('\n');
        hex(&mut out, t.circumscribed_radius);
        out.push('\n');
    }
    writeln!(out, "pairs {}", pairs.len()).unwrap();
    for c in pairs {
        write!(out, "{}", c.a).unwrap();
        hex(&mut out, c.sa);
        hex_pose(&mut out, &c.pose_a);
        write!(out, " {}", c.b).unwrap();
        hex(&mut out, c.sb);
        hex_pose(&mut out, &c.pose_b);
        hex3(&mut out, &c.axis);
        hex(&mut out, c.margin);
        out.push('\n');
    }
    writeln!(out, "facets {}", facets.len()).unwrap();
    for c in facets {
        write!(out, "{}", c.t).unwrap();
        hex(&mut out, c.s);
        hex_pose(&mut out, &c.pose);
        hex3(&mut out, &c.origin);
        for v in &c.tri {
            hex3(&mut out, v);
        }
        out.push('\n');
    }
    out
}

/// The status code the headers return for a Rust error (cuda/polytope.cuh, GeometryStatus).
fn status_code(e: &OverlapError) -> i64 {
    match e {
        OverlapError::TooManyPlanes(_) => 1,
        OverlapError::Hull(HullError::TooManyPoints) => 2,
        OverlapError::Hull(HullError::Degenerate) => 3,
        OverlapError::Hull(HullError::CapacityExceeded) => 4,
        OverlapError::Hull(HullError::Topology) => 5,
    }
}

/// One precision's result for one case, Rust or C++.
#[derive(Clone, Debug)]
struct Result1 {
    status: i64,
    intersects: bool,
    axis: Vector3<f64>,
    overlap: Overlap<f64>,
}

impl Result1 {
    /// No intersection and a zero overlap (what the headers leave on error), with `status`.
    fn empty(status: i64) -> Self {
        Result1 {
            status,
            intersects: false,
            axis: Vector3::zeros(),
            overlap: Overlap::default(),
        }
    }
}

fn from_rust(r: Result<PairGeometry, OverlapError>) -> Result1 {
    match r {
        Ok(g) => Result1 {
            status: 0,
            intersects: g.intersects,
            axis: g.separating_axis.unwrap_or_else(Vector3::zeros),
            overlap: g.overlap,
        },
        Err(e) => Result1::empty(status_code(&e)),
    }
}

/// Rust facet case in precision `T`: (facet_prism status, prism_overlap status, overlap).
fn rust_facet<T: Real>(
    shapes: &[Shape],
    c: &FacetCase,
    ws: &mut OverlapWorkspace<T>,
) -> (i64, Result1) {
    let mut body = PosedPolytope::<T>::default();
    body.place(&shapes[c.t].template, c.s, &c.pose, &c.origin);
    let tri = c.tri.map(|v| cast::<T>(&v));
    let Some(prism) = facet_prism(&tri) else {
        return (6, Result1::empty(0));
    };
    let r = match prism_overlap_culled(
        ws,
        &mut body,
        (&shapes[c.t].template, c.s, &c.pose),
        &c.origin,
        &prism,
    ) {
        Ok(o) => Result1 {
            status: 0,
            intersects: false,
            axis: Vector3::zeros(),
            overlap: o.to_world(&Vector3::zeros()),
        },
        Err(e) => Result1::empty(status_code(&e)),
    };
    (0, r)
}

/// Parses `n` hex doubles.
fn parse_f64s(tok: &mut std::slice::Iter<&str>, n: usize) -> Vec<f64> {
    (0..n)
        .map(|_| {
            let t = tok.next().expect("truncated harness output");
            f64::from_bits(u64::from_str_radix(t, 16).expect("hex double"))
        })
        .collect()
}

fn parse_int(tok: &mut std::slice::Iter<&str>) -> i64 {
    tok.next()
        .expect("truncated harness output")
        .parse()
        .expect("integer")
}

fn parse_overlap(tok: &mut std::slice::Iter<&str>) -> Overlap<f64> {
    let v = parse_f64s(tok, 12);
    Overlap {
        volume: v[0],
        centroid: Vector3::new(v[1], v[2], v[3]),
        dv_dxb: Vector3::new(v[4], v[5], v[6]),
        moment_b: Vector3::new(v[7], v[8], v[9]),
        depth: v[10],
        thickness: v[11],
    }
}

/// Worst relative deviations per quantity, with the case that produced each.
#[derive(Default)]
struct Worst {
    entries: Vec<(&'static str, f64, String)>,
    compared: usize,
    bitwise: usize,
}

impl Worst {
    fn note(&mut self, what: &'static str, err: f64, label: &str) {
        match self.entries.iter_mut().find(|e| e.0 == what) {
            Some(e) => {
                if err > e.1 {
                    e.1 = err;
                    e.2 = label.to_string();
                }
            }
            None => self.entries.push((what, err, label.to_string())),
        }
    }

    fn report(&self, title: &str) {
        println!(
            "{title}: {} results compared, {} bitwise identical",
            self.compared, self.bitwise
        );
        for (what, err, label) in &self.entries {
            if *err > 0.0 {
                println!("  worst {what:<10} {err:.3e}  ({label})");
            } else {
                println!("  worst {what:<10} 0");
            }
        }
    }
}

/// Natural scales of a case: the body size (circumscribed radius of the larger body) for
/// positions and lengths; the volume itself for the volume; for S the contact area |S|, or
/// V^(2/3) where that is larger (a body entirely inside the other has S = 0 exactly, and the
/// computed S is round-off on the scale of the overlap's faces); that area times the size for the
/// moment.
struct Scales {
    size: f64,
}

/// Compares the C++ result `got` with the Rust result `want` in tolerance `tol`, recording the
/// deviations in `worst` and any failure in `failures`.
fn compare(
    label: &str,
    want: &Result1,
    got: &Result1,
    sc: &Scales,
    tol: f64,
    worst: &mut Worst,
    failures: &mut Vec<String>,
) {
    worst.compared += 1;
    if want.status != got.status || want.intersects != got.intersects {
        failures.push(format!(
            "{label}: status/verdict differ: Rust ({}, intersects {}), C++ ({}, intersects {})",
            want.status, want.intersects, got.status, got.intersects
        ));
        return;
    }
    let (w, g) = (&want.overlap, &got.overlap);
    let rel = |d: f64, s: f64| {
        if d == 0.0 {
            0.0
        } else if s > 0.0 {
            d / s
        } else {
            f64::INFINITY
        }
    };
    let area = w.dv_dxb.norm().max(w.volume.abs().powf(2.0 / 3.0));
    // The thickness is measured along S/|S|, which is only defined when |S| is not round-off:
    // checked against the tolerance when |S| >= 0.1 V^(2/3) (bitwise identity is still counted).
    let thickness_defined = w.dv_dxb.norm() >= 0.1 * w.volume.abs().powf(2.0 / 3.0);
    let errs = [
        ("axis", rel((want.axis - got.axis).norm(), want.axis.norm())),
        ("volume", rel((w.volume - g.volume).abs(), w.volume.abs())),
        ("centroid", rel((w.centroid - g.centroid).norm(), sc.size)),
        ("S", rel((w.dv_dxb - g.dv_dxb).norm(), area)),
        (
            "moment",
            rel((w.moment_b - g.moment_b).norm(), area * sc.size),
        ),
        ("depth", rel((w.depth - g.depth).abs(), sc.size)),
        (
            "thickness",
            if thickness_defined {
                rel((w.thickness - g.thickness).abs(), sc.size)
            } else {
                0.0
            },
        ),
    ];
    let same = want.axis == got.axis
        && w.volume == g.volume
        && w.centroid == g.centroid
        && w.dv_dxb == g.dv_dxb
        && w.moment_b == g.moment_b
        && w.depth == g.depth
        && w.thickness == g.thickness;
    if same {
        worst.bitwise += 1;
    }
    for (what, e) in errs {
        worst.note(what, e, label);
        if e.is_nan() || e > tol {
            failures.push(format!(
                "{label}: {what} deviates by {e:e} (relative), tolerance {tol:e}\n    Rust {want:?}\n    C++  {got:?}"
            ));
        }
    }
}

/// A C++ compiler: `CXX` when set, else the first of c++, g++, clang++ that runs.
fn cxx() -> String {
    let candidates: Vec<String> = std::env::var("CXX")
        .ok()
        .into_iter()
        .chain(["c++", "g++", "clang++"].map(String::from))
        .collect();
    for c in &candidates {
        if Command::new(c)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
        {
            return c.clone();
        }
    }
    panic!(
        "no C++ compiler found (tried {candidates:?}): the CUDA host parity test needs g++ or \
         clang++ with C++17 (part of the project's setup; install g++ or set CXX)"
    );
}

/// Compiles the harness into `dir` and returns its path.
///
/// At `-O1`: g++ 12.2 at `-O2` (its SLP vectorizer) dropped a rounding the headers ask for,
/// `(double)(float)x` evaluated as `x` where mixed precision's frame takes the f64 LP's centre
/// rounded to f32 (`overlap_pair_mixed`), so three quarters of the mixed-precision cases
/// differed from the Rust code by the rounding; at `-O0`, `-O1`, `-O3`, or `-O2` with
/// `-fno-tree-slp-vectorize`, every case is bitwise the Rust result. The harness runs a few
/// seconds at either level.
fn build_harness(root: &Path, dir: &Path) -> PathBuf {
    build_harness_with(root, dir, &[])
}

/// [`build_harness`] with extra `-D` options.
fn build_harness_with(root: &Path, dir: &Path, defines: &[&str]) -> PathBuf {
    let exe = dir.join("geometry_harness");
    let cxx = cxx();
    let out = Command::new(&cxx)
        .args(["-O1", "-std=c++17", "-ffp-contract=off", "-Wall"])
        .args(defines)
        .arg("-I")
        .arg(root.join("cuda"))
        .arg(root.join("cuda/host/geometry_harness.cpp"))
        .arg("-o")
        .arg(&exe)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {cxx}: {e}"));
    assert!(
        out.status.success(),
        "{cxx} failed to compile cuda/host/geometry_harness.cpp:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    exe
}

/// The harness's output lines for the cases, from the host-compiled headers.
fn harness_lines(shapes: &[Shape], pairs: &[PairCase], facets: &[FacetCase]) -> Vec<String> {
    let root = repo_root();
    let dir = temp_dir("cuda-geometry-host");
    let exe = build_harness(&root, &dir);
    let cases = dir.join("cases.txt");
    std::fs::write(&cases, case_file(shapes, pairs, facets)).unwrap();
    let out = Command::new(&exe).arg(&cases).output().unwrap();
    assert!(
        out.status.success(),
        "harness failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(String::from)
        .collect()
}

fn put_overlap(out: &mut String, o: &Overlap<f64>) {
    hex(out, o.volume);
    hex3(out, &o.centroid);
    hex3(out, &o.dv_dxb);
    hex3(out, &o.moment_b);
    hex(out, o.depth);
    hex(out, o.thickness);
}

/// The same lines from the kernels of `cuda/probe.cu`, compiled by NVRTC and run on GPU 0.
fn gpu_lines(shapes: &[Shape], pairs: &[PairCase], facets: &[FacetCase]) -> Vec<String> {
    use polydem::backend::cuda::probe::{GeometryProbe, ProbeBody, ProbeFacet, ProbePair};
    let templates: Vec<&ConvexTemplate> = shapes.iter().map(|s| &s.template).collect();
    let mv = templates.iter().map(|t| t.vertices.len()).max().unwrap();
    let mf = templates.iter().map(|t| t.faces.len()).max().unwrap();
    let probe = GeometryProbe::new(0, mv, mf).expect("GPU probe");
    println!(
        "GPU: {} (workspace for {mv} vertices, {mf} faces)",
        probe.device
    );
    let body = |template, scale, pose: &Isometry3<f64>| ProbeBody {
        template,
        scale,
        pose: *pose,
    };
    let pair_cases: Vec<ProbePair> = pairs
        .iter()
        .map(|c| ProbePair {
            a: body(c.a, c.sa, &c.pose_a),
            b: body(c.b, c.sb, &c.pose_b),
            axis: c.axis,
            margin: c.margin,
        })
        .collect();
    let facet_cases: Vec<ProbeFacet> = facets
        .iter()
        .map(|c| ProbeFacet {
            body: body(c.t, c.s, &c.pose),
            origin: c.origin,
            triangle: c.tri,
        })
        .collect();
    let mut lines = Vec::new();
    for (i, (r64, r32, sep)) in probe
        .pairs(&templates, &pair_cases)
        .expect("probe_pairs")
        .iter()
        .enumerate()
    {
        let mut l = format!("P {i}");
        for r in [r64, r32] {
            write!(l, " {} {}", r.status, u8::from(r.intersects)).unwrap();
            hex3(&mut l, &r.separating_axis);
            put_overlap(&mut l, &r.overlap);
        }
        write!(l, " {}", u8::from(*sep)).unwrap();
        lines.push(l);
    }
    for (i, (r64, r32)) in probe
        .facets(&templates, &facet_cases)
        .expect("probe_facets")
        .iter()
        .enumerate()
    {
        let mut l = format!("F {i}");
        for r in [r64, r32] {
            write!(l, " {} {}", r.prism_status, r.status).unwrap();
            put_overlap(&mut l, &r.overlap);
        }
        lines.push(l);
    }
    lines
}

#[test]
fn cuda_geometry_headers_match_the_rust_reference_in_f64_and_f32() {
    parity("C++", harness_lines);
}

/// The same cases and tolerances with the headers compiled by NVRTC and run on the GPU: the
/// geometry of stages 4–6 on the device is the Rust reference's, bit for bit.
#[test]
#[ignore = "needs a CUDA GPU"]
fn cuda_geometry_kernels_match_the_rust_reference_on_the_gpu() {
    parity("GPU", gpu_lines);
}

/// Runs the Rust reference and `produce` (C++ on the host, or the GPU) on the same cases and
/// compares them.
/// Produces the harness's output lines for the cases.
type Producer = fn(&[Shape], &[PairCase], &[FacetCase]) -> Vec<String>;

fn parity(what: &str, produce: Producer) {
    let mut shapes = test_shapes();
    let mut pairs = pair_cases(&shapes, N_PAIRS, 4242);
    // Two cubes of a poured pile touching below what the dual resolves: GJK counts them as
    // intersecting, the Chebyshev centre finds no interior, the dual hull is degenerate, and
    // the pair touches with no volume (overlap_cases.rs has the same pair).
    let (cube, [(sa, pose_a), (sb, pose_b)]) = pile_touching_pair();
    shapes.push(Shape {
        name: "cube 12 mm",
        template: cube,
    });
    pairs.push(PairCase {
        a: shapes.len() - 1,
        b: shapes.len() - 1,
        sa,
        sb,
        pose_a,
        pose_b,
        axis: Vector3::zeros(),
        margin: 0.0,
        kind: "touching below the dual's resolution",
    });
    // A body on itself, and one wholly inside another, from either side: the defined answer of
    // geometry/contained.rs (inner volume from its faces, S = 0) in both precisions.
    let mut rng_inside = Rng::new(17);
    for k in 0..shapes.len().min(8) {
        let q = random_rotation(&mut rng_inside);
        let q_small = random_rotation(&mut rng_inside);
        let x = Vector3::new(0.3, -0.2, 0.1) * k as f64;
        let (big, small) = (pose(x, q), pose(x + Vector3::new(0.02, 0.01, 0.0), q_small));
        for (sa, pa, sb, pb, kind) in [
            (1.0, big, 1.0, big, "coincident"),
            (1.0, big, 0.05, small, "B inside A"),
            (0.05, small, 1.0, big, "A inside B"),
        ] {
            pairs.push(PairCase {
                a: k,
                b: k,
                sa,
                sb,
                pose_a: pa,
                pose_b: pb,
                axis: Vector3::zeros(),
                margin: 0.0,
                kind,
            });
        }
    }
    let facets = facet_cases(&shapes, N_FACETS, 99);

    // Rust reference results; the axis for axis_separates is GJK's (a separating one) for
    // disjoint pairs and the centre line otherwise, with margins from 0 to 10 % of the size.
    let mut ws64 = PairWorkspace::<f64>::boxed();
    let mut ws32 = PairWorkspace::<f32>::boxed();
    let mut rng = Rng::new(7);
    let mut want_pairs = Vec::with_capacity(pairs.len());
    for c in pairs.iter_mut() {
        let (ta, tb) = (&shapes[c.a].template, &shapes[c.b].template);
        let r64 = from_rust(overlap_pair(
            &mut ws64,
            (ta, c.sa, &c.pose_a),
            (tb, c.sb, &c.pose_b),
        ));
        let r32 = from_rust(overlap_pair(
            &mut ws32,
            (ta, c.sa, &c.pose_a),
            (tb, c.sb, &c.pose_b),
        ));
        let size = (ta.circumscribed_radius * c.sa).max(tb.circumscribed_radius * c.sb);
        c.axis = if r64.status == 0 && !r64.intersects {
            r64.axis
        } else {
            c.pose_a.translation.vector - c.pose_b.translation.vector
        };
        c.margin = [0.0, 1e-9, 1e-3, 0.1][rng.next_u64() as usize % 4] * size;
        let sep = axis_separates(
            (ta, c.sa, &c.pose_a),
            (tb, c.sb, &c.pose_b),
            &c.axis,
            c.margin,
        );
        want_pairs.push((r64, r32, sep, size));
    }
    let mut fws64 = OverlapWorkspace::<f64>::boxed();
    let mut fws32 = OverlapWorkspace::<f32>::boxed();
    let want_facets: Vec<_> = facets
        .iter()
        .map(|c| {
            (
                rust_facet(&shapes, c, &mut fws64),
                rust_facet(&shapes, c, &mut fws32),
            )
        })
        .collect();

    // The C++ headers on the same cases.
    let lines = produce(&shapes, &pairs, &facets);
    assert_eq!(
        lines.len(),
        pairs.len() + facets.len(),
        "{what} printed {} lines for {} cases",
        lines.len(),
        pairs.len() + facets.len()
    );

    let mut failures = Vec::new();
    let (mut w64, mut w32, mut wf64, mut wf32) = (
        Worst::default(),
        Worst::default(),
        Worst::default(),
        Worst::default(),
    );
    let mut kinds = std::collections::BTreeMap::<String, usize>::new();
    let mut axis_checked = [0usize; 2];
    let mut worst_mixed = 0.0f64;
    for (i, (c, (r64, r32, sep, size))) in pairs.iter().zip(&want_pairs).enumerate() {
        let toks: Vec<&str> = lines[i].split_whitespace().collect();
        assert_eq!(toks.len(), 37, "pair line {i}: {}", lines[i]);
        assert_eq!((toks[0], toks[1]), ("P", i.to_string().as_str()));
        let mut it = toks[2..].iter();
        let parse = |it: &mut std::slice::Iter<&str>| {
            let status = parse_int(it);
            let intersects = parse_int(it) != 0;
            let a = parse_f64s(it, 3);
            Result1 {
                status,
                intersects,
                axis: Vector3::new(a[0], a[1], a[2]),
                overlap: parse_overlap(it),
            }
        };
        let g64 = parse(&mut it);
        let g32 = parse(&mut it);
        let gsep = parse_int(&mut it) != 0;
        let label = format!(
            "pair {i} ({}, {} vs {}, scales {} {})",
            c.kind, shapes[c.a].name, shapes[c.b].name, c.sa, c.sb
        );
        let sc = Scales { size: *size };
        compare(
            &format!("{label} f64"),
            r64,
            &g64,
            &sc,
            TOL_F64,
            &mut w64,
            &mut failures,
        );
        compare(
            &format!("{label} f32"),
            r32,
            &g32,
            &sc,
            TOL_F32,
            &mut w32,
            &mut failures,
        );
        // Mixed precision's promise: the f32 volume within 1e-4 of the f64 one wherever the
        // overlap is above f32 round-off (V > 1e-6 of the smaller body, as in overlap_oracle.rs).
        let v_small = (shapes[c.a].template.volume * c.sa.powi(3))
            .min(shapes[c.b].template.volume * c.sb.powi(3));
        if r64.status == 0 && g32.status == 0 && r64.overlap.volume > 1e-6 * v_small {
            let e = (g32.overlap.volume - r64.overlap.volume).abs() / r64.overlap.volume;
            worst_mixed = worst_mixed.max(e);
            if e > 1e-4 {
                failures.push(format!(
                    "{label}: f32 volume {:e} is {e:e} off the f64 volume {:e}",
                    g32.overlap.volume, r64.overlap.volume
                ));
            }
        }
        if gsep != *sep {
            failures.push(format!("{label}: axis_separates Rust {sep}, C++ {gsep}"));
        }
        axis_checked[*sep as usize] += 1;
        let class = if r64.status != 0 {
            "error".to_string()
        } else if !r64.intersects {
            "separated".to_string()
        } else if r64.overlap.volume == 0.0 {
            "touching (no volume)".to_string()
        } else if r64.overlap.volume
            < 1e-6 * shapes[c.a].template.volume.min(shapes[c.b].template.volume)
        {
            "shallow (V < 1e-6 V_small)".to_string()
        } else {
            "overlapping".to_string()
        };
        *kinds.entry(class).or_default() += 1;
        if r32.intersects != r64.intersects {
            *kinds
                .entry("f32 verdict differs from f64".into())
                .or_default() += 1;
        }
    }
    let mut facet_hits = 0;
    for (i, (c, ((p64, f64r), (p32, f32r)))) in facets.iter().zip(&want_facets).enumerate() {
        let line = &lines[pairs.len() + i];
        let toks: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(toks.len(), 30, "facet line {i}: {line}");
        assert_eq!((toks[0], toks[1]), ("F", i.to_string().as_str()));
        let mut it = toks[2..].iter();
        let parse = |it: &mut std::slice::Iter<&str>| {
            let pst = parse_int(it);
            let status = parse_int(it);
            let overlap = parse_overlap(it);
            (
                pst,
                Result1 {
                    status,
                    intersects: false,
                    axis: Vector3::zeros(),
                    overlap,
                },
            )
        };
        let (gp64, g64) = parse(&mut it);
        let (gp32, g32) = parse(&mut it);
        let label = format!("facet {i} ({}, scale {})", shapes[c.t].name, c.s);
        if gp64 != *p64 || gp32 != *p32 {
            failures.push(format!(
                "{label}: facet_prism status Rust ({p64}, {p32}), C++ ({gp64}, {gp32})"
            ));
        }
        let sc = Scales {
            size: shapes[c.t].template.circumscribed_radius * c.s,
        };
        compare(
            &format!("{label} f64"),
            f64r,
            &g64,
            &sc,
            TOL_F64,
            &mut wf64,
            &mut failures,
        );
        compare(
            &format!("{label} f32"),
            f32r,
            &g32,
            &sc,
            TOL_F32,
            &mut wf32,
            &mut failures,
        );
        if f64r.overlap.volume > 0.0 {
            facet_hits += 1;
        }
    }

    println!("pair classes (f64 reference): {kinds:?}");
    println!(
        "axis_separates: {} separating, {} not",
        axis_checked[1], axis_checked[0]
    );
    println!(
        "facets with a penetrating volume: {facet_hits} of {}",
        facets.len()
    );
    println!("{what} f32 volume vs the f64 one (V > 1e-6 V_small): worst {worst_mixed:.3e}");
    w64.report(&format!("{what} overlap_pair f64"));
    w32.report(&format!("{what} overlap_pair f32"));
    wf64.report(&format!("{what} prism_overlap f64"));
    wf32.report(&format!("{what} prism_overlap f32"));

    // The case mix must exercise every path that matters.
    let count = |k: &str| kinds.get(k).copied().unwrap_or(0);
    assert!(
        count("overlapping") > 800,
        "too few overlapping pairs: {kinds:?}"
    );
    assert!(
        count("separated") > 300,
        "too few separated pairs: {kinds:?}"
    );
    assert!(
        count("shallow (V < 1e-6 V_small)") + count("touching (no volume)") > 100,
        "too few touching pairs: {kinds:?}"
    );
    assert!(
        facet_hits > 150,
        "too few penetrating facets ({facet_hits})"
    );
    assert!(
        axis_checked[0] > 100 && axis_checked[1] > 100,
        "axis_separates cases {axis_checked:?}"
    );
    assert!(
        failures.is_empty(),
        "{} parity failures (first 20):\n{}",
        failures.len(),
        failures
            .iter()
            .take(20)
            .cloned()
            .collect::<Vec<_>>()
            .join("\n")
    );
    // Same operations in the same order give the same bits: a change of the order of operations
    // in a header that stays inside the tolerances still shows up as lost bitwise identity.
    for (w, title) in [
        (&w64, "overlap_pair f64"),
        (&w32, "overlap_pair f32"),
        (&wf64, "prism_overlap f64"),
        (&wf32, "prism_overlap f32"),
    ] {
        assert!(
            w.bitwise as f64 >= MIN_BITWISE * w.compared as f64,
            "{what} {title}: only {} of {} results bitwise identical to the Rust reference",
            w.bitwise,
            w.compared
        );
    }
}

/// Runs the harness in `mode` (`--spheres`, `--law`; empty for the pairs and facets of the
/// parity test) on the cases `text` and returns the lines that differ from the Rust results
/// `want`, each as "C++ …\nRust …".
fn harness_mismatches(mode: &str, tag: &str, text: String, want: &[String]) -> Vec<String> {
    harness_mismatches_with(mode, tag, text, want, &[])
}

/// [`harness_mismatches`] with the harness built with extra `-D` options.
fn harness_mismatches_with(
    mode: &str,
    tag: &str,
    text: String,
    want: &[String],
    defines: &[&str],
) -> Vec<String> {
    let root = repo_root();
    let dir = temp_dir(tag);
    let exe = build_harness_with(&root, &dir, defines);
    let cases = dir.join("cases.txt");
    std::fs::write(&cases, text).unwrap();
    let mut cmd = Command::new(&exe);
    if !mode.is_empty() {
        cmd.arg(mode);
    }
    let out = cmd.arg(&cases).output().unwrap();
    assert!(
        out.status.success(),
        "harness failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got: Vec<String> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| l.trim_end().to_string())
        .collect();
    assert_eq!(got.len(), want.len());
    got.iter()
        .zip(want)
        .filter(|(g, w)| g.trim() != w.trim())
        .map(|(g, w)| format!("C++  {g}\nRust {w}"))
        .collect()
}

/// Pair cases of the committed periodic `packing` of template `shape` (its particles' scale):
/// each pair whose centres lie within twice the circumscribed radius by the minimum image, the
/// separation stretched by `1 + dilation`, kept where `keep` (called once for each such pair,
/// in order) says so.
fn packing_pairs(
    packing: &polydem::io::Packing,
    shapes: &[Shape],
    shape: usize,
    dilation: f64,
    mut keep: impl FnMut() -> bool,
) -> Vec<PairCase> {
    use nalgebra::Translation3;
    let p = &packing.particles;
    let reach = 2.0 * shapes[shape].template.circumscribed_radius * p[0].scale;
    let pose = |c, q: UnitQuaternion<f64>| Isometry3::from_parts(Translation3::from(c), q);
    let mut pairs = Vec::new();
    for i in 0..p.len() {
        for j in i + 1..p.len() {
            let mut x = p[j].position - p[i].position;
            for a in 0..3 {
                x[a] -= packing.cell[a] * (x[a] / packing.cell[a]).round();
            }
            let x = x * (1.0 + dilation);
            if x.norm() >= reach || !keep() {
                continue;
            }
            pairs.push(PairCase {
                a: shape,
                b: shape,
                sa: p[i].scale,
                sb: p[j].scale,
                pose_a: pose(p[i].position, p[i].orientation),
                pose_b: pose(p[i].position + x, p[j].orientation),
                axis: Vector3::zeros(),
                margin: 0.0,
                kind: "settled packing",
            });
        }
    }
    pairs
}

/// Mixed precision's routing (`overlap_pair_mixed` of `cuda/pair.cuh`, which the GPU's
/// full pair evaluation runs) against `geometry::pair::overlap_pair_mixed`, the CPU twin's
/// pair geometry, bit for bit: on the random cases of the parity test above and on the
/// contacts of the committed settled packing of dodecahedra, as compressed and dilated by
/// 1e-5 … 1e-4 (faces resting on faces, thinned until most are below f32's resolution, so
/// that both the f32 path and the routing of thin and unproven pairs to f64 are taken). With the
/// LP in f64 (the default) and in f32 (`POLYDEM_MIXED_LP=f32`, `PD_MIXED_LP_F32`, on trial).
#[test]
fn cuda_mixed_precision_routing_matches_the_cpu_twin_bitwise() {
    use polydem::geometry::pair::overlap_pair_mixed_with;
    use polydem::io::Packing;
    let root = repo_root();
    let mut shapes = test_shapes();
    let mut pairs = pair_cases(&shapes, N_PAIRS, 4242);
    let packing = Packing::read(&root.join("launch/bench/packings/dodecahedra.packing")).unwrap();
    shapes.push(Shape {
        name: "dodecahedron of the settled packing",
        template: ConvexTemplate::from_file(&root.join("meshes/particles/dodecahedron.stl"))
            .unwrap(),
    });
    let d = shapes.len() - 1;
    let mut close = 0usize;
    for (k, dilation) in [0.0, 1e-5, 3e-5, 1e-4].into_iter().enumerate() {
        // One close pair in four of each dilation, a different quarter each time.
        pairs.extend(packing_pairs(&packing, &shapes, d, dilation, || {
            close += 1;
            close % 4 == k
        }));
    }
    let (mut w32, mut w64) = (PairWorkspace::<f32>::boxed(), PairWorkspace::<f64>::boxed());
    let mut f64_ws = PairWorkspace::<f64>::boxed();
    // The LP in f64 (the default), then in f32 (POLYDEM_MIXED_LP=f32, PD_MIXED_LP_F32).
    for (wide_lp, defines) in [(true, &[][..]), (false, &["-DPD_MIXED_LP_F32=1"][..])] {
        let (mut in_f64, mut in_f32, mut contacts) = (0, 0, 0);
        let mut want = Vec::with_capacity(pairs.len());
        for (i, c) in pairs.iter().enumerate() {
            let (ta, tb) = (&shapes[c.a].template, &shapes[c.b].template);
            let (a, b) = ((ta, c.sa, &c.pose_a), (tb, c.sb, &c.pose_b));
            let r = from_rust(overlap_pair_mixed_with(&mut w32, &mut w64, a, b, wide_lp));
            if r.status == 0 && r.intersects && r.overlap.volume > 0.0 {
                contacts += 1;
                let wide = from_rust(overlap_pair(&mut f64_ws, a, b));
                if wide.overlap.volume.to_bits() == r.overlap.volume.to_bits() {
                    in_f64 += 1;
                } else {
                    in_f32 += 1;
                }
            }
            let mut l = format!("M {i} {} {}", r.status, u8::from(r.intersects));
            hex3(&mut l, &r.axis);
            put_overlap(&mut l, &r.overlap);
            want.push(l);
        }
        println!(
            "LP in {}: {} pairs ({} of the settled packing): {contacts} contacts, {in_f32} in f32, \
         {in_f64} in f64",
            if wide_lp { "f64" } else { "f32" },
            pairs.len(),
            pairs.len() - N_PAIRS
        );
        assert!(
            in_f32 > 1000 && in_f64 > 100,
            "both paths taken: {in_f32} in f32, {in_f64} in f64"
        );
        let mismatches = harness_mismatches_with(
            "--mixed",
            "cuda-mixed-host",
            case_file(&shapes, &pairs, &[]),
            &want,
            defines,
        );
        assert!(
            mismatches.is_empty(),
            "LP in f64 {wide_lp}: {} of {} pairs differ:\n{}",
            mismatches.len(),
            pairs.len(),
            mismatches[..mismatches.len().min(5)].join("\n")
        );
    }
}

/// The sphere fast path (`cuda/sphere.cuh`) against `geometry::sphere`, bit for bit, on random
/// lenses (apart, touching, shallow, deep, nested, radius ratios up to 1:10) and random caps
/// under triangles (disk inside, across edges and corners, apart, sphere behind the plane).
#[test]
fn cuda_sphere_headers_match_the_rust_reference_bitwise() {
    use polydem::geometry::sphere::{sphere_facet, sphere_lens};
    let mut rng = Rng::new(31);
    let mut uniform = |lo: f64, hi: f64| rng.range(lo, hi);
    let mut contacts = 0;
    let mut text = String::new();
    let mut want = Vec::new();
    let n = 2000;
    writeln!(text, "lenses {n}").unwrap();
    for i in 0..n {
        let (ra, rb) = (uniform(0.1, 1.0), uniform(0.1, 1.0));
        let dir = Vector3::new(uniform(-1.0, 1.0), uniform(-1.0, 1.0), uniform(-1.0, 1.0));
        let dist = match i % 4 {
            0 => (ra + rb) * uniform(0.999, 1.001), // about to touch
            1 => (ra + rb) * uniform(0.5, 1.2),
            2 => (ra - rb).abs() * uniform(0.0, 1.0), // nested
            _ => (ra + rb) * uniform(0.0, 2.0),
        };
        let d = dir.normalize() * dist;
        hex(&mut text, ra);
        hex(&mut text, rb);
        hex3(&mut text, &d);
        text.push('\n');
        let mut l = format!("L {i}");
        let o = sphere_lens(ra, rb, &d);
        contacts += usize::from(o.volume > 0.0);
        put_overlap(&mut l, &o);
        want.push(l);
    }
    writeln!(text, "caps {n}").unwrap();
    for i in 0..n {
        let tri = [0, 1, 2]
            .map(|_| Vector3::new(uniform(-1.0, 1.0), uniform(-1.0, 1.0), uniform(-0.2, 0.2)));
        let nrm = (tri[1] - tri[0]).cross(&(tri[2] - tri[0])).normalize();
        let r = uniform(0.05, 1.0);
        let on = (tri[0] + tri[1] + tri[2]) / 3.0
            + Vector3::new(uniform(-1.0, 1.0), uniform(-1.0, 1.0), uniform(-1.0, 1.0));
        let c = on + nrm * (r * uniform(-1.2, 1.1));
        hex3(&mut text, &c);
        hex(&mut text, r);
        for v in &tri {
            hex3(&mut text, v);
        }
        hex3(&mut text, &nrm);
        text.push('\n');
        let mut l = format!("C {i}");
        let o = sphere_facet(&c, r, &tri, &nrm);
        contacts += usize::from(o.volume > 0.0);
        put_overlap(&mut l, &o);
        want.push(l);
    }
    let mismatches = harness_mismatches("--spheres", "cuda-sphere-host", text, &want);
    println!(
        "{} sphere cases, {contacts} with some overlap, {} differ",
        want.len(),
        mismatches.len()
    );
    assert!(
        mismatches.is_empty(),
        "{}",
        mismatches[..mismatches.len().min(5)].join("\n")
    );
}

/// A vector with components uniform in [lo, hi).
fn rand3(rng: &mut Rng, lo: f64, hi: f64) -> Vector3<f64> {
    Vector3::new(rng.range(lo, hi), rng.range(lo, hi), rng.range(lo, hi))
}

/// The contact law (`cuda/contact_law.cuh`) and the portable math it and the integrator use
/// (`portable_sin_cos`, `portable_cbrt` in `cuda/common.cuh`) against `contact::law` and
/// `geometry::real`, bit for bit. The law's cases cover every branch: first touch with the
/// kick window open and carrying the missed share, the slope at V, a body wholly inside the
/// other (|S| ≈ 0), spheres on walls and on spheres, sticking and sliding springs, twisting
/// friction within and at its Coulomb cap, rocking damping at its one-step bound, rolling
/// friction at its Coulomb value and at the step's lock, μ = 0, e = 1,
/// dt = 0 (the first force evaluation), and face contacts sampled along their trajectory
/// (`face_window = "trajectory"`), first touches among them.
#[test]
fn cuda_contact_law_and_math_match_the_rust_reference_bitwise() {
    use polydem::contact::{ContactKinematics, ContactParameters, ContactState, contact_forces};
    use polydem::geometry::{
        portable_cbrt, portable_exp, portable_ln, portable_pow, portable_sin_cos,
    };
    let mut rng = Rng::new(47);
    let mut text = String::new();
    let mut want = Vec::new();
    let n = 4000;
    writeln!(text, "sincos {n}").unwrap();
    for i in 0..n {
        let x = match i % 3 {
            0 => rng.range(-1e-2, 1e-2),
            1 => rng.range(-10.0, 10.0),
            _ => rng.range(-1e5, 1e5),
        };
        hex(&mut text, x);
        text.push('\n');
        let (s, c) = portable_sin_cos(x);
        let mut l = format!("S {i}");
        hex(&mut l, s);
        hex(&mut l, c);
        want.push(l);
    }
    writeln!(text, "cbrt {n}").unwrap();
    for i in 0..n {
        let x = 10f64.powf(rng.range(-320.0, 300.0)) * if i % 2 == 0 { 1.0 } else { -1.0 };
        hex(&mut text, x);
        text.push('\n');
        let mut l = format!("R {i}");
        hex(&mut l, portable_cbrt(x));
        want.push(l);
    }
    writeln!(text, "pow {n}").unwrap();
    for i in 0..n {
        // The law's range (ratios in [0, 2], exponents in [1, 3]) and beyond.
        let (x, y) = if i % 2 == 0 {
            (rng.range(0.0, 2.0), rng.range(1.0, 3.0))
        } else {
            (
                10f64.powf(rng.range(-300.0, 300.0)),
                rng.range(-700.0, 700.0),
            )
        };
        hex(&mut text, x);
        hex(&mut text, y);
        text.push('\n');
        let mut l = format!("P {i}");
        hex(&mut l, portable_ln(x));
        hex(&mut l, portable_exp(y));
        hex(&mut l, portable_pow(x, y));
        want.push(l);
    }
    writeln!(text, "law {n}").unwrap();
    // window, first-touch share, inside, sliding, twist cap, sphere, exit, split caps,
    // trajectory, trajectory at first touch, deep face off the trajectory, rolling couple,
    // rolling couple at the step's lock
    let mut branches = [0usize; 13];
    for i in 0..n {
        let sphere = i % 4 == 3;
        let e = if i % 5 == 0 {
            1.0
        } else {
            0.1 + 0.85 * ((i * 7919) % 100) as f64 / 100.0
        };
        let mu = if i % 7 == 0 { 0.0 } else { 0.5 };
        let damping = if e < 1.0 {
            polydem::contact::hunt_crossley_alpha(e)
        } else {
            0.0
        };
        let params = ContactParameters {
            normal_stiffness: 2e8 * (1.0 + (i % 3) as f64),
            tangential_stiffness: 8e7,
            restitution: e,
            friction: mu,
            // Rolling friction on a third of the cases, from a couple far below the step's
            // lock to one far above it.
            rolling_friction: if i % 3 == 1 {
                10f64.powf(rng.range(-4.0, 0.0))
            } else {
                0.0
            },
            damping,
            rocking: !sphere,
            // A quarter of the cases along the trajectory (docs/contact.md §1): the face
            // contacts among them take its branch.
            face_window: if i % 4 == 2 {
                polydem::contact::FaceWindow::Trajectory
            } else {
                polydem::contact::FaceWindow::Secant
            },
        };
        let log_e = e.ln();
        let log_norm = (log_e.powi(2) + std::f64::consts::PI.powi(2)).sqrt();
        let volume = 10f64.powf(-14.0 + 6.0 * ((i * 37) % 97) as f64 / 97.0);
        let size = volume.cbrt();
        let inside = i % 17 == 0;
        let s_len = if inside {
            1e-10 * size * size
        } else {
            size * size * (1.0 + 50.0 * ((i * 13) % 11) as f64)
        };
        let normal = Vector3::from(rng.unit_vector());
        let x_a = rand3(&mut rng, -0.01, 0.01);
        let x_b = x_a + normal * 0.005 + rand3(&mut rng, -1e-3, 1e-3);
        let overlap = Overlap {
            volume,
            centroid: (x_a + x_b) * 0.5 + rand3(&mut rng, -1e-4, 1e-4),
            dv_dxb: -normal * s_len,
            moment_b: rand3(&mut rng, -1.0, 1.0) * (s_len * size * 0.1),
            depth: size * 0.1,
            // Local exponents k = |S| h / V from faces (k ≤ 1.5, the kick window) to vertices,
            // and a geometry without a thickness.
            thickness: if i % 23 == 0 {
                0.0
            } else {
                volume / s_len * [0.7, 1.0, 1.0, 1.2, 1.45, 2.0, 3.5][i % 7]
            },
        };
        let speed = 10f64.powf(rng.range(-3.0, 0.5));
        let mut kin = ContactKinematics {
            x_a,
            x_b,
            v_a: rand3(&mut rng, -1.0, 1.0) * speed,
            v_b: rand3(&mut rng, -1.0, 1.0) * speed,
            w_a: rand3(&mut rng, -1.0, 1.0) * (speed * 100.0),
            w_b: rand3(&mut rng, -1.0, 1.0) * (speed * 100.0),
            effective_mass: 10f64.powf(rng.range(-4.0, -2.0)),
            inverse_mass_a: 10f64.powf(rng.range(2.0, 4.0)),
            inverse_mass_b: if i % 6 == 1 {
                0.0
            } else {
                10f64.powf(rng.range(2.0, 4.0))
            },
            q_a: UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(
                nalgebra::Vector4::from(rng.unit_quaternion()),
            )),
            q_b: UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(
                nalgebra::Vector4::from(rng.unit_quaternion()),
            )),
            inverse_inertia_a: rand3(&mut rng, 1e6, 1e8),
            inverse_inertia_b: if i % 6 == 1 {
                Vector3::zeros()
            } else {
                rand3(&mut rng, 1e6, 1e8)
            },
            sphere_radius_a: if sphere { 0.005 } else { 0.0 },
            sphere_radius_b: if sphere && i % 8 == 3 { 0.004 } else { 0.0 },
            split_a: 1.0,
            split_b: 1.0,
            dashpot_mass: 0.0,
        };
        // The caps' mass splitting: single contacts (shares 1, the dashpot mass the effective
        // one) and bodies with up to 26 contacts each.
        if i % 4 == 1 {
            kin.split_a = ((i * 31) % 26 + 1) as f64;
            kin.split_b = if kin.inverse_inertia_b == Vector3::zeros() {
                1.0
            } else {
                ((i * 17) % 26 + 1) as f64
            };
            kin.dashpot_mass =
                kin.effective_mass / rng.range(1.0, 0.5 * (kin.split_a + kin.split_b));
        } else {
            kin.dashpot_mass = kin.effective_mass;
        }
        // Bodies moving together: the normal speed is exactly 0 (the reference speed's
        // branch for a contact at rest).
        if i % 29 == 11 {
            kin.v_b = kin.v_a;
            kin.w_a = Vector3::zeros();
            kin.w_b = Vector3::zeros();
        }
        let first = i % 3 == 0;
        let state = ContactState {
            spring: if first {
                Vector3::zeros()
            } else {
                rand3(&mut rng, -1.0, 1.0) * 10f64.powf(rng.range(-9.0, -4.0))
            },
            // Loading (positive) or unloading (negative) cycles of the reference speed.
            approach_speed: if first {
                0.0
            } else if i % 5 < 2 {
                -speed * rng.range(0.5, 2.0)
            } else {
                speed * rng.range(0.5, 2.0)
            },
            twist: if first {
                0.0
            } else {
                rng.range(-1.0, 1.0) * 10f64.powf(rng.range(-6.0, 0.0))
            },
        };
        let dt = if i % 19 == 0 {
            0.0
        } else {
            10f64.powf(rng.range(-7.0, -5.0))
        };
        for x in [
            params.normal_stiffness,
            params.tangential_stiffness,
            e,
            mu,
            damping,
            log_e,
            log_norm,
            if params.rocking { 1.0 } else { 0.0 },
            if params.face_window == polydem::contact::FaceWindow::Trajectory {
                1.0
            } else {
                0.0
            },
            params.rolling_friction,
            volume,
        ] {
            hex(&mut text, x);
        }
        hex3(&mut text, &overlap.centroid);
        hex3(&mut text, &overlap.dv_dxb);
        hex3(&mut text, &overlap.moment_b);
        hex(&mut text, overlap.depth);
        hex(&mut text, overlap.thickness);
        for v in [kin.x_a, kin.x_b, kin.v_a, kin.v_b, kin.w_a, kin.w_b] {
            hex3(&mut text, &v);
        }
        hex(&mut text, kin.effective_mass);
        hex(&mut text, kin.inverse_mass_a);
        hex(&mut text, kin.inverse_mass_b);
        for q in [kin.q_a, kin.q_b] {
            for x in [q.w, q.i, q.j, q.k] {
                hex(&mut text, x);
            }
        }
        hex3(&mut text, &kin.inverse_inertia_a);
        hex3(&mut text, &kin.inverse_inertia_b);
        hex(&mut text, kin.sphere_radius_a);
        hex(&mut text, kin.sphere_radius_b);
        hex(&mut text, kin.split_a);
        hex(&mut text, kin.split_b);
        hex(&mut text, kin.dashpot_mass);
        hex3(&mut text, &state.spring);
        hex(&mut text, state.approach_speed);
        hex(&mut text, state.twist);
        hex(&mut text, dt);
        text.push('\n');
        let mut after = state;
        let f = contact_forces(&params, &overlap, &kin, &mut after, dt);
        // Which branches the case took (recomputed as the law does).
        let area = overlap.area();
        let vn = (kin.v_b - kin.v_a).dot(&normal);
        let sweep = 0.5 * vn.abs() * dt * area;
        let depth = if overlap.thickness > 0.0 {
            overlap.thickness
        } else {
            volume / area
        };
        let face = !inside && area * depth / volume < 1.5;
        let trajectory = params.face_window == polydem::contact::FaceWindow::Trajectory;
        let windowed = face && !trajectory;
        // Along the trajectory within a few steps of entry or exit (trajectory.rs
        // TRAJECTORY_FRACTION), the slope at V deeper.
        let along = face && trajectory && dt > 0.0 && sweep > 0.1 * volume;
        branches[8] += usize::from(along);
        branches[9] += usize::from(along && first);
        branches[10] += usize::from(face && trajectory && dt > 0.0 && !along);
        branches[0] += usize::from(windowed && sweep > 0.5 * volume);
        branches[1] +=
            usize::from(windowed && first && volume - 2.0 * sweep <= 0.0 && volume - sweep > 0.0);
        // The exit, estimated with the speed before the kick (the law adds the kick's share).
        branches[6] += usize::from(
            windowed && vn > 0.0 && depth - vn * dt <= 0.0 && depth - 0.5 * vn * dt > 0.0,
        );
        branches[2] += usize::from(inside);
        // Sliding: the friction force is exactly the Coulomb force; the twist likewise its cap.
        let n_used = -overlap.dv_dxb / area;
        let f_normal = f.force_b.dot(&n_used);
        let f_tangential = (f.force_b - n_used * f_normal).norm();
        let disk = area / std::f64::consts::PI;
        let near = |a: f64, b: f64| b > 0.0 && (a - b).abs() <= 1e-9 * b;
        branches[3] += usize::from(mu > 0.0 && near(f_tangential, mu * f_normal));
        let (twist_before, twist_after) = (state.twist, after.twist);
        branches[4] += usize::from(
            mu > 0.0 && twist_after != 0.0 && twist_before != 0.0 && {
                // The twisting couple is capped where the element slipped: its stored state is
                // not the stick step's.
                let k_tw = 0.5 * params.tangential_stiffness * area * disk;
                let w_rel = kin.w_b - kin.w_a;
                let stick = twist_before + w_rel.dot(&n_used) * dt * k_tw.sqrt();
                (twist_after - stick).abs() > 1e-9 * stick.abs().max(twist_after.abs())
            },
        );
        branches[5] += usize::from(sphere);
        // The caps' mass splitting changed the outcome (the same contact with whole masses).
        let whole = ContactKinematics {
            split_a: 1.0,
            split_b: 1.0,
            dashpot_mass: kin.effective_mass,
            ..kin
        };
        let f_whole = contact_forces(&params, &overlap, &whole, &mut state.clone(), dt);
        branches[7] += usize::from(
            f_whole.force_b != f.force_b
                || f_whole.torque_a != f.torque_a
                || f_whole.torque_b != f.torque_b,
        );
        // The rolling couple acted (the torques differ without it), at its Coulomb value or at
        // the step's lock (which μ_r does not change: doubling μ_r leaves the torques).
        if params.rolling_friction > 0.0 {
            let with = |rolling_friction| {
                let p = ContactParameters {
                    rolling_friction,
                    ..params.clone()
                };
                contact_forces(&p, &overlap, &kin, &mut state.clone(), dt)
            };
            let (none, twice) = (with(0.0), with(2.0 * params.rolling_friction));
            let rolled = none.torque_b != f.torque_b;
            branches[11] += usize::from(rolled);
            branches[12] += usize::from(rolled && twice.torque_b == f.torque_b);
        }
        let mut l = format!("W {i}");
        hex3(&mut l, &f.force_b);
        hex3(&mut l, &f.torque_a);
        hex3(&mut l, &f.torque_b);
        hex(&mut l, f.elastic_energy);
        hex3(&mut l, &after.spring);
        hex(&mut l, after.approach_speed);
        hex(&mut l, after.twist);
        want.push(l);
    }
    let mismatches = harness_mismatches("--law", "cuda-law-host", text, &want);
    println!(
        "{} cases ({n} sin/cos, {n} cbrt, {n} ln/exp/pow, {n} law; law branches: window {}, \
         first-touch share {}, inside {}, sliding {}, twist capped {}, spheres {}, exit {}, \
         split caps {}, trajectory {}, trajectory at first touch {}, deep face off the \
         trajectory {}, rolling couple {}, rolling couple at its lock {}), {} differ",
        want.len(),
        branches[0],
        branches[1],
        branches[2],
        branches[3],
        branches[4],
        branches[5],
        branches[6],
        branches[7],
        branches[8],
        branches[9],
        branches[10],
        branches[11],
        branches[12],
        mismatches.len()
    );
    for (k, what) in [
        "window",
        "first-touch share",
        "inside",
        "sliding",
        "twist cap",
        "spheres",
        "exit",
        "split caps",
        "trajectory",
        "trajectory at first touch",
        "deep face off the trajectory",
        "rolling couple",
        "rolling couple at its lock",
    ]
    .iter()
    .enumerate()
    {
        assert!(
            branches[k] >= 20,
            "only {} law cases take the {what} branch",
            branches[k]
        );
    }
    assert!(
        mismatches.is_empty(),
        "{}",
        mismatches[..mismatches.len().min(5)].join("\n")
    );
}

/// The enumeration past 8 planes (`POLYDEM_ENUM_PLANES=16`; the headers with
/// `-DPD_ENUM_MAX_PLANES=16`) gives the Rust results bit for bit: f64 and f32 pairs, and mixed
/// precision's routing, on contacts of the committed settled cells of mineral grains and
/// cylinders, most of which keep 9–16 planes. The setting is read once per process, so this runs
/// [`sixteen_planes_in_this_process`] again in a child process with it.
#[test]
fn the_sixteen_plane_enumeration_matches_the_rust_reference_bitwise() {
    let out = Command::new(std::env::current_exe().unwrap())
        .env("POLYDEM_ENUM_PLANES", "16")
        .args([
            "--ignored",
            "--exact",
            "sixteen_planes_in_this_process",
            "--nocapture",
        ])
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    println!("{stdout}");
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("1 passed"), "{stdout}");
}

#[test]
#[ignore = "run by the_sixteen_plane_enumeration_matches_the_rust_reference_bitwise"]
fn sixteen_planes_in_this_process() {
    use polydem::geometry::pair::overlap_pair_mixed;
    use polydem::geometry::vertex_enumeration::enum_planes;
    use polydem::io::Packing;
    // `--ignored` runs this test in the parent process too, where the setting is not made:
    // there it leaves the check to the child the test above starts.
    if std::env::var("POLYDEM_ENUM_PLANES").as_deref() != Ok("16") {
        println!("POLYDEM_ENUM_PLANES=16 is not set: checked in the child process instead");
        return;
    }
    assert_eq!(enum_planes(), 16, "POLYDEM_ENUM_PLANES=16 set but not seen");
    let root = repo_root();
    let mineral =
        ConvexTemplate::from_file(&root.join("meshes/particles/mineral_grain.stl")).unwrap();
    let cylinder =
        polydem::scene::load_scene(&root.join("launch/bench/settled/cylinders_1e5.toml"))
            .unwrap()
            .templates[0]
            .clone();
    let shapes = vec![
        Shape {
            name: "mineral grain",
            template: mineral,
        },
        Shape {
            name: "cylinder",
            template: cylinder,
        },
    ];
    let mut pairs = Vec::new();
    for (t, name) in [(0, "mineral_grains"), (1, "cylinders")] {
        let cell =
            Packing::read(&root.join(format!("launch/bench/packings/{name}.packing"))).unwrap();
        let mut close = 0;
        pairs.extend(packing_pairs(&cell, &shapes, t, 0.0, || {
            close += 1;
            close % 8 == 0
        }));
    }
    let (mut w32, mut w64) = (PairWorkspace::<f32>::boxed(), PairWorkspace::<f64>::boxed());
    let (mut plain, mut mixed) = (Vec::new(), Vec::new());
    let mut past8 = 0;
    for (i, c) in pairs.iter().enumerate() {
        let (ta, tb) = (&shapes[c.a].template, &shapes[c.b].template);
        let (a, b) = ((ta, c.sa, &c.pose_a), (tb, c.sb, &c.pose_b));
        let mut l = format!("P {i}");
        let r64 = from_rust(overlap_pair(&mut w64, a, b));
        past8 += usize::from(r64.intersects && w64.a.planes().len() + w64.b.planes().len() > 8);
        let r32 = from_rust(overlap_pair(&mut w32, a, b));
        for r in [&r64, &r32] {
            write!(l, " {} {}", r.status, u8::from(r.intersects)).unwrap();
            hex3(&mut l, &r.axis);
            put_overlap(&mut l, &r.overlap);
        }
        write!(l, " {}", u8::from(axis_separates(a, b, &c.axis, c.margin))).unwrap();
        plain.push(l);
        let r = from_rust(overlap_pair_mixed(&mut w32, &mut w64, a, b));
        let mut l = format!("M {i} {} {}", r.status, u8::from(r.intersects));
        hex3(&mut l, &r.axis);
        put_overlap(&mut l, &r.overlap);
        mixed.push(l);
    }
    println!(
        "{} pairs of the settled cells, {past8} intersecting with more than 8 planes",
        pairs.len()
    );
    assert!(past8 > 1500, "only {past8} pairs past 8 planes");
    let text = case_file(&shapes, &pairs, &[]);
    for (mode, want) in [("", &plain), ("--mixed", &mixed)] {
        let differ = harness_mismatches_with(
            mode,
            "cuda-enum16",
            text.clone(),
            want,
            &["-DPD_ENUM_MAX_PLANES=16"],
        );
        assert!(
            differ.is_empty(),
            "{mode}: {} of {} pairs differ:\n{}",
            differ.len(),
            want.len(),
            differ[..differ.len().min(3)].join("\n")
        );
    }
}

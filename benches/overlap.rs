//! CPU throughput of the pair geometry: GJK and the dual-space overlap of dodecahedra (and the
//! other seed shapes), in pairs per second on one core, f64 and f32.
//!
//! The pairs are random overlapping placements (centre distance uniform in [0.3, 1] of the
//! circumscribed diameter), the population a dense packing's contact list sees after the broad
//! phase. Run with `cargo bench --bench overlap`.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use polydem::geometry::Real;
use polydem::geometry::gjk_intersect;
use polydem::geometry::pair::{PairWorkspace, overlap_pair};
use polydem::rng::Rng;
use polydem::shape::{ConvexTemplate, Generator};
use std::hint::black_box;

const PAIRS: usize = 1000;

fn poses(t: &ConvexTemplate, seed: u64) -> Vec<(Isometry3<f64>, Isometry3<f64>)> {
    let mut rng = Rng::new(seed);
    let rot = |rng: &mut Rng| {
        let [w, x, y, z] = rng.unit_quaternion();
        UnitQuaternion::new_normalize(Quaternion::new(w, x, y, z))
    };
    (0..PAIRS)
        .map(|_| {
            let d = 2.0 * t.circumscribed_radius * rng.range(0.3, 1.0);
            let dir = Vector3::from(rng.unit_vector());
            (
                Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.0), rot(&mut rng)),
                Isometry3::from_parts((dir * d).into(), rot(&mut rng)),
            )
        })
        .collect()
}

fn bench_overlap<T: Real>(c: &mut Criterion, label: &str, t: &ConvexTemplate) {
    let cases = poses(t, 1);
    let mut ws = PairWorkspace::<T>::boxed();
    let mut group = c.benchmark_group(format!("overlap_{label}"));
    group.throughput(Throughput::Elements(PAIRS as u64));
    group.bench_function(std::any::type_name::<T>(), |b| {
        b.iter(|| {
            let mut total = 0.0;
            for (pa, pb) in &cases {
                let g = overlap_pair(&mut ws, (t, 1.0, pa), (t, 1.0, pb)).unwrap();
                total += g.overlap.volume;
            }
            black_box(total)
        })
    });
    group.finish();
}

fn bench_gjk(c: &mut Criterion, label: &str, t: &ConvexTemplate) {
    type VertexPair = (Vec<Vector3<f64>>, Vec<Vector3<f64>>);
    let cases: Vec<VertexPair> = poses(t, 2)
        .iter()
        .map(|(pa, pb)| {
            (
                t.vertices.iter().map(|v| (pa * v).coords).collect(),
                t.vertices.iter().map(|v| (pb * v).coords).collect(),
            )
        })
        .collect();
    let mut group = c.benchmark_group(format!("gjk_{label}"));
    group.throughput(Throughput::Elements(PAIRS as u64));
    group.bench_function("f64", |b| {
        b.iter(|| {
            cases
                .iter()
                .filter(|(a, bb)| gjk_intersect(a, bb, bb[0] - a[0]))
                .count()
        })
    });
    group.finish();
}

fn benches(c: &mut Criterion) {
    let dodeca = Generator::Dodecahedron { size: 1.0 }.build().unwrap();
    bench_gjk(c, "dodecahedron", &dodeca);
    bench_overlap::<f64>(c, "dodecahedron", &dodeca);
    bench_overlap::<f32>(c, "dodecahedron", &dodeca);
    let cube = Generator::Cube { size: 1.0 }.build().unwrap();
    bench_overlap::<f64>(c, "cube", &cube);
    let cylinder = Generator::Prism {
        sides: 20,
        diameter: 8.0,
        height: 5.3,
    }
    .build()
    .unwrap();
    bench_overlap::<f64>(c, "cylinder20", &cylinder);
}

criterion_group! {
    name = overlap;
    config = Criterion::default().sample_size(20).measurement_time(std::time::Duration::from_secs(3));
    targets = benches
}
criterion_main!(overlap);

use nalgebra::Vector3;
use polydem::geometry::overlap::{PairWorkspace, overlap_pair};
use polydem::geometry::{chebyshev_centre, Plane};
use polydem::rng::Rng;
#[path = "../tests/common/mod.rs"]
mod common;
use common::*;
fn main() {
    let shapes = test_shapes();
    let mut rng = Rng::new(2026);
    let k = shapes.len();
    let want: Vec<usize> = std::env::args().skip(1).map(|s| s.parse().unwrap()).collect();
    let mut ws = PairWorkspace::<f64>::boxed();
    for i in 0..2420 {
        let (a, b) = (i % k, (i / k) % k);
        let ra = shapes[a].template.circumscribed_radius;
        let rb = shapes[b].template.circumscribed_radius;
        let pa = Vector3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
        let dir = Vector3::from(rng.unit_vector());
        let dist = rng.uniform() * 1.05 * (ra + rb);
        let pose_a = pose(pa, random_rotation(&mut rng));
        let pose_b = pose(pa + dir * dist, random_rotation(&mut rng));
        if !want.contains(&i) { continue; }
        let (ta, tb) = (&shapes[a].template, &shapes[b].template);
        let r = overlap_pair(&mut ws, (ta, 1.0, &pose_a), (tb, 1.0, &pose_b));
        let mut planes = world_planes(ta, &pose_a);
        planes.extend(world_planes(tb, &pose_b));
        let o = oracle_intersection(&planes, 5.0);
        println!("case {i} {} vs {}: {:?}\n oracle {}", shapes[a].name, shapes[b].name, r, o.volume);
        let pl: Vec<Plane<f64>> = planes.iter().map(|(n,h)| Plane{normal:*n, offset:*h}).collect();
        let na = ta.faces.len();
        let c = chebyshev_centre(&pl[..na], &pl[na..], (pose_a.translation.vector + pose_b.translation.vector)/2.0);
        let o = pose_a.translation.vector;
        let pl2: Vec<Plane<f64>> = planes.iter().map(|(n,h)| Plane{normal:*n, offset:*h - n.dot(&o)}).collect();
        let c2 = chebyshev_centre(&pl2[..na], &pl2[na..], (pose_b.translation.vector - o)/2.0);
        println!(" cheb pair frame {:?}", c2);
        println!(" cheb {:?}", c);
    }
}

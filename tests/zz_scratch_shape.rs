use nalgebra::{Point3, UnitQuaternion, Vector3};
use polydem::rng::Rng;
use polydem::shape::ConvexTemplate;
#[test]
fn scratch() {
    let mut rng = Rng::new(5);
    let mut stats = std::collections::BTreeMap::new();
    for trial in 0..3000 {
        let kind = trial % 3;
        let n = 4 + (rng.uniform() * 60.0) as usize;
        let noise = [0.0, 1e-12, 1e-9, 1e-7, 1e-6, 3e-6, 1e-5, 1e-4][(rng.uniform() * 8.0) as usize];
        let q = UnitQuaternion::from_euler_angles(rng.range(0.0, 6.0), rng.range(0.0, 6.0), rng.range(0.0, 6.0));
        let pts: Vec<Point3<f64>> = (0..n).map(|_| {
            let p = match kind {
                0 => Vector3::new((rng.uniform()*4.0).floor(), (rng.uniform()*4.0).floor(), (rng.uniform()*4.0).floor()),
                1 => { let mut c = [rng.range(-1.0,1.0), rng.range(-1.0,1.0), rng.range(-1.0,1.0)]; let k = (rng.uniform()*3.0) as usize; c[k] = c[k].signum(); Vector3::new(c[0],c[1],c[2]) }
                _ => { let u = rng.unit_vector(); let r = if rng.uniform() < 0.5 {1.0} else {0.5}; Vector3::new(u[0]*r, u[1]*r, (u[2]*r).clamp(-0.3,0.3)) }
            };
            let j = Vector3::new(rng.range(-1.0,1.0), rng.range(-1.0,1.0), rng.range(-1.0,1.0)) * noise;
            Point3::from(q * (p + j))
        }).collect();
        let key = match ConvexTemplate::from_points("t", &pts) {
            Ok(t) => {
                // invariants
                let size = 2.0*t.circumscribed_radius;
                let mut bad = false;
                for f in &t.faces { for v in &t.vertices { if f.normal.dot(&v.coords) > f.offset + 1e-12*size { bad = true; } } }
                let mapped: Vec<_> = pts.iter().map(|p| t.file_to_body * p).collect();
                let mut worst: f64 = 0.0;
                for f in &t.faces { for m in &mapped { worst = worst.max(f.normal.dot(&m.coords) - f.offset); } }
                if worst > 1e-5 * size { println!("trial {trial} kind {kind} noise {noise}: input point outside by {:e} nf {} nv {} pts {:?}", worst/size, t.faces.len(), t.vertices.len(), pts.iter().map(|p| [p.x,p.y,p.z]).collect::<Vec<_>>()); bad = true; }
                if bad { "ok-but-bad".to_string() } else { "ok".to_string() }
            }
            Err(e) => { let s = e.to_string(); if s.contains("construction fail") { println!("trial {trial} kind {kind} noise {noise} n {n}: {s}"); } s.split(':').nth(1).unwrap_or("").chars().take(30).collect() }
        };
        *stats.entry(key).or_insert(0) += 1;
    }
    println!("{stats:#?}");
}

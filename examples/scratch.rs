use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use polydem::geometry::overlap::{PairWorkspace, overlap_pair};
use polydem::shape::Generator;
fn main() {
    let cube = Generator::Cuboid { a: 1.0, b: 1.0, c: 1.0 }.build().unwrap();
    let mut ws = PairWorkspace::<f64>::boxed();
    for (qa, far) in [((0.0,0.0,0.0), 0.0), ((0.3,-1.1,2.0), 0.0), ((0.3,-1.1,2.0), 1e3), ((0.0,0.0,0.3), 0.0), ((0.3,0.0,0.0), 0.0), ((0.0,0.3,0.0), 0.0)] {
        let q = UnitQuaternion::from_euler_angles(qa.0, qa.1, qa.2);
        let far = Vector3::new(far, -2.0 * far, 0.5 * far);
        let pa = Isometry3::from_parts(far.into(), q);
        let pb = Isometry3::from_parts((far + q * Vector3::new(1.0 - 1e-4, 0.2, 0.0)).into(), q);
        let r = overlap_pair(&mut ws, (&cube, 1.0, &pa), (&cube, 1.0, &pb)).unwrap();
        println!("{qa:?} V = {:e} depth {:e}", r.overlap.volume, r.overlap.depth);
    }
}

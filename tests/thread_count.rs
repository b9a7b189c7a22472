//! A run is bitwise the same at any thread count (docs/design.md §4): the CPU backend's loops
//! split by rayon only decide who computes which item (`polydem::par`), never the arithmetic.
//! The small pour (330 dodecahedra of 4 mm into an open box STL) stepped on one thread
//! and on three must agree in every bit of every particle field.

mod common;

use common::*;
use polydem::pipeline::Simulation;
use polydem::scene::load_scene;
use polydem::state::Particles;

/// Steps the small pour for `steps` steps inside a pool of `threads` threads.
fn pour_after(steps: u64, threads: usize) -> (Particles, usize) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let scene = load_scene(&repo_root().join("launch/validation/pour_small.toml")).unwrap();
        let mut sim = Simulation::builder(scene).build().unwrap();
        for _ in 0..steps {
            sim.step().unwrap();
        }
        let contacts = (sim.state.stats.contacts + sim.state.stats.wall_contacts) as usize;
        (sim.state.particles.clone(), contacts)
    })
}

#[test]
fn one_thread_and_three_give_the_same_bits() {
    // 7000 steps: the first grains have landed on the floor and on each other.
    let (one, contacts) = pour_after(7000, 1);
    let (three, _) = pour_after(7000, 3);
    assert_eq!(one.len(), 330);
    assert!(
        contacts > 50,
        "only {contacts} contacts: the test would not exercise the pair stage"
    );
    let bits = |p: &Particles| -> Vec<u64> {
        let mut v = Vec::new();
        for i in 0..p.len() {
            v.extend(p.position[i].iter().map(|x| x.to_bits()));
            v.extend(p.velocity[i].iter().map(|x| x.to_bits()));
            v.extend(p.angular_velocity[i].iter().map(|x| x.to_bits()));
            v.extend(p.orientation[i].coords.iter().map(|x| x.to_bits()));
            v.extend(p.force[i].iter().map(|x| x.to_bits()));
            v.extend(p.torque[i].iter().map(|x| x.to_bits()));
        }
        v
    };
    assert_eq!(one.id, three.id);
    let (a, b) = (bits(&one), bits(&three));
    let differing = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    assert_eq!(differing, 0, "{differing} of {} words differ", a.len());
}

//! The halo: ghost (virtual-region) copies of the neighbours' outer-region particles
//! (seed paper Sec. 2.6, docs/design.md §6).
//!
//! At each neighbour-list rebuild a rank decides which of its particles each neighbour needs:
//! those within the halo width (the pair-list cutoff `2 r_max + skin`) of the neighbour's box,
//! or of a periodic image of it. Particles farther than the halo from every face of their own
//! box (the inner region) are never looked at. The chosen particles go out with the ghost
//! payload — global id, type, scale, centroid, velocity, orientation, angular velocity — and
//! the periodic image they were chosen for; mass and inertia follow from type and scale on the
//! receiving side, by the same arithmetic as on the owner. Between rebuilds the same particles
//! are sent in the same order with only what changes each step (centroid, velocity, orientation,
//! angular velocity: 104 bytes a ghost), so the receiver's pair list stays valid.
//!
//! Ghosts keep their true (wrapped) centroid: the pair search takes the minimum-image
//! displacement from it exactly as a single rank does, so a pair across a periodic seam gets
//! bitwise the shift it gets on one rank. The image only decides where the ghost is binned.

use super::decomposition::Subdomains;
use super::pack::{Reader, Writer};
use crate::scene::Scene;
use crate::state::Particles;
use nalgebra::Vector3;

/// Which owned particles go to whom, fixed from one rebuild to the next.
#[derive(Clone, Debug, Default)]
pub struct HaloPlan {
    /// Neighbour ranks, sorted ([`Subdomains::neighbours`]).
    pub neighbours: Vec<usize>,
    /// Per neighbour: local index of each particle sent, with its image offset.
    pub sends: Vec<Vec<(u32, [i8; 3])>>,
    /// Own particles needed as ghosts of this rank itself, at a periodic image (a box that
    /// does not span a periodic axis but is its only rank along it cannot occur with boxes at
    /// least 2 × halo wide, yet the case is kept general).
    pub self_images: Vec<(u32, [i8; 3])>,
}

/// Ghost particles and where they are binned.
#[derive(Clone, Debug, Default)]
pub struct Ghosts {
    /// The ghosts' state (force and torque unused), neighbour by neighbour in
    /// [`HaloPlan::neighbours`] order, then this rank's own images.
    pub particles: Particles,
    /// Image offset of each ghost.
    pub images: Vec<[i8; 3]>,
}

impl HaloPlan {
    /// The plan for `rank` holding `positions` (its owned particles).
    pub fn new(sub: &Subdomains, rank: usize, positions: &[Vector3<f64>]) -> Self {
        let neighbours = sub.neighbours(rank);
        let own = sub.boxes[rank];
        let h = sub.halo;
        // Axes along which this box has a boundary that another box lies behind.
        let bounded: Vec<usize> = (0..3).filter(|&k| !sub.spans(rank, k)).collect();
        let targets: Vec<(usize, Vec<[i8; 3]>)> = neighbours
            .iter()
            .map(|&r| (r, sub.image_offsets(Some(r))))
            .chain(std::iter::once((rank, sub.image_offsets(Some(rank)))))
            .collect();
        let shifts: Vec<Vec<Vector3<f64>>> = targets
            .iter()
            .map(|(_, offs)| offs.iter().map(|o| sub.shift(o)).collect())
            .collect();
        let mut sends = vec![Vec::new(); neighbours.len()];
        let mut self_images = Vec::new();
        for (i, x) in positions.iter().enumerate() {
            // Inner region: farther than the halo from every boundary of the own box.
            if bounded
                .iter()
                .all(|&k| x[k] - own.lo[k] >= h && own.hi[k] - x[k] >= h)
            {
                continue;
            }
            for (t, (r, offs)) in targets.iter().enumerate() {
                let b = &sub.boxes[*r];
                for (o, s) in offs.iter().zip(&shifts[t]) {
                    if *r == rank && *o == [0, 0, 0] {
                        continue;
                    }
                    if b.distance(&(x + s)) < h {
                        if *r == rank {
                            self_images.push((i as u32, *o));
                        } else {
                            sends[t].push((i as u32, *o));
                        }
                    }
                }
            }
        }
        HaloPlan {
            neighbours,
            sends,
            self_images,
        }
    }

    /// Ghosts sent in all.
    pub fn sent(&self) -> usize {
        self.sends.iter().map(Vec::len).sum()
    }

    /// The particles the plan sends (to any neighbour or as an own image), each once and in
    /// index order, and the same plan over them: entry `m` of that list is particle `m` of the
    /// returned plan. [`build_ghosts`] with it and only these particles sends what it sends with
    /// this plan and all of them (a GPU rank copies down only these).
    pub fn compact(&self) -> (HaloPlan, Vec<u32>) {
        let mut sent: Vec<u32> = self
            .sends
            .iter()
            .flatten()
            .chain(&self.self_images)
            .map(|&(i, _)| i)
            .collect();
        sent.sort_unstable();
        sent.dedup();
        let renumber = |list: &[(u32, [i8; 3])]| -> Vec<(u32, [i8; 3])> {
            list.iter()
                .map(|(i, o)| {
                    let m = sent.binary_search(i).expect("a sent particle is listed");
                    (m as u32, *o)
                })
                .collect()
        };
        let plan = HaloPlan {
            neighbours: self.neighbours.clone(),
            sends: self.sends.iter().map(|l| renumber(l)).collect(),
            self_images: renumber(&self.self_images),
        };
        (plan, sent)
    }
}

/// Full ghost record of particle `i` at image `o`.
fn write_ghost(w: &mut Writer, p: &Particles, i: usize, o: &[i8; 3]) {
    w.u64(p.id[i]);
    w.u32(p.kind[i]);
    w.u32(u32::from_le_bytes([o[0] as u8, o[1] as u8, o[2] as u8, 0]));
    w.f64(p.scale[i]);
    write_motion(w, p, i);
}

/// What changes from step to step: the motion, and the contact count of the last evaluation
/// (the dashpot caps' mass splitting needs the whole count, contacts on other ranks included).
fn write_motion(w: &mut Writer, p: &Particles, i: usize) {
    w.v3(&p.position[i]);
    w.v3(&p.velocity[i]);
    w.quat(&p.orientation[i]);
    w.v3(&p.angular_velocity[i]);
    w.u32(p.contacts[i]);
}

/// Appends a ghost read from a full record.
fn read_ghost(r: &mut Reader, scene: &Scene, g: &mut Ghosts) {
    let id = r.u64();
    let kind = r.u32();
    let o = r.u32().to_le_bytes();
    let scale = r.f64();
    let (x, v, q, w) = (r.v3(), r.v3(), r.quat(), r.v3());
    let contacts = r.u32();
    let ty = &scene.particle_types[kind as usize];
    let density = scene.materials[ty.material].density;
    let p = &mut g.particles;
    p.push(
        id,
        kind,
        scale,
        x,
        q,
        &scene.templates[ty.template],
        density,
    );
    let i = p.len() - 1;
    p.velocity[i] = v;
    p.angular_velocity[i] = w;
    p.contacts[i] = contacts;
    g.images.push([o[0] as i8, o[1] as i8, o[2] as i8]);
}

/// Ghost payload bytes per particle at a rebuild and between rebuilds.
pub const GHOST_BYTES_FULL: usize = 8 + 4 + 4 + 8 + GHOST_BYTES_MOTION;
pub const GHOST_BYTES_MOTION: usize = 13 * 8 + 4;

/// Exchanges the halo with the neighbours: each gets the records `write` makes of the plan's
/// particles for it (`bytes` each); returns what every neighbour sent, in the plan's order,
/// followed by this rank's own images.
fn exchange(
    comm: &dyn super::comm::Comm,
    plan: &HaloPlan,
    bytes: usize,
    write: impl Fn(&mut Writer, usize, &[i8; 3]),
) -> Vec<Vec<u8>> {
    let records = |list: &[(u32, [i8; 3])]| {
        let mut w = Writer::default();
        w.buf.reserve(list.len() * bytes);
        for (i, o) in list {
            write(&mut w, *i as usize, o);
        }
        w.buf
    };
    let sends: Vec<(usize, Vec<u8>)> = plan
        .neighbours
        .iter()
        .zip(&plan.sends)
        .map(|(&r, list)| (r, records(list)))
        .collect();
    let mut received = comm.neighbor_exchange(&sends, &plan.neighbours);
    received.push(records(&plan.self_images));
    received
}

/// Sends every neighbour its ghosts (full records) and returns the ghosts received.
pub fn build_ghosts(
    comm: &dyn super::comm::Comm,
    plan: &HaloPlan,
    owned: &Particles,
    scene: &Scene,
) -> Ghosts {
    let received = exchange(comm, plan, GHOST_BYTES_FULL, |w, i, o| {
        write_ghost(w, owned, i, o)
    });
    let mut g = Ghosts::default();
    for buf in &received {
        let mut r = Reader::new(buf);
        while !r.done() {
            read_ghost(&mut r, scene, &mut g);
        }
    }
    g
}

/// Sends the same particles as the last [`build_ghosts`], motion only, and overwrites the
/// ghosts' motion in the same order.
pub fn refresh_ghosts(
    comm: &dyn super::comm::Comm,
    plan: &HaloPlan,
    owned: &Particles,
    ghosts: &mut Ghosts,
) {
    let received = exchange(comm, plan, GHOST_BYTES_MOTION, |w, i, _| {
        write_motion(w, owned, i)
    });
    let p = &mut ghosts.particles;
    let mut k = 0;
    for buf in &received {
        let mut r = Reader::new(buf);
        while !r.done() {
            p.position[k] = r.v3();
            p.velocity[k] = r.v3();
            p.orientation[k] = r.quat();
            p.angular_velocity[k] = r.v3();
            p.contacts[k] = r.u32();
            k += 1;
        }
    }
    assert_eq!(
        k,
        p.len(),
        "halo refresh: ghost count changed between rebuilds"
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::neighbor::Bounds;
    use crate::rng::Rng;

    /// The plan sends a particle to a rank at an image exactly when that image lies within the
    /// halo of the rank's box (brute force over every rank and image), on a periodic grid of
    /// 3 × 2 × 1 boxes where one rank spans z.
    #[test]
    fn plan_matches_brute_force_over_ranks_and_images() {
        let domain = Bounds {
            min: Vector3::new(0.0, 0.0, 0.0),
            max: Vector3::new(3.0, 2.0, 1.0),
            periodic: [true, false, true],
        };
        let halo = 0.2;
        let sub = Subdomains::grid(domain, halo, [3, 2, 1]);
        let mut rng = Rng::new(21);
        for rank in 0..6 {
            let b = sub.boxes[rank];
            let x: Vec<Vector3<f64>> = (0..3000)
                .map(|_| Vector3::from_fn(|k, _| rng.range(b.lo[k], b.hi[k])))
                .collect();
            let plan = HaloPlan::new(&sub, rank, &x);
            let mut got: Vec<(usize, u32, [i8; 3])> = Vec::new();
            for (t, &r) in plan.neighbours.iter().enumerate() {
                got.extend(plan.sends[t].iter().map(|&(i, o)| (r, i, o)));
            }
            got.extend(plan.self_images.iter().map(|&(i, o)| (rank, i, o)));
            got.sort_unstable();
            let mut want = Vec::new();
            for r in 0..6 {
                for o in sub.image_offsets(Some(r)) {
                    if r == rank && o == [0, 0, 0] {
                        continue;
                    }
                    for (i, p) in x.iter().enumerate() {
                        if sub.boxes[r].distance(&(p + sub.shift(&o))) < halo {
                            want.push((r, i as u32, o));
                        }
                    }
                }
            }
            want.sort_unstable();
            assert_eq!(got.len(), want.len(), "rank {rank}");
            assert_eq!(got, want, "rank {rank}");
            // z is spanned by every box: no image along it, and no self images at all.
            assert!(got.iter().all(|g| g.2[2] == 0));
            assert!(plan.self_images.is_empty());
            // Every rank is sent something: x wraps around, y has two rows.
            assert!(plan.sent() > 100);
            // The compact plan names the same particles through its list, each listed once.
            let (compact, list) = plan.compact();
            assert!(list.windows(2).all(|w| w[0] < w[1]));
            assert!(list.len() < x.len(), "the inner region is not sent");
            for (full, short) in plan.sends.iter().zip(&compact.sends) {
                let back: Vec<(u32, [i8; 3])> =
                    short.iter().map(|&(m, o)| (list[m as usize], o)).collect();
                assert_eq!(&back, full);
            }
            assert_eq!(compact.neighbours, plan.neighbours);
        }
    }
}

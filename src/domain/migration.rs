//! Migration: particles whose centroid left their rank's box move to the owner with their full
//! state and the contact-history entries they are a member of (docs/design.md §6), at neighbour-list
//! rebuilds (between rebuilds a particle may stray up to half the skin outside its box, which
//! the halo width allows for).
//!
//! The same packing carries whole particle sets: checkpoints are gathered on rank 0 and a
//! restart hands each rank its particles ([`pack_particles`], [`unpack_particles`]).

use super::comm::Comm;
use super::decomposition::Subdomains;
use super::pack::{Reader, Writer};
use crate::contact::{ContactHistory, ContactKey, ContactState};
use crate::state::Particles;

/// Appends particle `i` with every field.
pub fn write_particle(w: &mut Writer, p: &Particles, i: usize) {
    w.u64(p.id[i]);
    w.u32(p.kind[i]);
    w.f64(p.scale[i]);
    w.v3(&p.position[i]);
    w.v3(&p.velocity[i]);
    w.quat(&p.orientation[i]);
    w.v3(&p.angular_velocity[i]);
    w.v3(&p.force[i]);
    w.v3(&p.torque[i]);
    w.f64(p.mass[i]);
    w.v3(&p.inertia[i]);
    w.u32(p.contacts[i]);
}

/// Reads a particle written by [`write_particle`] and appends it.
pub fn read_particle(r: &mut Reader, p: &mut Particles) {
    p.id.push(r.u64());
    p.kind.push(r.u32());
    p.scale.push(r.f64());
    p.position.push(r.v3());
    p.velocity.push(r.v3());
    p.orientation.push(r.quat());
    p.angular_velocity.push(r.v3());
    p.force.push(r.v3());
    p.torque.push(r.v3());
    p.mass.push(r.f64());
    p.inertia.push(r.v3());
    p.contacts.push(r.u32());
}

fn write_entry(w: &mut Writer, (k, s): &(ContactKey, ContactState)) {
    w.u64(k.a);
    w.u64(k.b);
    w.v3(&s.spring);
    w.f64(s.approach_speed);
    w.f64(s.twist);
}

fn read_entry(r: &mut Reader) -> (ContactKey, ContactState) {
    let (a, b) = (r.u64(), r.u64());
    let spring = r.v3();
    let (approach_speed, twist) = (r.f64(), r.f64());
    (
        ContactKey { a, b },
        ContactState {
            spring,
            approach_speed,
            twist,
        },
    )
}

/// Particles `which` of `p` and the history entries with a member among them, packed.
pub fn pack_particles(p: &Particles, which: &[usize], history: &ContactHistory) -> Vec<u8> {
    let mut w = Writer::default();
    w.u64(which.len() as u64);
    for &i in which {
        write_particle(&mut w, p, i);
    }
    let mut ids: Vec<u64> = which.iter().map(|&i| p.id[i]).collect();
    ids.sort_unstable();
    let member = |x: u64| ids.binary_search(&x).is_ok();
    let entries: Vec<&(ContactKey, ContactState)> = history
        .entries()
        .iter()
        .filter(|(k, _)| member(k.a) || (k.wall_index().is_none() && member(k.b)))
        .collect();
    w.u64(entries.len() as u64);
    for e in entries {
        write_entry(&mut w, e);
    }
    w.buf
}

/// Appends the particles of a [`pack_particles`] buffer to `p` and returns its history entries.
pub fn unpack_particles(buf: &[u8], p: &mut Particles) -> Vec<(ContactKey, ContactState)> {
    if buf.is_empty() {
        return Vec::new();
    }
    let mut r = Reader::new(buf);
    let n = r.u64();
    for _ in 0..n {
        read_particle(&mut r, p);
    }
    let m = r.u64();
    (0..m).map(|_| read_entry(&mut r)).collect()
}

/// Per rank, the indices of the particles at `positions` (owned by `rank`) whose centroid is in
/// that rank's box and not in `rank`'s own: those that migrate, in index order (empty for
/// `rank` itself).
pub fn leaving(
    sub: &Subdomains,
    rank: usize,
    ranks: usize,
    positions: &[nalgebra::Vector3<f64>],
) -> Vec<Vec<usize>> {
    let mut leaving: Vec<Vec<usize>> = vec![Vec::new(); ranks];
    for (i, x) in positions.iter().enumerate() {
        if !sub.contains(rank, x) {
            leaving[sub.owner(x)].push(i);
        }
    }
    leaving
}

/// Sends every owned particle outside this rank's box to its owner; returns how many left.
/// History entries travel with their members and are merged on arrival (an entry the
/// receiver already holds, for a pair it evaluated itself, is bitwise the same).
pub fn migrate(
    comm: &dyn Comm,
    sub: &Subdomains,
    p: &mut Particles,
    history: &mut ContactHistory,
) -> usize {
    let me = comm.rank();
    let leaving = leaving(sub, me, comm.size(), &p.position);
    let sends: Vec<Vec<u8>> = leaving
        .iter()
        .enumerate()
        .map(|(r, which)| {
            if r == me || which.is_empty() {
                Vec::new()
            } else {
                pack_particles(p, which, history)
            }
        })
        .collect();
    let mut gone: Vec<usize> = leaving.concat();
    gone.sort_unstable();
    let moved = gone.len();
    let received = comm.all_to_all(&sends);
    p.remove(&gone);
    let mut arrived = Vec::new();
    for buf in &received {
        arrived.extend(unpack_particles(buf, p));
    }
    history.merge(arrived);
    moved
}

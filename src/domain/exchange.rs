//! The decomposed part of stage 1 (docs/design.md §1, §6): insertion over all ranks, and at a
//! neighbour-list rebuild rebalancing, migration and the ghosts chosen afresh.
//!
//! These take the parts of a rank's state they change (particles, contact history, inserter,
//! next id) rather than the simulation, so the decomposition depends on no stage of the step.

use super::halo::{HaloPlan, build_ghosts, refresh_ghosts};
use super::migration::{migrate, read_particle, write_particle};
use super::pack::{Reader, Writer};
use super::{Aabb, DecompositionError, Parallel};
use crate::contact::ContactHistory;
use crate::scene::{Inserter, Scene, SceneError};
use crate::state::Particles;
use nalgebra::Vector3;
use std::time::Instant;

/// Errors of the decomposed exchange.
#[derive(Debug, thiserror::Error)]
pub enum ExchangeError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Decomposition(#[from] DecompositionError),
    /// The ghosts chosen at a rebuild are inconsistent ([`Parallel::check_ghosts`]).
    #[error("step {step}: {message}")]
    Ghosts { step: u64, message: String },
}

/// What [`Parallel::exchange`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Exchanged {
    /// No rank needed a rebuild: the same ghosts were refreshed.
    Refreshed,
    /// The ranks rebuilt together: particles migrated and the ghosts were chosen afresh;
    /// `redrawn` when the boxes were redrawn first.
    Rebuilt { redrawn: bool },
}

impl Parallel {
    /// Insertion in a decomposed run: every rank runs the same inserter (same generator, same
    /// draws) against the bounding spheres of all ranks' particles near the insertion regions,
    /// gathered from every rank, so it places exactly the particles one rank would; each rank
    /// keeps those whose centroid is in its box. Returns how many were placed in all.
    pub fn insert_distributed(
        &mut self,
        inserter: &mut Inserter,
        time: f64,
        particles: &mut Particles,
        scene: &Scene,
        next_id: &mut u64,
    ) -> Result<u64, SceneError> {
        if !inserter.pending(time, scene) {
            return Ok(0);
        }
        let t0 = Instant::now();
        let par = &*self;
        let s = scene;
        // A new sphere inside its region can touch spheres up to 2 r_max from it.
        let reach = s.insertion_reach();
        let regions: Vec<Aabb> = s
            .insertions
            .iter()
            .map(|ins| {
                let (lo, hi) = ins.region.aabb();
                Aabb { lo, hi }.grown(reach)
            })
            .collect();
        let offsets = par.subdomains.image_offsets(None);
        let shifts: Vec<Vector3<f64>> = offsets.iter().map(|o| par.subdomains.shift(o)).collect();
        let p = &*particles;
        let mut w = Writer::default();
        for i in 0..p.len() {
            let near = shifts.iter().any(|sh| {
                let x = p.position[i] + sh;
                regions.iter().any(|r| r.distance(&x) == 0.0)
            });
            if near {
                w.u64(p.id[i]);
                w.u32(p.kind[i]);
                w.f64(p.scale[i]);
                w.v3(&p.position[i]);
            }
        }
        let mut occupied = Particles::default();
        for buf in par.comm.all_gather(&w.buf) {
            let mut r = Reader::new(&buf);
            while !r.done() {
                let (id, kind, scale, x) = (r.u64(), r.u32(), r.f64(), r.v3());
                let ty = &s.particle_types[kind as usize];
                occupied.push(
                    id,
                    kind,
                    scale,
                    x,
                    nalgebra::UnitQuaternion::identity(),
                    &s.templates[ty.template],
                    0.0,
                );
            }
        }
        let first_new = occupied.len();
        let report = inserter.insert(time, &mut occupied, s, next_id)?;
        let me = par.rank();
        let mut w = Writer::default();
        let mut kept = 0;
        for i in first_new..occupied.len() {
            if par.subdomains.contains(me, &occupied.position[i]) {
                write_particle(&mut w, &occupied, i);
                kept += 1;
            }
        }
        let mut r = Reader::new(&w.buf);
        for _ in 0..kept {
            read_particle(&mut r, particles);
        }
        self.timers.insert += t0.elapsed().as_secs_f64();
        Ok(report.inserted)
    }

    /// The decomposed part of stage 1. All ranks decide together whether the neighbour lists
    /// are rebuilt (`need`: this rank inserted, removed, or has a particle that moved half the
    /// skin); at a rebuild the boxes may be redrawn, particles migrate and the ghosts are
    /// chosen afresh, otherwise the same ghosts are refreshed. `step` names the step in errors.
    pub fn exchange(
        &mut self,
        need: bool,
        particles: &mut Particles,
        history: &mut ContactHistory,
        scene: &Scene,
        step: u64,
    ) -> Result<Exchanged, ExchangeError> {
        let domain_error = |message: String| ExchangeError::Ghosts { step, message };
        let par = self;
        let t0 = Instant::now();
        // The first collective of the step: time spent here is waiting for the slowest rank.
        let rebuild = par.comm.any(need);
        par.timers.wait += t0.elapsed().as_secs_f64();
        if !rebuild {
            let t0 = Instant::now();
            refresh_ghosts(&*par.comm, &par.plan, particles, &mut par.ghosts);
            par.timers.halo += t0.elapsed().as_secs_f64();
            return Ok(Exchanged::Refreshed);
        }
        let t0 = Instant::now();
        let redrawn = par.rebalance_if_needed(&particles.position)?;
        par.timers.balance += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let moved = migrate(&*par.comm, &par.subdomains, particles, history);
        par.timers.migrated += moved as u64;
        par.timers.migrate += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        par.plan = HaloPlan::new(&par.subdomains, par.rank(), &particles.position);
        par.ghosts = build_ghosts(&*par.comm, &par.plan, particles, scene);
        par.timers.rebuilds += 1;
        par.check_ghosts(&particles.id).map_err(domain_error)?;
        par.timers.halo += t0.elapsed().as_secs_f64();
        Ok(Exchanged::Rebuilt { redrawn })
    }
}

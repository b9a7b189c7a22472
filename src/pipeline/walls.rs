//! Stage 6: per particle, the facet contacts with every wall near it and the contact law, one
//! rayon job per particle, in the wall's own frame.

use super::pairs::{normal_effective_mass, with_workspace};
use super::{Simulation, SimulationError};
use crate::contact::{
    ContactForces, ContactKey, ContactKinematics, ContactState, contact_forces, mass_share,
};
use crate::geometry::{Overlap, PairWorkspace, PosedPolytope};
use crate::run_state::FirstFailure;
use nalgebra::{Isometry3, Vector3};
use rayon::prelude::*;
use std::time::Instant;

/// A failed wall contact: its key (particle id, wall index) for the smallest-first report, and
/// the error.
type WallFailure = ((u64, u64), SimulationError);

/// A particle's total wall contribution.
#[derive(Clone, Debug, Default)]
pub(super) struct WallOutcome {
    pub(super) force: Vector3<f64>,
    pub(super) torque: Vector3<f64>,
    pub(super) energy: f64,
    pub(super) per_wall: Vec<(usize, Vector3<f64>)>,
    pub(super) states: Vec<(ContactKey, ContactState)>,
    /// The deepest wall contact: overlap volume over the particle's volume, and the wall.
    pub(super) penetration: (f64, usize),
}

impl Simulation {
    /// Stage 6 with its timer.
    pub(super) fn wall_stage(&mut self, dt: f64) -> Result<Vec<WallOutcome>, SimulationError> {
        let t0 = Instant::now();
        let wall_outcomes = self.wall_contacts(dt)?;
        self.state.timers.walls += t0.elapsed().as_secs_f64();
        Ok(wall_outcomes)
    }

    /// The facets stage 6 clips: (particle–facet items within each owned particle's bounding
    /// radius, over every wall at its current pose; particles with at least one).
    pub fn wall_candidates(&self) -> (u64, u64) {
        let p = &self.state.particles;
        let poses: Vec<Isometry3<f64>> = self
            .state
            .scene
            .walls
            .iter()
            .map(|w| w.motion.transform(self.state.time))
            .collect();
        (0..p.len())
            .into_par_iter()
            .map_init(Vec::new, |facets, i| {
                let pose = Isometry3::from_parts(p.position[i].into(), p.orientation[i]);
                let mut items = 0u64;
                for (mesh, wall_pose) in self.state.walls.iter().zip(&poses) {
                    let local = wall_pose.inverse() * pose;
                    mesh.facets_near(&local.translation.vector, self.work.radius[i], facets);
                    items += facets.len() as u64;
                }
                (items, u64::from(items > 0))
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
    }

    /// Stage 6 for every owned particle, in index order: its contacts with the walls, or the
    /// failed contact of the smallest particle id and wall
    /// ([`FailureKey`](crate::run_state::FailureKey)). No walls, no work.
    pub(super) fn wall_contacts(&self, dt: f64) -> Result<Vec<WallOutcome>, SimulationError> {
        if self.state.walls.is_empty() {
            return Ok(Vec::new());
        }
        let p = &self.state.particles;
        let s = &self.state.scene;
        let t = self.state.time;
        let poses: Vec<Isometry3<f64>> = s.walls.iter().map(|w| w.motion.transform(t)).collect();
        let failure = FirstFailure::default();
        let outcomes = (0..p.len())
            .into_par_iter()
            .with_min_len(crate::par::CONTACT)
            .map_init(Vec::new, |facets, i| {
                let outcome = with_workspace(self.work.enum_planes, |ws| {
                    let mut out = WallOutcome::default();
                    for (k, wall_pose) in poses.iter().enumerate() {
                        let Some(world) = self.wall_overlap(ws, facets, i, k, wall_pose)? else {
                            continue;
                        };
                        let (f, key, state) = self.wall_law(i, k, &world, dt);
                        let depth = world.volume / self.state.equivalent_volume(i);
                        if depth > out.penetration.0 {
                            out.penetration = (depth, k);
                        }
                        out.force -= f.force_b;
                        out.torque += f.torque_a;
                        out.energy += f.elastic_energy;
                        out.per_wall.push((k, f.force_b));
                        out.states.push((key, state));
                    }
                    Ok(out)
                });
                outcome.unwrap_or_else(|(key, error)| {
                    failure.offer(key, error);
                    WallOutcome::default()
                })
            })
            .collect::<Vec<_>>();
        failure.into_result()?;
        Ok(outcomes)
    }

    /// Stage 6's geometry for particle `i` and wall `k` at `wall_pose`: the overlap with the
    /// facets near the particle, in world coordinates, or `None` (`facets` is the caller's
    /// buffer of facet indices). A failed geometry is returned with its failure key.
    fn wall_overlap(
        &self,
        ws: &mut PairWorkspace<f64>,
        facets: &mut Vec<u32>,
        i: usize,
        k: usize,
        wall_pose: &Isometry3<f64>,
    ) -> Result<Option<Overlap<f64>>, WallFailure> {
        let p = &self.state.particles;
        let s = &self.state.scene;
        let mesh = &self.state.walls[k];
        let tmpl = &s.templates[s.particle_types[p.kind[i] as usize].template];
        let pose = Isometry3::from_parts(p.position[i].into(), p.orientation[i]);
        // Work in the wall's own frame, where its facets are binned.
        let local = wall_pose.inverse() * pose;
        mesh.facets_near(&local.translation.vector, self.work.radius[i], facets);
        if facets.is_empty() {
            return Ok(None);
        }
        let o = if tmpl.sphere {
            mesh.sphere_contact(&local.translation.vector, self.work.radius[i], facets)
        } else {
            let body: &mut PosedPolytope<f64> = &mut ws.a;
            body.place(tmpl, p.scale[i], &local, &Vector3::zeros());
            mesh.contact(&mut ws.overlap, body, (tmpl, p.scale[i], &local), facets)
                .map_err(|e| {
                    let error = SimulationError::Geometry {
                        step: self.state.step,
                        what: format!("particle {} and wall {}", p.id[i], s.walls[k].name),
                        message: e.to_string(),
                    };
                    ((p.id[i], k as u64), error)
                })?
        };
        if o.volume <= 0.0 {
            return Ok(None);
        }
        let rot = wall_pose.rotation;
        Ok(Some(Overlap {
            volume: o.volume,
            centroid: (wall_pose * nalgebra::Point3::from(o.centroid)).coords,
            dv_dxb: rot * o.dv_dxb,
            moment_b: rot * o.moment_b,
            depth: o.depth,
            thickness: o.thickness,
        }))
    }

    /// Stage 7 for particle `i` on wall `k`, overlapping by `world`: the contact law's forces,
    /// the contact's key and its new history record.
    fn wall_law(
        &self,
        i: usize,
        k: usize,
        world: &Overlap<f64>,
        dt: f64,
    ) -> (ContactForces, ContactKey, ContactState) {
        let p = &self.state.particles;
        let s = &self.state.scene;
        let t = self.state.time;
        let sphere = s.templates[s.particle_types[p.kind[i] as usize].template].sphere;
        let params = self.contact_parameters(i, None, s.walls[k].material);
        let key = ContactKey::wall(p.id[i], k);
        let mut state = self.state.history.get(&key).copied().unwrap_or_default();
        let c = world.centroid;
        let (effective_mass, dashpot_mass) = normal_effective_mass(p, &[(i, p.position[i])], world);
        let kin = ContactKinematics {
            x_a: p.position[i],
            x_b: c,
            v_a: p.velocity[i],
            v_b: s.walls[k].motion.velocity_at(t, &c),
            w_a: p.angular_velocity[i],
            w_b: s.walls[k].motion.angular_velocity(),
            effective_mass,
            inverse_mass_a: 1.0 / p.mass[i],
            inverse_mass_b: 0.0,
            dashpot_mass,
            q_a: p.orientation[i],
            q_b: nalgebra::UnitQuaternion::identity(),
            inverse_inertia_a: p.inertia[i].map(|x| 1.0 / x),
            inverse_inertia_b: Vector3::zeros(),
            sphere_radius_a: if sphere { self.work.radius[i] } else { 0.0 },
            sphere_radius_b: 0.0,
            split_a: mass_share(p.contacts[i]),
            split_b: 1.0,
        };
        let f = contact_forces(&params, world, &kin, &mut state, dt);
        (f, key, state)
    }
}

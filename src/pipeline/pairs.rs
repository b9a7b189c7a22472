//! Stages 3–7 for particle pairs: bounding-sphere broad phase, narrow phase (the interior-point
//! LP's proof of an intersection, GJK where it proves none), dual-space overlap and the contact
//! law, one rayon job per candidate pair; and what the pair and wall stages share (contact
//! parameters, the effective mass, the per-thread workspace).

use super::{Simulation, SimulationError};
use crate::contact::{
    ContactForces, ContactKey, ContactKinematics, ContactParameters, ContactState, contact_forces,
    mass_share,
};
use crate::geometry::Overlap;
use crate::geometry::pair::{
    PairWorkspace, Precision, axis_separates, overlap_pair, overlap_pair_mixed_with,
};
use crate::geometry::sphere::sphere_lens;
use crate::geometry::vertex_enumeration::ENUM_MAX_PLANES;
use crate::run_state::{FirstFailure, pair_failure_key};
use crate::state::Particles;
use nalgebra::{Isometry3, Vector3};
use rayon::prelude::*;
use std::time::Instant;

/// The result of one pair's contact evaluation.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct PairOutcome {
    /// GJK's separating axis for a disjoint pair (zero otherwise).
    pub(super) separating_axis: Vector3<f64>,
    pub(super) forces: ContactForces,
    pub(super) state: Option<(ContactKey, ContactState)>,
    /// The overlap's volume over the smaller particle's volume (the stability guard's measure).
    pub(super) penetration: f64,
}

impl Simulation {
    /// The contact law's parameters of particle `i` against particle `other`, or against a wall
    /// of material `wall_material` when `other` is `None`.
    pub(super) fn contact_parameters(
        &self,
        i: usize,
        other: Option<usize>,
        wall_material: usize,
    ) -> ContactParameters {
        let s = &self.state.scene;
        let p = &self.state.particles;
        let side = |k: usize| {
            let ty = &s.particle_types[p.kind[k] as usize];
            let m = &s.materials[ty.material];
            let r = s.templates[ty.template].equivalent_radius * p.scale[k];
            (
                ty.material,
                m.youngs_modulus / r,
                m.youngs_modulus / (2.0 * (1.0 + m.poisson_ratio) * r),
            )
        };
        let (ma, cn_a, ct_a) = side(i);
        // A wall is flat: its radius is infinite and only the particle's term remains.
        let (mb, cn_b, ct_b) = match other {
            Some(j) => side(j),
            None => (wall_material, 0.0, 0.0),
        };
        let pair = s.pairs.get(ma, mb);
        ContactParameters {
            normal_stiffness: cn_a + cn_b,
            tangential_stiffness: ct_a + ct_b,
            restitution: pair.restitution,
            friction: pair.friction,
            rolling_friction: pair.rolling_friction,
            damping: self.work.damping[ma * s.materials.len() + mb],
            rocking: !s.templates[s.particle_types[p.kind[i] as usize].template].sphere,
            face_window: s.simulation.face_window,
        }
    }

    /// Stages 3–7 with their timer: the outcome per candidate pair, and each pair's separating
    /// axis kept for the next step. The ghosts [`Simulation::join_ghosts`] appended are dropped
    /// again, whatever the outcome.
    pub(super) fn pair_stage(
        &mut self,
        dt: f64,
        owned: usize,
    ) -> Result<Vec<PairOutcome>, SimulationError> {
        let t0 = Instant::now();
        let mut outcomes = std::mem::take(&mut self.work.pair_outcomes);
        let done = self.pair_contacts(dt, &mut outcomes);
        self.state.particles.truncate(owned);
        self.work.radius.truncate(owned);
        done?;
        for (axis, o) in self.work.separating_axes.iter_mut().zip(&outcomes) {
            *axis = o.separating_axis;
        }
        self.state.timers.pairs += t0.elapsed().as_secs_f64();
        Ok(outcomes)
    }

    /// Stages 3–7 for every candidate pair of the list, in list order (ghosts joined after the
    /// owned particles): the outcome per pair, or the failed pair of the smallest ids
    /// ([`FailureKey`](crate::run_state::FailureKey)).
    pub(super) fn pair_contacts(
        &self,
        dt: f64,
        outcomes: &mut Vec<PairOutcome>,
    ) -> Result<(), SimulationError> {
        let failure = FirstFailure::default();
        // Mixed precision's LP in f64 unless POLYDEM_MIXED_LP=f32 (on trial; the GPU's too).
        let wide_lp = !crate::tuning::Tuning::get().mixed_lp_f32;
        self.work
            .pairs
            .pairs
            .par_iter()
            .zip(self.work.separating_axes.par_iter())
            .with_min_len(crate::par::CONTACT)
            .map(|(pair, axis)| {
                let (a, b) = (pair[0] as usize, pair[1] as usize);
                let xb = self.partner_image(a, b);
                match self.pair_overlap(a, b, xb, axis, wide_lp, &failure) {
                    Ok(overlap) => self.pair_law(a, b, xb, &overlap, dt),
                    Err(separating_axis) => PairOutcome {
                        separating_axis,
                        ..PairOutcome::default()
                    },
                }
            })
            // Into the buffer of the last evaluation: its pages are already mapped, where a
            // fresh vector of this size (tens of MB) faults them in again every step.
            .collect_into_vec(outcomes);
        failure.into_result()
    }

    /// B's periodic image from the current centroids by the list build's minimum-image
    /// arithmetic (not the build's shift: a particle wrapped across a periodic face since the
    /// build keeps its contacts); B's centre without periodic axes.
    fn partner_image(&self, a: usize, b: usize) -> Vector3<f64> {
        let p = &self.state.particles;
        if self.state.bounds.periodic.iter().any(|&k| k) {
            let (xa, xb) = (p.position[a], p.position[b]);
            xb + (self.state.bounds.displacement(&xa, &xb) - (xb - xa))
        } else {
            p.position[b]
        }
    }

    /// Stages 3–5 for pair (`a`, `b`), B at `xb`: the overlap in world coordinates, or for a
    /// pair that does not overlap the separating axis to keep for the next step (zero for none).
    /// `axis` is last step's separating axis (zero for none); a failed geometry is offered to
    /// `failure` and counts as no contact.
    fn pair_overlap(
        &self,
        a: usize,
        b: usize,
        xb: Vector3<f64>,
        axis: &Vector3<f64>,
        wide_lp: bool,
        failure: &FirstFailure,
    ) -> Result<Overlap<f64>, Vector3<f64>> {
        let p = &self.state.particles;
        let s = &self.state.scene;
        let d = xb - p.position[a];
        let reach = self.work.radius[a] + self.work.radius[b];
        // Stage 3: bounding spheres.
        if d.norm_squared() >= reach * reach {
            return Err(Vector3::zeros());
        }
        if s.spheres_only() {
            // Stages 4–5 for spheres: the lens in closed form.
            let o =
                sphere_lens(self.work.radius[a], self.work.radius[b], &d).to_world(&p.position[a]);
            return if o.volume <= 0.0 {
                Err(Vector3::zeros())
            } else {
                Ok(o)
            };
        }
        let mixed = self.work.pair_precision == Precision::Mixed;
        let ta = &s.templates[s.particle_types[p.kind[a] as usize].template];
        let tb = &s.templates[s.particle_types[p.kind[b] as usize].template];
        let pose_a = Isometry3::from_parts(p.position[a].into(), p.orientation[a]);
        let pose_b = Isometry3::from_parts(xb.into(), p.orientation[b]);
        let (body_a, body_b) = ((ta, p.scale[a], &pose_a), (tb, p.scale[b], &pose_b));
        // Stage 4 shortcut: last step's separating axis, with a margin far above GJK's touching
        // tolerance (1e-12 of the size in f64), so the verdict is GJK's.
        if *axis != Vector3::zeros() && axis_separates(body_a, body_b, axis, 1e-9 * reach) {
            return Err(*axis);
        }
        // Stages 4–5: the narrow phase (GJK where the Chebyshev centre proves no
        // intersection), then the overlap.
        let g = match if mixed {
            with_workspaces(self.work.enum_planes, |w32, w64| {
                overlap_pair_mixed_with(w32, w64, body_a, body_b, wide_lp)
            })
        } else {
            with_workspace(self.work.enum_planes, |ws| overlap_pair(ws, body_a, body_b))
        } {
            Ok(g) => g,
            Err(e) => {
                let error = SimulationError::Geometry {
                    step: self.state.step,
                    what: format!("particles {} and {}", p.id[a], p.id[b]),
                    message: format!(
                        "{e}; to reproduce with `{}polydem probe overlap{}`: A {}, B {}",
                        // The probe has no scene: it takes the run's enumeration limit from
                        // the setting, whose default is 8.
                        if self.work.enum_planes == ENUM_MAX_PLANES {
                            String::new()
                        } else {
                            format!("POLYDEM_ENUM_PLANES={} ", self.work.enum_planes)
                        },
                        if mixed { " --precision mixed" } else { "" },
                        probe_body(ta, p.scale[a], &pose_a),
                        probe_body(tb, p.scale[b], &pose_b)
                    ),
                };
                failure.offer(pair_failure_key(p.id[a], p.id[b]), error);
                return Err(Vector3::zeros());
            }
        };
        if g.overlap.volume <= 0.0 {
            return Err(g.separating_axis.unwrap_or_default());
        }
        Ok(g.overlap)
    }

    /// Stage 7 for pair (`a`, `b`), B at `xb`, overlapping by `overlap`: the contact law's
    /// forces and the contact's new history record.
    fn pair_law(
        &self,
        a: usize,
        b: usize,
        xb: Vector3<f64>,
        overlap: &Overlap<f64>,
        dt: f64,
    ) -> PairOutcome {
        let p = &self.state.particles;
        let spheres = self.state.scene.spheres_only();
        let params = self.contact_parameters(a, Some(b), 0);
        let key = ContactKey::particles(p.id[a], p.id[b]);
        let mut state = self.state.history.get(&key).copied().unwrap_or_default();
        let (split_a, split_b) = (mass_share(p.contacts[a]), mass_share(p.contacts[b]));
        // A lens's centroid is on the line of centres: no rotational term.
        let (effective_mass, dashpot_mass) = if spheres {
            (
                1.0 / (1.0 / p.mass[a] + 1.0 / p.mass[b]),
                1.0 / (split_a / p.mass[a] + split_b / p.mass[b]),
            )
        } else {
            normal_effective_mass(p, &[(a, p.position[a]), (b, xb)], overlap)
        };
        let kin = ContactKinematics {
            x_a: p.position[a],
            x_b: xb,
            v_a: p.velocity[a],
            v_b: p.velocity[b],
            w_a: p.angular_velocity[a],
            w_b: p.angular_velocity[b],
            effective_mass,
            inverse_mass_a: 1.0 / p.mass[a],
            inverse_mass_b: 1.0 / p.mass[b],
            dashpot_mass,
            q_a: p.orientation[a],
            q_b: p.orientation[b],
            inverse_inertia_a: p.inertia[a].map(|x| 1.0 / x),
            inverse_inertia_b: p.inertia[b].map(|x| 1.0 / x),
            sphere_radius_a: if spheres { self.work.radius[a] } else { 0.0 },
            sphere_radius_b: if spheres { self.work.radius[b] } else { 0.0 },
            split_a,
            split_b,
        };
        let forces = contact_forces(&params, overlap, &kin, &mut state, dt);
        PairOutcome {
            separating_axis: Vector3::zeros(),
            forces,
            state: Some((key, state)),
            penetration: overlap.volume
                / self
                    .state
                    .equivalent_volume(a)
                    .min(self.state.equivalent_volume(b)),
        }
    }
}

thread_local! {
    /// One pair workspace per worker thread, made on first use: the workspace holds the
    /// fixed-capacity overlap buffers (tens of kilobytes), too big to build per rayon job.
    static WORKSPACE: std::cell::RefCell<Option<Box<PairWorkspace<f64>>>> =
        const { std::cell::RefCell::new(None) };
}

/// Runs `f` with this thread's pair workspace (a fresh one if it is already in use, which only
/// a nested call could cause), its enumeration limit set to `enum_planes` (the scene's: a
/// thread's workspace serves whichever run the thread works for).
pub(super) fn with_workspace<R>(
    enum_planes: usize,
    f: impl FnOnce(&mut PairWorkspace<f64>) -> R,
) -> R {
    let run = |ws: &mut PairWorkspace<f64>| {
        ws.set_enum_planes(enum_planes);
        f(ws)
    };
    WORKSPACE.with(|cell| match cell.try_borrow_mut() {
        Ok(mut slot) => run(slot.get_or_insert_with(PairWorkspace::boxed)),
        Err(_) => run(&mut PairWorkspace::boxed()),
    })
}

thread_local! {
    /// The f32 pair workspace of the mixed precision's pair geometry, per worker thread.
    static WORKSPACE_F32: std::cell::RefCell<Option<Box<PairWorkspace<f32>>>> =
        const { std::cell::RefCell::new(None) };
}

/// Runs `f` with this thread's f32 and f64 pair workspaces (for
/// [`overlap_pair_mixed_with`]).
fn with_workspaces<R>(
    enum_planes: usize,
    f: impl FnOnce(&mut PairWorkspace<f32>, &mut PairWorkspace<f64>) -> R,
) -> R {
    let run = |w32: &mut PairWorkspace<f32>| {
        w32.set_enum_planes(enum_planes);
        with_workspace(enum_planes, |w64| f(w32, w64))
    };
    WORKSPACE_F32.with(|cell| match cell.try_borrow_mut() {
        Ok(mut slot) => run(slot.get_or_insert_with(PairWorkspace::boxed)),
        Err(_) => run(&mut PairWorkspace::boxed()),
    })
}

/// The mass a contact's normal impulse sees: `1/m* = Σ 1/m + (r × n)·I⁻¹(r × n)` over the
/// bodies touching (centres `x`, lever arms `r` from them to the overlap centroid). The damping
/// is scaled with it, so that the prescribed restitution holds for eccentric impacts too, where
/// the contact point also turns the body (seed Eq. 15 uses the translational mass only, which
/// over-damps such impacts: 4 % too little spin after the cylinder–wall impact at 75°).
/// Returned with the dashpot caps' `m̃*`, each body's term multiplied by its share
/// ([`mass_share`] of its contact count; [`crate::contact::law::DASHPOT_STEP_FRACTION`]).
pub(super) fn normal_effective_mass(
    p: &Particles,
    bodies: &[(usize, Vector3<f64>)],
    o: &Overlap<f64>,
) -> (f64, f64) {
    let Some(n) = o.normal() else {
        let (mut mass, mut split) = (f64::MAX, f64::MAX);
        for &(i, _) in bodies {
            mass = mass.min(p.mass[i]);
            split = split.min(p.mass[i] / mass_share(p.contacts[i]));
        }
        return (mass, split);
    };
    let (mut inverse, mut split) = (0.0, 0.0);
    for &(i, x) in bodies {
        let arm = (o.centroid - x).cross(&n);
        let body = p.orientation[i].inverse_transform_vector(&arm);
        let term = 1.0 / p.mass[i] + body.component_div(&p.inertia[i]).dot(&body);
        inverse += term;
        split += mass_share(p.contacts[i]) * term;
    }
    (1.0 / inverse, 1.0 / split)
}

/// A body of a failed pair query as `polydem probe overlap` takes it (launch/probe/README.md):
/// the template and scale, and the pose as JSON to the last bit (`{:?}` prints the shortest
/// decimal that reads back the same f64).
fn probe_body(t: &crate::shape::ConvexTemplate, scale: f64, pose: &Isometry3<f64>) -> String {
    let (x, q) = (pose.translation.vector, pose.rotation.quaternion());
    format!(
        "template \"{}\" scale {scale:?} {{\"position\": [{:?}, {:?}, {:?}], \"orientation\": \
         [{:?}, {:?}, {:?}, {:?}]}}",
        t.name, x.x, x.y, x.z, q.w, q.i, q.j, q.k
    )
}

//! Stage 9 and the reduction of stage 8 on the GPU, host side: the [`Integrator`] launches the
//! two passes over the particle state of a step, `kick_drift` (with the periodic wrap and the
//! per-step checks, reduced into its [`StepFlags`]) and `reduce_and_kick` (the force reduction
//! fused with the second half kick), both of cuda/integrate.cu.

use super::error::CudaError;
use super::gpu::Gpu;
use super::launch::{cfg, ptr};
use super::layout::{KickDriftParams, ReduceKickParams, StepFlags};
use super::pair_list::PairList;
use super::particles::DeviceParticles;
use super::walls::WallStage;
use cudarc::driver::CudaSlice;
use nalgebra::Vector3;

/// What the per-step checks of `kick_drift` compare against: the pair list's and the wall
/// list's reference positions, and the guard's speed bound.
pub(super) struct DriftChecks<'a> {
    /// The pair list's reference positions (3n values).
    pub(super) reference: &'a CudaSlice<f64>,
    /// Half the skin: how far a particle may move before the pair list is due.
    pub(super) half_skin: f64,
    /// How far a particle may move before the next host-built list's snapshot is due
    /// (infinite: none is wanted).
    pub(super) snapshot_distance: f64,
    /// The wall list's reference positions (null: none to check) and how far a particle may
    /// move from them ([`WallStage::check`]).
    pub(super) wall_reference: u64,
    pub(super) wall_half_reach: f64,
    /// The stability guard's speed bound.
    pub(super) max_speed: f64,
}

/// The time integration's device state: the status flags of the drift.
pub(super) struct Integrator {
    flags: CudaSlice<StepFlags>,
}

impl Integrator {
    pub(super) fn new(gpu: &Gpu) -> Result<Self, CudaError> {
        Ok(Integrator {
            flags: gpu.stream.alloc_zeros::<StepFlags>(1)?,
        })
    }

    /// The first half of a step for every particle: half kick with last step's forces, drift,
    /// periodic wrap when `wrap`, and when `checks` the per-step checks against `limits`, whose
    /// flags it returns (read back, which waits for the drift; without checks the cleared flags,
    /// and nothing is waited for).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn kick_drift(
        &mut self,
        gpu: &Gpu,
        p: &mut DeviceParticles,
        gravity: Vector3<f64>,
        dt: f64,
        wrap: bool,
        checks: bool,
        limits: DriftChecks,
    ) -> Result<StepFlags, CudaError> {
        let st = &gpu.stream;
        let mut flags = [StepFlags::default()];
        if checks {
            st.memset_zeros(&mut self.flags)?;
        }
        let args = KickDriftParams {
            n: p.n as i32,
            wrap: i32::from(wrap),
            checks: i32::from(checks),
            pad: 0,
            ghost: ptr(&p.ghost, st),
            position: ptr(&p.position, st),
            velocity: ptr(&p.velocity, st),
            orientation: ptr(&p.orientation, st),
            angular_velocity: ptr(&p.angular_velocity, st),
            force: ptr(&p.force, st),
            torque: ptr(&p.torque, st),
            mass: ptr(&p.mass, st),
            inertia: ptr(&p.inertia, st),
            radius: ptr(&p.radius, st),
            gravity: gravity.into(),
            dt,
            grid: gpu.grid,
            reference: ptr(limits.reference, st),
            half_skin: limits.half_skin,
            snapshot_distance: limits.snapshot_distance,
            wall_reference: limits.wall_reference,
            wall_half_reach: limits.wall_half_reach,
            max_speed: limits.max_speed,
            flags: ptr(&self.flags, st),
        };
        // SAFETY: every state buffer holds 3n (4n) values, `reference` 3n since the last list
        // build (read only with checks), `wall_reference` is null or the wall list's 3n
        // positions; `flags` holds one StepFlags.
        unsafe { gpu.k.kick_drift(st, cfg(p.n), &args)? };
        if checks {
            // A copy into pageable memory returns once it is done: the step's one wait before
            // the forces.
            st.memcpy_dtoh(&self.flags, &mut flags)?;
        }
        Ok(flags[0])
    }

    /// Stage 8 and the second half kick (`kick`): the pair forces of `pairs` summed per
    /// particle in the order of its references, then the wall sums, stored as the particles'
    /// forces and torques, with its contacts (pairs and walls, for the next evaluation's
    /// dashpot caps), then the half kick with them.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn reduce_and_kick(
        &self,
        gpu: &Gpu,
        p: &mut DeviceParticles,
        pairs: &PairList,
        walls: Option<&WallStage>,
        gravity: Vector3<f64>,
        dt: f64,
        kick: bool,
    ) -> Result<(), CudaError> {
        let st = &gpu.stream;
        // Without walls the wall sums are not read (PD_WALLS 0): null pointers.
        let (wf, wt, wc, nw) = match walls {
            Some(w) => (
                ptr(&w.force, st),
                ptr(&w.torque, st),
                ptr(&w.contact, st),
                w.n as i32,
            ),
            None => (0u64, 0u64, 0u64, 0),
        };
        let args = ReduceKickParams {
            n: p.n as i32,
            kick: i32::from(kick),
            ref_offset: ptr(&pairs.ref_offset, st),
            refs: ptr(&pairs.refs, st),
            pair_forces: ptr(&pairs.forces, st),
            wall_force: wf,
            wall_torque: wt,
            force: ptr(&p.force, st),
            torque: ptr(&p.torque, st),
            ghost: ptr(&p.ghost, st),
            velocity: ptr(&p.velocity, st),
            angular_velocity: ptr(&p.angular_velocity, st),
            mass: ptr(&p.mass, st),
            inertia: ptr(&p.inertia, st),
            orientation: ptr(&p.orientation, st),
            pair_contact: ptr(&pairs.contact, st),
            wall_contact: wc,
            contacts: ptr(&p.contacts, st),
            n_walls: nw,
            pad: 0,
            gravity: gravity.into(),
            dt,
        };
        // SAFETY: `ref_offset` holds n + 1 offsets into `refs`, whose pair slots index `forces`
        // (nine values each) and `contact`; the wall sums hold 3n values and the wall flags
        // n·n_walls when walls exist; the particle buffers 3n (4n, n) values. Each thread
        // writes only its own particle's slots.
        unsafe { gpu.k.reduce_and_kick(st, cfg(p.n), &args)? };
        Ok(())
    }
}

//! Stage 6 on the GPU, host side: the [`WallStage`] owns the wall meshes with their facet
//! grids, the wall list and the per-particle wall outputs, and launches the wall kernels of
//! `cuda/contact.cu`: the list build (`wall_candidates`), the facet overlaps on the wall stream
//! alongside the pair kernels (`wall_facet_overlaps`), and the per-particle sums with the
//! contact law (`wall_contacts`).

use super::error::CudaError;
use super::gpu::Gpu;
use super::history::WallOutcomes;
use super::launch::{Kernels, cfg, ptr, zeros};
use super::layout::{
    HISTORY_WIDTH, ParticleView, WallCandidatesParams, WallContactsParams, WallInfo,
    WallOverlapsParams, WallState,
};
use super::particles::{DeviceParticles, Gather};
use crate::contact::WallMesh;
use crate::contact::wall::frame_drift;
use crate::scene::{Scene, WallMotion};
use cudarc::driver::{CudaSlice, CudaStream};
use nalgebra::Vector3;
use std::sync::Arc;

/// The wall list: per particle and wall, the facets within its bounding radius plus the skin
/// when it was built, in the order of their sums (`wall_candidates` of cuda/contact.cu), with
/// room for their overlaps. It stays valid while every particle is within half the skin of
/// where it was in every wall's frame: its own motion (`kick_drift`'s check against
/// `reference`) plus the walls' motion since `poses` (bounded on the host,
/// [`WallStage::check`]). The CPU queries the facet grid every step instead; both evaluate the
/// same facets in the same order.
pub(super) struct WallList {
    /// Per particle, its items `offset[i]..offset[i + 1]`.
    pub(super) offset: CudaSlice<u32>,
    /// (particle · walls + wall, facet) per item, in summation order.
    pub(super) items: CudaSlice<u32>,
    pub(super) n_items: usize,
    /// Twelve values per item, written each step by `wall_facet_overlaps`.
    pub(super) overlaps: CudaSlice<f64>,
    /// The particles' positions at the build.
    pub(super) reference: CudaSlice<f64>,
    /// The walls' poses at the build.
    pub(super) poses: Vec<nalgebra::Isometry3<f64>>,
}

/// Wall meshes, the wall list and the per-particle wall outputs.
pub(super) struct WallStage {
    pub(super) n: usize,
    pub(super) info: CudaSlice<WallInfo>,
    pub(super) states: CudaSlice<WallState>,
    pub(super) triangles: CudaSlice<f64>,
    pub(super) prisms: CudaSlice<f64>,
    pub(super) cell_start: CudaSlice<u32>,
    pub(super) cell_items: CudaSlice<u32>,
    pub(super) spring_in: CudaSlice<f64>,
    pub(super) spring_out: CudaSlice<f64>,
    pub(super) force: CudaSlice<f64>,
    pub(super) torque: CudaSlice<f64>,
    pub(super) energy: CudaSlice<f64>,
    pub(super) per_wall_force: CudaSlice<f64>,
    pub(super) contact: CudaSlice<u32>,
    /// The particles' candidate facets, built when due ([`WallList`]); `None` when due.
    pub(super) list: Option<WallList>,
    /// Wall lists built so far.
    pub(super) list_builds: u64,
}

impl WallStage {
    /// The walls of `scene` uploaded (`restricted`: a decomposed rank's meshes, cut to its box
    /// plus the halo), `None` without walls. `list_builds` carries the count over a re-upload.
    pub(super) fn upload(
        gpu: &Gpu,
        scene: &Scene,
        restricted: Option<&[WallMesh]>,
        list_builds: u64,
    ) -> Result<Option<Self>, CudaError> {
        if scene.walls.is_empty() {
            return Ok(None);
        }
        let cell = scene.cutoff();
        let mut info = Vec::new();
        let (mut triangles, mut prisms, mut starts, mut items) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (k, w) in scene.walls.iter().enumerate() {
            // A rank of a decomposed run keeps the facets that reach its box plus the halo (in
            // their order: the candidates' summation order is unchanged).
            let whole;
            let mesh = match restricted {
                Some(meshes) => &meshes[k],
                None => {
                    whole = WallMesh::new(&w.triangles, cell);
                    &whole
                }
            };
            let g = mesh.grid_parts();
            let facet_offset = (triangles.len() / 9) as i32;
            for t in &mesh.triangles {
                for v in t {
                    triangles.extend_from_slice(v.as_slice());
                }
            }
            for p in &mesh.prisms {
                for plane in p {
                    prisms.extend_from_slice(plane.normal.as_slice());
                    prisms.push(plane.offset);
                }
            }
            let cell_offset = starts.len() as i32;
            let item_base = items.len() as u32;
            starts.extend(g.start.iter().map(|&x| x + item_base));
            items.extend_from_slice(g.items);
            info.push(WallInfo {
                facet_offset,
                n_facets: mesh.len() as i32,
                cell_offset,
                material: w.material as i32,
                grid_min: g.min.into(),
                grid_size: g.size,
                dims: g.dims.map(|d| d as i32),
                pad: 0,
            });
        }
        let st = &gpu.stream;
        let n_walls = info.len();
        if items.is_empty() {
            items.push(0);
        }
        Ok(Some(WallStage {
            n: n_walls,
            info: st.clone_htod(&info)?,
            states: st.alloc_zeros::<WallState>(n_walls)?,
            triangles: st.clone_htod(&triangles)?,
            prisms: st.clone_htod(&prisms)?,
            cell_start: st.clone_htod(&starts)?,
            cell_items: st.clone_htod(&items)?,
            spring_in: st.alloc_zeros::<f64>(1)?,
            spring_out: st.alloc_zeros::<f64>(1)?,
            force: st.alloc_zeros::<f64>(1)?,
            torque: st.alloc_zeros::<f64>(1)?,
            energy: st.alloc_zeros::<f64>(1)?,
            per_wall_force: st.alloc_zeros::<f64>(1)?,
            contact: st.alloc_zeros::<u32>(1)?,
            list: None,
            list_builds,
        }))
    }

    /// Per-particle buffers for `n` particles, the springs from `spring` (`n · walls` records
    /// of the host's history); the list is due.
    pub(super) fn resize(
        &mut self,
        st: &Arc<CudaStream>,
        n: usize,
        spring: &[f64],
    ) -> Result<(), CudaError> {
        self.install(st, n, st.clone_htod(spring)?)
    }

    /// Per-particle buffers for `n` particles, the springs `spring` already on the device
    /// (`n · walls` records); the list is due.
    pub(super) fn install(
        &mut self,
        st: &Arc<CudaStream>,
        n: usize,
        spring: CudaSlice<f64>,
    ) -> Result<(), CudaError> {
        let nw = (n * self.n).max(1);
        self.spring_in = spring;
        self.spring_out = st.alloc_zeros::<f64>(HISTORY_WIDTH * nw)?;
        self.force = st.alloc_zeros::<f64>(3 * n.max(1))?;
        self.torque = st.alloc_zeros::<f64>(3 * n.max(1))?;
        self.energy = st.alloc_zeros::<f64>(n.max(1))?;
        self.per_wall_force = st.alloc_zeros::<f64>(3 * nw)?;
        self.contact = st.alloc_zeros::<u32>(nw)?;
        self.list = None;
        Ok(())
    }

    /// The contact flags per particle slot and wall (slot `i · n + k`; for the step's geometry
    /// errors).
    pub(super) fn flags(&self, st: &Arc<CudaStream>) -> Result<Vec<u32>, CudaError> {
        Ok(st.clone_dtoh(&self.contact)?)
    }

    /// The last evaluation's outcome per particle slot and wall (slot `i · n + k`), copied
    /// down: the contact flags, springs (after the step's swap), the forces on each wall, and
    /// per particle the elastic energy of its wall contacts.
    pub(super) fn outcomes(&self, st: &Arc<CudaStream>) -> Result<WallOutcomes, CudaError> {
        Ok(WallOutcomes {
            walls: self.n,
            contact: self.flags(st)?,
            spring: st.clone_dtoh(&self.spring_in)?,
            energy: st.clone_dtoh(&self.energy)?,
            per_wall_force: st.clone_dtoh(&self.per_wall_force)?,
        })
    }

    /// Bytes of device memory held by the meshes, the outputs and the list.
    pub(super) fn bytes(&self) -> usize {
        fn b<T>(s: &CudaSlice<T>) -> usize {
            s.len() * std::mem::size_of::<T>()
        }
        let mut total = b(&self.triangles)
            + b(&self.prisms)
            + b(&self.cell_start)
            + b(&self.cell_items)
            + b(&self.spring_in)
            + b(&self.spring_out)
            + b(&self.force)
            + b(&self.torque)
            + b(&self.energy)
            + b(&self.per_wall_force)
            + b(&self.contact);
        if let Some(l) = &self.list {
            total += b(&l.offset) + b(&l.items) + b(&l.overlaps) + b(&l.reference);
        }
        total
    }

    /// Reorders the springs of the `n` particles by a list build's `order`.
    pub(super) fn gather_springs(
        &mut self,
        k: &Kernels,
        st: &Arc<CudaStream>,
        n: usize,
        order: &CudaSlice<u32>,
    ) -> Result<(), CudaError> {
        self.spring_in = f64::gather(k, st, n, HISTORY_WIDTH * self.n, &self.spring_in, order)?;
        Ok(())
    }

    /// Stage 6, first part: the walls' poses at time `t` uploaded, the wall list built when
    /// due, then `wall_facet_overlaps` queued on the wall stream after everything queued so far
    /// on the main one (the particles' poses of this step): one thread per listed
    /// particle–facet for the distance test and the prism overlap. A dense bed against a wall
    /// has too few items to fill the GPU with that serial work per thread, so they share it
    /// with the pair kernels rather than run after them.
    pub(super) fn start_overlaps(
        &mut self,
        gpu: &Gpu,
        p: &DeviceParticles,
        view: &ParticleView,
        scene: &Scene,
        t: f64,
    ) -> Result<(), CudaError> {
        let st = &gpu.stream;
        let states: Vec<WallState> = scene
            .walls
            .iter()
            .map(|wall| wall_state(&wall.motion, t))
            .collect();
        st.memcpy_htod(&states, &mut self.states)?;
        if self.list.is_none() {
            self.build_list(gpu, p, view, scene, t)?;
        }
        let list = self.list.as_ref().expect("built above");
        let side = &gpu.wall_stream;
        side.poses_ready.record(st)?;
        side.stream.wait(&side.poses_ready)?;
        if list.n_items > 0 {
            let args = WallOverlapsParams {
                n_items: list.n_items as i32,
                n_walls: self.n as i32,
                items: ptr(&list.items, st),
                p: *view,
                states: ptr(&self.states, st),
                triangles: ptr(&self.triangles, st),
                prisms: ptr(&self.prisms, st),
                overlaps: ptr(&list.overlaps, st),
                error: ptr(&gpu.error, st),
            };
            // SAFETY: the list holds 2 × n_items ids and 12 × n_items overlaps. The wall stream
            // runs it after the main stream's work so far (the poses, the walls' states, the
            // list); the main stream waits for it before reading the overlaps
            // (`finish`), and nothing else writes what it reads meanwhile. `error` is shared
            // with the pair kernels, which report into it by the same atomic compare-and-swap.
            unsafe {
                gpu.k
                    .wall_facet_overlaps(&side.stream, cfg(list.n_items), &args)?;
            }
        }
        side.overlaps_done.record(&side.stream)?;
        Ok(())
    }

    /// Stage 6, second part, on the main stream once the facet overlaps are done: per particle
    /// the sums and the contact law (`wall_contacts`).
    pub(super) fn finish(
        &mut self,
        gpu: &Gpu,
        n: usize,
        view: &ParticleView,
        n_materials: i32,
        dt: f64,
        max_overlap: f64,
    ) -> Result<(), CudaError> {
        let st = &gpu.stream;
        st.wait(&gpu.wall_stream.overlaps_done)?;
        let list = self.list.as_ref().expect("built by start_overlaps");
        let args = WallContactsParams {
            n: n as i32,
            n_walls: self.n as i32,
            n_materials,
            pad: 0,
            p: *view,
            states: ptr(&self.states, st),
            walls: ptr(&self.info, st),
            item_offset: ptr(&list.offset, st),
            items: ptr(&list.items, st),
            overlaps: ptr(&list.overlaps, st),
            materials: ptr(&gpu.materials, st),
            spring_in: ptr(&self.spring_in, st),
            spring_out: ptr(&self.spring_out, st),
            wall_force: ptr(&self.force, st),
            wall_torque: ptr(&self.torque, st),
            wall_energy: ptr(&self.energy, st),
            per_wall_force: ptr(&self.per_wall_force, st),
            wall_contact: ptr(&self.contact, st),
            dt,
            max_overlap,
            error: ptr(&gpu.error, st),
        };
        // SAFETY: the list holds n + 1 offsets, 2 × n_items ids and 12 × n_items overlaps, the
        // wall outputs n × walls slots (n values for the sums).
        unsafe { gpu.k.wall_contacts(st, cfg(n), &args)? };
        Ok(())
    }

    /// Builds the wall list ([`WallList`]): the facets within each particle's bounding radius
    /// plus the skin, counted, scanned and listed by `wall_candidates` at the walls' poses at
    /// time `t` (`self.states`, uploaded for this step).
    fn build_list(
        &mut self,
        gpu: &Gpu,
        p: &DeviceParticles,
        view: &ParticleView,
        scene: &Scene,
        t: f64,
    ) -> Result<(), CudaError> {
        let st = gpu.stream.clone();
        let n = p.n;
        let counts = zeros::<u32>(&st, n)?;
        let mut args = WallCandidatesParams {
            n: n as i32,
            n_walls: self.n as i32,
            p: *view,
            walls: ptr(&self.info, &st),
            states: ptr(&self.states, &st),
            triangles: ptr(&self.triangles, &st),
            cell_start: ptr(&self.cell_start, &st),
            cell_items: ptr(&self.cell_items, &st),
            skin: gpu.skin,
            counts: ptr(&counts, &st),
            // Null offsets and items: `wall_candidates` counts.
            offset: 0,
            items: 0,
        };
        // SAFETY: `counts` holds n values; `offset` and `items` are null (count) or point to
        // n + 1 offsets and 2 × (their total) ids (list).
        unsafe { gpu.k.wall_candidates(&st, cfg(n), &args)? };
        let mut offset = zeros::<u32>(&st, n + 1)?;
        let n_items = gpu.scan(&counts, n, &mut offset)? as usize;
        let items = zeros::<u32>(&st, 2 * n_items)?;
        args.offset = ptr(&offset, &st);
        args.items = ptr(&items, &st);
        unsafe { gpu.k.wall_candidates(&st, cfg(n), &args)? };
        self.list = Some(WallList {
            offset,
            items,
            n_items,
            overlaps: zeros::<f64>(&st, 12 * n_items)?,
            reference: st.clone_dtod(&p.position)?,
            poses: scene
                .walls
                .iter()
                .map(|wall| wall.motion.transform(t))
                .collect(),
        });
        self.list_builds += 1;
        Ok(())
    }

    /// Before the drift to time `t`: the wall list's reference positions and how far a
    /// particle may move from them, half the skin less the most any point near the domain
    /// moved in any wall's frame since the list's build. In a wall's frame a particle at `x`
    /// sits at `P⁻¹ x`, so between poses `P₀` and `P` it moved by at most |x − x₀| +
    /// |P⁻¹ x − P₀⁻¹ x|, the second term bounded over the domain box grown by the cutoff by
    /// [`frame_drift`]. With no list, or walls that moved half the skin, the list is due and
    /// nothing is checked (a null reference).
    pub(super) fn check(&mut self, gpu: &Gpu, scene: &Scene, t: f64) -> (u64, f64) {
        let half_skin = 0.5 * gpu.skin;
        let g = gpu.grid;
        let grow = scene.cutoff();
        let Some(list) = &self.list else {
            return (0, 0.0);
        };
        let lo = Vector3::from(g.min).add_scalar(-grow);
        let hi = Vector3::from(g.max).add_scalar(grow);
        let moved = scene
            .walls
            .iter()
            .zip(&list.poses)
            .map(|(wall, pose)| frame_drift(pose, &wall.motion.transform(t), &lo, &hi))
            .fold(0.0, f64::max);
        let reach = half_skin - moved;
        if reach <= 0.0 && moved > 0.0 {
            self.list = None;
            return (0, 0.0);
        }
        (ptr(&list.reference, &gpu.stream), reach)
    }
}

/// A wall's pose and velocity field at time `t` (the GPU form of [`WallMotion::transform`],
/// `velocity_at` and `angular_velocity`: v(c) = v0 + ω × (c − origin)).
fn wall_state(motion: &WallMotion, t: f64) -> WallState {
    let pose = motion.transform(t);
    let c = pose.rotation.coords;
    let (v0, omega, origin) = match motion {
        WallMotion::Rotate { origin, .. } => (Vector3::zeros(), motion.angular_velocity(), *origin),
        _ => (
            motion.velocity_at(t, &Vector3::zeros()),
            Vector3::zeros(),
            Vector3::zeros(),
        ),
    };
    WallState {
        rotation: [c.x, c.y, c.z, c.w],
        translation: pose.translation.vector.into(),
        v0: v0.into(),
        omega: omega.into(),
        origin: origin.into(),
    }
}

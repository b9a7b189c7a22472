//! Stages 3–8 on the GPU, host side: the pair contacts, the wall contacts with the walls'
//! poses at the current time, and the deterministic reduction fused with the half kick
//! (kernels in `cuda/contact.cu` and `cuda/integrate.cu`).

use super::simulation::{
    CudaError, CudaSimulation, DeviceWalls, PairArgs, PairOutputs, ParticleView, SPHERE_PAIR_BLOCK,
    WallList, WallState, cfg, cfg_with, ptr, zeros,
};
use crate::contact::wall::frame_drift;
use crate::pipeline::SimulationError;
use crate::scene::WallMotion;
use cudarc::driver::{CudaSlice, PushKernelArg};
use nalgebra::Vector3;
use std::time::Instant;

impl CudaSimulation {
    /// Prints the pair kernels' per-phase clock totals so far (a profiling build,
    /// `POLYDEM_PHASE_CLOCKS`): thread-cycles summed over all pairs, from `clock64()` at the
    /// phase boundaries of `cuda/overlap.cuh` and `cuda/contact.cu`.
    fn report_phase_clocks(&self) -> Result<(), CudaError> {
        const PHASES: [&str; 16] = [
            "broad phase and cached axis",
            "planes placed",
            "planes reaching the other ball",
            "faces set aside",
            "Chebyshev centre",
            "proof of intersection",
            "planes moved to the centre",
            "overlap (faces and their sums)",
            "contact law",
            "",
            "",
            "pairs evaluated (count)",
            "pairs needing GJK (count)",
            "  of which the faces (enumeration, or dual hull)",
            "  of which volume, centroid, S and moment",
            "",
        ];
        let view = self.k.contact.get_global("pd_clk", &self.stream)?;
        // SAFETY: `pd_clk` is `unsigned long long[16]` in cuda/overlap.cuh (PD_PHASE_CLOCKS).
        let typed = unsafe { view.transmute::<u64>(PHASES.len()) }
            .ok_or_else(|| CudaError::Compile("pd_clk is smaller than expected".into()))?;
        let clocks = self.stream.clone_dtoh(&typed)?;
        let lines: Vec<String> = PHASES
            .iter()
            .zip(&clocks)
            .filter(|(name, _)| !name.is_empty())
            .map(|(name, c)| format!("{name}: {c}"))
            .collect();
        eprintln!("pair phase clocks: {}", lines.join("; "));
        Ok(())
    }

    /// The arguments of the pair kernels for this step.
    fn pair_args(&self, view: &ParticleView, n_mat: i32, dt: f64) -> PairArgs {
        let st = &self.stream;
        let pairs = self.pairs.as_ref().expect("built");
        PairArgs {
            pairs: ptr(&pairs.pairs, st),
            grid: self.grid,
            axes: ptr(&pairs.axes, st),
            p: *view,
            materials: ptr(&self.materials, st),
            n_materials: n_mat,
            spring_in: ptr(&pairs.spring_in, st),
            spring_out: ptr(&pairs.spring_out, st),
            out: PairOutputs {
                ptrs: [
                    ptr(&pairs.forces, st),
                    ptr(&pairs.energy, st),
                    ptr(&pairs.contact, st),
                ],
            },
            dt,
            max_overlap: self.host.guard.max_overlap,
            error: ptr(&self.error, st),
        }
    }

    /// Stages 3–7 for the pairs `first..last` of the list. Spheres in one pass; polyhedra in
    /// two lean passes (`pair_planes`, then the faces and the contact law in `pair_faces`, with
    /// the staged pairs listed by plane count in between by `bucket_pairs`), the pairs that need
    /// GJK or the dual hull queued for [`Self::launch_deferred_pairs`].
    fn launch_pair_contacts(
        &mut self,
        first: usize,
        last: usize,
        args: &PairArgs,
    ) -> Result<(), CudaError> {
        if last <= first {
            return Ok(());
        }
        let st = self.stream.clone();
        let pairs = self.pairs.as_mut().expect("built");
        let (fi, li) = (first as i32, last as i32);
        if self.config.spheres {
            // SAFETY: the argument list matches `pair_contacts` of cuda/contact.cu; `args`
            // points into buffers alive for the whole call.
            unsafe {
                st.launch_builder(self.k.get("pair_contacts"))
                    .arg(&fi)
                    .arg(&li)
                    .arg(args)
                    .launch(cfg_with(last - first, SPHERE_PAIR_BLOCK))?;
            }
            return Ok(());
        }
        st.memset_zeros(&mut pairs.bucket_count)?;
        st.memset_zeros(&mut pairs.bucket_fill)?;
        // SAFETY: the argument lists match `pair_planes`, `bucket_pairs` and `pair_faces` of
        // cuda/contact.cu; `deferred`, `bucket` and `order` hold one slot per pair, `staged`
        // one StagedPlanes record per pair (sizes checked by static_assert), the bucket counts
        // and fill cursors PLANE_BUCKETS values.
        unsafe {
            st.launch_builder(self.k.get("pair_planes"))
                .arg(&fi)
                .arg(&li)
                .arg(args)
                .arg(&mut pairs.deferred)
                .arg(&mut pairs.deferred_count)
                .arg(&mut pairs.staged)
                .arg(&mut pairs.bucket)
                .arg(&mut pairs.bucket_count)
                .launch(cfg(last - first))?;
            st.launch_builder(self.k.get("bucket_pairs"))
                .arg(&fi)
                .arg(&li)
                .arg(&pairs.bucket)
                .arg(&pairs.bucket_count)
                .arg(&mut pairs.bucket_fill)
                .arg(&mut pairs.order)
                .launch(cfg(last - first))?;
            st.launch_builder(self.k.get("pair_faces"))
                .arg(args)
                .arg(&pairs.order)
                .arg(&pairs.bucket_count)
                .arg(&pairs.staged)
                .arg(&mut pairs.deferred)
                .arg(&mut pairs.deferred_count)
                .launch(cfg(last - first))?;
        }
        Ok(())
    }

    /// The pairs queued by the pair pass, evaluated in full (GJK included). The count stays on
    /// the device: the kernel loops over it, so the grid only needs to be large enough to keep
    /// the GPU busy when many pairs are deferred.
    fn launch_deferred_pairs(&mut self, args: &PairArgs) -> Result<(), CudaError> {
        let st = self.stream.clone();
        let pairs = self.pairs.as_ref().expect("built");
        if pairs.n == 0 || self.host.scene.spheres_only() {
            return Ok(());
        }
        // A sixteenth of the pairs per sweep: a dense packing defers a few per cent.
        let threads = pairs.n.div_ceil(16).max(1);
        // SAFETY: the argument list matches `pair_contacts_deferred` of cuda/contact.cu; the
        // list and its count were written by `pair_contacts` this step.
        unsafe {
            st.launch_builder(self.k.get("pair_contacts_deferred"))
                .arg(args)
                .arg(&pairs.deferred)
                .arg(&pairs.deferred_count)
                .launch(cfg(threads))?;
        }
        Ok(())
    }

    /// Stages 2–8: the list (rebuilt when due), the pair and wall contacts and the reduction
    /// into the particles' forces and torques, followed by the second half kick of the step
    /// when `kick` (fused into the reduction's pass over the particles).
    pub(super) fn forces(&mut self, dt: f64, kick: bool) -> Result<(), CudaError> {
        let t0 = Instant::now();
        if self.rebuild || self.pairs.is_none() {
            self.build_pairs()?;
        }
        self.stream.synchronize()?;
        self.host.timers.neighbor += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let st = self.stream.clone();
        let view = self.particle_view();
        let n = self.n;
        let ni = n as i32;
        let n_mat = self.host.scene.materials.len() as i32;
        // A decomposed run between rebuilds: the ghosts' motion is in flight while the pairs of
        // two owned particles are evaluated; the pairs with a ghost follow its arrival.
        let overlap = std::mem::take(&mut self.halo_due);
        let (np, n_interior) = {
            let q = self.pairs.as_ref().expect("built above");
            (q.n, if overlap { q.n_interior } else { q.n })
        };
        let args = self.pair_args(&view, n_mat, dt);
        {
            let pairs = self.pairs.as_mut().expect("built above");
            st.memset_zeros(&mut pairs.deferred_count)?;
        }
        // The walls' facet overlaps read only the particles' poses, final for this step once
        // the ghosts' have arrived: they run on the wall stream alongside the pairs. In a
        // decomposed run they are queued behind the interior pairs (the ghosts arrive while
        // those run), so they overlap only the ghosts' and the deferred pairs.
        let mut wall_host = 0.0;
        if !overlap {
            wall_host += self.start_wall_overlaps(&view)?;
        }
        if overlap {
            self.start_halo()?;
        }
        self.launch_pair_contacts(0, n_interior, &args)?;
        if overlap {
            self.finish_halo()?;
            wall_host += self.start_wall_overlaps(&view)?;
            self.launch_pair_contacts(n_interior, np, &args)?;
        }
        self.launch_deferred_pairs(&args)?;
        // Kernels run asynchronously: wait for the stage so that its timer measures it (a few
        // microseconds per stage, negligible against the step).
        st.synchronize()?;
        self.host.timers.pairs += t0.elapsed().as_secs_f64() - wall_host;
        self.host.timers.walls += wall_host;
        if super::kernels::phase_clocks() {
            self.report_phase_clocks()?;
        }
        let t0 = Instant::now();
        self.finish_walls(&view, n_mat, dt)?;
        st.synchronize()?;
        self.host.timers.walls += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let pairs = self.pairs.as_mut().expect("built above");
        // Without walls the wall sums are not read (PD_WALLS 0): null pointers.
        let (wf, wt) = match &self.walls {
            Some(w) => (ptr(&w.force, &st), ptr(&w.torque, &st)),
            None => (0u64, 0u64),
        };
        let g = self.host.scene.gravity;
        let kick = i32::from(kick);
        let p = &mut self.p;
        // SAFETY: `reduce_and_kick` of cuda/integrate.cu; `ref_offset` holds n + 1 offsets
        // into `refs`, whose pair slots index `forces` (nine values each); the wall sums hold
        // 3n values when walls exist; the particle buffers 3n (4n) values. Each thread writes
        // only its own particle's slots.
        unsafe {
            st.launch_builder(self.k.get("reduce_and_kick"))
                .arg(&ni)
                .arg(&pairs.ref_offset)
                .arg(&pairs.refs)
                .arg(&pairs.forces)
                .arg(&wf)
                .arg(&wt)
                .arg(&mut p.force)
                .arg(&mut p.torque)
                .arg(&kick)
                .arg(&p.ghost)
                .arg(&mut p.velocity)
                .arg(&mut p.angular_velocity)
                .arg(&p.mass)
                .arg(&p.inertia)
                .arg(&p.orientation)
                .arg(&g.x)
                .arg(&g.y)
                .arg(&g.z)
                .arg(&dt)
                .launch(cfg(n))?;
        }
        // The springs just computed are the history of the next evaluation.
        std::mem::swap(&mut pairs.spring_in, &mut pairs.spring_out);
        if let Some(w) = &mut self.walls {
            std::mem::swap(&mut w.spring_in, &mut w.spring_out);
        }
        let mut error = [0u32; 3];
        st.memcpy_dtoh(&self.error, &mut error)?;
        self.host.timers.reduce += t0.elapsed().as_secs_f64();
        // A geometry error fails the step; the fused kick has already applied this step's
        // forces to the velocities on the device (the run stops with the error: `engine.step()?`).
        if error[0] != 0 || error[1] != 0 {
            return Err(self.geometry_error(error).into());
        }
        self.host_current = false;
        if error[2] != 0 {
            // The stability guard's overlap bound (cuda/contact.cu `guard_overlap`).
            let i = (u32::MAX - error[2]) as usize;
            self.sync_host()?;
            if i >= self.host.particles.len() {
                return Err(SimulationError::Domain {
                    step: self.host.step,
                    message: format!(
                        "a contact of ghost slot {i} overlaps more than {} of the smaller \
                         particle's volume (simulation.guard.max_overlap); its owner's rank \
                         names it",
                        self.host.guard.max_overlap
                    ),
                }
                .into());
            }
            let problem = crate::stability::Instability::DeepContact {
                fraction: self.host.guard.max_overlap,
            };
            return Err(self.host.unstable(i, Some(problem)).into());
        }
        Ok(())
    }
}

impl CudaSimulation {
    /// The geometry error the kernels recorded (`report_error` of cuda/contact.cu): of all
    /// that failed this step, the pair of the smallest list index, else the particle–wall
    /// item of the smallest particle slot and wall, named by global ids as the CPU names them.
    fn geometry_error(&self, error: [u32; 3]) -> SimulationError {
        let key = !(u64::from(error[0]) | (u64::from(error[1]) << 32));
        let (source, index, status) = (key >> 40, (key >> 8) & 0xffff_ffff, key & 0xff);
        let step = self.host.step;
        let message = format!("geometry status {status} (cuda/polytope.cuh status codes)");
        let st = &self.stream;
        let ids = st.clone_dtoh(&self.p.id).unwrap_or_default();
        let id = |slot: usize| {
            ids.get(slot)
                .map_or(format!("slot {slot}"), |g| g.to_string())
        };
        let what = if source == 0 {
            let pair = self
                .pairs
                .as_ref()
                .and_then(|p| st.clone_dtoh(&p.pairs).ok())
                .and_then(|pr| {
                    Some((
                        *pr.get(2 * index as usize)?,
                        *pr.get(2 * index as usize + 1)?,
                    ))
                });
            match pair {
                Some((a, b)) => format!("particles {} and {}", id(a as usize), id(b as usize)),
                None => format!("pair slot {index}"),
            }
        } else {
            let walls = self.host.scene.walls.len().max(1);
            let (i, k) = (index as usize / walls, index as usize % walls);
            let name = self
                .host
                .scene
                .walls
                .get(k)
                .map_or("?", |w| w.name.as_str());
            format!("particle {} and wall {name}", id(i))
        };
        SimulationError::Geometry {
            step,
            what,
            message,
        }
    }

    /// Stage 6, first part: the walls' poses at the current time uploaded, the wall list built
    /// when due, then `wall_facet_overlaps` queued on the wall stream after everything queued
    /// so far on the main one (the particles' poses of this step): one thread per listed
    /// particle–facet for the distance test and the prism overlap. A dense bed against a wall
    /// has too few items to fill the GPU with that serial work per thread, so they share it
    /// with the pair kernels rather than run after them. Returns the host seconds spent (a list
    /// build waits for its count).
    fn start_wall_overlaps(&mut self, view: &ParticleView) -> Result<f64, CudaError> {
        let t0 = Instant::now();
        // Taken out while the stage runs, so that the scan helper can borrow `self`.
        let Some(mut w) = self.walls.take() else {
            return Ok(0.0);
        };
        let st = self.stream.clone();
        let states: Vec<WallState> = self
            .host
            .scene
            .walls
            .iter()
            .map(|wall| wall_state(&wall.motion, self.host.time))
            .collect();
        st.memcpy_htod(&states, &mut w.states)?;
        if w.list.is_none() {
            self.build_wall_list(&mut w, view)?;
        }
        let list = w.list.as_mut().expect("built above");
        let nw = w.n as i32;
        let n_items_i = list.n_items as i32;
        let side = &self.wall_stream;
        side.poses_ready.record(&st)?;
        side.stream.wait(&side.poses_ready)?;
        if list.n_items > 0 {
            // SAFETY: the argument list matches `wall_facet_overlaps` of cuda/contact.cu; the
            // list holds 2 × n_items ids and 12 × n_items overlaps. The wall stream runs it after
            // the main stream's work so far (the poses, the walls' states, the list); the main
            // stream waits for it before reading the overlaps (`finish_walls`), and nothing
            // else writes what it reads meanwhile. `error` is shared with the pair kernels,
            // which report into it by the same atomic compare-and-swap.
            unsafe {
                side.stream
                    .launch_builder(self.k.get("wall_facet_overlaps"))
                    .arg(&n_items_i)
                    .arg(&list.items)
                    .arg(&nw)
                    .arg(view)
                    .arg(&w.states)
                    .arg(&w.triangles)
                    .arg(&w.prisms)
                    .arg(&mut list.overlaps)
                    .arg(&mut self.error)
                    .launch(cfg(list.n_items))?;
            }
        }
        side.overlaps_done.record(&side.stream)?;
        self.walls = Some(w);
        Ok(t0.elapsed().as_secs_f64())
    }

    /// Stage 6, second part, on the main stream once the facet overlaps are done: per particle
    /// the sums and the contact law (`wall_contacts`).
    fn finish_walls(&mut self, view: &ParticleView, n_mat: i32, dt: f64) -> Result<(), CudaError> {
        let Some(w) = self.walls.as_mut() else {
            return Ok(());
        };
        let st = &self.stream;
        st.wait(&self.wall_stream.overlaps_done)?;
        let list = w.list.as_ref().expect("built by start_wall_overlaps");
        let (ni, nw) = (self.n as i32, w.n as i32);
        // SAFETY: the argument list matches `wall_contacts` of cuda/contact.cu; the list holds
        // n + 1 offsets, 2 × n_items ids and 12 × n_items overlaps, the wall outputs n × walls
        // slots (n values for the sums).
        unsafe {
            st.launch_builder(self.k.get("wall_contacts"))
                .arg(&ni)
                .arg(view)
                .arg(&nw)
                .arg(&w.states)
                .arg(&w.info)
                .arg(&list.offset)
                .arg(&list.items)
                .arg(&list.overlaps)
                .arg(&self.materials)
                .arg(&n_mat)
                .arg(&w.spring_in)
                .arg(&mut w.spring_out)
                .arg(&mut w.force)
                .arg(&mut w.torque)
                .arg(&mut w.energy)
                .arg(&mut w.per_wall_force)
                .arg(&mut w.contact)
                .arg(&dt)
                .arg(&self.host.guard.max_overlap)
                .arg(&mut self.error)
                .launch(cfg(self.n))?;
        }
        Ok(())
    }

    /// Builds the wall list of `w` ([`WallList`]): the facets within each particle's bounding
    /// radius plus the skin, counted, scanned and listed by `wall_candidates` at the walls'
    /// poses now (`w.states`, uploaded for this step).
    fn build_wall_list(&self, w: &mut DeviceWalls, view: &ParticleView) -> Result<(), CudaError> {
        let st = self.stream.clone();
        let n = self.n;
        let ni = n as i32;
        let nw = w.n as i32;
        let skin = self.skin;
        let mut counts = zeros::<u32>(&st, n)?;
        // `wall_candidates` counts (null offset and item pointers) or lists.
        let candidates = |counts: &mut CudaSlice<u32>, offset: u64, items: u64| {
            // SAFETY: the argument list matches `wall_candidates` of cuda/contact.cu; `offset`
            // and `items` are null or point to n + 1 offsets and 2 × (their total) ids.
            unsafe {
                st.launch_builder(self.k.get("wall_candidates"))
                    .arg(&ni)
                    .arg(view)
                    .arg(&nw)
                    .arg(&w.info)
                    .arg(&w.states)
                    .arg(&w.triangles)
                    .arg(&w.cell_start)
                    .arg(&w.cell_items)
                    .arg(&skin)
                    .arg(counts)
                    .arg(&offset)
                    .arg(&items)
                    .launch(cfg(n))
            }
        };
        candidates(&mut counts, 0, 0)?;
        let mut offset = zeros::<u32>(&st, n + 1)?;
        let n_items = self.scan(&counts, n, &mut offset)? as usize;
        let items = zeros::<u32>(&st, 2 * n_items)?;
        candidates(&mut counts, ptr(&offset, &st), ptr(&items, &st))?;
        let t = self.host.time;
        w.list = Some(WallList {
            offset,
            items,
            n_items,
            overlaps: zeros::<f64>(&st, 12 * n_items)?,
            reference: st.clone_dtod(&self.p.position)?,
            poses: self
                .host
                .scene
                .walls
                .iter()
                .map(|wall| wall.motion.transform(t))
                .collect(),
        });
        w.list_builds += 1;
        Ok(())
    }

    /// Before the drift to time `t`: the wall list's reference positions and how far a
    /// particle may move from them, half the skin less the most any point near the domain
    /// moved in any wall's frame since the list's build. In a wall's frame a particle at `x`
    /// sits at `P⁻¹ x`, so between poses `P₀` and `P` it moved by at most |x − x₀| +
    /// |P⁻¹ x − P₀⁻¹ x|, the second term bounded over the domain box grown by the cutoff by
    /// [`frame_drift`]. With no list, or walls that moved half the skin, the list is due and
    /// nothing is checked (a null reference).
    pub(super) fn wall_check(&mut self, t: f64) -> (u64, f64) {
        let half_skin = 0.5 * self.skin;
        let g = self.grid;
        let grow = self.host.scene.cutoff();
        let Some(w) = &mut self.walls else {
            return (0, 0.0);
        };
        let Some(list) = &w.list else {
            return (0, 0.0);
        };
        let lo = Vector3::from(g.min).add_scalar(-grow);
        let hi = Vector3::from(g.max).add_scalar(grow);
        let moved = self
            .host
            .scene
            .walls
            .iter()
            .zip(&list.poses)
            .map(|(wall, pose)| frame_drift(pose, &wall.motion.transform(t), &lo, &hi))
            .fold(0.0, f64::max);
        let reach = half_skin - moved;
        if reach <= 0.0 && moved > 0.0 {
            w.list = None;
            return (0, 0.0);
        }
        (ptr(&list.reference, &self.stream), reach)
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

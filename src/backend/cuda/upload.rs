//! Moving the host state onto the device: templates into constant memory, wall meshes with
//! their facet grids, and the particles with their contact history (as a CSR over the upload
//! order, which the next list build carries over).

use super::layout::{HISTORY_WIDTH, TemplateTables, history_record};
use super::simulation::{
    CudaError, CudaSimulation, DeviceParticles, DeviceWalls, HistorySource, WallInfo, WallState,
};
use crate::contact::WallMesh;
use cudarc::driver::{CudaModule, CudaStream, DeviceRepr};
use nalgebra::{UnitQuaternion, Vector3};
use std::collections::HashMap;
use std::sync::Arc;

/// Vectors as the kernels store them: xyz interleaved.
pub(super) fn flat3(v: &[Vector3<f64>]) -> Vec<f64> {
    v.iter().flat_map(|x| [x.x, x.y, x.z]).collect()
}

/// Quaternions as the kernels store them: x, y, z, w.
pub(super) fn flat_quats(v: &[UnitQuaternion<f64>]) -> Vec<f64> {
    v.iter()
        .flat_map(|q| {
            let c = q.coords;
            [c.x, c.y, c.z, c.w]
        })
        .collect()
}

impl CudaSimulation {
    pub(super) fn upload_templates(&mut self) -> Result<(), CudaError> {
        let s = &self.host.scene;
        let (nt, mv, mf) = (
            self.config.templates,
            self.config.max_vertices,
            self.config.max_faces,
        );
        let t = TemplateTables::new(&s.templates, nt, mv, mf);
        fn set<T: DeviceRepr>(
            module: &Arc<CudaModule>,
            stream: &Arc<CudaStream>,
            name: &str,
            data: &[T],
        ) -> Result<(), CudaError> {
            let mut view = module.get_global(name, stream)?;
            // SAFETY: the symbol holds at least data.len() values of T (sized by the same
            // KernelConfig that sized `data`).
            let mut typed = unsafe { view.transmute_mut::<T>(data.len()) }.ok_or_else(|| {
                CudaError::Compile(format!("constant {name} is smaller than expected"))
            })?;
            stream.memcpy_htod(data, &mut typed)?;
            Ok(())
        }
        let m = &self.k.contact;
        set(m, &self.stream, "pd_template_vertices", &t.vertices)?;
        set(m, &self.stream, "pd_template_normals", &t.normals)?;
        set(m, &self.stream, "pd_template_offsets", &t.offsets)?;
        set(m, &self.stream, "pd_template_counts", &t.counts)?;
        set(m, &self.stream, "pd_template_radius", &t.radius)?;
        set(m, &self.stream, "pd_template_equivalent", &t.equivalent)?;
        set(m, &self.stream, "pd_template_face_start", &t.face_start)?;
        set(m, &self.stream, "pd_template_face_points", &t.face_points)?;
        set(m, &self.stream, "pd_template_face_mask", &t.face_mask)?;
        Ok(())
    }

    pub(super) fn upload_walls(&mut self) -> Result<(), CudaError> {
        let s = &self.host.scene;
        if s.walls.is_empty() {
            return Ok(());
        }
        let cell = s.cutoff();
        let mut info = Vec::new();
        let (mut triangles, mut prisms, mut starts, mut items) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (k, w) in s.walls.iter().enumerate() {
            // A rank of a decomposed run keeps the facets that reach its box plus the halo (in
            // their order: the candidates' summation order is unchanged).
            let restricted = self.host.parallel.is_some().then(|| &self.host.walls[k]);
            let whole;
            let mesh = match restricted {
                Some(m) => m,
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
        let st = &self.stream;
        let n_walls = info.len();
        let one = |v: &mut Vec<u32>| {
            if v.is_empty() {
                v.push(0);
            }
        };
        one(&mut items);
        // A decomposed run uploads its walls again at each rebuild: the count goes on.
        let list_builds = self.walls.as_ref().map_or(0, |w| w.list_builds);
        self.walls = Some(DeviceWalls {
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
        });
        Ok(())
    }

    /// Uploads the host state (particles, forces, contact history) and schedules a list build.
    pub(super) fn upload_from_host(&mut self) -> Result<(), CudaError> {
        let st = self.stream.clone();
        let h = &self.host;
        // A rank of a decomposed run uploads its ghosts after its owned particles.
        let combined;
        let (p, owned) = match h.parallel.as_deref() {
            Some(par) => {
                let mut c = h.particles.clone();
                c.extend_from(&par.ghosts.particles);
                combined = c;
                (&combined, h.particles.len())
            }
            None => (&h.particles, h.particles.len()),
        };
        let s = &h.scene;
        let n = p.len();
        self.n = n;
        let mut ghost: Vec<u32> = (0..n).map(|i| u32::from(i >= owned)).collect();
        if ghost.is_empty() {
            ghost.push(0);
        }
        let (flat, quats) = (flat3, flat_quats);
        let mut tmpl = Vec::with_capacity(n);
        let mut material = Vec::with_capacity(n);
        let (mut radius, mut cn, mut ct) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..n {
            let ty = &s.particle_types[p.kind[i] as usize];
            let t = &s.templates[ty.template];
            let m = &s.materials[ty.material];
            tmpl.push(ty.template as u32);
            material.push(ty.material as u32);
            radius.push(t.circumscribed_radius * p.scale[i]);
            let r = t.equivalent_radius * p.scale[i];
            cn.push(m.youngs_modulus / r);
            ct.push(m.youngs_modulus / (2.0 * (1.0 + m.poisson_ratio) * r));
        }
        let pad = |mut v: Vec<f64>| {
            if v.is_empty() {
                v.push(0.0);
            }
            v
        };
        let pad32 = |mut v: Vec<u32>| {
            if v.is_empty() {
                v.push(0);
            }
            v
        };
        let mut ids = p.id.clone();
        if ids.is_empty() {
            ids.push(0);
        }
        self.p = DeviceParticles {
            id: st.clone_htod(&ids)?,
            tmpl: st.clone_htod(&pad32(tmpl))?,
            material: st.clone_htod(&pad32(material))?,
            kind: st.clone_htod(&pad32(p.kind.clone()))?,
            scale: st.clone_htod(&pad(p.scale.clone()))?,
            radius: st.clone_htod(&pad(radius))?,
            cn: st.clone_htod(&pad(cn))?,
            ct: st.clone_htod(&pad(ct))?,
            mass: st.clone_htod(&pad(p.mass.clone()))?,
            position: st.clone_htod(&pad(flat(&p.position)))?,
            velocity: st.clone_htod(&pad(flat(&p.velocity)))?,
            angular_velocity: st.clone_htod(&pad(flat(&p.angular_velocity)))?,
            orientation: st.clone_htod(&pad(quats(&p.orientation)))?,
            force: st.clone_htod(&pad(flat(&p.force)))?,
            torque: st.clone_htod(&pad(flat(&p.torque)))?,
            inertia: st.clone_htod(&pad(flat(&p.inertia)))?,
            ghost: st.clone_htod(&ghost)?,
        };
        // History, as a CSR over the uploaded order, for the coming list build.
        let index: HashMap<u64, usize> = p.id.iter().enumerate().map(|(i, &g)| (g, i)).collect();
        let mut per: Vec<Vec<(u64, [f64; HISTORY_WIDTH])>> = vec![Vec::new(); n];
        let n_walls = self.walls.as_ref().map_or(0, |w| w.n);
        let mut wall_spring = vec![0.0f64; (n * n_walls * HISTORY_WIDTH).max(1)];
        for (key, state) in h.history.entries() {
            let Some(&i) = index.get(&key.a) else {
                continue;
            };
            match key.wall_index() {
                Some(k) if k < n_walls => {
                    let slot = (i * n_walls + k) * HISTORY_WIDTH;
                    wall_spring[slot..slot + HISTORY_WIDTH].copy_from_slice(&history_record(state));
                }
                Some(_) => {}
                None => per[i].push((key.b, history_record(state))),
            }
        }
        let mut offset = vec![0u32; n + 1];
        let (mut partner, mut spring) = (Vec::new(), Vec::new());
        for i in 0..n {
            for (b, sp) in &per[i] {
                partner.push(*b);
                spring.extend_from_slice(sp);
            }
            offset[i + 1] = partner.len() as u32;
        }
        if partner.is_empty() {
            partner.push(u64::MAX);
            spring.extend_from_slice(&[0.0; HISTORY_WIDTH]);
        }
        self.pending_history = Some(HistorySource {
            offset: st.clone_htod(&offset)?,
            partner: st.clone_htod(&partner)?,
            spring: st.clone_htod(&spring)?,
        });
        if let Some(w) = &mut self.walls {
            let nw = (n * n_walls).max(1);
            w.spring_in = st.clone_htod(&wall_spring)?;
            w.spring_out = st.alloc_zeros::<f64>(HISTORY_WIDTH * nw)?;
            w.force = st.alloc_zeros::<f64>(3 * n.max(1))?;
            w.torque = st.alloc_zeros::<f64>(3 * n.max(1))?;
            w.energy = st.alloc_zeros::<f64>(n.max(1))?;
            w.per_wall_force = st.alloc_zeros::<f64>(3 * nw)?;
            w.contact = st.alloc_zeros::<u32>(nw)?;
            w.list = None;
        }
        self.pairs = None;
        self.halo = None;
        self.rebuild = true;
        self.host_current = true;
        Ok(())
    }
}

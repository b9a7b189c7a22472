//! Moving the host state onto the device: templates into constant memory, wall meshes with
//! their facet grids, and the particles with their contact history (as a CSR over the upload
//! order, which the next list build carries over).

use super::CudaSimulation;
use super::error::CudaError;
use super::history::{HistoryRows, history_rows};
use super::layout::TemplateTables;
use super::pairs::HistorySource;
use super::particles::{DeviceParticles, HostParticleArrays};
use super::walls::WallStage;
use crate::scene::Scene;
use crate::state::Particles;
use cudarc::driver::{CudaModule, CudaStream, DeviceRepr};
use nalgebra::{UnitQuaternion, Vector3};
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

/// Particles `p` of `scene` in the device's layout, with the `device` fields derived: the
/// template and material of each one's type, its circumscribed radius, and the normal and
/// tangential stiffness scales `E / r` and `G / r` of its equivalent radius; the particles from
/// `owned` on are a decomposed run's ghosts.
pub(super) fn host_arrays(scene: &Scene, p: &Particles, owned: usize) -> HostParticleArrays {
    let n = p.len();
    let ghost: Vec<u32> = (0..n).map(|i| u32::from(i >= owned)).collect();
    let mut tmpl = Vec::with_capacity(n);
    let mut material = Vec::with_capacity(n);
    let (mut radius, mut cn, mut ct) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..n {
        let ty = &scene.particle_types[p.kind[i] as usize];
        let t = &scene.templates[ty.template];
        let m = &scene.materials[ty.material];
        tmpl.push(ty.template as u32);
        material.push(ty.material as u32);
        radius.push(t.circumscribed_radius * p.scale[i]);
        let r = t.equivalent_radius * p.scale[i];
        cn.push(m.youngs_modulus / r);
        ct.push(m.youngs_modulus / (2.0 * (1.0 + m.poisson_ratio) * r));
    }
    HostParticleArrays {
        scale: p.scale.clone(),
        radius,
        cn,
        ct,
        mass: p.mass.clone(),
        position: flat3(&p.position),
        velocity: flat3(&p.velocity),
        angular_velocity: flat3(&p.angular_velocity),
        orientation: flat_quats(&p.orientation),
        force: flat3(&p.force),
        torque: flat3(&p.torque),
        inertia: flat3(&p.inertia),
        tmpl,
        material,
        kind: p.kind.clone(),
        ghost,
        contacts: p.contacts.clone(),
        id: p.id.clone(),
    }
}

impl CudaSimulation {
    /// The scene's templates into `contact.cu`'s constant and global tables.
    pub(super) fn upload_templates(&mut self) -> Result<(), CudaError> {
        let s = &self.state.scene;
        let config = &self.gpu.config;
        let (nt, mv, mf) = (config.templates, config.max_vertices, config.max_faces);
        let t = TemplateTables::new(&s.templates, nt, mv, mf);
        fn set<T: DeviceRepr>(
            module: &Arc<CudaModule>,
            stream: &Arc<CudaStream>,
            name: &'static str,
            data: &[T],
        ) -> Result<(), CudaError> {
            let mut view = module.get_global(name, stream)?;
            // SAFETY: the symbol holds at least data.len() values of T (sized by the same
            // KernelConfig that sized `data`).
            let mut typed =
                unsafe { view.transmute_mut::<T>(data.len()) }.ok_or(CudaError::Symbol {
                    name,
                    expected: data.len(),
                })?;
            stream.memcpy_htod(data, &mut typed)?;
            Ok(())
        }
        let (m, st) = (&self.gpu.k.contact, &self.gpu.stream);
        set(m, st, "pd_template_vertices", &t.vertices)?;
        set(m, st, "pd_template_normals", &t.normals)?;
        set(m, st, "pd_template_offsets", &t.offsets)?;
        set(m, st, "pd_template_counts", &t.counts)?;
        set(m, st, "pd_template_radius", &t.radius)?;
        set(m, st, "pd_template_equivalent", &t.equivalent)?;
        set(m, st, "pd_template_face_start", &t.face_start)?;
        set(m, st, "pd_template_face_points", &t.face_points)?;
        set(m, st, "pd_template_face_mask", &t.face_mask)?;
        Ok(())
    }

    /// The walls uploaded ([`WallStage::upload`]): a decomposed rank's restricted meshes, or
    /// the scene's whole. A decomposed run uploads its walls again at each rebuild: the count
    /// of wall lists goes on.
    pub(super) fn upload_walls(&mut self) -> Result<(), CudaError> {
        let restricted = self
            .state
            .parallel
            .is_some()
            .then_some(self.state.walls.as_slice());
        let list_builds = self.walls.as_ref().map_or(0, |w| w.list_builds);
        let walls = WallStage::upload(&self.gpu, &self.state.scene, restricted, list_builds)?;
        if walls.is_some() {
            self.walls = walls;
        }
        Ok(())
    }

    /// Uploads the host state (particles, forces, contact history) and schedules a list build.
    pub(super) fn upload_from_host(&mut self) -> Result<(), CudaError> {
        let st = self.gpu.stream.clone();
        let h = &self.state;
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
        let n = p.len();
        self.particles =
            DeviceParticles::upload(&st, n, host_arrays(&h.scene, p, owned)).map_err(|e| {
                e.out_of_memory(
                    || format!("the particle arrays of {n} particles"),
                    Some(n * DeviceParticles::BYTES_PER_PARTICLE),
                )
            })?;
        // History, as a CSR over the uploaded order, for the coming list build.
        let n_walls = self.walls.as_ref().map_or(0, |w| w.n);
        let HistoryRows {
            offset,
            partner,
            spring,
            wall_spring,
        } = history_rows(&p.id, &h.history, n_walls);
        let history = HistorySource::Rows {
            offset: st.clone_htod(&offset)?,
            partner: st.clone_htod(&partner)?,
            spring: st.clone_htod(&spring)?,
        };
        if let Some(w) = &mut self.walls {
            w.resize(&st, n, &wall_spring)?;
        }
        self.pairs.reset(history);
        self.halo.reset();
        self.host_current = true;
        Ok(())
    }
}

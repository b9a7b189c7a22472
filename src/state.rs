//! Particle state, materials and particle types: the data every stage reads and writes; and
//! the observables a force evaluation leaves ([`StepStats`]).
//!
//! Particles are a structure of arrays indexed by a local index (docs/design.md §3); each has a
//! global id that never changes and names it in output and checkpoints. Positions, velocities,
//! orientations and angular velocities are f64 on the CPU.

use crate::shape::ConvexTemplate;
use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Elastic and inertial properties of a material.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Material {
    /// Name used by particle types, walls and material pairs.
    pub name: String,
    /// Young's modulus E (Pa).
    pub youngs_modulus: f64,
    /// Poisson's ratio ν.
    pub poisson_ratio: f64,
    /// Density ρ (kg/m³).
    pub density: f64,
}

/// Interaction parameters of two materials.
#[derive(Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PairParameters {
    /// Coefficient of normal restitution e ∈ (0, 1].
    pub restitution: f64,
    /// Coulomb friction coefficient μ ≥ 0.
    pub friction: f64,
    /// Rolling friction coefficient μ_r ≥ 0: the couple against the relative rolling of the
    /// two bodies is at most `μ_r R_r F_n` ([`crate::contact::law`], docs/contact.md §5);
    /// 0 (the default) adds none.
    #[serde(default)]
    pub rolling_friction: f64,
}

/// Printed as the derived form, with `rolling_friction` only where it is set: the restart
/// fingerprint (`scene::restart`) prints the pair table, and a checkpoint written before the
/// key existed must still restart the scene it came from.
impl std::fmt::Debug for PairParameters {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut d = f.debug_struct("PairParameters");
        d.field("restitution", &self.restitution)
            .field("friction", &self.friction);
        if self.rolling_friction != 0.0 {
            d.field("rolling_friction", &self.rolling_friction);
        }
        d.finish()
    }
}

/// A kind of particle: a template and a material.
#[derive(Clone, Debug)]
pub struct ParticleType {
    /// Name used by insertions.
    pub name: String,
    /// Index into the scene's templates (`Scene::templates`).
    pub template: usize,
    /// Index into the material table.
    pub material: usize,
}

/// Per-particle state, structure of arrays.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Particles {
    /// Global id, unique and permanent.
    pub id: Vec<u64>,
    /// Particle type index.
    pub kind: Vec<u32>,
    /// Uniform scale applied to the type's template.
    pub scale: Vec<f64>,
    /// Centroid position (world).
    pub position: Vec<Vector3<f64>>,
    /// Centroid velocity (world).
    pub velocity: Vec<Vector3<f64>>,
    /// Rotation body → world.
    pub orientation: Vec<UnitQuaternion<f64>>,
    /// Angular velocity (world frame).
    pub angular_velocity: Vec<Vector3<f64>>,
    /// Total force of the last force evaluation (world).
    pub force: Vec<Vector3<f64>>,
    /// Total torque about the centroid of the last force evaluation (world).
    pub torque: Vec<Vector3<f64>>,
    /// Mass, from the type's material and template and the scale.
    pub mass: Vec<f64>,
    /// Principal moments of inertia (body frame).
    pub inertia: Vec<Vector3<f64>>,
    /// Contacts (particles and walls) of the last force evaluation: the number the dashpot
    /// caps of the next one split the particle's mass among ([`crate::contact::law`],
    /// docs/contact.md §2). Not stored in checkpoints: [`Particles::count_contacts`] recovers
    /// it from the contact history, which holds exactly those contacts.
    pub contacts: Vec<u32>,
}

impl Particles {
    /// Number of particles.
    pub fn len(&self) -> usize {
        self.id.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.id.is_empty()
    }

    /// Appends a particle at rest, with mass and inertia from its type, material and scale:
    /// `m = ρ V s³`, `I = ρ I₁ s⁵` (the template's inertia is per unit density).
    #[allow(clippy::too_many_arguments)]
    pub fn push(
        &mut self,
        id: u64,
        kind: u32,
        scale: f64,
        position: Vector3<f64>,
        orientation: UnitQuaternion<f64>,
        template: &ConvexTemplate,
        density: f64,
    ) {
        self.id.push(id);
        self.kind.push(kind);
        self.scale.push(scale);
        self.position.push(position);
        self.velocity.push(Vector3::zeros());
        self.orientation.push(orientation);
        self.angular_velocity.push(Vector3::zeros());
        self.force.push(Vector3::zeros());
        self.torque.push(Vector3::zeros());
        self.mass.push(density * template.volume * scale.powi(3));
        self.inertia
            .push(template.principal_inertia * (density * scale.powi(5)));
        self.contacts.push(0);
    }

    /// The particles at local indices `which`, in that order.
    pub fn select(&self, which: &[usize]) -> Particles {
        macro_rules! pick {
            ($($f:ident),*) => { Particles { $($f: which.iter().map(|&i| self.$f[i]).collect(),)* } };
        }
        pick!(
            id,
            kind,
            scale,
            position,
            velocity,
            orientation,
            angular_velocity,
            force,
            torque,
            mass,
            inertia,
            contacts
        )
    }

    /// Appends every particle of `other`.
    pub fn extend_from(&mut self, other: &Particles) {
        self.id.extend_from_slice(&other.id);
        self.kind.extend_from_slice(&other.kind);
        self.scale.extend_from_slice(&other.scale);
        self.position.extend_from_slice(&other.position);
        self.velocity.extend_from_slice(&other.velocity);
        self.orientation.extend_from_slice(&other.orientation);
        self.angular_velocity
            .extend_from_slice(&other.angular_velocity);
        self.force.extend_from_slice(&other.force);
        self.torque.extend_from_slice(&other.torque);
        self.mass.extend_from_slice(&other.mass);
        self.inertia.extend_from_slice(&other.inertia);
        self.contacts.extend_from_slice(&other.contacts);
    }

    /// Keeps the first `n` particles.
    pub fn truncate(&mut self, n: usize) {
        self.id.truncate(n);
        self.kind.truncate(n);
        self.scale.truncate(n);
        self.position.truncate(n);
        self.velocity.truncate(n);
        self.orientation.truncate(n);
        self.angular_velocity.truncate(n);
        self.force.truncate(n);
        self.torque.truncate(n);
        self.mass.truncate(n);
        self.inertia.truncate(n);
        self.contacts.truncate(n);
    }

    /// Sets [`Particles::contacts`] from a contact history: each particle's count of the
    /// entries it is a member of (an entry's members that are not here are skipped). The
    /// history holds exactly the contacts of the evaluation that wrote it, so this recovers the
    /// counts that evaluation left (a restart continues bitwise).
    pub fn count_contacts(&mut self, history: &crate::contact::ContactHistory) {
        let mut by_id: Vec<(u64, usize)> = self.id.iter().copied().zip(0..).collect();
        by_id.sort_unstable();
        let find = |id: u64| {
            by_id
                .binary_search_by_key(&id, |e| e.0)
                .ok()
                .map(|k| by_id[k].1)
        };
        let mut counts = vec![0u32; self.len()];
        for (key, _) in history.entries() {
            if let Some(i) = find(key.a) {
                counts[i] += 1;
            }
            if key.wall_index().is_none()
                && let Some(j) = find(key.b)
            {
                counts[j] += 1;
            }
        }
        self.contacts = counts;
    }

    /// The local indices of the first `n` particles in global id order, or `None` when they
    /// are in it already (one rank that inserted and removed particles, but was not restarted
    /// from another backend's order or given migrants). Sums that must not depend on the local
    /// order, which a list build on the GPU, a restart or a migration changes, run in this one.
    pub fn id_order(&self, n: usize) -> Option<Vec<usize>> {
        id_order(&self.id[..n])
    }

    /// Removes the particles at the (sorted) local indices `remove`, keeping the others' order.
    pub fn remove(&mut self, remove: &[usize]) {
        let mut keep = vec![true; self.len()];
        for &i in remove {
            keep[i] = false;
        }
        let kept: Vec<usize> = (0..self.len()).filter(|&i| keep[i]).collect();
        *self = self.select(&kept);
    }

    /// Translational plus rotational kinetic energy of particle `i`.
    pub fn kinetic_energy(&self, i: usize) -> f64 {
        let w_body = self.orientation[i].inverse_transform_vector(&self.angular_velocity[i]);
        0.5 * self.mass[i] * self.velocity[i].norm_squared()
            + 0.5 * w_body.component_mul(&self.inertia[i]).dot(&w_body)
    }
}

/// Per-step observables.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StepStats {
    /// Particle pairs with a positive overlap.
    pub contacts: u64,
    /// Particle–wall contacts with a positive overlap.
    pub wall_contacts: u64,
    /// Elastic energy stored in all contacts.
    pub elastic_energy: f64,
    /// Particles removed because they left a non-periodic domain, cumulative.
    pub removed: u64,
}

/// The indices of `ids` in increasing order of id, or `None` when they are in it already
/// ([`Particles::id_order`]; also for id arrays copied from a device).
pub fn id_order(ids: &[u64]) -> Option<Vec<usize>> {
    if ids.windows(2).all(|w| w[0] < w[1]) {
        return None;
    }
    let mut order: Vec<usize> = (0..ids.len()).collect();
    order.sort_unstable_by_key(|&i| ids[i]);
    Some(order)
}

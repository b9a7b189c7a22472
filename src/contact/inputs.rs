//! What one contact evaluation of the law ([`super::law::contact_forces`]) takes and gives:
//! the pair's material and size parameters, the two bodies' kinematics and masses, and the
//! forces, torques and stored energy it returns.

use super::trajectory::FaceWindow;
use nalgebra::{UnitQuaternion, Vector3};

/// Parameters of one pair of materials and particle sizes.
#[derive(Clone, Debug)]
pub struct ContactParameters {
    /// `c = E₁/R₁ + E₂/R₂` (Pa/m): the elastic stiffness per unit contact area and V^{1/3}.
    pub normal_stiffness: f64,
    /// `E₁/(2(1+ν₁)R₁) + E₂/(2(1+ν₂)R₂)` (Pa/m): tangential stiffness per unit area.
    pub tangential_stiffness: f64,
    /// Restitution coefficient e.
    pub restitution: f64,
    /// Friction coefficient μ.
    pub friction: f64,
    /// Rolling friction coefficient μ_r (0: no rolling couple).
    pub rolling_friction: f64,
    /// Hunt–Crossley coefficient `ᾱ(e)` ([`super::restitution::hunt_crossley_alpha`]).
    pub damping: f64,
    /// Whether the contact area resists rocking (polyhedra). A sphere's contact has no face
    /// to rock on, and the couple would brake its rolling (viscous rolling resistance).
    pub rocking: bool,
    /// How a face contact's force is sampled over a step ([`FaceWindow`]).
    pub face_window: FaceWindow,
}

/// The kinematics of a contact.
#[derive(Clone, Copy, Debug)]
pub struct ContactKinematics {
    /// Centres of A and B.
    pub x_a: Vector3<f64>,
    pub x_b: Vector3<f64>,
    /// Velocities of A and B.
    pub v_a: Vector3<f64>,
    pub v_b: Vector3<f64>,
    /// Angular velocities (world) of A and B.
    pub w_a: Vector3<f64>,
    pub w_b: Vector3<f64>,
    /// Effective mass `(1/m_A + 1/m_B)^{-1}` (m_A for a wall contact).
    pub effective_mass: f64,
    /// Inverse masses `1/m_A`, `1/m_B` (zero for a wall).
    pub inverse_mass_a: f64,
    pub inverse_mass_b: f64,
    /// Orientations (body → world) of A and B.
    pub q_a: UnitQuaternion<f64>,
    pub q_b: UnitQuaternion<f64>,
    /// Inverse principal moments of inertia of A and B (zero for a wall).
    pub inverse_inertia_a: Vector3<f64>,
    pub inverse_inertia_b: Vector3<f64>,
    /// Sphere radii of A and B on the sphere fast path, zero for a polyhedron or a wall (see
    /// [`contact_point`](super::law::contact_point)).
    pub sphere_radius_a: f64,
    pub sphere_radius_b: f64,
    /// The shares `k_A`, `k_B` ≥ 1 into which the dashpot caps split each body's mass: its
    /// contacts at the last evaluation (1 for a wall, and for a body that had none). See
    /// [`DASHPOT_STEP_FRACTION`](super::law::DASHPOT_STEP_FRACTION).
    pub split_a: f64,
    pub split_b: f64,
    /// The effective mass the dashpot cap sees, with each body's inverse-mass term (the
    /// effective mass's `1/m + (r × n)·I⁻¹(r × n)`) multiplied by its share: equal to
    /// `effective_mass` bit for bit when both shares are 1.
    pub dashpot_mass: f64,
}

impl ContactKinematics {
    /// `u·(k_A I_A⁻¹ + k_B I_B⁻¹)u`: the inverse of the moment of inertia the relative rotation
    /// about the unit axis `u` sees (world inverse inertia `R diag(1/I) Rᵀ` of each body), each
    /// body's term multiplied by its share `k_a`, `k_b` (1 and 1, or the caps' mass splitting).
    pub fn weighted_inverse_inertia(&self, u: &Vector3<f64>, k_a: f64, k_b: f64) -> f64 {
        let term = |q: &UnitQuaternion<f64>, inv: &Vector3<f64>| {
            let b = q.inverse_transform_vector(u);
            b.component_mul(inv).dot(&b)
        };
        k_a * term(&self.q_a, &self.inverse_inertia_a)
            + k_b * term(&self.q_b, &self.inverse_inertia_b)
    }

    /// The inverse mass a tangential force at the point `r` sees, summed over the two
    /// directions of the tangent plane of the unit normal `n`: the trace of the tangential
    /// block of `W = Σ k (1/m − [r − x]× I⁻¹ [r − x]×)` over the two bodies, each term
    /// multiplied by its share `k_a`, `k_b` (a wall's term is zero), computed without a basis
    /// as `tr W − n·W n`. The trace bounds the block's largest eigenvalue, so friction's lock
    /// and spring sized by it ([`super::friction`]) take at most their share of the motion
    /// in any tangential direction; for a sphere, or any body whose block is isotropic, it is
    /// twice the inverse mass along each direction.
    pub fn tangential_inverse_mass_trace(
        &self,
        r: &Vector3<f64>,
        n: &Vector3<f64>,
        k_a: f64,
        k_b: f64,
    ) -> f64 {
        let term = |x: &Vector3<f64>, q: &UnitQuaternion<f64>, d: &Vector3<f64>, m: f64| {
            let b = q.inverse_transform_vector(&(r - x));
            let nb = q.inverse_transform_vector(n);
            let (x2, y2, z2) = (b.x * b.x, b.y * b.y, b.z * b.z);
            let trace = d.x * (y2 + z2) + d.y * (x2 + z2) + d.z * (x2 + y2);
            let a = b.cross(&nb);
            2.0 * m + (trace - a.component_mul(d).dot(&a))
        };
        let sum =
            k_a * term(
                &self.x_a,
                &self.q_a,
                &self.inverse_inertia_a,
                self.inverse_mass_a,
            ) + k_b
                * term(
                    &self.x_b,
                    &self.q_b,
                    &self.inverse_inertia_b,
                    self.inverse_mass_b,
                );
        sum.max(0.0)
    }
}

/// A body's share of the dashpot caps' mass splitting: its contact count at the last
/// evaluation, at least 1 ([`ContactKinematics::split_a`]).
pub fn mass_share(contacts: u32) -> f64 {
    f64::from(contacts.max(1))
}

/// Forces and torques of one contact.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactForces {
    /// Force on B (the force on A is its negative).
    pub force_b: Vector3<f64>,
    /// Torque on A about its centre.
    pub torque_a: Vector3<f64>,
    /// Torque on B about its centre.
    pub torque_b: Vector3<f64>,
    /// Elastic energy stored: `W(V) + k_t |ξ|² / 2 + k_tw φ² / 2` (the potential and the
    /// friction springs).
    pub elastic_energy: f64,
}

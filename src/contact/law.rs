//! The volume-based contact law (seed paper Eq. 12–22), in its energy-conserving form.
//!
//! Normal, elastic: the potential `U(V) = (3/4) c V^{4/3}` with `c = E₁/R₁ + E₂/R₂` (R the
//! volume-equivalent radii; for a wall `R₂ → ∞`) gives `F_B = −U'(V) S = c V^{1/3} A_n n`, the
//! seed's Eq. 12–13 with `n = −S/|S|` and `A_n = |S|` taken from `S = dV/dx_B`, and the torque on
//! B about its centre `−U'(V) (M_B + (c_V − x_B) × S)` (validation.md §1). With both taken from S
//! and the surface moment, the elastic contact conserves energy exactly in the time-continuous
//! limit, for any shapes.
//!
//! Normal, damping: `F_d = −γ(e, p) √(m_eff k_loc) (v_r · n) n` with `k_loc = p F_e / δ` the local
//! stiffness of the power law `F_e ∝ δ^p`, where `δ` is the overlap's thickness along the normal
//! and `p = (4q + 1)/3` follows from the area exponent `q` of `A_n ∝ δ^q`, measured as
//! `q = A_n δ / V − 1` (since `dV/dδ = A_n`). `γ(e, p)` comes from [`super::restitution`]; this
//! makes the restitution the prescribed `e` for vertex, edge and face impacts alike, where seed
//! Eq. 15 (tuned for a linear spring) does not.
//!
//! Tangential: Cundall–Strack spring (seed Eq. 17–20): the displacement ξ is rotated into the
//! current tangent plane each step (keeping its length), incremented by `v_t dt`, and
//! `F_t = −k_t ξ − c_t v_t` with `k_t = (E₁/(2(1+ν₁)R₁) + E₂/(2(1+ν₂)R₂)) A_n` and `c_t` from
//! Eq. 20; capped at `μ |F_n|`, in which case ξ is reset to the spring length that carries the
//! capped force (sliding). The incremental, rotated form cannot create energy in elastic
//! sticking impacts (validation.md §6).

use super::history::ContactState;
use super::restitution::DampingTable;
use crate::geometry::Overlap;
use nalgebra::Vector3;

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
    /// Elastic energy stored: `(3/4) c V^{4/3} + k_t |ξ|² / 2`.
    pub elastic_energy: f64,
}

/// Evaluates the contact law for an overlap, updating the contact's history `state` over `dt`.
pub fn contact_forces(
    params: &ContactParameters,
    damping: &DampingTable,
    overlap: &Overlap<f64>,
    kin: &ContactKinematics,
    state: &mut ContactState,
    dt: f64,
) -> ContactForces {
    let area = overlap.area();
    let volume = overlap.volume;
    if volume <= 0.0 || area <= 0.0 {
        return ContactForces::default();
    }
    let n = -overlap.dv_dxb / area; // from A to B
    let c = overlap.centroid;
    let v_rel =
        (kin.v_b + kin.w_b.cross(&(c - kin.x_b))) - (kin.v_a + kin.w_a.cross(&(c - kin.x_a)));
    let vn = v_rel.dot(&n); // > 0 when separating

    // Elastic part: U'(V) = c V^{1/3}; F_B = −U' S.
    let u_prime = params.normal_stiffness * volume.cbrt();
    let f_elastic = u_prime * area;
    let torque_b_el = -(overlap.moment_b + (c - kin.x_b).cross(&overlap.dv_dxb)) * u_prime;
    let torque_a_el = -(-overlap.moment_b + (c - kin.x_a).cross(&(-overlap.dv_dxb))) * u_prime;

    // Penetration δ and the exponent of F ∝ δ^p from the geometry: with V ∝ δ^{q+1} and
    // A_n ∝ δ^q, q = A_n δ / V − 1 (0 face, 1 edge, 2 vertex) and p = (4q + 1)/3.
    let delta = overlap.thickness.max(volume / area);
    let q = (area * delta / volume - 1.0).max(0.0);
    let p = (4.0 * q + 1.0) / 3.0;
    let k_loc = p * f_elastic / delta;
    let gamma = damping.gamma(p);
    let mut f_damp = -gamma * (kin.effective_mass * k_loc).sqrt() * vn;
    // The face–face stiffness, and with it the damping coefficient, grows without bound as
    // δ → 0; an explicit step must not let the dashpot reverse the normal approach on its own
    // (its impulse is at most the normal momentum m*|v_n|), or it over-damps the first steps of
    // a flat impact.
    if dt > 0.0 {
        let limit = kin.effective_mass * vn.abs() / dt;
        f_damp = f_damp.clamp(-limit, limit);
    }
    // The contact pushes, never pulls.
    let f_normal = (f_elastic + f_damp).max(0.0);
    let mut force_b = n * f_normal;

    // Tangential spring.
    let v_t = v_rel - n * vn;
    let mut tangential = Vector3::zeros();
    if params.friction > 0.0 {
        let old = state.spring;
        let in_plane = old - n * old.dot(&n);
        let len = in_plane.norm();
        let rotated = if len > 0.0 {
            in_plane * (old.norm() / len)
        } else {
            Vector3::zeros()
        };
        let mut xi = rotated + v_t * dt;
        let k_t = params.tangential_stiffness * area;
        let e = params.restitution;
        let c_t = if e < 1.0 {
            2.0 * e.ln().abs() * (k_t * kin.effective_mass).sqrt()
                / (e.ln().powi(2) + std::f64::consts::PI.powi(2)).sqrt()
        } else {
            0.0
        };
        // Force on B from the spring and dashpot, opposing B's slip relative to A.
        let mut f_t = -xi * k_t - v_t * c_t;
        let cap = params.friction * f_normal;
        let magnitude = f_t.norm();
        if magnitude > cap {
            // Sliding: the spring carries exactly the Coulomb force.
            f_t *= if magnitude > 0.0 {
                cap / magnitude
            } else {
                0.0
            };
            xi = if k_t > 0.0 {
                -f_t / k_t
            } else {
                Vector3::zeros()
            };
        }
        state.spring = xi;
        tangential = f_t;
    } else {
        state.spring = Vector3::zeros();
    }
    force_b += tangential;

    // Non-elastic forces act at the overlap centroid.
    let f_other = force_b - n * f_elastic;
    let torque_b = torque_b_el + (c - kin.x_b).cross(&f_other);
    let torque_a = torque_a_el + (c - kin.x_a).cross(&(-f_other));
    let k_t = params.tangential_stiffness * area;
    ContactForces {
        force_b,
        torque_a,
        torque_b,
        // U(V) = (3/4) c V^{4/3} = (3/4) U'(V) V: no second root.
        elastic_energy: 0.75 * u_prime * volume + 0.5 * k_t * state.spring.norm_squared(),
    }
}

//! The volume-based contact law (seed paper Eq. 12–22): the seed's energy-conserving elastic
//! part, with damping, friction and rolling resistance that behave for flat contacts. The
//! equations and the reasoning behind each term are in docs/contact.md; in short:
//!
//! - Elastic: `U(V) = (3/4) c V^{4/3}`, `c = E₁/R₁ + E₂/R₂`, gives `F_B = −U'(V) S` and the
//!   torque `−U'(V) (M_B + (c_V − x_B) × S)` (seed Eq. 12–13). A face contact's stiffness
//!   `F/(3δ)` is unbounded at first touch, so the slope at one point of the step (seed Eq. 12
//!   as written) makes a face impact's energy depend on where in a step it starts. For such
//!   contacts (local exponent `k = A_n h / V < 3/2`, `h` the overlap's thickness), `U'` is
//!   taken as the mean of the potential's slope over the volume swept in the step's kick
//!   window, `[V − A_n s, V + A_n s]` with `s = |v_n| Δt/2` (the secant of U, exact at rest);
//!   a contact's first step also carries the share of the kick before it that the contact
//!   entered during, and its last step the share of the kick after it that it leaves during.
//!   Other contacts take the slope at V, which keeps the step symplectic. Every contact takes
//!   U regularized below `V* = (A_n Δt √(c/m*)/2)³` ([`resolved_volume`]): linear in V there,
//!   with a stiffness the step resolves, so that a face resting under a load (whose seed
//!   stiffness no practical step resolves) stays at rest instead of chattering.
//! - Normal damping (Hunt–Crossley): `F_d = −ᾱ(e) F_e v_n / v_ref`, `v_ref` the approach
//!   speed of the contact's current loading cycle ([`loading_cycle_speed`], kept in the
//!   contact history), at least `√(2U/m*)`. It is bounded wherever the
//!   elastic force is, and gives restitution `e` for every exponent of `F_e(δ)`
//!   ([`super::restitution::hunt_crossley_alpha`]).
//! - The normal force acts on the elastic force's line of action, through
//!   `r_e = c_V + (S × M_B)/|S|²`: a dashpot at the overlap centroid has the lever
//!   `θ L²/(12 δ)` on a tilted face and pumps its rocking.
//! - Friction ([`super::friction`]): at `r_e`, a spring and a dashpot side by side in series
//!   with a Coulomb slider (`μ |F_n|`), the spring rotated into the current tangent plane each
//!   step and carried at constant energy, the dashpot the step's lock (the slip of one step,
//!   against the mass the slip sees). It never does positive work over a contact's life, and
//!   a sticking impact ends rolling, as rigid-body theory with Coulomb friction has it.
//! - Rocking damping of a polyhedron's contact area: the normal dashpot spread over the
//!   contact disk of area `A_n` resists the relative rotation about tangent axes with the
//!   couple `−c_n A_n/(4π) ω⊥` (`c_n = ᾱ F_e / v_ref`). Spheres have none: they have no face to
//!   rock on, and it would brake their rolling.
//! - Twisting friction: the same element as the tangential one about the normal, its spring
//!   the tangential spring spread over the contact disk (`k_t A_n/(2π)`), its lock against the
//!   moments of inertia about the normal, its slider `μ |F_n| (2/3) √(A_n/π)`, the Coulomb
//!   limit of a disk.
//!
//! Every dissipative term is bounded by what one explicit step can remove: its impulse never
//! reverses the relative velocity it acts on.

use super::friction::{lock_coefficient, resolved_stiffness, slip_step, stretch};
use super::history::ContactState;
use super::potential::{LocalPowerLaw, resolved_pressure};
pub use super::potential::{
    RESOLVED_STEP, SINGULAR_EXPONENT, WINDOW_FRACTION, mean_pressure, resolved_mean_pressure,
    resolved_potential, resolved_volume,
};
use super::trajectory::{FaceWindow, NormalMotion, TRAJECTORY_FRACTION};
use crate::geometry::Overlap;
use crate::geometry::portable_cbrt;
use nalgebra::Vector3;

pub use super::inputs::{ContactForces, ContactKinematics, ContactParameters, mass_share};

/// Below this fraction of the overlap's area scale `V^{2/3}`, `|S|` is taken for a body
/// wholly inside the other ([`wholly_inside`]).
pub const INSIDE_AREA_FRACTION: f64 = 1e-6;

/// `INSIDE_AREA_FRACTION³`, the form the law compares with.
const INSIDE_AREA_CUBED: f64 = 1e-18;

/// `V^{2/3}`: the area scale of an overlap of volume `V`.
fn volume_area_scale(volume: f64) -> f64 {
    let r = portable_cbrt(volume);
    r * r
}

/// The overlap of a body wholly inside the other, where `S = dV/dx_B` vanishes (moving B does
/// not change V) and what the geometry returns is round-off in magnitude and direction. Its
/// force is defined instead: along the line of centres from A to B (+z for coincident
/// centres), with the overlap's area scale `V^{2/3}` for `|S|` and no surface moment, so the
/// bodies are pushed apart by `c V` and the stability guard (`crate::stability`) names them.
pub fn wholly_inside(overlap: &Overlap<f64>, kin: &ContactKinematics) -> Overlap<f64> {
    let d = kin.x_b - kin.x_a;
    let len = d.norm();
    let u = if len > 0.0 { d / len } else { Vector3::z() };
    Overlap {
        dv_dxb: -u * volume_area_scale(overlap.volume),
        moment_b: Vector3::zeros(),
        ..*overlap
    }
}

/// Where the damping and friction of a contact act: on the elastic force's line of action, at
/// the contact surface.
///
/// - Polyhedra: `r_e = c_V + (S × M_B)/|S|²`, the line of action at the centroid's depth. For a
///   face on a face (most contacts of a packing) the centroid lies midway between the two
///   faces, on the contact surface.
/// - A sphere on a wall: the sphere's surface point `x_A + R_A n`, so that friction has the
///   lever `R` of the rigid sphere and rolling means `v = ω R`. The centroid of the cap lies
///   `2δ/3` inside the surface, which shortened the lever by that much: ω' after a sliding
///   impact was up to 1 % low for soft spheres (δ/R ≈ 1 %).
/// - Two spheres: the plane of the lens's rim, where the two surfaces meet, at
///   `(d² + R_A² − R_B²)/(2d)` from A's centre along the line of centres. One point for both
///   bodies keeps the pair's angular momentum.
pub fn contact_point(
    overlap: &Overlap<f64>,
    kin: &ContactKinematics,
    n: &Vector3<f64>,
) -> Vector3<f64> {
    let (ra, rb) = (kin.sphere_radius_a, kin.sphere_radius_b);
    if ra > 0.0 {
        if rb <= 0.0 {
            return kin.x_a + n * ra;
        }
        let d = kin.x_b - kin.x_a;
        let d2 = d.norm_squared();
        if d2 > 0.0 {
            return kin.x_a + d * ((d2 + ra * ra - rb * rb) / (2.0 * d2));
        }
    }
    let area = overlap.area();
    // The line of action at the centroid's depth: r_e − c = S × M_B / |S|².
    let offset = overlap.dv_dxb.cross(&overlap.moment_b) / (area * area);
    if offset.iter().all(|x| x.is_finite()) {
        overlap.centroid + offset
    } else {
        overlap.centroid
    }
}

/// The largest share of its relative speed that the normal or rocking dashpot of a contact
/// damped by the floor `√(2W/m*)` (at rest, or loaded slowly) may take in one explicit step:
/// `c Δt/m̃* ≤ 1/2`; a contact damped to its cycle's approach speed (an impact) keeps the
/// whole speed and the whole effective mass, `c Δt/m* ≤ 1`, as its restitution needs at low
/// `e` and coarse steps (a vertex at e = 0.1 and t_c/40 rebounds at 0.12 with 1/2; a grain
/// rocking onto neighbours that rest on others needs the whole mass).
///
/// `m̃*` is the effective mass with each body's mass split among its contacts (mass splitting):
/// `1/m̃* = Σ k (1/m + (r × n)·I⁻¹(r × n))` over the two bodies, `k` a body's contacts at the last
/// evaluation ([`ContactKinematics::dashpot_mass`]; the moments of inertia alike for the rocking
/// and twisting caps at the floor). A particle's contacts are evaluated apart, so their dashpots
/// add up on it unseen by each other, and at the floor a low restitution's damping is far
/// overcritical (`ᾱ/2` of critical at the regularized face's `ω Δt = 1/2`: 5 for e = 0.1). Capped
/// against the whole `m*` each, the caps of a particle's `k` contacts took up to `k` times its
/// speed per step: a cube of e = 0.1 resting on four others kept oscillating, and a periodic
/// lattice of 64 compressed cubes (26 contacts each) at e = 0.1 heated from 2e-4 to 1.5e-2 m/s.
/// With the mass split, the caps of all a particle's contacts together take at most the share of
/// its speed, and a network of them is damped without overshoot (the Jacobi iteration with mass
/// splitting of rigid-body solvers).
pub const DASHPOT_STEP_FRACTION: f64 = 0.5;

/// The Hunt–Crossley reference speed a contact carries into the next step, given the stored
/// one and this step's normal speed `vn` (> 0 separating; docs/contact.md §2). Its magnitude is
/// the approach speed of the current loading cycle, its sign the phase: positive while the
/// contact is loaded (approaching), negative while it unloads; 0 before the first evaluation.
///
/// A cycle begins at first touch, at the contact's impact speed, and again whenever a contact
/// that was unloading approaches once more while still in contact (a rebound inside the
/// contact, a face rocking back, the oscillation of a contact settling under load); during the
/// approach the magnitude follows the largest speed reached. A central impact is one cycle
/// whose approach speed only falls, so it keeps its first-touch speed and the restitution `e`
/// that ᾱ was solved for (an eccentric one whose contact point rebounds and approaches again
/// inside the impact is several cycles: docs/contact.md §2). Keeping the first impact's speed
/// for every later cycle (about 1 m/s for a poured grain) would leave a contact settling at
/// µm/s with a damping some 10⁴ times too weak.
pub fn loading_cycle_speed(stored: f64, vn: f64) -> f64 {
    let speed = vn.abs().max(f64::MIN_POSITIVE);
    if vn < 0.0 {
        if stored > 0.0 {
            stored.max(speed)
        } else {
            speed
        }
    } else if stored == 0.0 {
        -speed
    } else {
        -stored.abs()
    }
}

/// The normal part of a contact's force over the step, with what its damping set for the
/// friction and rocking caps (docs/contact.md §1–2).
struct NormalPart {
    /// `U'` as the step samples it (the window's mean, or the slope at V).
    pressure: f64,
    /// The elastic normal force `U' A_n`.
    f_elastic: f64,
    /// The Hunt–Crossley coefficient.
    c_n: f64,
    /// The normal force with damping and caps, never pulling.
    f_normal: f64,
    /// The regularized potential `W(V)`.
    energy: f64,
    /// The share of the relative speed a dashpot may take per step ([`DASHPOT_STEP_FRACTION`]).
    share: f64,
    /// The bodies' shares in the caps' mass splitting.
    cap_a: f64,
    cap_b: f64,
}

/// The Hunt–Crossley dashpot of a contact's loading cycle and its caps (docs/contact.md §2):
/// what the normal force needs besides the pressure.
struct Dashpot {
    /// The damping coefficient's scale `ᾱ(e)`.
    damping: f64,
    /// The reference speed: the cycle's approach speed, or the floor of a contact at rest.
    v_ref: f64,
    /// The share of the relative speed a dashpot may take per step ([`DASHPOT_STEP_FRACTION`]).
    share: f64,
    /// The mass the cap is taken against.
    cap_mass: f64,
    /// The bodies' shares in the caps' and locks' mass splitting.
    cap_a: f64,
    cap_b: f64,
}

impl Dashpot {
    /// The dashpot of a contact of potential `energy` whose cycle's approach speed is in
    /// `state` (updated before).
    fn new(
        params: &ContactParameters,
        state: &ContactState,
        energy: f64,
        kin: &ContactKinematics,
    ) -> Self {
        let (cycle, floor) = (
            state.approach_speed.abs(),
            (2.0 * energy / kin.effective_mass).sqrt(),
        );
        let v_ref = cycle.max(floor);
        // The share of the relative speed a dashpot may take per step: the whole of it for a
        // contact damped to its cycle's approach speed (an impact), DASHPOT_STEP_FRACTION where
        // the floor sets the damping (a contact at rest or loaded slowly, overcritical at low
        // e), and there against the bodies' masses split among their contacts
        // (DASHPOT_STEP_FRACTION).
        let at_floor = floor > cycle;
        let (share, cap_mass) = if at_floor {
            (DASHPOT_STEP_FRACTION, kin.dashpot_mass)
        } else {
            (1.0, kin.effective_mass)
        };
        // The bodies' shares in the caps' and locks' mass splitting.
        let (cap_a, cap_b) = if at_floor {
            (kin.split_a, kin.split_b)
        } else {
            (1.0, 1.0)
        };
        Dashpot {
            damping: params.damping,
            v_ref,
            share,
            cap_mass,
            cap_a,
            cap_b,
        }
    }

    /// For `pressure` on the area `area` at normal speed `vn`: the elastic force, the
    /// Hunt–Crossley coefficient and the normal force with damping, capped and never pulling.
    fn normal(&self, pressure: f64, area: f64, vn: f64, dt: f64) -> (f64, f64, f64) {
        let f_elastic = pressure * area;
        let c_n = self.damping * f_elastic / self.v_ref;
        let mut f_damp = -c_n * vn;
        // An explicit step's dashpot impulse takes at most `share` of the normal approach
        // speed: never reverses it on its own.
        if dt > 0.0 {
            let limit = self.share * self.cap_mass * vn.abs() / dt;
            f_damp = f_damp.clamp(-limit, limit);
        }
        // The contact pushes, never pulls.
        (f_elastic, c_n, (f_elastic + f_damp).max(0.0))
    }
}

/// The elastic normal force as the step samples it (the secant window, the trajectory, the
/// slope at V; the entry and exit), the Hunt–Crossley damping of the loading cycle and its
/// caps (docs/contact.md §1–2). Updates the cycle's approach speed in `state`.
fn normal_part(
    params: &ContactParameters,
    overlap: &Overlap<f64>,
    kin: &ContactKinematics,
    state: &mut ContactState,
    dt: f64,
    vn: f64,
    first_touch: bool,
) -> NormalPart {
    let (volume, area) = (overlap.volume, overlap.area());
    // Elastic part. Where the contact's stiffness is unbounded at first touch (a face on a
    // face, local exponent k < 3/2), U' is the mean slope over the volume swept in the kick
    // window ±Δt/2; elsewhere the slope at V, the seed's Eq. 12 (symplectic).
    let stiffness = params.normal_stiffness;
    let sweep = 0.5 * vn.abs() * dt * area;
    let local = LocalPowerLaw::new(volume, area, overlap.thickness);
    let windowed = local.exponent < SINGULAR_EXPONENT;
    // The potential is regularized where the step cannot resolve the stiffness (a face at
    // rest, V below V*); elsewhere W is U up to a constant, and the force is the seed's. Every
    // contact takes W, so that a face tilting onto an edge (its exponent crossing 3/2) keeps a
    // continuous force; an edge or a vertex never gets below V* in practice (V* grows as
    // A_n³, faster than its V).
    let resolved = resolved_volume(stiffness, area, dt, kin.effective_mass);
    let secant = windowed && params.face_window == FaceWindow::Secant;
    let mut pressure = if secant {
        secant_pressure(stiffness, volume, sweep, resolved, first_touch)
    } else {
        resolved_pressure(stiffness, volume, resolved)
    };
    // Hunt–Crossley damping, on the elastic force's line of action, referred to this loading
    // cycle's approach speed.
    state.approach_speed = loading_cycle_speed(state.approach_speed, vn);
    let energy = resolved_potential(stiffness, volume, resolved);
    let dashpot = Dashpot::new(params, state, energy, kin);
    // Or the impulse of the contact's own normal motion over the kick window, its entry and
    // its exit included (trajectory.rs), from the slope at V as the first guess. Whether the
    // coming drift ends apart (the window after) is judged with the force the kick applies,
    // damping included, as the next step will find it.
    // A contact deep against its step's travel keeps the slope at V (see TRAJECTORY_FRACTION).
    if windowed && !secant && dt > 0.0 && sweep > TRAJECTORY_FRACTION * volume {
        let motion = NormalMotion::new(local, stiffness, resolved, kin.effective_mass);
        let kick = |force: f64| dashpot.normal(force / area, area, vn, dt).2;
        pressure = motion.window_force(vn, dt, first_touch, pressure * area, kick) / area;
    }
    let (mut f_elastic, mut c_n, mut f_normal) = dashpot.normal(pressure, area, vn, dt);
    // The exit, the mirror of the entry: a separating contact that the coming drift carries
    // apart (its depth h is at most 2 s', s' = u Δt/2 with u the normal speed after this
    // step's kick) lies in contact over part of the next kick's window, which the next step,
    // finding it apart, cannot see: that part, U(V(h − s'))/(2 s'), is carried now. Its
    // volume comes from the local power law, which is apart exactly at the depth h.
    if secant && vn > 0.0 && dt > 0.0 {
        let exit = 0.5 * (vn + f_normal * dt / kin.effective_mass) * dt;
        if local.depth - 2.0 * exit <= 0.0 && local.depth - exit > 0.0 {
            pressure += resolved_potential(stiffness, local.volume_at(-exit), resolved)
                / (2.0 * exit * area);
            (f_elastic, c_n, f_normal) = dashpot.normal(pressure, area, vn, dt);
        }
    }
    NormalPart {
        pressure,
        f_elastic,
        c_n,
        f_normal,
        energy,
        share: dashpot.share,
        cap_a: dashpot.cap_a,
        cap_b: dashpot.cap_b,
    }
}

/// The secant window's `U'` of a windowed contact: the mean slope over the volume `V ± sweep`
/// swept in the kick window where the window is wide against the volume, else the slope at V;
/// and for a contact that began during the last drift (the last position, V − 2 A s, was
/// apart), the part of the last kick's window that lay in contact, `[0, V − A s]`, which that
/// kick missed, carried now.
fn secant_pressure(
    stiffness: f64,
    volume: f64,
    sweep: f64,
    resolved: f64,
    first_touch: bool,
) -> f64 {
    // Where the window is narrow against the volume the slope at V is as good (and keeps the
    // step symplectic: a contact at rest or in slow motion is Eq. 12 exactly).
    let mut pressure = if sweep > WINDOW_FRACTION * volume {
        resolved_mean_pressure(stiffness, volume - sweep, volume + sweep, resolved)
    } else {
        resolved_pressure(stiffness, volume, resolved)
    };
    if first_touch && sweep > 0.0 && volume - 2.0 * sweep <= 0.0 && volume - sweep > 0.0 {
        pressure += resolved_potential(stiffness, volume - sweep, resolved) / (2.0 * sweep);
    }
    pressure
}

/// Friction at `r_e`: the tangential Kelvin–Voigt element in series with the Coulomb slider
/// (friction.rs), its dashpot the step's lock against the mass the slip sees, and the same
/// element about the normal (twisting) on the disk of area A_n. `v_t` and `wn` are the
/// relative tangential speed at `r_e` and spin about `n`. Returns the tangential force on B
/// and the twisting moment; updates the springs in `state`.
#[allow(clippy::too_many_arguments)]
fn friction_part(
    params: &ContactParameters,
    kin: &ContactKinematics,
    state: &mut ContactState,
    normal: &NormalPart,
    (n, r_e): (&Vector3<f64>, &Vector3<f64>),
    (v_t, wn): (&Vector3<f64>, f64),
    area: f64,
    dt: f64,
) -> (Vector3<f64>, f64) {
    let NormalPart {
        f_normal,
        share,
        cap_a,
        cap_b,
        ..
    } = *normal;
    let disk = area / std::f64::consts::PI; // a² of the disk of area A_n
    // The element's spring: the seed's (Eq. 17) or, where that is softer, the stiffest the
    // step resolves; its dashpot the step's lock (friction.rs).
    let seed_t = params.tangential_stiffness * area;
    let w_t = kin.tangential_inverse_mass_trace(r_e, n, cap_a, cap_b);
    let k_t = seed_t.max(resolved_stiffness(w_t, dt));
    let root_t = k_t.sqrt();
    // The stored state, carried into the current tangent plane at its length.
    let old = state.spring;
    let in_plane = old - n * old.dot(n);
    let len = in_plane.norm();
    let carried = if len > 0.0 {
        in_plane * (old.norm() / len)
    } else {
        Vector3::zeros()
    };
    let c_t = lock_coefficient(share, w_t, dt);
    let cap = params.friction * f_normal;
    let (f_t, xi) = slip_step(stretch(carried, root_t), *v_t, k_t, c_t, cap, dt);
    state.spring = xi * root_t;
    // Twisting friction: the same element about the normal, on the disk of area A_n.
    let w_n = kin.weighted_inverse_inertia(n, cap_a, cap_b);
    let k_tw = (0.5 * seed_t * disk).max(resolved_stiffness(w_n, dt));
    let root_tw = k_tw.sqrt();
    let c_tw = lock_coefficient(share, w_n, dt);
    let cap_tw = cap * (2.0 / 3.0) * disk.sqrt();
    let (m, phi) = slip_step(stretch(state.twist, root_tw), wn, k_tw, c_tw, cap_tw, dt);
    state.twist = phi * root_tw;
    (f_t, m)
}

/// Rocking damping of the contact area: the normal dashpot (`c_n`) spread over the disk of
/// area A_n (`disk` = a²), against the relative rotation about tangent axes `w_perp`, capped
/// like the normal dashpot (docs/contact.md §3). The couple it takes from B, `None` where
/// there is none.
fn rocking_couple(
    params: &ContactParameters,
    kin: &ContactKinematics,
    normal: &NormalPart,
    w_perp: &Vector3<f64>,
    disk: f64,
    dt: f64,
) -> Option<Vector3<f64>> {
    let rocking = w_perp.norm();
    if !(params.rocking && normal.c_n > 0.0 && rocking > 0.0) {
        return None;
    }
    let mut c_roll = 0.25 * normal.c_n * disk;
    let inverse = kin.weighted_inverse_inertia(&(w_perp / rocking), normal.cap_a, normal.cap_b);
    if dt > 0.0 && inverse > 0.0 {
        c_roll = c_roll.min(normal.share / (dt * inverse));
    }
    Some(w_perp * c_roll)
}

/// Rolling friction (docs/contact.md §5): a couple against the relative rolling `w_perp` of
/// Coulomb's form, `μ_r R_r F_n` about `−ŵ⊥`, with the rolling radius `R_r = r_A r_B/(r_A +
/// r_B)` from the bodies' centres to the contact point `r_e` (`r_A` against a wall), capped
/// at the step's lock (friction.rs): one step's couple takes at most `share` of the relative
/// rolling it opposes, so it never reverses the rolling and never does positive work. A body
/// held by it creeps by at most one step's gain of rolling speed, which vanishes with the
/// step. The couple it takes from B, `None` where there is none.
fn rolling_couple(
    params: &ContactParameters,
    kin: &ContactKinematics,
    normal: &NormalPart,
    r_e: &Vector3<f64>,
    w_perp: &Vector3<f64>,
    dt: f64,
) -> Option<Vector3<f64>> {
    let rolling = w_perp.norm();
    if !(params.rolling_friction > 0.0 && normal.f_normal > 0.0 && rolling > 0.0) {
        return None;
    }
    let r_a = (r_e - kin.x_a).norm();
    // A wall (no inverse mass) is flat: its radius is infinite and only A's term remains.
    let radius = if kin.inverse_mass_b > 0.0 {
        let r_b = (r_e - kin.x_b).norm();
        r_a * r_b / (r_a + r_b)
    } else {
        r_a
    };
    let axis = w_perp / rolling;
    let inverse = kin.weighted_inverse_inertia(&axis, normal.cap_a, normal.cap_b);
    let lock = lock_coefficient(normal.share, inverse, dt) * rolling;
    Some(axis * (params.rolling_friction * radius * normal.f_normal).min(lock))
}

/// Evaluates the contact law for an overlap, updating the contact's history `state` over `dt`
/// (the module docs and docs/contact.md give every term).
pub fn contact_forces(
    params: &ContactParameters,
    overlap: &Overlap<f64>,
    kin: &ContactKinematics,
    state: &mut ContactState,
    dt: f64,
) -> ContactForces {
    let volume = overlap.volume;
    if volume <= 0.0 {
        return ContactForces::default();
    }
    let inside;
    // |S| > f V^{2/3} as |S|³ > f³ V², without a cube root on every contact's path.
    let area = overlap.area();
    let overlap = if area * area * area > INSIDE_AREA_CUBED * volume * volume {
        overlap
    } else {
        inside = wholly_inside(overlap, kin);
        &inside
    };
    let area = overlap.area();
    let s_vec = overlap.dv_dxb;
    let n = -s_vec / area; // from A to B
    let c = overlap.centroid;
    let r_e = contact_point(overlap, kin, &n);
    let v_rel =
        (kin.v_b + kin.w_b.cross(&(r_e - kin.x_b))) - (kin.v_a + kin.w_a.cross(&(r_e - kin.x_a)));
    let vn = v_rel.dot(&n); // > 0 when separating
    let first_touch = state.approach_speed == 0.0;
    // The normal force, elastic and damped, and the elastic torque the potential gives.
    let normal = normal_part(params, overlap, kin, state, dt, vn, first_touch);
    let NormalPart {
        pressure,
        f_elastic,
        f_normal,
        energy,
        ..
    } = normal;
    let torque_b_el = -(overlap.moment_b + (c - kin.x_b).cross(&s_vec)) * pressure;
    let torque_a_el = -(-overlap.moment_b + (c - kin.x_a).cross(&(-s_vec))) * pressure;

    // The relative rotation: about the normal (twist) and about tangent axes (rocking).
    let w_rel = kin.w_b - kin.w_a;
    let wn = w_rel.dot(&n);
    let w_perp = w_rel - n * wn;
    // Friction at r_e, sliding and twisting; the rocking damping of the contact area.
    let v_t = v_rel - n * vn;
    let disk = area / std::f64::consts::PI; // a² of the disk of area A_n
    let (tangential, m_tw) = if params.friction > 0.0 {
        friction_part(
            params,
            kin,
            state,
            &normal,
            (&n, &r_e),
            (&v_t, wn),
            area,
            dt,
        )
    } else {
        state.spring = Vector3::zeros();
        state.twist = 0.0;
        (Vector3::zeros(), 0.0)
    };
    let mut couple_b = n * m_tw;
    if let Some(rocking) = rocking_couple(params, kin, &normal, &w_perp, disk, dt) {
        couple_b -= rocking;
    }
    if let Some(rolling) = rolling_couple(params, kin, &normal, &r_e, &w_perp, dt) {
        couple_b -= rolling;
    }

    // The elastic force and torque as the potential gives them; the damping and the friction
    // at r_e.
    let f_line = n * (f_normal - f_elastic) + tangential;
    let force_b = n * f_normal + tangential;
    let torque_b = torque_b_el + (r_e - kin.x_b).cross(&f_line) + couple_b;
    let torque_a = torque_a_el + (r_e - kin.x_a).cross(&(-f_line)) - couple_b;
    ContactForces {
        force_b,
        torque_a,
        torque_b,
        elastic_energy: energy
            + 0.5 * state.spring.norm_squared()
            + 0.5 * state.twist * state.twist,
    }
}

#[cfg(test)]
mod tests {
    use super::loading_cycle_speed;

    /// Every transition of the reference speed's state, against its definition: first touch
    /// (stored 0) approaching, separating, at rest and with a NaN speed; a loading cycle that
    /// slows or speeds up; an unloading; a new cycle after an unloading.
    #[test]
    fn loading_cycles_start_follow_and_turn() {
        let tiny = f64::MIN_POSITIVE;
        for (stored, vn, want) in [
            (0.0, -2.0, 2.0),
            (0.0, 2.0, -2.0),
            (0.0, 0.0, -tiny),
            (0.0, -0.0, -tiny),
            (0.0, f64::NAN, -tiny),
            (3.0, -2.0, 3.0),
            (1.0, -2.0, 2.0),
            (3.0, 2.0, -3.0),
            (3.0, 0.0, -3.0),
            (-3.0, 2.0, -3.0),
            (-3.0, -2.0, 2.0),
            (-tiny, -1e-9, 1e-9),
        ] {
            let got = loading_cycle_speed(stored, vn);
            assert_eq!(
                got.to_bits(),
                f64::to_bits(want),
                "stored {stored:e}, vn {vn:e}: {got:e}, want {want:e}"
            );
        }
    }
}

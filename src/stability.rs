//! The stability guard: a particle that starts to blow up stops the run within one step, with
//! an error that names the step, the particle and its contacts (docs/contact.md §7).
//!
//! An explicit DEM step goes unstable locally first: one contact too stiff for the step, or a
//! particle driven into another, gains energy each step until values overflow. Left alone, the
//! first sign is a NaN thousands of steps later, or particles leaving the domain, long after
//! the cause. Three bounds catch it at its start:
//!
//! - **finiteness** of the position, velocity, angular velocity and orientation;
//! - **speed**: `|v| + |ω| R` (the fastest point of the particle, `R` its circumscribed radius)
//!   at most `max_speed`, by default `speed_factor` (10) times the scene's speed scale
//!   ([`speed_scale`]): what gravity, insertion, the walls' motion, the initial velocities and
//!   the initial contacts' elastic energy can give a particle;
//! - **overlap**: the overlap volume of every contact at most `max_overlap` (0.1) of the smaller
//!   particle's volume (`(4π/3) R³` of its volume-equivalent radius R). The volume, not the
//!   depth: the volume law's energy `(3/4) c V^{4/3}` is set by V whatever touches, so a vertex
//!   may legitimately reach deep where a face stays shallow (a soft 1 cm cube's corner reaches
//!   40 % of R into a face at 3 m/s, with V 1 % of the cube). Healthy contacts stay near 1 %; a
//!   tenth of a particle means the law no longer holds the bodies apart (and a body entirely
//!   inside another has no defined normal at all).
//!
//! The checks run on each step's state on both backends: speed and finiteness after the
//! drift (the GPU checks them in the same kernel), overlaps where the contact geometry is
//! evaluated.

use crate::scene::{GuardSettings, Scene};
use crate::state::Particles;
use nalgebra::Vector3;

/// The bounds a run is held to, resolved from [`GuardSettings`] and the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StabilityGuard {
    /// Whether the guard checks speeds and overlaps (finiteness is always checked).
    pub enabled: bool,
    /// Largest `|v| + |ω| R` (m/s); infinite when the scene has no speed scale.
    pub max_speed: f64,
    /// Largest overlap volume as a fraction of the smaller particle's volume.
    pub max_overlap: f64,
    /// The scene's speed scale (m/s) the default `max_speed` derives from.
    pub speed_scale: f64,
}

impl StabilityGuard {
    /// The guard of a scene whose speed scale is `speed_scale` ([`speed_scale`]; in a
    /// decomposed run the largest over the ranks, so that every rank holds the same bounds).
    pub fn new(settings: &GuardSettings, speed_scale: f64) -> Self {
        let max_speed = match settings.max_speed {
            Some(v) => v,
            None if speed_scale > 0.0 => settings.speed_factor * speed_scale,
            None => f64::INFINITY,
        };
        StabilityGuard {
            enabled: settings.enabled,
            max_speed: if settings.enabled {
                max_speed
            } else {
                f64::INFINITY
            },
            max_overlap: if settings.enabled {
                settings.max_overlap
            } else {
                f64::INFINITY
            },
            speed_scale,
        }
    }

    /// What is wrong with particle `i` (circumscribed radius `radius`) after the drift, if
    /// anything: a non-finite value, or a speed above the bound.
    pub fn check_motion(&self, p: &Particles, radius: f64, i: usize) -> Option<Instability> {
        let finite = |v: &Vector3<f64>| v.iter().all(|x| x.is_finite());
        for (field, ok) in [
            ("position", finite(&p.position[i])),
            ("velocity", finite(&p.velocity[i])),
            ("angular velocity", finite(&p.angular_velocity[i])),
            (
                "orientation",
                p.orientation[i].coords.iter().all(|x| x.is_finite()),
            ),
        ] {
            if !ok {
                return Some(Instability::NonFinite { field });
            }
        }
        let speed = p.velocity[i].norm() + p.angular_velocity[i].norm() * radius;
        (speed > self.max_speed).then_some(Instability::Speed {
            speed,
            bound: self.max_speed,
            scale: self.speed_scale,
        })
    }
}

/// `(4π/3) r³`: the volume the guard measures a particle by (`r` its volume-equivalent
/// radius), written as the GPU computes it.
pub fn ball_volume(r: f64) -> f64 {
    4.0 / 3.0 * std::f64::consts::PI * r * r * r
}

/// What the guard found.
#[derive(Clone, Debug, PartialEq)]
pub enum Instability {
    /// A value is NaN or infinite.
    NonFinite { field: &'static str },
    /// `|v| + |ω| R` above the bound.
    Speed { speed: f64, bound: f64, scale: f64 },
    /// A contact's overlap above the bound, as the GPU reports it (without the partner), with
    /// the host's f64 evaluation of the same state: the deepest overlap of the particle with
    /// another particle (partner, fraction of the smaller particle's volume), if any.
    DeepContact {
        fraction: f64,
        host: Option<(String, f64)>,
    },
    /// A contact's overlap volume above the bound.
    Overlap {
        partner: String,
        volume: f64,
        particle_volume: f64,
        fraction: f64,
    },
}

impl std::fmt::Display for Instability {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Instability::NonFinite { field } => write!(f, "its {field} is not finite"),
            Instability::Speed {
                speed,
                bound,
                scale,
            } => write!(
                f,
                "it moves at {speed:.4e} m/s (|v| + |ω| R), above the bound {bound:.4e} m/s \
                 (simulation.guard.max_speed; the scene's speed scale is {scale:.4e} m/s)"
            ),
            Instability::DeepContact { fraction, host } => {
                write!(
                    f,
                    "on the device one of its contacts overlaps more than {fraction} of the \
                     smaller particle's volume (simulation.guard.max_overlap)"
                )?;
                match host {
                    Some((partner, x)) => write!(
                        f,
                        "; evaluated in f64 on the host from the same state, its deepest contact \
                         with a particle of this rank overlaps {partner} by {x:.3e} of the \
                         smaller volume"
                    )?,
                    None => write!(
                        f,
                        "; evaluated in f64 on the host from the same state, it overlaps no \
                         particle of this rank"
                    )?,
                }
                if host.as_ref().is_none_or(|h| h.1 <= *fraction) {
                    write!(
                        f,
                        " (so the deep contact is a wall's or another rank's particle's, or the \
                         device's geometry differs from f64: run with --gpu-precision double to \
                         tell)"
                    )?;
                }
                Ok(())
            }
            Instability::Overlap {
                partner,
                volume,
                particle_volume,
                fraction,
            } => write!(
                f,
                "it overlaps {partner} by {volume:.4e} m³, {:.3} of the smaller particle's volume \
                 {particle_volume:.4e} m³ (simulation.guard.max_overlap = {fraction})",
                volume / particle_volume
            ),
        }
    }
}

/// The speed a particle of the scene can be expected to reach (m/s): free fall across the
/// domain's diagonal, plus the fastest insertion (`|v| + |ω| R`), the fastest wall surface
/// point, the fastest particle now placed and the speed the contacts' stored elastic energy
/// `elastic` (J) would give the lightest particle now placed, `√(2 U / m_min)` (a packing that
/// starts compressed releases it). Zero for a scene where nothing drives motion.
pub fn speed_scale(scene: &Scene, particles: &Particles, radius: &[f64], elastic: f64) -> f64 {
    SpeedScale::of(scene, particles, radius, elastic).value()
}

/// The parts of [`speed_scale`], so that a decomposed run can combine its ranks' particles:
/// what the scene drives, and the placed particles' fastest point, stored elastic energy and
/// lightest mass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedScale {
    /// Free fall, insertion and wall motion (m/s): the same on every rank.
    pub driven: f64,
    /// The fastest `|v| + |ω| R` of the placed particles (m/s).
    pub placed: f64,
    /// The elastic energy stored in their contacts (J).
    pub elastic: f64,
    /// The lightest of them (kg; infinite for none).
    pub lightest: f64,
}

impl SpeedScale {
    /// The parts for `particles` (circumscribed radii `radius`) of `scene`.
    pub fn of(scene: &Scene, particles: &Particles, radius: &[f64], elastic: f64) -> Self {
        let d = scene.domain.max - scene.domain.min;
        let fall = (2.0 * scene.gravity.norm() * d.norm()).sqrt();
        let max_radius = scene.max_bounding_radius();
        let insert = scene
            .insertions
            .iter()
            .map(|ins| ins.velocity.norm() + ins.angular_velocity.norm() * max_radius)
            .fold(0.0, f64::max);
        let wall = scene
            .walls
            .iter()
            .map(|w| w.motion.max_speed(&w.triangles))
            .fold(0.0, f64::max);
        let placed = (0..particles.len().min(radius.len()))
            .map(|i| {
                particles.velocity[i].norm() + particles.angular_velocity[i].norm() * radius[i]
            })
            .filter(|s| s.is_finite())
            .fold(0.0, f64::max);
        let lightest = particles.mass.iter().copied().fold(f64::INFINITY, f64::min);
        SpeedScale {
            driven: fall + insert + wall,
            placed,
            elastic,
            lightest,
        }
    }

    /// The parts of several ranks' particles as one: the fastest, the summed energy (in rank
    /// order), the lightest.
    pub fn merged(parts: &[SpeedScale]) -> Self {
        parts.iter().skip(1).fold(parts[0], |a, b| SpeedScale {
            driven: a.driven.max(b.driven),
            placed: a.placed.max(b.placed),
            elastic: a.elastic + b.elastic,
            lightest: a.lightest.min(b.lightest),
        })
    }

    /// The speed scale (m/s).
    pub fn value(&self) -> f64 {
        let released = if self.elastic > 0.0 && self.lightest.is_finite() && self.lightest > 0.0 {
            (2.0 * self.elastic / self.lightest).sqrt()
        } else {
            0.0
        };
        self.driven + self.placed + released
    }
}

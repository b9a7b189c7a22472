//! `polydem pack`: a dense random packing built by quasi-static compression of a periodic box,
//! frozen into a [`Packing`] that insertions tile (`[[insertions]] packing`, docs/scene.md).
//!
//! The scene places its particles loosely (random insertion) in a box periodic on every axis,
//! without gravity or walls. Then, in cycles of two critical steps (40 steps at
//! `dt_fraction = 0.05`):
//!
//! 1. the box and every centre are scaled about the box's corner by `1 − s`
//!    ([`crate::run_state::RunState::rescale_periodic_box`]);
//! 2. the particles move under their contact forces for one cycle;
//! 3. every velocity is set to zero (a quench): the kinetic energy the compression fed in is
//!    taken out, so the packing follows a sequence of nearly static states.
//!
//! The strain per cycle `s` is 1 % while particles barely touch (Z < 2), 0.2 % on the way to
//! the target, 0.05 % within 1.5 contacts of it. Once a cycle ends with Z (contacts per
//! particle, 2 × contacts / N, rattlers included) at the target, the box is held for
//! `RELAX_CYCLES` more quenched cycles; the packing is done when Z is still at the target after
//! them, and compressed further otherwise. Friction during the compression is the scene's:
//! the lower it is, the denser the packing at a given Z.

use crate::Precision;
use crate::backend::{BackendChoice, Engine, Start, select_device};
use crate::domain::SerialComm;
use crate::io::{PackedParticle, Packing};
use crate::run_state::RunState;
use crate::scene::{Scene, load_scene};
use anyhow::{Context, Result, bail};
use nalgebra::Vector3;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

/// Length of a cycle in critical steps (the smaller of the Rayleigh step and the face contact
/// time, as `polydem check` reports them): long enough for a contact to push its particles
/// apart after a compression step, short enough that the quench keeps what the compression
/// fed in from piling up.
const CYCLE_CRITICAL_STEPS: f64 = 2.0;
/// Quenched cycles at a fixed box before Z counts as settled.
const RELAX_CYCLES: u32 = 10;
/// Cycles after which the compression gives up.
const MAX_CYCLES: u32 = 20_000;

/// Options of `polydem pack`.
#[derive(Clone, Debug)]
pub struct PackOptions {
    /// The scene: a fully periodic box without gravity or walls, particles inserted loosely.
    pub scene: PathBuf,
    /// Target contacts per particle (2 × contacts / N).
    pub contacts: f64,
    /// Where to write the packing.
    pub out: PathBuf,
    /// Where the steps run (the compression is the same on either backend; the GPU is much
    /// faster for polyhedra).
    pub backend: BackendChoice,
    /// Pair-geometry arithmetic on the GPU.
    pub precision: Precision,
}

/// Refuses a scene that cannot be compressed as a whole periodic box.
fn check_scene(scene: &Scene, path: &std::path::Path) -> Result<()> {
    let file = path.display();
    if scene.domain.periodic != [true; 3] {
        bail!(
            "{file}: [domain] periodic must be [true, true, true] to pack (the box is compressed as a whole)"
        );
    }
    if !scene.walls.is_empty() {
        bail!(
            "{file}: [[walls]] are not allowed in a packing scene (the box is compressed as a whole)"
        );
    }
    if scene.gravity.norm() != 0.0 {
        bail!(
            "{file}: gravity must be [0, 0, 0] in a packing scene (a periodic box would fall forever)"
        );
    }
    if scene.insertions.is_empty() {
        bail!("{file}: [[insertions]] must place the particles to compress");
    }
    Ok(())
}

/// Solid fraction of the periodic box.
fn solid_fraction(sim: &RunState) -> f64 {
    let scene = &sim.scene;
    let solid: f64 = (0..sim.particles.len())
        .map(|i| {
            let ptype = &scene.particle_types[sim.particles.kind[i] as usize];
            sim.particles.mass[i] / scene.materials[ptype.material].density
        })
        .sum();
    let l = scene.domain.max - scene.domain.min;
    solid / (l.x * l.y * l.z)
}

/// One cycle: `steps` steps, then every velocity zeroed and, when `factor` is given, the box
/// rescaled by it. Returns Z after the steps.
fn cycle(engine: &mut Engine, steps: u64, factor: Option<f64>) -> Result<f64> {
    for _ in 0..steps {
        engine.step()?;
    }
    let (contacts, _) = engine.contact_counts()?;
    let z = 2.0 * contacts as f64 / engine.particle_count().max(1) as f64;
    let mut rescaled = Ok(());
    engine.edit(|state| {
        state.particles.velocity.fill(Vector3::zeros());
        state.particles.angular_velocity.fill(Vector3::zeros());
        if let Some(f) = factor {
            rescaled = state.rescale_periodic_box(f);
        }
    })?;
    rescaled?;
    if factor.is_some() {
        // The next step's kick needs the forces of the rescaled positions.
        engine.refresh()?;
    }
    Ok(z)
}

/// `polydem pack`: compresses the scene's particles to `contacts` contacts per particle and
/// writes the packing; returns a report (cycles, steps, Z, solid fraction, cell, seconds).
pub fn pack(opts: &PackOptions) -> Result<serde_json::Value> {
    if !(opts.contacts > 0.0 && opts.contacts.is_finite()) {
        bail!(
            "--contacts must be a positive number, got {}",
            opts.contacts
        );
    }
    let scene = load_scene(&opts.scene)?;
    check_scene(&scene, &opts.scene)?;
    let t = crate::scene::critical_time_step(&scene);
    let critical = t.contact_time.map_or(t.rayleigh, |c| c.min(t.rayleigh));
    let steps = (CYCLE_CRITICAL_STEPS * critical / t.dt)
        .ceil()
        .clamp(1.0, 1e6) as u64;
    let start = Instant::now();
    let comm = std::sync::Arc::new(SerialComm);
    let device = select_device(opts.backend, opts.precision, &*comm)?;
    let mut engine = Engine::new(
        Start::Scene {
            scene: Box::new(scene),
            comm,
        },
        device,
    )
    .with_context(|| format!("{}: placing the particles", opts.scene.display()))?;
    let n = engine.particle_count();
    let phi0 = solid_fraction(engine.state());
    let target = opts.contacts;
    let mut cycles = 0u32;
    let mut z = cycle(&mut engine, steps, None)?;
    loop {
        cycles += 1;
        if cycles > MAX_CYCLES {
            bail!(
                "{}: Z = {z:.2} contacts per particle after {MAX_CYCLES} compression cycles \
                 (solid fraction {:.3}), short of {target}; lower --contacts or the friction",
                opts.scene.display(),
                solid_fraction(engine.state())
            );
        }
        if z >= target {
            for _ in 0..RELAX_CYCLES {
                z = cycle(&mut engine, steps, None)?;
            }
            tracing::info!(
                cycles,
                z,
                phi = solid_fraction(engine.state()),
                "relaxed at the target"
            );
            if z >= target {
                break;
            }
        }
        let strain = if z < 2.0 {
            1e-2
        } else if z < target - 1.5 {
            2e-3
        } else {
            5e-4
        };
        z = cycle(&mut engine, steps, Some(1.0 - strain))?;
        if cycles.is_multiple_of(25) {
            tracing::info!(
                cycles,
                z,
                phi = solid_fraction(engine.state()),
                "compressing"
            );
        }
    }
    let sim = engine.synced()?;
    let min = sim.scene.domain.min;
    let cell = sim.scene.domain.max - min;
    // In id order: the backends keep their particles in different orders (the GPU's by its
    // bins), and the file must not depend on which one compressed it.
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| sim.particles.id[i]);
    let particles = order
        .into_iter()
        .map(|i| {
            let p = &sim.particles;
            // Centres relative to the corner, strictly inside the cell once written with 12
            // digits (a centre within 1e-11 of the far face is its periodic image at 0).
            let position = Vector3::from_fn(|a, _| {
                let x = (p.position[i][a] - min[a]).rem_euclid(cell[a]);
                if x >= cell[a] * (1.0 - 1e-11) { 0.0 } else { x }
            });
            PackedParticle {
                position,
                orientation: p.orientation[i],
                scale: p.scale[i],
            }
        })
        .collect();
    let packing = Packing { cell, particles };
    let phi = solid_fraction(sim);
    let comments = [
        format!(
            "compressed by `polydem pack {} --contacts {target}`",
            opts.scene.display()
        ),
        format!(
            "{n} particles, {cycles} cycles of {steps} steps: solid fraction {phi0:.4} -> \
             {phi:.4}, {z:.3} contacts per particle"
        ),
    ];
    packing
        .write(&opts.out, &comments)
        .with_context(|| "writing the packing")?;
    Ok(json!({
        "scene": opts.scene.display().to_string(),
        "out": opts.out.display().to_string(),
        "particles": n,
        "cycles": cycles,
        "steps": sim.step,
        "contacts_per_particle": z,
        "solid_fraction_start": phi0,
        "solid_fraction": phi,
        "cell": [cell.x, cell.y, cell.z],
        "seconds": start.elapsed().as_secs_f64(),
    }))
}

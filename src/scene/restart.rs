//! What a checkpoint must agree on with the scene that restarts it.
//!
//! [`SceneFingerprint`] hashes the scene as parsed, section by section, meshes included (the
//! particle templates and wall triangles as read from their files), so that an edit which
//! changes nothing the simulation sees (a comment, a reformatted table, a longer `end_time`, any
//! `[output]` or `[parallel]` key) is accepted, and every other edit is refused with the list of
//! sections that differ. [`check_against_scene`] checks a checkpoint's particles against the
//! scene's particle types and time step.

use super::Scene;
use crate::io::Checkpoint;
use crate::io::checkpoint::fnv1a64;

/// Name of the checkpoint `extra` record holding the per-section hashes: UTF-8 lines
/// `<section>\t<hash as 16 hex digits>`.
pub const SECTIONS_RECORD: &str = "scene_sections";

/// Per-section hashes of a parsed scene, and the hash of them all (the checkpoint's
/// `scene_hash`).
///
/// Each section is hashed (FNV-1a 64, the same on every platform and run) from the `Debug` text
/// of its resolved values: floats print with the shortest digits that parse back to the same
/// bits, so two scenes hash equal exactly when their values are equal. `simulation.end_time`,
/// `[simulation.guard]`, `simulation.neighbor.mode` and `hybrid_skin`, `domain.on_leaving`,
/// `[output]` and `[parallel]` are left out:
/// changing them does not change the state a step produces, and a restart is how a run is
/// extended, its output changed, or a run the guard or a lost particle stopped continued.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SceneFingerprint {
    /// `(section, hash)` in file order, e.g. `("walls[0] (box)", …)`.
    pub sections: Vec<(String, u64)>,
    /// `(section, hash, hint)`: a section as it hashed under an earlier default, and what to
    /// write to continue a checkpoint of that time (the face window's default was the secant):
    /// a refused restart whose section matches says so.
    pub earlier_defaults: Vec<(String, u64, &'static str)>,
}

impl SceneFingerprint {
    /// The fingerprint of `scene`.
    pub fn of(scene: &Scene) -> Self {
        let mut sections = Vec::new();
        let mut add = |name: String, text: String| sections.push((name, fnv1a64(text.as_bytes())));
        let mut sim = scene.simulation.clone();
        sim.end_time = 0.0; // may change on a restart
        // The guard and the leaving rule only decide whether a run stops: a run stopped by
        // either is continued with them relaxed.
        sim.guard = Default::default();
        // Who builds the pair list changes no bit of the run (docs/design.md §7): a run may
        // continue in another mode. The hybrid skin is left out of the text, so that
        // checkpoints written before it existed keep their fingerprint.
        sim.neighbor.mode = crate::scene::NeighborMode::Auto;
        // The face window came later, with the secant as its default: the secant hashes as
        // before the key existed, so that the checkpoints of earlier runs still restart where
        // their scene names it.
        let hashed = |sim: &crate::scene::SimulationSettings| {
            let text = format!("{sim:?}").replace(", face_window: Secant", "");
            match (text.find(", hybrid_skin: "), text.find(" }, guard")) {
                (Some(a), Some(b)) if a < b => format!("{}{}", &text[..a], &text[b..]),
                _ => text,
            }
        };
        let mut earlier_defaults = Vec::new();
        if sim.face_window == crate::contact::FaceWindow::Trajectory {
            let mut secant = sim.clone();
            secant.face_window = crate::contact::FaceWindow::Secant;
            earlier_defaults.push((
                "simulation".to_string(),
                fnv1a64(hashed(&secant).as_bytes()),
                "the checkpoint was written with the face window then the default, \
                 `simulation.face_window = \"secant\"`: name it in the scene's [simulation] to \
                 continue the run",
            ));
        }
        add("simulation".into(), hashed(&sim));
        let mut domain = scene.domain;
        domain.on_leaving = Default::default();
        add("domain".into(), format!("{domain:?}"));
        add("gravity".into(), format!("{:?}", scene.gravity));
        for (i, m) in scene.materials.iter().enumerate() {
            add(format!("materials[{i}] ({})", m.name), format!("{m:?}"));
        }
        add("material_pairs".into(), format!("{:?}", scene.pairs));
        for (i, t) in scene.particle_types.iter().enumerate() {
            // The template is the mesh as read (or the generator's hull): a changed mesh file
            // changes it.
            let template = scene.templates.get(t.template);
            let scale = scene.scale_distributions.get(i);
            add(
                format!("particle_types[{i}] ({})", t.name),
                format!("{t:?} {template:?} {scale:?}"),
            );
        }
        for (i, ins) in scene.insertions.iter().enumerate() {
            // A rate insertion's `interval` came later: unset, it hashes as before it existed,
            // so that the checkpoints of earlier runs still restart.
            let text = format!("{ins:?}").replace(", interval: None", "");
            add(format!("insertions[{i}]"), text);
        }
        for (i, w) in scene.walls.iter().enumerate() {
            add(format!("walls[{i}] ({})", w.name), format!("{w:?}"));
        }
        SceneFingerprint {
            sections,
            earlier_defaults,
        }
    }

    /// The hash of all sections: what a checkpoint stores as `scene_hash`.
    pub fn hash(&self) -> u64 {
        fnv1a64(&self.record())
    }

    /// The `extra` record ([`SECTIONS_RECORD`]) a checkpoint carries so that a refused restart
    /// can say which sections differ.
    pub fn record(&self) -> Vec<u8> {
        let mut s = String::new();
        for (name, h) in &self.sections {
            s.push_str(&format!("{name}\t{h:016x}\n"));
        }
        s.into_bytes()
    }

    /// Reads a [`SceneFingerprint::record`]; `None` when it is malformed.
    pub fn from_record(bytes: &[u8]) -> Option<Self> {
        let text = std::str::from_utf8(bytes).ok()?;
        let sections = text
            .lines()
            .map(|l| {
                let (name, h) = l.rsplit_once('\t')?;
                Some((name.to_string(), u64::from_str_radix(h, 16).ok()?))
            })
            .collect::<Option<Vec<_>>>()?;
        Some(SceneFingerprint {
            sections,
            earlier_defaults: Vec::new(),
        })
    }

    /// The sections that differ between `self` (this scene) and `then` (the checkpoint's), in
    /// this scene's order, then those only the checkpoint's scene has.
    pub fn differences(&self, then: &SceneFingerprint) -> Vec<String> {
        let find = |f: &SceneFingerprint, name: &str| {
            f.sections.iter().find(|(n, _)| n == name).map(|(_, h)| *h)
        };
        let mut out = Vec::new();
        for (name, h) in &self.sections {
            match find(then, name) {
                Some(old) if old == *h => {}
                Some(_) => out.push(format!("{name} changed")),
                None => out.push(format!("{name} is new")),
            }
        }
        for (name, _) in &then.sections {
            if find(self, name).is_none() {
                out.push(format!("{name} was removed"));
            }
        }
        out
    }

    /// Errors unless checkpoint `c` was written for this scene. `legacy_hash` is the hash older
    /// versions stored (FNV-1a of the scene file's bytes): a checkpoint without the section
    /// record is accepted when it matches, so that their checkpoints still restart.
    pub fn check(&self, c: &Checkpoint, legacy_hash: u64) -> Result<(), String> {
        if c.scene_hash == self.hash() {
            return Ok(());
        }
        let record = c.extra.iter().find(|(k, _)| k == SECTIONS_RECORD);
        let Some((_, record)) = record else {
            if c.scene_hash == legacy_hash {
                return Ok(());
            }
            return Err(
                "written for another scene, or for this scene file before an edit (this \
                 checkpoint predates per-section scene hashes, so its scene file must be \
                 unchanged byte for byte)"
                    .into(),
            );
        };
        let Some(then) = SceneFingerprint::from_record(record) else {
            return Err(format!("its `{SECTIONS_RECORD}` record is malformed"));
        };
        let diff = self.differences(&then);
        let mut list = if diff.is_empty() {
            // Equal sections under another total: a record that does not match the header.
            "its scene hash does not match its own section record".to_string()
        } else {
            diff.join(", ")
        };
        for (name, hash, hint) in &self.earlier_defaults {
            let then_hash = then.sections.iter().find(|(n, _)| n == name).map(|s| s.1);
            if diff == [format!("{name} changed")] && then_hash == Some(*hash) {
                list = format!("{list} ({hint})");
            }
        }
        Err(format!(
            "written for another scene: {list}; a restart may change only \
             `simulation.end_time`, `[simulation.guard]`, `simulation.neighbor.mode` and \
             `hybrid_skin`, `domain.on_leaving`, `[output]` and `[parallel]`"
        ))
    }
}

/// Relative tolerance of the mass and inertia check: both are computed by the same expression
/// when a particle is made, so only a corrupted or edited value departs from it.
const MASS_TOLERANCE: f64 = 1e-12;

/// Relative tolerance of `time` against `step × dt`: the time is accumulated step by step, so
/// it departs from the product by round-off only.
const TIME_TOLERANCE: f64 = 1e-6;

/// Checks checkpoint `c` against the scene that restarts it (after [`Checkpoint::validate`],
/// which checks what needs no scene): every `kind` is one of the scene's particle types; every
/// scale is within its type's distribution; mass and inertia are the type's
/// (`ρ V s³`, `ρ I₁ s⁵`); `time` is `step × dt`; wall contacts name walls of the scene. The message names the field and the particle (index and id).
pub fn check_against_scene(c: &Checkpoint, scene: &Scene) -> Result<(), String> {
    let p = &c.particles;
    let types = scene.particle_types.len();
    for i in 0..p.id.len() {
        let id = p.id[i];
        let at = |field: &str, what: String| format!("particle {i} (id {id}): `{field}` {what}");
        let kind = p.kind[i] as usize;
        if kind >= types {
            let allowed = match types {
                0 => "the scene has no particle types".to_string(),
                n => format!("the scene has {n} particle type(s), kind 0 to {}", n - 1),
            };
            return Err(at("kind", format!("is {kind}, {allowed}")));
        }
        let ptype = &scene.particle_types[kind];
        let s = p.scale[i];
        if let Some(d) = scene.scale_distributions.get(kind) {
            let (lo, hi) = (d.min_scale(), d.max_scale());
            // Exactly within: the neighbour cutoff, the halo and the critical step are sized
            // from the range (a sampled scale never leaves it).
            if !(lo..=hi).contains(&s) {
                return Err(at(
                    "scale",
                    format!(
                        "is {s}, particle type `{}` has scales {lo} to {hi}",
                        ptype.name
                    ),
                ));
            }
        }
        let density = scene
            .materials
            .get(ptype.material)
            .map_or(0.0, |m| m.density);
        let t = &scene.templates[ptype.template];
        let mass = density * t.volume * s.powi(3);
        let close = |a: f64, b: f64| (a - b).abs() <= MASS_TOLERANCE * b.abs();
        if !close(p.mass[i], mass) {
            return Err(at(
                "mass",
                format!(
                    "is {}, particle type `{}` at scale {s} has mass {mass}",
                    p.mass[i], ptype.name
                ),
            ));
        }
        let inertia = t.principal_inertia * (density * s.powi(5));
        if !(0..3).all(|k| close(p.inertia[i][k], inertia[k])) {
            let q = p.inertia[i];
            return Err(at(
                "inertia",
                format!(
                    "is [{}, {}, {}], particle type `{}` at scale {s} has [{}, {}, {}]",
                    q.x, q.y, q.z, ptype.name, inertia.x, inertia.y, inertia.z
                ),
            ));
        }
    }
    let dt = scene.time_step();
    let expected = c.step as f64 * dt;
    if (c.time - expected).abs() > TIME_TOLERANCE * expected.abs() {
        return Err(format!(
            "`time` {} is not `step` {} × dt {dt} = {expected}",
            c.time, c.step
        ));
    }
    // Contacts may outlive a removed particle until the next force evaluation, so only their
    // walls are checked.
    for (k, _) in c.history.entries() {
        if k.wall_index().is_some_and(|w| w >= scene.walls.len()) {
            return Err(format!(
                "contact of particle {} names wall {}, the scene has {} wall(s)",
                k.a,
                k.wall_index().unwrap_or(0),
                scene.walls.len()
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{NeighborMode, test_sphere_scene};

    fn scene(neighbor: &str) -> Scene {
        test_sphere_scene(neighbor)
    }

    /// Who builds the pair list is not part of the fingerprint (a run may continue in another
    /// mode, bit for bit the same), and the text hashed is the one from before the hybrid skin
    /// existed; the skin still is.
    #[test]
    fn the_neighbor_mode_and_hybrid_skin_do_not_change_the_fingerprint() {
        let a = scene("skin = 0.0002");
        let b = scene("skin = 0.0002\nmode = \"hybrid\"\nhybrid_skin = 0.001");
        assert_eq!(b.simulation.neighbor.mode, NeighborMode::Hybrid);
        assert_eq!(SceneFingerprint::of(&a), SceneFingerprint::of(&b));
        let c = scene("skin = 0.0003");
        assert_ne!(SceneFingerprint::of(&a), SceneFingerprint::of(&c));
        // The hashed text of the simulation section, as before `hybrid_skin` and
        // `face_window`, for a run with the face window of that time (the secant).
        let mut a = a;
        a.simulation.face_window = crate::contact::FaceWindow::Secant;
        let mut sim = a.simulation.clone();
        sim.end_time = 0.0;
        sim.guard = Default::default();
        let old = format!("{sim:?}")
            .replace(", hybrid_skin: 0.0004", "")
            .replace(", face_window: Secant", "");
        assert!(!old.contains("hybrid_skin") && !old.contains("face_window"));
        let simulation = SceneFingerprint::of(&a).sections[0].clone();
        assert_eq!(
            simulation,
            ("simulation".to_string(), fnv1a64(old.as_bytes()))
        );
    }

    /// A checkpoint of a run made when the secant was the face window's default is refused by
    /// the same scene under today's default (the law differs), with what to write to continue
    /// it; with that written it restarts. Another change to the section gets no such hint.
    #[test]
    fn a_checkpoint_of_the_secant_default_names_the_key_that_continues_it() {
        let mut then = scene("skin = 0.0002");
        then.simulation.face_window = crate::contact::FaceWindow::Secant;
        let now = scene("skin = 0.0002");
        assert_eq!(
            now.simulation.face_window,
            crate::contact::FaceWindow::Trajectory
        );
        let old = SceneFingerprint::of(&then);
        let checkpoint = Checkpoint {
            step: 0,
            time: 0.0,
            particles: Default::default(),
            history: Default::default(),
            rng_state: [0; 4],
            inserter: Vec::new(),
            next_id: 0,
            scene_hash: old.hash(),
            extra: vec![(SECTIONS_RECORD.to_string(), old.record())],
        };
        let refused = SceneFingerprint::of(&now)
            .check(&checkpoint, 0)
            .unwrap_err();
        assert!(refused.contains("simulation changed"), "{refused}");
        assert!(
            refused.contains("`simulation.face_window = \"secant\"`"),
            "{refused}"
        );
        SceneFingerprint::of(&then).check(&checkpoint, 0).unwrap();
        let mut other = scene("skin = 0.0003");
        other.simulation.face_window = crate::contact::FaceWindow::Trajectory;
        let refused = SceneFingerprint::of(&other)
            .check(&checkpoint, 0)
            .unwrap_err();
        assert!(!refused.contains("face_window"), "{refused}");
    }
}

//! `polydem check` and the time-step warnings that `polydem run` repeats.
use crate::scene::{Scene, check_report, face_contact_times, impact_speed, load_scene};
use anyhow::Result;
use serde_json::json;
use std::path::Path;

/// `polydem check`: validates the scene and reports the time-step estimates and counts.
///
/// Besides the Rayleigh step, it reports the face-to-face contact time of each particle type
/// with itself and of each pair of types (`a + b`, under `per_type`) at the free-fall speed over
/// the domain's height (at least 1 m/s), and the chosen dt as a fraction of the shortest. A dt
/// above [`SAFE_FACE_FRACTION`] of it is flagged: face impacts then leave the 2 % restitution
/// band of the contact law (docs/contact.md); up to [`ENERGY_FACE_FRACTION`] of it an elastic
/// face impact also keeps its energy to 1e-3 (docs/validation.md §4).
pub fn check(scene_path: &Path) -> Result<serde_json::Value> {
    let scene: Scene = load_scene(scene_path)?;
    let mut report = check_report(&scene);
    let v_fall = impact_speed(&scene);
    let times = face_contact_times(&scene, v_fall);
    let shortest = times.iter().map(|t| t.1).fold(f64::INFINITY, f64::min);
    let dt = scene.time_step();
    report["contact_time"] = json!({
        "face_to_face_at_impact_speed": v_fall,
        "per_type": times.iter().map(|(n, t)| json!({"type": n, "seconds": t})).collect::<Vec<_>>(),
        "dt_fraction_of_shortest": dt / shortest,
        "recommended_dt_max": SAFE_FACE_FRACTION * shortest,
        "energy_conserving_dt_max": ENERGY_FACE_FRACTION * shortest,
    });
    let warnings = time_step_warnings(&scene);
    for msg in &warnings {
        tracing::warn!("{msg}");
    }
    if !warnings.is_empty() {
        report["warnings"] = json!(warnings);
    }
    Ok(report)
}

/// The time-step warnings of a scene: a step above [`SAFE_FACE_FRACTION`] of the shortest
/// face-to-face contact time. `polydem check` reports them and `polydem run` logs them at the
/// start and lists them in `summary.json`, so that a run at an unstable step is never silent.
pub fn time_step_warnings(scene: &Scene) -> Vec<String> {
    let v_fall = impact_speed(scene);
    let shortest = face_contact_times(scene, v_fall)
        .iter()
        .map(|t| t.1)
        .fold(f64::INFINITY, f64::min);
    let dt = scene.time_step();
    let mut out = Vec::new();
    // The relative margin keeps dt_fraction = 0.05 itself, whose product with the contact time
    // can round one ulp above 0.05 × that time, from being flagged.
    if dt > SAFE_FACE_FRACTION * shortest * (1.0 + 1e-12) {
        out.push(format!(
            "dt = {dt:e} s is {:.3} of the face-to-face contact time {shortest:e} s at {v_fall:.2} m/s, above {SAFE_FACE_FRACTION} of it: face impacts leave the 2 % restitution band",
            dt / shortest
        ));
    }
    out
}

/// The largest step, as a fraction of the face-to-face contact time, at which every face impact
/// keeps the restitution of the contact law within 2 % at every phase of first touch
/// (docs/contact.md §1: within 0.16 % at this step in the dimensionless face impact for e = 0.3
/// … 1; at t_c/13 a face impact with e = 0.1 rebounds at up to 1.5 e, its dashpot capped by
/// the step).
pub const SAFE_FACE_FRACTION: f64 = 0.05;

/// The largest step, as a fraction of the face-to-face contact time, at which no elastic face
/// impact gains more than 1e-3 of its energy (8e-4 measured, docs/validation.md §4).
pub const ENERGY_FACE_FRACTION: f64 = 0.025;

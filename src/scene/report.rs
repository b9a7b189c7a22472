//! The summary `polydem check` prints: particles to insert, wall facets, templates, time steps.

use super::*;

/// The motion of a wall as JSON: its kind and parameters.
fn motion_json(m: &WallMotion) -> serde_json::Value {
    use serde_json::json;
    match m {
        WallMotion::Fixed => json!({ "kind": "fixed" }),
        WallMotion::Rotate { axis, origin, rpm } => json!({
            "kind": "rotate", "axis": axis.as_slice(), "origin": origin.as_slice(), "rpm": rpm,
        }),
        WallMotion::Translate { velocity } => {
            json!({ "kind": "translate", "velocity": velocity.as_slice() })
        }
        WallMotion::Sinusoidal {
            direction,
            amplitude,
            frequency,
        } => json!({
            "kind": "sinusoidal", "direction": direction.as_slice(), "amplitude": amplitude,
            "frequency": frequency,
        }),
    }
}

/// A summary for `polydem check`: particles to insert, wall facets, templates, time steps.
pub fn check_report(scene: &Scene) -> serde_json::Value {
    use serde_json::json;
    let ts = critical_time_step(scene);
    let end = scene.simulation.end_time;
    let insertions: Vec<_> = scene
        .insertions
        .iter()
        .map(|ins| {
            json!({
                "type": scene.particle_types.get(ins.particle_type).map(|p| p.name.clone()),
                "mode": match ins.mode { InsertionMode::Count(_) => "count", InsertionMode::Rate { .. } => "rate" },
                "particles": ins.planned_count(end),
                "region_volume": ins.region.volume(),
            })
        })
        .collect();
    let total: u64 = scene.insertions.iter().map(|i| i.planned_count(end)).sum();
    let walls: Vec<_> = scene
        .walls
        .iter()
        .map(|w| {
            json!({
                "name": w.name,
                "facets": w.triangles.len(),
                "material": scene.materials.get(w.material).map(|m| m.name.clone()),
                "motion": motion_json(&w.motion),
            })
        })
        .collect();
    let templates: Vec<_> = scene
        .templates
        .iter()
        .map(|t| {
            json!({
                "name": t.name,
                "vertices": t.vertices.len(),
                "faces": t.faces.len(),
                "volume": t.volume,
                "circumscribed_radius": t.circumscribed_radius,
                "equivalent_radius": t.equivalent_radius,
            })
        })
        .collect();
    let finite = |x: f64| if x.is_finite() { Some(x) } else { None };
    json!({
        "file": scene.file.display().to_string(),
        "particles_to_insert": total,
        "insertions": insertions,
        "walls": walls,
        "templates": templates,
        "time_step": {
            "rayleigh": finite(ts.rayleigh),
            "per_material": ts.per_material,
            "contact_time": ts.contact_time,
            "dt": finite(ts.dt),
            "fraction_of_rayleigh": finite(ts.fraction_of_rayleigh),
            "steps": finite((end / ts.dt).ceil()),
        },
        "neighbor_skin": scene.simulation.neighbor.skin,
        "neighbor_mode": scene.simulation.neighbor.mode.name(),
        "neighbor_hybrid_skin": scene.simulation.neighbor.hybrid_skin,
    })
}

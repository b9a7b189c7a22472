//! `polydem probe`: the contact-geometry queries on user-given shapes and poses, one JSON line
//! per query. It is both a user tool (check what the contact law will see for a given pair) and
//! a test hook (oracle tests drive it from Python).
//!
//! Input (`probe overlap`):
//! ```json
//! {"shapes": {"NAME": {"vertices": [[x,y,z], ...]} | {"mesh": "path.stl"}
//!                   | {"generator": "dodecahedron", "size": 1.0}},   (exactly one source)
//!  "pairs": [{"a": "NAME", "b": "NAME",
//!             "pose_a": {"position": [x,y,z], "orientation": [w,x,y,z]},
//!             "pose_b": {...}}]}
//! ```
//! A shape is placed in the coordinates it was given in: `world = R(q)·v + position`, with no
//! re-centring (the template's principal frame is undone through `file_to_body`).
//!
//! Input (`probe wall`): the same `shapes`, and
//! `"cases": [{"shape": "NAME", "pose": {...}, "triangles": [[[x,y,z],[x,y,z],[x,y,z]], ...]}]`
//! with triangles counter-clockwise seen from the side the particle is meant to be on.

use crate::geometry::clip::facet_contact;
use crate::geometry::overlap::OverlapWorkspace;
use crate::geometry::pair::{PairWorkspace, overlap_pair, overlap_pair_mixed_with};
use crate::geometry::polytope::{PosedPolytope, cast, widen};
use crate::geometry::{Overlap, Real};
use crate::shape::{ConvexTemplate, Generator, MESH_EXTENSIONS};
use anyhow::{Context, Result, anyhow, bail};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

/// The arithmetic a probe evaluates one pair in: a run's [`crate::Precision`] (f64 is
/// `Double`'s, mixed is `Mixed`'s) or, to see what f32 alone gives, f32 throughout.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Arithmetic {
    /// All f64 (the reference).
    F64,
    /// f32 pair geometry in a frame centred on the first body (positions stay f64).
    F32,
    /// The GPU's mixed precision ([`crate::geometry::pair::overlap_pair_mixed`]): f32 where it
    /// resolves the overlap, f64 for thin, unproven and bent pairs; walls in f64.
    Mixed,
}

enum ShapeSpec {
    Vertices(Vec<[f64; 3]>),
    Mesh(String),
    Generator { generator: String, size: f64 },
}

/// The keys a shape may have; `size` goes with `generator` only.
const SHAPE_KEYS: [&str; 4] = ["vertices", "mesh", "generator", "size"];

/// Reads `shapes.NAME`: exactly one of `vertices`, `mesh` and `generator` (with `size`). A
/// second source is an error naming both keys, not silently ignored.
fn shape_spec(name: &str, value: &Value) -> Result<ShapeSpec> {
    let usage = "expected {\"vertices\": [[x,y,z], ...]}, {\"mesh\": \"file.stl|obj\"} or \
                 {\"generator\": \"dodecahedron\", \"size\": 1.0}";
    let Some(obj) = value.as_object() else {
        bail!("shapes.{name}: {usage}");
    };
    if let Some(key) = obj.keys().find(|k| !SHAPE_KEYS.contains(&k.as_str())) {
        bail!("shapes.{name}.{key}: unknown key; allowed: vertices, mesh, generator (with size)");
    }
    let given: Vec<&str> = SHAPE_KEYS[..3]
        .iter()
        .copied()
        .filter(|k| obj.contains_key(*k))
        .collect();
    let source = match given.as_slice() {
        [one] => *one,
        [] => bail!("shapes.{name}: {usage}"),
        many => bail!(
            "shapes.{name}: give exactly one of \"vertices\", \"mesh\" and \"generator\", got {}",
            many.iter()
                .map(|k| format!("\"{k}\""))
                .collect::<Vec<_>>()
                .join(" and ")
        ),
    };
    if source != "generator" && obj.contains_key("size") {
        bail!("shapes.{name}.size: only a \"generator\" takes a size, not \"{source}\"");
    }
    let field = |key: &str| &obj[key];
    Ok(match source {
        "vertices" => ShapeSpec::Vertices(
            serde_json::from_value(field("vertices").clone())
                .with_context(|| format!("shapes.{name}.vertices: expected [[x,y,z], ...]"))?,
        ),
        "mesh" => ShapeSpec::Mesh(
            field("mesh")
                .as_str()
                .ok_or_else(|| anyhow!("shapes.{name}.mesh: expected a file name (a string)"))?
                .to_string(),
        ),
        _ => ShapeSpec::Generator {
            generator: field("generator")
                .as_str()
                .ok_or_else(|| anyhow!("shapes.{name}.generator: expected a name (a string)"))?
                .to_string(),
            size: obj.get("size").and_then(Value::as_f64).ok_or_else(|| {
                anyhow!("shapes.{name}.size: a generator needs a size (circumscribed diameter)")
            })?,
        },
    })
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PoseSpec {
    position: [f64; 3],
    orientation: [f64; 4],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PairSpec {
    a: String,
    b: String,
    pose_a: PoseSpec,
    pose_b: PoseSpec,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WallCaseSpec {
    shape: String,
    pose: PoseSpec,
    triangles: Vec<[[f64; 3]; 3]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct OverlapInput {
    shapes: BTreeMap<String, Value>,
    pairs: Vec<PairSpec>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WallInput {
    shapes: BTreeMap<String, Value>,
    cases: Vec<WallCaseSpec>,
}

/// A loaded shape: its template, and the pose correction that places it in input coordinates.
struct PlacedShape {
    template: ConvexTemplate,
    body_to_input: Isometry3<f64>,
}

fn load_shapes(
    shapes: &BTreeMap<String, Value>,
    base: &Path,
) -> Result<BTreeMap<String, PlacedShape>> {
    let mut out = BTreeMap::new();
    for (name, value) in shapes {
        let template = match shape_spec(name, value)? {
            ShapeSpec::Vertices(vertices) => {
                let pts: Vec<_> = vertices
                    .iter()
                    .map(|v| nalgebra::Point3::new(v[0], v[1], v[2]))
                    .collect();
                ConvexTemplate::from_points(name, &pts)
                    .with_context(|| format!("shapes.{name}.vertices"))?
            }
            ShapeSpec::Mesh(mesh) => ConvexTemplate::from_file(&base.join(&mesh))
                .with_context(|| format!("shapes.{name}.mesh"))?,
            ShapeSpec::Generator { generator, size } => Generator::parse(&generator, size)
                .and_then(|g| g.build())
                .with_context(|| format!("shapes.{name}.generator"))?,
        };
        if template.sphere {
            return Err(anyhow!(
                "shapes.{name}.generator: the probe computes polyhedral overlaps and a \"sphere\" \
                 is not a polyhedron; use \"icosahedron\" or a vertex list"
            ));
        }
        let body_to_input = template.file_to_body.inverse();
        out.insert(
            name.clone(),
            PlacedShape {
                template,
                body_to_input,
            },
        );
    }
    Ok(out)
}

fn pose_of(spec: &PoseSpec, field: &str) -> Result<Isometry3<f64>> {
    if spec.position.iter().any(|x| !x.is_finite()) {
        bail!("{field}.position: coordinates must be finite numbers");
    }
    let [w, x, y, z] = spec.orientation;
    let q = Quaternion::new(w, x, y, z);
    let norm = q.norm();
    // Unit quaternions are expected; round-off in hand-written values (a few 1e-7) is accepted
    // and normalised, anything else is an input error rather than a silent rescaling.
    if !norm.is_finite() || (norm - 1.0).abs() > 1e-6 {
        bail!("{field}.orientation: [w, x, y, z] must be a unit quaternion (norm is {norm})");
    }
    let [px, py, pz] = spec.position;
    Ok(Isometry3::from_parts(
        Translation3::new(px, py, pz),
        UnitQuaternion::new_normalize(q),
    ))
}

fn lookup<'a>(
    shapes: &'a BTreeMap<String, PlacedShape>,
    name: &str,
    field: &str,
) -> Result<&'a PlacedShape> {
    shapes.get(name).ok_or_else(|| {
        let known: Vec<_> = shapes.keys().map(String::as_str).collect();
        anyhow!(
            "{field}: unknown shape \"{name}\" (defined: {})",
            known.join(", ")
        )
    })
}

fn vec_json(v: &Vector3<f64>) -> Value {
    json!([v.x, v.y, v.z])
}

/// `|S|` at or below this fraction of `V^(2/3)` is reported as zero, with no normal. S is the
/// vector area of B's part of the overlap surface; when that part is (nearly) closed, as for
/// coincident bodies or one inside the other, S is a sum of terms that cancel, and what is left
/// is rounding noise (about 1e-16 of `V^(2/3)` in f64, 1e-7 in f32) whose direction means
/// nothing and differs between precisions. Genuine contacts have `|S|` of order `V^(2/3)` or
/// more (a thin lens: far more).
pub const CLOSED_SURFACE_TOL: f64 = 1e-5;

/// JSON of one pair's result (fields of the `probe overlap` output).
pub fn overlap_json(intersects: bool, o: &Overlap<f64>) -> Value {
    if o.volume > 0.0 && o.area() <= CLOSED_SURFACE_TOL * o.volume.powf(2.0 / 3.0) {
        json!({"intersects": intersects, "volume": o.volume, "dv_dxb": [0.0, 0.0, 0.0],
               "area": 0.0, "normal": null, "centroid": vec_json(&o.centroid)})
    } else if o.volume > 0.0 {
        let normal = o.normal().map(|n| vec_json(&n)).unwrap_or(Value::Null);
        json!({"intersects": intersects, "volume": o.volume, "dv_dxb": vec_json(&o.dv_dxb),
               "area": o.area(), "normal": normal, "centroid": vec_json(&o.centroid)})
    } else {
        json!({"intersects": intersects, "volume": 0.0, "dv_dxb": null, "area": null,
               "normal": null, "centroid": null})
    }
}

fn read_input(path: &Path) -> Result<(String, &Path)> {
    let text = crate::input::read_bounded_text(path, crate::input::InputKind::Probe)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    Ok((text, path.parent().unwrap_or(Path::new("."))))
}

/// `polydem probe overlap FILE`: writes one JSON object per pair, in input order.
pub fn probe_overlap(path: &Path, precision: Arithmetic, out: &mut dyn Write) -> Result<()> {
    let (text, base) = read_input(path)?;
    let input: OverlapInput =
        serde_json::from_str(&text).with_context(|| format!("{}", path.display()))?;
    let shapes = load_shapes(&input.shapes, base).with_context(|| format!("{}", path.display()))?;
    let mut ws64 = PairWorkspace::<f64>::boxed();
    let mut ws32 = PairWorkspace::<f32>::boxed();
    for (i, pair) in input.pairs.iter().enumerate() {
        let field = |f: &str| format!("{}: pairs[{i}].{f}", path.display());
        let a = lookup(&shapes, &pair.a, &field("a"))?;
        let b = lookup(&shapes, &pair.b, &field("b"))?;
        let pose_a = pose_of(&pair.pose_a, &field("pose_a"))? * a.body_to_input;
        let pose_b = pose_of(&pair.pose_b, &field("pose_b"))? * b.body_to_input;
        let body_a = (&a.template, 1.0, &pose_a);
        let body_b = (&b.template, 1.0, &pose_b);
        let result = match precision {
            Arithmetic::F64 => overlap_pair(&mut ws64, body_a, body_b),
            Arithmetic::F32 => overlap_pair(&mut ws32, body_a, body_b),
            Arithmetic::Mixed => overlap_pair_mixed_with(
                &mut ws32,
                &mut ws64,
                body_a,
                body_b,
                !crate::tuning::Tuning::get().mixed_lp_f32,
            ),
        }
        .map_err(|e| anyhow!("{}: {e}", field("")))?;
        writeln!(out, "{}", overlap_json(result.intersects, &result.overlap))?;
    }
    Ok(())
}

fn wall_case<T: Real>(
    ws: &mut OverlapWorkspace<T>,
    body: &mut PosedPolytope<T>,
    shape: &PlacedShape,
    pose: &Isometry3<f64>,
    triangles: &[[[f64; 3]; 3]],
) -> Result<Value> {
    let origin = pose.translation.vector;
    body.place(&shape.template, 1.0, pose, &origin);
    let mut facets = Vec::new();
    let (mut total_area, mut total_volume) = (0.0, 0.0);
    for tri in triangles {
        let t: [Vector3<T>; 3] = tri.map(|p| cast(&(Vector3::from(p) - origin)));
        let c = facet_contact(ws, body, &t)?;
        total_area += c.area.f64();
        total_volume += c.volume.f64();
        let centroid = (c.area > T::zero()).then(|| vec_json(&(widen(&c.centroid) + origin)));
        let dv_dx = (c.volume > T::zero()).then(|| vec_json(&widen(&c.dv_dx)));
        facets.push(json!({"area": c.area.f64(), "centroid": centroid,
                           "volume": c.volume.f64(), "dv_dx": dv_dx}));
    }
    Ok(json!({"area": total_area, "volume": total_volume, "facets": facets}))
}

/// `polydem probe wall FILE`: writes one JSON object per case: per-facet clipped section area and
/// centroid, penetrating volume and its gradient, and their totals.
pub fn probe_wall(path: &Path, precision: Arithmetic, out: &mut dyn Write) -> Result<()> {
    let (text, base) = read_input(path)?;
    let input: WallInput =
        serde_json::from_str(&text).with_context(|| format!("{}", path.display()))?;
    let shapes = load_shapes(&input.shapes, base).with_context(|| format!("{}", path.display()))?;
    let mut ws64 = PairWorkspace::<f64>::boxed();
    let mut ws32 = PairWorkspace::<f32>::boxed();
    for (i, case) in input.cases.iter().enumerate() {
        let field = |f: &str| format!("{}: cases[{i}].{f}", path.display());
        let shape = lookup(&shapes, &case.shape, &field("shape"))?;
        let pose = pose_of(&case.pose, &field("pose"))? * shape.body_to_input;
        if case
            .triangles
            .iter()
            .flatten()
            .flatten()
            .any(|x| !x.is_finite())
        {
            bail!("{}: coordinates must be finite numbers", field("triangles"));
        }
        let value = match precision {
            // Mixed precision evaluates walls in f64.
            Arithmetic::F64 | Arithmetic::Mixed => wall_case(
                &mut ws64.overlap,
                &mut ws64.a,
                shape,
                &pose,
                &case.triangles,
            ),
            Arithmetic::F32 => wall_case(
                &mut ws32.overlap,
                &mut ws32.a,
                shape,
                &pose,
                &case.triangles,
            ),
        }
        .map_err(|e| anyhow!("{}: {e}", field("")))?;
        writeln!(out, "{value}")?;
    }
    Ok(())
}

/// `polydem shape info`: a template's counts and mass properties as one JSON object.
pub fn shape_info(shape: &str, size: f64, out: &mut dyn Write) -> Result<()> {
    let path = Path::new(shape);
    let is_mesh_name = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| MESH_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
    let template = if path.exists() {
        ConvexTemplate::from_file(path)?
    } else if is_mesh_name || shape.contains(std::path::MAIN_SEPARATOR) || shape.contains('/') {
        // A file name, not a generator: say that the file is missing rather than that no
        // generator has this name.
        bail!("{shape}: no such file (a mesh file .stl or .obj, or a generator name)");
    } else {
        Generator::parse(shape, size)
            .map_err(|e| anyhow!("{e}; and no file \"{shape}\" exists"))?
            .build()?
    };
    let i = template.principal_inertia;
    let value = json!({
        "name": template.name,
        "vertices": template.vertices.len(),
        "faces": template.faces.len(),
        "edges": template.edges.len(),
        "volume": template.volume,
        "principal_inertia_per_density": [i.x, i.y, i.z],
        "circumscribed_radius": template.circumscribed_radius,
        "equivalent_radius": template.equivalent_radius,
    });
    writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
    Ok(())
}

//! `polydem probe`: the command-line contract (input formats, placement rule, output fields,
//! errors that name the pair and field).

mod common;

use common::*;
use serde_json::Value;
use std::process::Command;

fn probe(kind: &str, json: &str, extra: &[&str]) -> (bool, Vec<Value>, String) {
    let dir = temp_dir(&format!(
        "probe-{kind}-{:x}",
        json.len() ^ extra.len() << 16
    ));
    let file = dir.join("input.json");
    std::fs::write(&file, json).unwrap();
    let out = Command::new(polydem_bin())
        .args(["probe", kind])
        .arg(&file)
        .args(extra)
        .output()
        .expect("run polydem");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let lines = stdout
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON line"))
        .collect();
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!stderr.contains("panicked"), "polydem panicked: {stderr}");
    (out.status.success(), lines, stderr)
}

const CUBE: &str = "[[0,0,0],[1,0,0],[1,1,0],[0,1,0],[0,0,1],[1,0,1],[1,1,1],[0,1,1]]";

fn pose(p: [f64; 3], q: [f64; 4]) -> String {
    format!("{{\"position\": {p:?}, \"orientation\": {q:?}}}")
}

#[test]
fn overlap_output_for_vertex_generator_and_mesh_shapes() {
    let root = repo_root();
    let mesh = root.join("meshes/particles/cube.stl");
    let json = format!(
        r#"{{"shapes": {{"box": {{"vertices": {CUBE}}},
                        "dodeca": {{"generator": "dodecahedron", "size": 1.0}},
                        "stl": {{"mesh": "{}"}}}},
            "pairs": [
              {{"a": "box", "b": "box", "pose_a": {}, "pose_b": {}}},
              {{"a": "box", "b": "box", "pose_a": {}, "pose_b": {}}},
              {{"a": "dodeca", "b": "dodeca", "pose_a": {}, "pose_b": {}}},
              {{"a": "stl", "b": "stl", "pose_a": {}, "pose_b": {}}}
            ]}}"#,
        mesh.display(),
        pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
        pose([0.75, 0.5, 0.0], [1.0, 0.0, 0.0, 0.0]),
        pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
        pose([1.5, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
        pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
        pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
        pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
        pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
    );
    for precision in ["f64", "f32"] {
        let tol = if precision == "f64" { 1e-12 } else { 1e-5 };
        let (ok, lines, err) = probe("overlap", &json, &["--precision", precision]);
        assert!(ok, "{err}");
        assert_eq!(lines.len(), 4);
        // Vertex-list cube [0,1]³ placed as given (no re-centring): B at (0.75, 0.5, 0) overlaps
        // in [0.75,1]×[0.5,1]×[0,1], volume 0.125, centroid (0.875, 0.75, 0.5).
        let l = &lines[0];
        assert_eq!(l["intersects"], true);
        assert!((l["volume"].as_f64().unwrap() - 0.125).abs() < tol);
        let c: Vec<f64> = l["centroid"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        for (x, y) in c.iter().zip([0.875, 0.75, 0.5]) {
            assert!((x - y).abs() < tol, "centroid {c:?}");
        }
        // S = dV/dx_B = (−0.5, −0.25, 0) (faces x = 0.75 and y = 0.5 of B), area |S|.
        let s: Vec<f64> = l["dv_dxb"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert!(
            (s[0] + 0.5).abs() < tol && (s[1] + 0.25).abs() < tol && s[2].abs() < tol,
            "S {s:?}"
        );
        assert!(
            (l["area"].as_f64().unwrap() - (0.5f64.powi(2) + 0.25f64.powi(2)).sqrt()).abs() < tol
        );
        // Separated dodecahedra: zero volume and null geometry.
        assert_eq!(lines[1]["volume"], 0.0);
        assert!(
            lines[1]["normal"].is_null()
                && lines[1]["centroid"].is_null()
                && lines[1]["dv_dxb"].is_null()
        );
        // Coincident bodies: the body's volume (dodecahedron of circumradius 1/2, edge 1/(√3 φ)).
        let phi = (1.0 + 5f64.sqrt()) / 2.0;
        let edge = 1.0 / (3f64.sqrt() * phi);
        let dodeca = (15.0 + 7.0 * 5f64.sqrt()) / 4.0 * edge.powi(3);
        assert!((lines[2]["volume"].as_f64().unwrap() - dodeca).abs() < tol * dodeca);
        assert!(lines[3]["volume"].as_f64().unwrap() > 0.0);
    }
}

#[test]
fn bad_input_names_the_pair_and_field() {
    let good_pose = pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
    let cases = [
        (
            format!(
                r#"{{"shapes": {{"box": {{"vertices": {CUBE}}}}}, "pairs": [{{"a": "box", "b": "box", "pose_a": {good_pose}, "pose_b": {good_pose}}}, {{"a": "box", "b": "ball", "pose_a": {good_pose}, "pose_b": {good_pose}}}]}}"#
            ),
            vec!["pairs[1].b", "unknown shape \"ball\"", "box"],
        ),
        (
            format!(
                r#"{{"shapes": {{"box": {{"vertices": {CUBE}}}}}, "pairs": [{{"a": "box", "b": "box", "pose_a": {}, "pose_b": {good_pose}}}]}}"#,
                pose([0.0, 0.0, 0.0], [2.0, 0.0, 0.0, 0.0])
            ),
            vec!["pairs[0].pose_a.orientation", "unit quaternion"],
        ),
        (
            r#"{"shapes": {"flat": {"vertices": [[0,0,0],[1,0,0],[0,1,0],[1,1,0]]}}, "pairs": []}"#
                .to_string(),
            vec!["shapes.flat.vertices"],
        ),
        (
            r#"{"shapes": {"m": {"mesh": "no/such/file.stl"}}, "pairs": []}"#.to_string(),
            vec!["shapes.m.mesh", "no/such/file.stl"],
        ),
        (
            r#"{"shapes": {"g": {"generator": "ellipsoid", "size": 1.0}}, "pairs": []}"#
                .to_string(),
            vec!["shapes.g.generator", "dodecahedron"],
        ),
        (
            r#"{"shapes": {"g": {"generator": "sphere", "size": 1.0}}, "pairs": []}"#.to_string(),
            vec!["shapes.g.generator", "not a polyhedron", "icosahedron"],
        ),
        (
            r#"{"shapes": {}, "pairs": [], "extra": 1}"#.to_string(),
            vec!["unknown field", "extra"],
        ),
        // Two sources: the generator used to be ignored silently.
        (
            r#"{"shapes": {"g": {"mesh": "../../meshes/particles/cube.stl", "generator": "dodecahedron", "size": 1.0}}, "pairs": []}"#
                .to_string(),
            vec![
                r#"shapes.g: give exactly one of "vertices", "mesh" and "generator", got "mesh" and "generator""#,
            ],
        ),
        (
            format!(r#"{{"shapes": {{"v": {{"vertices": {CUBE}, "size": 2.0}}}}, "pairs": []}}"#),
            vec![r#"shapes.v.size: only a "generator" takes a size, not "vertices""#],
        ),
        (
            r#"{"shapes": {"g": {"generator": "cube", "size": 1.0, "colour": 1}}, "pairs": []}"#
                .to_string(),
            vec!["shapes.g.colour: unknown key; allowed: vertices, mesh, generator (with size)"],
        ),
        (
            r#"{"shapes": {"g": {"generator": "cube"}}, "pairs": []}"#.to_string(),
            vec!["shapes.g.size: a generator needs a size"],
        ),
    ];
    for (json, needles) in cases {
        let (ok, _, err) = probe("overlap", &json, &[]);
        assert!(!ok, "accepted bad input {json}");
        for n in needles {
            assert!(err.contains(n), "error message {err:?} lacks {n:?}");
        }
    }
}

#[test]
fn coincident_bodies_have_no_normal_in_either_precision() {
    // B = A: B's part of the overlap surface is all of B's closed surface, so S = 0 and the
    // normal is undefined; it used to be a "unit" vector of rounding noise, another one in f32.
    let q = [0.8, 0.6, 0.0, 0.0];
    let same = pose([0.3, 0.2, 0.1], q);
    let json = format!(
        r#"{{"shapes": {{"d": {{"generator": "dodecahedron", "size": 1.0}}, "box": {{"vertices": {CUBE}}}}},
             "pairs": [{{"a": "d", "b": "d", "pose_a": {same}, "pose_b": {same}}},
                       {{"a": "box", "b": "box", "pose_a": {same}, "pose_b": {same}}},
                       {{"a": "box", "b": "box", "pose_a": {same}, "pose_b": {}}}]}}"#,
        pose([0.3, 0.7, 0.1], q)
    );
    for precision in ["f64", "f32"] {
        let (ok, lines, err) = probe("overlap", &json, &["--precision", precision]);
        assert!(ok, "{err}");
        let tol = if precision == "f64" { 1e-12 } else { 1e-6 };
        for (line, volume) in lines[..2].iter().zip([0.348_145_482_890_328_2, 1.0]) {
            assert!(
                (line["volume"].as_f64().unwrap() - volume).abs() < tol,
                "{precision}: {line}"
            );
            assert!(line["normal"].is_null(), "{precision}: {line}");
            assert_eq!(line["area"].as_f64(), Some(0.0), "{precision}: {line}");
            assert_eq!(
                line["dv_dxb"],
                serde_json::json!([0.0, 0.0, 0.0]),
                "{precision}"
            );
        }
        // B moved by 0.5 along y: a genuine contact keeps its normal (area 1.005: the face
        // areas B shows towards −y, the cube being turned about x).
        let n = &lines[2]["normal"];
        assert!(!n.is_null(), "{precision}: {}", lines[2]);
        let area = lines[2]["area"].as_f64().unwrap();
        assert!((area - 1.004_987_562_112_089).abs() < tol, "{}", lines[2]);
    }
}

#[test]
fn shape_info_names_a_missing_file() {
    let run = |args: &[&str]| {
        let out = Command::new(polydem_bin())
            .args(["shape", "info"])
            .args(args)
            .output()
            .expect("run polydem");
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stderr).to_string(),
        )
    };
    // It used to say "unknown shape generator".
    let (ok, err) = run(&["missing.stl"]);
    assert!(!ok);
    assert!(
        err.contains("missing.stl: no such file (a mesh file .stl or .obj, or a generator name)"),
        "{err}"
    );
    let (ok, err) = run(&["no/such/dir/grain"]);
    assert!(
        !ok && err.contains("no/such/dir/grain: no such file"),
        "{err}"
    );
    let (ok, err) = run(&["ellipsoid"]);
    assert!(!ok);
    assert!(
        err.contains("ellipsoid: unknown shape generator; allowed: tetrahedron")
            && err.contains("and no file \"ellipsoid\" exists"),
        "{err}"
    );
    let (ok, _) = run(&["cube"]);
    assert!(ok);
}

#[test]
fn wall_probe_sums_over_a_triangulated_wall() {
    // The wall is the square [−1, 2]² of the plane z = 0, facing +z, in two triangles; the unit
    // cube spans z ∈ [−0.1, 0.9] over [0, 1]²: penetrating volume 0.1, section area 1.
    let json = format!(
        r#"{{"shapes": {{"box": {{"vertices": {CUBE}}}}},
            "cases": [{{"shape": "box", "pose": {},
                        "triangles": [[[-1,-1,0],[2,-1,0],[2,2,0]], [[-1,-1,0],[2,2,0],[-1,2,0]]]}}]}}"#,
        pose([0.0, 0.0, -0.1], [1.0, 0.0, 0.0, 0.0])
    );
    for precision in ["f64", "f32"] {
        let (ok, lines, err) = probe("wall", &json, &["--precision", precision]);
        assert!(ok, "{err}");
        let tol = if precision == "f64" { 1e-12 } else { 1e-5 };
        assert!(
            (lines[0]["volume"].as_f64().unwrap() - 0.1).abs() < tol,
            "{}",
            lines[0]
        );
        assert!(
            (lines[0]["area"].as_f64().unwrap() - 1.0).abs() < tol,
            "{}",
            lines[0]
        );
        assert_eq!(lines[0]["facets"].as_array().unwrap().len(), 2);
    }
}

/// `--precision mixed` is the GPU's mixed precision: each pair is evaluated either in f32 (a
/// contact f32 resolves) or in f64 (thin, unproven or bent), so each output line is the f32 or
/// the f64 line of the same pair; a face resting on a face 1e-9 of the size deep is thin and
/// comes out as f64, a deep overlap as f32. Walls are f64 in mixed precision.
#[test]
fn mixed_precision_is_f32_or_f64_pair_by_pair_and_f64_for_walls() {
    let unit = |q: [f64; 4]| {
        let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
        q.map(|c| c / n)
    };
    let q = [1.0, 0.0, 0.0, 0.0];
    let json = format!(
        r#"{{"shapes": {{"box": {{"vertices": {CUBE}}},
                        "dodeca": {{"generator": "dodecahedron", "size": 1.0}}}},
            "pairs": [
              {{"a": "box", "b": "box", "pose_a": {}, "pose_b": {}}},
              {{"a": "box", "b": "box", "pose_a": {}, "pose_b": {}}},
              {{"a": "dodeca", "b": "dodeca", "pose_a": {}, "pose_b": {}}}
            ]}}"#,
        pose([0.0, 0.0, 0.0], q),
        pose([0.2, 0.3, 0.25], q),
        pose([0.0, 0.0, 0.0], q),
        pose([0.1, 0.2, 1.0 - 1e-9], q),
        pose([0.0, 0.0, 0.0], q),
        pose([0.3, 0.1, 0.2], unit([0.9, 0.1, 0.3, 0.2])),
    );
    let run = |p: &str| {
        let (ok, lines, err) = probe("overlap", &json, &["--precision", p]);
        assert!(ok, "--precision {p}: {err}");
        lines
    };
    let (f64s, f32s, mixed) = (run("f64"), run("f32"), run("mixed"));
    assert_eq!(mixed.len(), 3);
    assert_eq!(mixed[0], f32s[0], "a deep box overlap is f32");
    assert_ne!(f32s[0], f64s[0]);
    assert_eq!(
        mixed[1], f64s[1],
        "a face resting on a face 1e-9 deep is f64"
    );
    assert_ne!(f32s[1], f64s[1]);
    assert_eq!(mixed[2], f32s[2], "a deep dodecahedron overlap is f32");
    let wall = format!(
        r#"{{"shapes": {{"box": {{"vertices": {CUBE}}}}},
            "cases": [{{"shape": "box", "pose": {}, "triangles": [[[-1,-1,0],[3,-1,0],[-1,3,0]]]}}]}}"#,
        pose([0.0, 0.0, -0.3], unit([0.99, 0.05, 0.1, 0.0]))
    );
    let walls = |p: &str| probe("wall", &wall, &["--precision", p]);
    let (ok, w_mixed, err) = walls("mixed");
    assert!(ok, "{err}");
    assert_eq!(w_mixed, walls("f64").1);
    assert_ne!(w_mixed, walls("f32").1);
}

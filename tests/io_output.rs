//! Output and checkpoints (src/io, docs/design.md §8): frames read back by meshio (an independent
//! reader, tests/oracles/read_vtu.py), collections, particle CSV, time series and checkpoints.
//!
//! The meshio tests need the Python of python/requirements.txt: `POLYDEM_PYTHON`, else
//! `<root>/.venv/bin/python` (root: `POLYDEM_ROOT` or the current directory). Without either
//! they fail and say to run `make test`, which sets it up.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use polydem::contact::history::{ContactHistory, ContactKey, ContactState};
use polydem::io::checkpoint::MAGIC;
use polydem::io::{
    Checkpoint, CheckpointError, FrameView, FrameWriter, SeriesRow, SeriesWriter, WallView,
    encode_checkpoint, read_checkpoint, read_particle_csv, temporary_path, write_checkpoint,
    write_particle_csv,
};
use polydem::shape::{ConvexTemplate, Generator};
use polydem::state::Particles;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn repo_root() -> PathBuf {
    std::env::var_os("POLYDEM_ROOT")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::current_dir().expect("current directory"))
}

/// `POLYDEM_PYTHON`, else `<root>/.venv/bin/python`; fails the test when there is neither.
fn python() -> PathBuf {
    if let Some(p) = std::env::var_os("POLYDEM_PYTHON") {
        return PathBuf::from(p);
    }
    let venv = repo_root().join(".venv/bin/python");
    assert!(
        venv.exists(),
        "this test reads the output back with meshio: run `make test` (it creates {}), or set \
         POLYDEM_PYTHON to a Python that has python/requirements.txt installed",
        venv.display()
    );
    venv
}

/// Runs the meshio oracle and parses its JSON.
fn oracle(mode: &str, file: &Path) -> Value {
    let script = repo_root().join("tests/oracles/read_vtu.py");
    let out = Command::new(python())
        .arg(&script)
        .arg(mode)
        .arg(file)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}", script.display()));
    assert!(
        out.status.success(),
        "read_vtu.py {mode} {} failed:\n{}",
        file.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("oracle JSON")
}

/// A fresh scratch directory for one test, removed when the test passes (kept for a look when
/// it fails).
struct Scratch(PathBuf);

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

fn scratch(name: &str) -> Scratch {
    let d = std::env::temp_dir().join(format!("polydem-io-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    Scratch(d)
}

/// Templates [dodecahedron (20 vertices, 12 faces), cube (8, 6)]; kinds 0 → dodecahedron,
/// 1 → cube, 2 → dodecahedron again (type and template differ).
fn templates() -> (Vec<ConvexTemplate>, Vec<usize>) {
    let t = vec![
        Generator::Dodecahedron { size: 1.0 }.build().unwrap(),
        Generator::Cube { size: 1.0 }.build().unwrap(),
    ];
    (t, vec![0, 1, 0])
}

/// `n` particles of interleaved kinds with awkward values (−0, subnormals, thirds).
fn particles(n: usize, first_id: u64, t: &[ConvexTemplate], tt: &[usize]) -> Particles {
    let mut p = Particles::default();
    for k in 0..n {
        let kind = (k % 3) as u32;
        let q = UnitQuaternion::from_euler_angles(0.3 * k as f64, -1.1 + k as f64, 0.7);
        let x = Vector3::new(k as f64 * 1.5, (k as f64).sqrt(), -2.0 / 3.0);
        let s = 0.5 + 0.125 * k as f64;
        p.push(
            first_id + 7 * k as u64,
            kind,
            s,
            x,
            q,
            &t[tt[kind as usize]],
            2500.0,
        );
        p.velocity[k] = Vector3::new(1.0 / 3.0 + k as f64, -0.0, 5e-324 * k as f64);
        p.angular_velocity[k] = Vector3::new(1e-300, -7.25 * k as f64, 0.1);
        p.force[k] = Vector3::new(9.81e3, k as f64 / 7.0, -1e17);
        p.torque[k] = Vector3::new(0.5, 0.25, -(k as f64));
    }
    p
}

fn view<'a>(
    particles: &'a Particles,
    templates: &'a [ConvexTemplate],
    type_template: &'a [usize],
    rank: u32,
    fields: &'a [String],
) -> FrameView<'a> {
    FrameView {
        particles,
        templates,
        type_template,
        rank,
        fields,
    }
}

fn bits3(v: &Vector3<f64>) -> Vec<u64> {
    vec![v.x.to_bits(), v.y.to_bits(), v.z.to_bits()]
}

fn as_u64s(v: &Value) -> Vec<u64> {
    match v {
        Value::Array(a) => a.iter().flat_map(as_u64s).collect(),
        other => vec![other.as_u64().expect("integer")],
    }
}

const ALL_FIELDS: [&str; 7] = [
    "velocity",
    "angular_velocity",
    "force",
    "torque",
    "orientation",
    "rank",
    "template",
];

#[test]
fn frame_reads_back_with_meshio_exactly() {
    let dir = scratch("frame");
    let (t, tt) = templates();
    let p = particles(7, 1000, &t, &tt);
    let fields: Vec<String> = ALL_FIELDS.iter().map(|s| s.to_string()).collect();
    let view = FrameView {
        particles: &p,
        templates: &t,
        type_template: &tt,
        rank: 0,
        fields: &fields,
    };
    let mut w = FrameWriter::new(&dir, 1).unwrap();
    w.write_frame(100, 0.25, &[view], &[]).unwrap();
    let piece = dir.join("frames/step_0000000100_r0000.vtu");
    let m = oracle("mesh", &piece);

    let n_vertices = |i: usize| t[tt[p.kind[i] as usize]].vertices.len();
    let points = m["points"].as_array().unwrap();
    assert_eq!(points.len(), (0..7).map(n_vertices).sum::<usize>()); // 5 × 20 + 2 × 8 = 116
    assert_eq!(points.len(), 116);

    // Blocks by vertex count: 2 cubes, then 5 dodecahedra.
    let blocks = m["blocks"].as_array().unwrap();
    let kinds: Vec<(&str, usize)> = blocks
        .iter()
        .map(|b| {
            (
                b["type"].as_str().unwrap(),
                b["cells"].as_array().unwrap().len(),
            )
        })
        .collect();
    assert_eq!(kinds, vec![("polyhedron8", 2), ("polyhedron20", 5)]);

    let cd = &m["cell_data"];
    let ids = as_u64s(&cd["id"]);
    let mut sorted = ids.clone();
    sorted.sort();
    assert_eq!(sorted, p.id);
    let cells: Vec<&Value> = blocks
        .iter()
        .flat_map(|b| b["cells"].as_array().unwrap())
        .collect();
    for (c, id) in ids.iter().enumerate() {
        let i = p.id.iter().position(|x| x == id).unwrap();
        let kind = p.kind[i] as usize;
        let template = &t[tt[kind]];
        let vec = |name: &str, nc: usize| {
            as_u64s(&cd[name][c])
                .into_iter()
                .take(nc)
                .collect::<Vec<u64>>()
        };
        assert_eq!(
            vec("velocity", 3),
            bits3(&p.velocity[i]),
            "velocity of {id}"
        );
        assert_eq!(vec("angular_velocity", 3), bits3(&p.angular_velocity[i]));
        assert_eq!(vec("force", 3), bits3(&p.force[i]));
        assert_eq!(vec("torque", 3), bits3(&p.torque[i]));
        let q = p.orientation[i].quaternion();
        let qb: Vec<u64> = [q.w, q.i, q.j, q.k].iter().map(|x| x.to_bits()).collect();
        assert_eq!(vec("orientation", 4), qb);
        assert_eq!(as_u64s(&cd["type"][c]), vec![kind as u64]);
        assert_eq!(as_u64s(&cd["template"][c]), vec![tt[kind] as u64]);
        assert_eq!(as_u64s(&cd["rank"][c]), vec![0]);

        // Faces: as many as the template's, of the same sizes, outward (CCW from outside), on
        // the particle's world vertices R(q)(s v) + x computed here with a rotation matrix.
        let faces = cells[c].as_array().unwrap();
        assert_eq!(faces.len(), template.faces.len(), "faces of particle {id}");
        let mut sizes: Vec<usize> = faces.iter().map(|f| f.as_array().unwrap().len()).collect();
        let mut want: Vec<usize> = template.faces.iter().map(|f| f.vertices.len()).collect();
        sizes.sort();
        want.sort();
        assert_eq!(sizes, want);
        let r = p.orientation[i].to_rotation_matrix();
        let world: Vec<Vector3<f64>> = template
            .vertices
            .iter()
            .map(|v| r * (v.coords * p.scale[i]) + p.position[i])
            .collect();
        let mut used = Vec::new();
        for f in faces {
            let pts: Vec<Vector3<f64>> = as_u64s(f)
                .iter()
                .map(|&k| {
                    used.push(k);
                    let a = points[k as usize].as_array().unwrap();
                    Vector3::new(
                        a[0].as_f64().unwrap(),
                        a[1].as_f64().unwrap(),
                        a[2].as_f64().unwrap(),
                    )
                })
                .collect();
            for q in &pts {
                let d = world
                    .iter()
                    .map(|w| (w - q).norm())
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    d < 1e-12,
                    "point {q} of particle {id} is no vertex (off by {d})"
                );
            }
            let centroid = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
            let mut normal = Vector3::zeros(); // Newell
            for k in 0..pts.len() {
                normal += pts[k].cross(&pts[(k + 1) % pts.len()]);
            }
            assert!(
                normal.dot(&(centroid - p.position[i])) > 0.0,
                "inward face on {id}"
            );
        }
        used.sort();
        used.dedup();
        assert_eq!(used.len(), template.vertices.len());
    }
}

#[test]
fn collections_list_frames_and_resume_drops_later_ones() {
    let dir = scratch("collection");
    let (t, tt) = templates();
    let p0 = particles(4, 1, &t, &tt);
    let p1 = particles(3, 500, &t, &tt);
    let fields = vec!["velocity".to_string(), "rank".to_string()];
    let floor = [
        [
            Vector3::new(-5.0, -5.0, 0.0),
            Vector3::new(5.0, -5.0, 0.0),
            Vector3::new(5.0, 5.0, 0.0),
        ],
        [
            Vector3::new(-5.0, -5.0, 0.0),
            Vector3::new(5.0, 5.0, 0.0),
            Vector3::new(-5.0, 5.0, 0.0),
        ],
    ];
    let lid = [[
        Vector3::new(0.0, 0.0, 9.0),
        Vector3::new(1.0, 0.0, 9.0),
        Vector3::new(0.0, 1.0, 9.0),
    ]];
    let frame = |w: &mut FrameWriter, step: u64| {
        let walls = [
            WallView {
                name: "floor",
                triangles: &floor,
                force: Vector3::new(0.0, 0.0, 12.5),
            },
            WallView {
                name: "lid, top",
                triangles: &lid,
                force: Vector3::new(0.0, 0.0, -1.0),
            },
        ];
        w.write_frame(
            step,
            step as f64 * 0.01,
            &[
                view(&p0, &t, &tt, 0, &fields),
                view(&p1, &t, &tt, 1, &fields),
            ],
            &walls,
        )
        .unwrap();
    };
    let mut w = FrameWriter::new(&dir, 2).unwrap();
    for step in [0, 10, 20] {
        frame(&mut w, step);
    }
    let c = oracle("collection", &dir.join("frames.pvd"));
    let ds = c["datasets"].as_array().unwrap();
    let times: Vec<f64> = ds.iter().map(|d| d["timestep"].as_f64().unwrap()).collect();
    assert_eq!(times, vec![0.0, 0.1, 0.2]);
    for d in ds {
        assert_eq!(d["pieces"].as_array().unwrap().len(), 2);
        assert_eq!(d["cells"], 7);
        let arrays: Vec<&str> = d["cell_arrays"]
            .as_array()
            .unwrap()
            .iter()
            .map(|a| a.as_str().unwrap())
            .collect();
        assert_eq!(arrays, ["id", "type", "velocity", "rank"]);
    }
    let walls = oracle("collection", &dir.join("walls.pvd"));
    let wd = walls["datasets"].as_array().unwrap();
    assert_eq!(wd.len(), 3);
    assert!(wd.iter().all(|d| d["cells"] == 3));
    let wm = oracle("mesh", &dir.join("frames/walls_0000000010.vtu"));
    assert_eq!(wm["blocks"][0]["type"], "triangle");
    assert_eq!(as_u64s(&wm["cell_data"]["wall_id"]), vec![0, 0, 1]);
    assert_eq!(
        as_u64s(&wm["cell_data"]["force"][0]),
        bits3(&Vector3::new(0.0, 0.0, 12.5))
    );

    // Restart from a checkpoint at t = 0.1: the frame at 0.2 leaves both collections.
    let mut w = FrameWriter::resume(&dir, 2, 10.0 * 0.01).unwrap();
    assert_eq!(w.frames(), 2);
    let c = oracle("collection", &dir.join("frames.pvd"));
    assert_eq!(c["datasets"].as_array().unwrap().len(), 2);
    assert_eq!(
        oracle("collection", &dir.join("walls.pvd"))["datasets"]
            .as_array()
            .unwrap()
            .len(),
        2
    );
    frame(&mut w, 20);
    frame(&mut w, 30);
    let c = oracle("collection", &dir.join("frames.pvd"));
    let times: Vec<f64> = c["datasets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["timestep"].as_f64().unwrap())
        .collect();
    assert_eq!(times, vec![0.0, 0.1, 0.2, 0.3]);
}

#[test]
fn bad_frame_input_is_an_error_not_a_panic() {
    let dir = scratch("bad-frame");
    let (t, tt) = templates();
    let mut p = particles(3, 1, &t, &tt);
    let bad_field = vec!["colour".to_string()];
    let mut w = FrameWriter::new(&dir, 1).unwrap();
    let e = w
        .write_frame(0, 0.0, &[view(&p, &t, &tt, 0, &bad_field)], &[])
        .unwrap_err();
    assert!(
        e.to_string().contains("colour") && e.to_string().contains("velocity"),
        "{e}"
    );
    let e = w
        .write_frame(0, 0.0, &[view(&p, &t, &tt[..1], 0, &[])], &[])
        .unwrap_err();
    assert!(e.to_string().contains("no template"), "{e}");
    p.velocity.pop();
    let e = w
        .write_frame(0, 0.0, &[view(&p, &t, &tt, 0, &[])], &[])
        .unwrap_err();
    assert!(e.to_string().contains("velocity"), "{e}");
    assert!(FrameWriter::new(&dir, 0).is_err());
}

#[test]
fn particle_csv_round_trips_f64_exactly() {
    let dir = scratch("csv");
    let (t, tt) = templates();
    let p = particles(5, 42, &t, &tt);
    let view = FrameView {
        particles: &p,
        templates: &t,
        type_template: &tt,
        rank: 0,
        fields: &[],
    };
    let path = dir.join("particles_000100.csv");
    write_particle_csv(&path, 1.0 / 3.0, &view).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "time,id,x,y,z,vx,vy,vz,wx,wy,wz,qw,qx,qy,qz"
    );
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), 5);
    for (i, row) in rows.iter().enumerate() {
        let c: Vec<&str> = row.split(',').collect();
        assert_eq!(c.len(), 15);
        let f = |k: usize| c[k].parse::<f64>().unwrap().to_bits();
        assert_eq!(f(0), (1.0f64 / 3.0).to_bits());
        assert_eq!(c[1].parse::<u64>().unwrap(), p.id[i]);
        let q = p.orientation[i].quaternion();
        let want = [
            p.position[i].x,
            p.position[i].y,
            p.position[i].z,
            p.velocity[i].x,
            p.velocity[i].y,
            p.velocity[i].z,
            p.angular_velocity[i].x,
            p.angular_velocity[i].y,
            p.angular_velocity[i].z,
            q.w,
            q.i,
            q.j,
            q.k,
        ];
        for (k, x) in want.iter().enumerate() {
            assert_eq!(f(k + 2), x.to_bits(), "row {i} column {}", k + 2);
        }
    }
    // Read back: every row bit for bit.
    let back = read_particle_csv(&path).unwrap();
    assert_eq!(back.len(), 5);
    for (i, r) in back.iter().enumerate() {
        assert_eq!(r.time.to_bits(), (1.0f64 / 3.0).to_bits());
        assert_eq!(r.id, p.id[i]);
        for k in 0..3 {
            assert_eq!(r.position[k].to_bits(), p.position[i][k].to_bits());
            assert_eq!(r.velocity[k].to_bits(), p.velocity[i][k].to_bits());
            assert_eq!(
                r.angular_velocity[k].to_bits(),
                p.angular_velocity[i][k].to_bits()
            );
        }
    }
    // A damaged table is refused with its file, line and field.
    let bad = dir.join("bad.csv");
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    lines[3] = lines[3].replacen(',', ",x", 3);
    std::fs::write(&bad, lines.join("\n")).unwrap();
    let e = read_particle_csv(&bad).unwrap_err().to_string();
    assert!(e.contains("bad.csv") && e.contains("line 4"), "{e}");
    std::fs::write(&bad, "a,b\n").unwrap();
    let e = read_particle_csv(&bad).unwrap_err().to_string();
    assert!(e.contains("line 1") && e.contains("header"), "{e}");
}

fn checkpoint() -> Checkpoint {
    let (t, tt) = templates();
    let mut particles = particles(6, 77, &t, &tt);
    particles.force[2].y = f64::from_bits(0x8000_0000_0000_beef); // a negative subnormal
    // A quaternion off unit length by rounding: must come back with the same bits.
    particles.orientation[1] =
        UnitQuaternion::new_unchecked(Quaternion::new(0.6, 0.8, 1e-17, -0.0));
    let history = ContactHistory::from_entries(vec![
        (
            ContactKey::particles(91, 77),
            ContactState {
                spring: Vector3::new(1e-9, -2e-9, 1.0 / 3.0),
                approach_speed: 0.25,
                twist: -1e-310,
            },
        ),
        (
            ContactKey::wall(84, 3),
            ContactState {
                spring: Vector3::new(0.0, -0.0, 1e-300),
                // An unloading cycle's reference speed is stored negative.
                approach_speed: -f64::MIN_POSITIVE,
                twist: 0.0,
            },
        ),
    ]);
    Checkpoint {
        step: 123_456_789_012,
        time: 0.1 + 0.2,
        particles,
        history,
        rng_state: [u64::MAX, 0, 0x0123_4567_89ab_cdef, 42],
        inserter: b"inserter state \x00\xff".to_vec(),
        next_id: 1 << 40,
        scene_hash: 0xdead_beef_cafe_f00d,
        extra: vec![("walls".into(), vec![1, 2, 3]), ("timers/ü".into(), vec![])],
    }
}

/// Many contacts and few particles: the reader's length checks must use the real record size
/// (a dense packing has several contacts per particle).
#[test]
fn checkpoint_with_many_contacts_round_trips() {
    let dir = scratch("ckpt-contacts");
    let path = dir.join("dense.ckpt");
    let mut c = checkpoint();
    c.extra.clear();
    c.inserter.clear();
    c.history = ContactHistory::from_entries(
        (0..5000u64)
            .map(|k| {
                let state = ContactState {
                    spring: Vector3::new(k as f64, -1e-7, 0.5),
                    approach_speed: 1.0 + k as f64,
                    twist: -(k as f64),
                };
                (ContactKey::particles(k, k + 1 + k % 7), state)
            })
            .collect(),
    );
    write_checkpoint(&path, &c).unwrap();
    let back = read_checkpoint(&path).unwrap();
    assert_eq!(back.history.len(), 5000);
    assert!(back.history == c.history);
}

#[test]
fn checkpoint_round_trip_is_bitwise() {
    let dir = scratch("ckpt");
    let path = dir.join("state.ckpt");
    let c = checkpoint();
    write_checkpoint(&path, &c).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(&bytes[..8], MAGIC);
    let r = read_checkpoint(&path).unwrap();
    // Re-encoding gives the same bytes: every float kept its bits (subnormals included).
    assert_eq!(encode_checkpoint(&r, &path).unwrap(), bytes);
    assert_eq!(r.particles.force[2].y.to_bits(), 0x8000_0000_0000_beef);
    assert_eq!(
        r.particles.orientation[1]
            .quaternion()
            .coords
            .map(f64::to_bits),
        c.particles.orientation[1]
            .quaternion()
            .coords
            .map(f64::to_bits)
    );
    assert_eq!(r.history, c.history);
    assert_eq!(r.history.len(), 2);
    assert_eq!(r.extra, c.extra);
    assert_eq!(
        (r.step, r.time.to_bits(), r.rng_state),
        (c.step, c.time.to_bits(), c.rng_state)
    );
    assert_eq!(
        (r.inserter.clone(), r.next_id, r.scene_hash),
        (c.inserter.clone(), c.next_id, c.scene_hash)
    );
    assert_eq!(r.particles.id, c.particles.id);
    assert_eq!(r.particles.kind, c.particles.kind);
    assert!(r.check_scene(c.scene_hash, &path).is_ok());
    let e = r.check_scene(1, &path).unwrap_err().to_string();
    assert!(
        e.contains("state.ckpt") && e.contains("another scene"),
        "{e}"
    );
    // An empty state round-trips too.
    let empty = Checkpoint {
        particles: Particles::default(),
        history: ContactHistory::default(),
        extra: vec![],
        inserter: vec![],
        ..checkpoint()
    };
    write_checkpoint(&path, &empty).unwrap();
    assert_eq!(read_checkpoint(&path).unwrap(), empty);
}

/// A checksum proves only that the file is the one written: a state that cannot be stepped is
/// refused on read, naming the file, the field and the particle.
#[test]
fn checkpoints_with_bad_fields_are_rejected_naming_the_field() {
    let dir = scratch("ckpt-fields");
    let path = dir.join("fields.ckpt");
    type Edit = fn(&mut Checkpoint);
    let cases: [(Edit, &str); 9] = [
        (|c| c.time = f64::NAN, "`time` is NaN"),
        (
            |c| c.time = 0.0,
            "`step` 123456789012 and `time` 0 disagree",
        ),
        (
            |c| c.particles.id[3] = c.particles.id[1],
            "particle 3 (id 84): `id` appears twice",
        ),
        (
            |c| c.next_id = 80,
            "particle 1 (id 84): `id` is not below `next_id` = 80",
        ),
        (
            |c| c.particles.scale[2] = -0.5,
            "particle 2 (id 91): `scale` is -0.5",
        ),
        (
            |c| c.particles.mass[0] = 0.0,
            "particle 0 (id 77): `mass` is 0",
        ),
        (
            |c| c.particles.inertia[5].z = f64::INFINITY,
            "particle 5 (id 112): `inertia` is inf",
        ),
        (
            |c| {
                c.particles.orientation[4] =
                    UnitQuaternion::new_unchecked(Quaternion::new(0.0, 0.0, 0.0, 0.0))
            },
            "particle 4 (id 105): `orientation` is (w 0, i 0, j 0, k 0) of norm 0",
        ),
        (
            |c| c.particles.force[2].y = f64::NAN,
            "particle 2 (id 91): `force` is [",
        ),
    ];
    for (edit, want) in cases {
        let mut c = checkpoint();
        edit(&mut c);
        write_checkpoint(&path, &c).unwrap();
        let e = read_checkpoint(&path).expect_err(want).to_string();
        assert!(e.contains("fields.ckpt") && e.contains(want), "{want}: {e}");
    }
}

#[test]
fn damaged_checkpoints_are_rejected_naming_the_file() {
    let dir = scratch("ckpt-bad");
    let good = encode_checkpoint(&checkpoint(), Path::new("x")).unwrap();
    let path = dir.join("damaged.ckpt");
    let check = |bytes: &[u8], what: &str| -> String {
        std::fs::write(&path, bytes).unwrap();
        let e = read_checkpoint(&path).expect_err(what).to_string();
        assert!(e.contains("damaged.ckpt"), "{what}: {e}");
        e
    };
    let mut flipped = good.clone();
    flipped[good.len() / 2] ^= 0x10;
    assert!(check(&flipped, "bit flip").contains("checksum mismatch"));
    assert!(check(&good[..good.len() - 100], "truncated").contains("truncated"));
    assert!(check(b"", "empty").contains("not a polydem checkpoint"));
    let mut version = good.clone();
    version[8] = 9;
    assert!(check(&version, "version").contains("format version 9"));
    let mut longer = good.clone();
    longer.push(0);
    check(&longer, "trailing byte");
    // Every truncation is an error, never a panic.
    for len in 0..good.len() {
        check(&good[..len], "prefix");
    }
    let missing = read_checkpoint(&dir.join("none.ckpt")).unwrap_err();
    assert!(
        matches!(missing, CheckpointError::Io { .. }) && missing.to_string().contains("none.ckpt")
    );
}

#[test]
fn interrupted_write_leaves_the_checkpoint_intact() {
    let dir = scratch("ckpt-atomic");
    let path = dir.join("state.ckpt");
    let a = checkpoint();
    write_checkpoint(&path, &a).unwrap();
    // A run killed while writing the next checkpoint leaves only a partial temporary file.
    let mut b = checkpoint();
    b.step += 1000;
    let b_bytes = encode_checkpoint(&b, &path).unwrap();
    let tmp = temporary_path(&path);
    std::fs::write(&tmp, &b_bytes[..b_bytes.len() / 3]).unwrap();
    assert_eq!(read_checkpoint(&path).unwrap().step, a.step);
    // The next write goes through and leaves no temporary file behind.
    write_checkpoint(&path, &b).unwrap();
    assert_eq!(read_checkpoint(&path).unwrap().step, b.step);
    assert!(!tmp.exists());
    // A write that cannot happen (no such directory) reports the file.
    let e = write_checkpoint(&dir.join("no/such/dir.ckpt"), &b)
        .unwrap_err()
        .to_string();
    assert!(e.contains("dir.ckpt"), "{e}");
}

fn row(step: u64, walls: usize) -> SeriesRow {
    let t = step as f64 * 0.1;
    SeriesRow {
        step,
        time: t,
        kinetic_translational: 1.0 / (step as f64 + 3.0),
        kinetic_rotational: 1e-300 * step as f64,
        potential_gravity: -9.81 * t,
        elastic: 2.5e-7,
        contacts: 10 * step,
        wall_contacts: step,
        wall_forces: (0..walls)
            .map(|k| Vector3::new(k as f64, -t, 1.0 / 7.0))
            .collect(),
    }
}

#[test]
fn series_resume_drops_rows_after_the_cutoff() {
    let dir = scratch("series");
    let path = dir.join("series.csv");
    let walls = vec!["floor".to_string(), "lid, top".to_string()];
    let mut s = SeriesWriter::new(&path, &walls).unwrap();
    // Step 1 twice, as older builds wrote a run's last row: the resumed series has it once.
    for step in [0, 1, 1, 2, 3, 4] {
        s.append(&row(step, 2)).unwrap();
    }
    assert!(s.append(&row(5, 1)).is_err());
    drop(s);
    // A row cut short by a kill.
    let mut text = std::fs::read_to_string(&path).unwrap();
    text.push_str("5,0.5,1.2");
    std::fs::write(&path, &text).unwrap();

    let mut s = SeriesWriter::resume(&path, &walls, 2).unwrap();
    s.append(&row(3, 2)).unwrap();
    drop(s);
    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[0],
        "step,time,kinetic_translational,kinetic_rotational,potential_gravity,elastic,contacts,\
         wall_contacts,floor_fx,floor_fy,floor_fz,\"lid, top_fx\",\"lid, top_fy\",\"lid, top_fz\""
    );
    assert_eq!(lines.len(), 1 + 4);
    let steps: Vec<u64> = lines[1..]
        .iter()
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(steps, vec![0, 1, 2, 3]);
    for l in &lines[1..] {
        let c: Vec<&str> = l.split(',').collect();
        assert_eq!(c.len(), 14);
        let r = row(c[0].parse().unwrap(), 2);
        let f = |k: usize| c[k].parse::<f64>().unwrap().to_bits();
        assert_eq!(f(1), r.time.to_bits());
        assert_eq!(f(2), r.kinetic_translational.to_bits());
        assert_eq!(f(3), r.kinetic_rotational.to_bits());
        assert_eq!(f(4), r.potential_gravity.to_bits());
        assert_eq!(c[6].parse::<u64>().unwrap(), r.contacts);
        assert_eq!(f(12), r.wall_forces[1].y.to_bits());
    }
    // Another scene's walls: refused, naming the file.
    let e = SeriesWriter::resume(&path, &["floor".to_string()], 1)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("series.csv") && e.contains("header"), "{e}");
}

#[test]
fn empty_piece_reads_back() {
    let dir = scratch("empty");
    let (t, tt) = templates();
    let p = Particles::default();
    let fields = vec!["velocity".to_string()];
    let mut w = FrameWriter::new(&dir, 1).unwrap();
    w.write_frame(0, 0.0, &[view(&p, &t, &tt, 0, &fields)], &[])
        .unwrap();
    let m = oracle("mesh", &dir.join("frames/step_0000000000_r0000.vtu"));
    assert_eq!(m["points"].as_array().unwrap().len(), 0);
    let c = oracle("collection", &dir.join("frames.pvd"));
    assert_eq!(c["datasets"][0]["cells"], 0);
}

/// Size of a frame of 20-vertex dodecahedra with the fields (id, type, velocity,
/// angular velocity, force): a guard against accidental growth, printed for the record.
#[test]
fn dodecahedron_frame_size_per_particle() {
    let dir = scratch("size");
    let t = vec![Generator::Dodecahedron { size: 1.0 }.build().unwrap()];
    let tt = vec![0];
    let mut p = Particles::default();
    let n: u64 = 1000;
    for k in 0..n {
        let q = UnitQuaternion::from_euler_angles(0.1 * k as f64, 0.2, 0.3);
        let x = Vector3::new(k as f64, 0.5 * k as f64, 1.0);
        p.push(k, 0, 1.0, x, q, &t[0], 1000.0);
    }
    let fields: Vec<String> = ["velocity", "angular_velocity", "force"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let mut w = FrameWriter::new(&dir, 1).unwrap();
    w.write_frame(0, 0.0, &[view(&p, &t, &tt, 0, &fields)], &[])
        .unwrap();
    let vtu = std::fs::metadata(dir.join("frames/step_0000000000_r0000.vtu"))
        .unwrap()
        .len();
    let csv = dir.join("p.csv");
    write_particle_csv(&csv, 0.0, &view(&p, &t, &tt, 0, &fields)).unwrap();
    let csv = std::fs::metadata(&csv).unwrap().len();
    let ckpt = dir.join("c.ckpt");
    let c = Checkpoint {
        step: 0,
        time: 0.0,
        particles: p,
        history: ContactHistory::default(),
        rng_state: [0; 4],
        inserter: vec![],
        next_id: n,
        scene_hash: 0,
        extra: vec![],
    };
    write_checkpoint(&ckpt, &c).unwrap();
    let ckpt = std::fs::metadata(&ckpt).unwrap().len();
    let per = |b: u64| b as f64 / n as f64;
    println!(
        "bytes per 20-vertex dodecahedron: vtu {:.1}, particle csv {:.1}, checkpoint {:.1}",
        per(vtu),
        per(csv),
        per(ckpt)
    );
    // Raw: 480 (points) + 80 (connectivity) + 292 (faces) + 8 (offsets) + 1 (type)
    // + 8 + 4 + 72 (cell data) = 945 bytes, × 4/3 for base64.
    assert!(per(vtu) < 1400.0, "{} bytes per particle", per(vtu));
}

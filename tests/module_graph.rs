//! `scripts/module_graph.py`, which `make lint` (and so CI) runs to fail on an import cycle
//! between top-level modules: it must find a cycle where there is one, name the lines that
//! close it, and pass a layered tree. Python 3 (standard library only) must be on PATH.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

/// A crate tree under a fresh temporary folder: `files` as (path, contents).
fn tree(name: &str, files: &[(&str, &str)]) -> PathBuf {
    let root = std::env::temp_dir().join(format!("polydem-graph-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    for (path, text) in files {
        let p = root.join(path);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    }
    std::fs::create_dir_all(root.join("cuda")).unwrap();
    root
}

fn check(root: &Path) -> (i32, String) {
    let script = common::repo_root().join("scripts/module_graph.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg("--check")
        .arg("--root")
        .arg(root)
        .output()
        .expect("python3 runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_cycle_between_modules_fails_and_names_its_lines() {
    let root = tree(
        "cycle",
        &[
            ("src/lib.rs", "pub mod a;\npub mod b;\npub mod c;\n"),
            ("src/a/mod.rs", "mod inner;\n"),
            ("src/a/inner.rs", "//! a\n\nuse crate::b::X;\n"),
            ("src/b.rs", "use crate::{c::Z, geometry};\npub struct X;\n"),
            (
                "src/c.rs",
                "pub struct Z;\nfn f() { let _ = crate::a::inner::g; }\n",
            ),
        ],
    );
    let (code, report) = check(&root);
    assert_eq!(code, 1, "{report}");
    assert!(report.contains("a -> b: src/a/inner.rs:3"), "{report}");
    assert!(report.contains("b -> c: src/b.rs:1"), "{report}");
    assert!(report.contains("c -> a: src/c.rs:2"), "{report}");
    let _ = std::fs::remove_dir_all(root);
}

#[test]
fn a_layered_tree_passes() {
    let root = tree(
        "layered",
        &[
            ("src/lib.rs", "pub mod a;\npub mod b;\n"),
            (
                "src/a.rs",
                "use crate::b::X;\n/// See [`crate::b`] (a doc link is not an import).\npub struct Y;\n",
            ),
            ("src/b.rs", "//! Used by [`crate::a`].\npub struct X;\n"),
        ],
    );
    let (code, report) = check(&root);
    assert_eq!(code, 0, "{report}");
    let _ = std::fs::remove_dir_all(root);
}

#[test]
fn the_crate_has_no_cycle() {
    let (code, report) = check(&common::repo_root());
    assert_eq!(code, 0, "{report}");
}

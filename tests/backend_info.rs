//! `polydem info`: CUDA detection without panics, on machines with and without a GPU.

mod common;

use common::*;
use serde_json::Value;
use std::process::Command;

fn info() -> Value {
    let out = Command::new(polydem_bin())
        .arg("info")
        .output()
        .expect("run polydem info");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && !stderr.contains("panicked"),
        "polydem info failed: {stderr}"
    );
    serde_json::from_slice(&out.stdout).expect("JSON")
}

/// Without a GPU, detection explains why; with one, it lists it. Either way it never panics.
#[test]
fn info_reports_gpus_or_why_there_are_none() {
    let v = info();
    let gpus = v["gpus"].as_array().expect("gpus list");
    if gpus.is_empty() {
        assert!(
            v["unavailable"].as_str().is_some_and(|s| !s.is_empty()),
            "{v}"
        );
    } else {
        for g in gpus {
            assert!(g["name"].as_str().is_some_and(|s| !s.is_empty()), "{v}");
        }
    }
}

#[test]
#[ignore = "needs a CUDA GPU"]
fn info_lists_the_gpu_driver_and_nvrtc() {
    let v = info();
    println!("{v:#}");
    let gpus = v["gpus"].as_array().expect("gpus list");
    assert!(!gpus.is_empty(), "no GPU listed: {v}");
    let cc = gpus[0]["compute_capability"].as_array().unwrap();
    assert!(cc[0].as_i64().unwrap() >= 7, "compute capability {cc:?}");
    assert!(gpus[0]["total_memory"].as_u64().unwrap() > 1 << 30);
    assert!(
        v["driver_version"].is_string() && v["nvrtc_version"].is_string(),
        "{v}"
    );
    assert!(v["unavailable"].is_null(), "{v}");
}

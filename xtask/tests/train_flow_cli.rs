//! `cargo xtask train-flow` with rendered scene pairs (`--scene-pairs`, `--scene-validation`) on the
//! tiny checked-in fixture: a two-step run writes weights and reports the scene validation EPE, and
//! bad scene flags are refused with a message naming the flag or the directory.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;
use std::process::Command;

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data-fixtures/tiny")
}

fn train_flow(out: &std::path::Path, extra: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_xtask"))
        .arg("train-flow")
        .args([
            "--levels",
            "2",
            "--size",
            "16",
            "--pretrain-steps",
            "0",
            "--steps",
            "0",
            "--joint-steps",
            "2",
            "--joint-batch",
            "2",
            "--eval-pairs",
            "2",
            "--report-every",
            "0",
        ])
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

#[test]
fn scene_pairs_train_and_validate() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("w.safetensors");
    let scene = fixture().display().to_string();
    let o = train_flow(
        &out,
        &[
            "--scene-pairs",
            &scene,
            "--scene-fraction",
            "1",
            "--scene-validation",
            &scene,
        ],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    // The fixture has 15 frames, 14 with flow to the next: a blurred and a sharp pair each.
    assert!(err.contains("28 scene pairs from 1 scenes"), "{err}");
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let pairs = report["scene_validation_pairs"].as_u64().unwrap();
    assert!((1..=28).contains(&pairs), "{pairs} validation pairs");
    let (epe, zero) = (
        report["scene_validation_epe"].as_f64().unwrap(),
        report["scene_validation_zero_flow_epe"].as_f64().unwrap(),
    );
    // Validation counts moving pixels only (|flow| > 0.25 px at 16×16), so zero flow errs.
    assert!(epe.is_finite() && zero > 0.25, "epe {epe}, zero {zero}");
    assert!(flow::load_safetensors(&out).is_ok());
    // Without validation scenes the scene figures are null, not a made-up 0.
    let o = train_flow(&out, &["--scene-pairs", &scene]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(report["scene_validation_ratio"].is_null(), "{report}");
    assert_eq!(report["scene_validation_pairs"], 0);
}

#[test]
fn bad_scene_flags_are_refused_with_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("w.safetensors");
    let scene = fixture().display().to_string();
    for (args, expect) in [
        (
            vec!["--scene-pairs", scene.as_str(), "--scene-fraction", "1.5"],
            "--scene-fraction",
        ),
        (
            vec!["--scene-pairs", scene.as_str(), "--scene-static-weight=-1"],
            "--scene-static-weight",
        ),
        (
            vec!["--scene-pairs", "/nonexistent/scene"],
            "/nonexistent/scene",
        ),
        (
            vec!["--scene-validation", "/nonexistent/val"],
            "/nonexistent/val",
        ),
    ] {
        let o = train_flow(&out, &args);
        assert!(!o.status.success(), "{args:?} was accepted");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(expect), "{args:?}: {err}");
    }
    assert!(!out.exists(), "a refused run wrote weights");
}

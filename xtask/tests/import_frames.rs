//! `cargo xtask import frames` end to end on the tiny fixture's sharp frames and poses: the scene it
//! writes loads, holds what the flags asked for, and trains; count mismatches are refused naming
//! both counts.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data-fixtures/tiny")
}

fn xtask() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_xtask"));
    c.env("RUST_BACKTRACE", "0");
    c
}

/// The fixture's poses as a JSON list (the first `count`).
fn write_poses(path: &Path, count: usize) {
    let text = std::fs::read_to_string(fixture().join("scene.json")).unwrap();
    let s: serde_json::Value = serde_json::from_str(&text).unwrap();
    let list: Vec<serde_json::Value> = s["frames"]
        .as_array()
        .unwrap()
        .iter()
        .take(count)
        .map(|f| serde_json::json!({"pose": f["pose"], "transl": f["transl"]}))
        .collect();
    std::fs::write(path, serde_json::to_string(&list).unwrap()).unwrap();
}

fn import(out: &Path, poses: &Path, extra: &[&str]) -> Output {
    let fx = fixture();
    xtask()
        .args(["import", "frames", "--fps", "30", "--images"])
        .arg(fx.join("sharp"))
        .arg("--masks")
        .arg(fx.join("masks"))
        .arg("--camera")
        .arg(fx.join("scene.json"))
        .arg("--poses")
        .arg(poses)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

#[test]
fn frames_and_poses_become_a_scene_that_trains() {
    let dir = tempfile::tempdir().unwrap();
    let poses = dir.path().join("poses.json");
    write_poses(&poses, 15);
    // The frames as observations: 15 frames, the 7/3 split, the given exposure.
    let plain = dir.path().join("plain");
    let o = import(&plain, &poses, &["--exposure-s", "0.02"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = scene::load(&plain).unwrap();
    assert_eq!(s.frames.len(), 15);
    assert!((s.exposure_s - 0.02).abs() < 1e-12);
    assert_eq!(
        s.frames
            .iter()
            .filter(|f| f.split == scene::Split::Test)
            .count(),
        3
    );
    assert!(s
        .frames
        .iter()
        .all(|f| f.mask.is_some() && f.sharp.is_none()));
    // The ZJU-MoCap-Blur recipe: windows of 3, events simulated.
    let blurred = dir.path().join("blurred");
    let o = import(&blurred, &poses, &["--blur", "3", "--events", "simulate"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = scene::load(&blurred).unwrap();
    assert_eq!(s.frames.len(), 5);
    assert!((s.exposure_s - 0.1).abs() < 1e-12);
    assert!(s
        .frames
        .iter()
        .all(|f| f.sharp.is_some() && f.events.is_some()));
    // It trains (exposure model + event loss, the default) for a few steps.
    let config = dir.path().join("tiny.toml");
    std::fs::write(
        &config,
        "steps = 4\nhuman_gaussians = 200\nscene_gaussians = 400\nmax_gaussians = 2000\n\
         deform_hidden = 16\nskinning_until = 4\nskinning_samples = 32\nnonrigid_from = 2\n\
         densify_from = 8\ndensify_until = 8\n",
    )
    .unwrap();
    let run = dir.path().join("run");
    let o = xtask()
        .arg("reconstruct")
        .arg("--data")
        .arg(&blurred)
        .arg("--out")
        .arg(&run)
        .arg("--config")
        .arg(&config)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("event loss: "), "{out}");
    assert!(run.join("model").is_dir());
}

#[test]
fn mismatched_counts_and_settings_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let poses = dir.path().join("poses.json");
    write_poses(&poses, 14);
    let o = import(&dir.path().join("a"), &poses, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("14 poses") && err.contains("15 frames"),
        "{err}"
    );
    write_poses(&poses, 15);
    let o = import(&dir.path().join("b"), &poses, &["--blur", "4"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("blur"), "{err}");
    let o = import(
        &dir.path().join("c"),
        &poses,
        &["--blur", "3", "--exposure-s", "0.01"],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("exposure_s"), "{err}");
    assert!(!dir.path().join("a").join("scene.json").exists());
}

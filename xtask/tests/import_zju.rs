//! `cargo xtask import zju` on a ZJU-MoCap-layout subject made from the tiny fixture (JPEG frames,
//! PNG masks, `cam_params.json` in OpenCV's pixel convention, `models/*.npz` fits): the scene it
//! writes has the camera in the scene's convention, the fits' poses, the blur windows and events
//! asked for, and trains; a missing view is refused by name.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

fn subject() -> PathBuf {
    common::import_fixtures().join("zju/CoreView_tiny")
}

fn xtask() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_xtask"));
    c.env("RUST_BACKTRACE", "0");
    c
}

fn import(root: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    xtask()
        .args([
            "import",
            "zju",
            "--body",
            "builtin:makehuman",
            "--fps",
            "30",
            "--root",
        ])
        .arg(root)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

#[test]
fn a_zju_subject_becomes_a_blurred_scene_with_events_that_trains() {
    let dir = tempfile::tempdir().unwrap();
    let tiny = common::tiny();
    let out = dir.path().join("scene");
    let o = import(&subject(), &out, &["--blur", "3", "--events", "simulate"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = scene::load(&out).unwrap();
    assert_eq!(s.frames.len(), 5);
    assert_eq!(
        s.camera, tiny.camera,
        "the camera comes back in the scene's convention"
    );
    for (j, f) in s.frames.iter().enumerate() {
        let centre = &tiny.frames[3 * j + 1];
        assert_eq!(f.pose, centre.pose, "frame {j}");
        assert_eq!(f.transl, centre.transl, "frame {j}");
        assert!(f.sharp.is_some() && f.events.is_some() && f.mask.is_some());
    }
    // It trains for a few steps.
    common::reconstruct(
        &out,
        &dir.path().join("run"),
        &common::tiny_config(dir.path()),
    );
}

#[test]
fn a_distorting_lens_changes_the_frames_and_a_missing_view_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let (plain, bent) = (dir.path().join("plain"), dir.path().join("bent"));
    let o = import(&subject(), &bent, &["--max-frames", "2"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    common::write_subject(&dir.path().join("flat"), [0.0; 5]);
    let o = import(&dir.path().join("flat"), &plain, &["--max-frames", "2"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let read = |d: &Path| {
        let s = scene::load(d).unwrap();
        scene::read_rgb(&d.join(&s.frames[0].image), s.images)
            .unwrap()
            .data
    };
    let (a, b) = (read(&plain), read(&bent));
    let differ = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| (*x - *y).abs() > 0.02)
        .count();
    assert!(
        differ > a.len() / 20,
        "{differ} of {} values moved",
        a.len()
    );
    let o = import(&subject(), &dir.path().join("x"), &["--view", "7"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("7"), "{err}");
    // Distortion coefficients that are not 5 are refused naming the file and the field.
    let root = dir.path().join("flat");
    let cams = root.join("cam_params.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&cams).unwrap()).unwrap();
    v["1"]["D"] = serde_json::json!([-0.3, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    std::fs::write(&cams, v.to_string()).unwrap();
    let o = import(&root, &dir.path().join("y"), &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("cam_params.json") && err.contains("`1`.D"),
        "{err}"
    );
}

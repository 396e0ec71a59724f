//! `eval --align-test-cameras N` on a model of the tiny fixture: every scored frame's camera is
//! aligned to its observed frame first, and `metrics.json` reports each alignment's twist and
//! losses.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;

#[test]
fn aligned_cameras_report_every_frames_twist_and_never_raise_their_loss() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    reconstruct(&fixture(), &run, &tiny_config(dir.path()));
    let out = dir.path().join("aligned");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_xtask"))
        .arg("eval")
        .arg("--model")
        .arg(run.join("model"))
        .arg("--data")
        .arg(fixture())
        .args(["--align-test-cameras", "2", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["camera_alignment_steps"], 2);
    let test_frames = tiny()
        .frames
        .iter()
        .filter(|f| f.split == scene::Split::Test)
        .count();
    let per_frame = metrics["per_frame"].as_array().unwrap();
    assert!(test_frames > 0);
    assert_eq!(per_frame.len(), test_frames);
    for entry in per_frame {
        let a = &entry["camera_alignment"];
        let twist = a["twist"].as_array().unwrap();
        assert_eq!(twist.len(), 6, "{a}");
        assert!(twist.iter().all(|v| v.as_f64().unwrap().is_finite()));
        assert!(a["loss_after"].as_f64().unwrap() <= a["loss_before"].as_f64().unwrap());
    }
}

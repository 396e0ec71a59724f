//! The README's study commands on tiny inputs, to success, checking what they wrote:
//! `reconstruct --pose-correction on` on a scene with estimated poses (and its pose report),
//! `reconstruct --camera-correction on` on a hand-held scene with estimated cameras (and its
//! camera report, also from `eval`),
//! `bench step` from that run's checkpoint, and `ablate --blur-levels` on the slow, medium and fast
//! variants of the tiny benchmark.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

fn xtask() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_xtask"));
    c.env("RUST_BACKTRACE", "0");
    c
}

/// Runs `command`, asserts success, returns its standard output.
fn run(command: &mut Command) -> String {
    let o = command.output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn camera_correction_trains_on_estimated_cameras_and_reports_their_error() {
    let dir = tempfile::tempdir().unwrap();
    let scene: PathBuf = dir.path().join("scene");
    run(xtask()
        .args(["synth", "--preset", "tiny", "--camera-motion", "handheld"])
        .args([
            "--camera-error-deg",
            "0.5",
            "--camera-error-cm",
            "1",
            "--out",
        ])
        .arg(&scene));
    assert!(scene.join("cameras_true.json").is_file());
    let out = dir.path().join("run");
    let stdout = run(xtask()
        .args(["reconstruct", "--camera-correction", "on"])
        .args(["--camera-correction-from", "0", "--data"])
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .arg("--config")
        .arg(common::tiny_config(dir.path())));
    assert!(
        stdout.contains("camera correction: each training frame's camera"),
        "{stdout}"
    );
    let line = stdout
        .lines()
        .find(|l| l.starts_with("camera error (RMS rotation / centre"))
        .unwrap_or_else(|| panic!("no camera report:\n{stdout}"));
    assert!(
        line.contains(" → ") && line.contains("held-out frames"),
        "{line}"
    );
    let metrics = json(&out.join("metrics.json"));
    let report = &metrics["camera_error"];
    let figure = |part: &str, what: &str| report[part][what].as_f64().unwrap();
    // 0.5° and 1 cm RMS over all frames as generated; the training frames' share is near that.
    let (deg, cm) = (
        figure("train_given", "rotation_rms_deg"),
        figure("train_given", "centre_rms_cm"),
    );
    assert!(deg > 0.2 && deg < 1.0 && cm > 0.4 && cm < 2.0, "{report}");
    // Four steps of correction move the cameras, but not far.
    let corrected = figure("train_corrected", "rotation_rms_deg");
    assert!(
        corrected != deg && (corrected - deg).abs() < 0.3,
        "{report}"
    );
    assert!(figure("test_corrected", "centre_rms_cm") > 0.0);
    // `eval` of the saved model reports the same errors.
    let eval_out = dir.path().join("eval");
    let stdout = run(xtask()
        .args(["eval", "--model"])
        .arg(out.join("model"))
        .arg("--data")
        .arg(&scene)
        .arg("--out")
        .arg(&eval_out));
    assert!(stdout.lines().any(|l| l == line), "{stdout}");
    assert_eq!(
        json(&eval_out.join("metrics.json"))["camera_error"],
        *report
    );
}

#[test]
fn pose_correction_trains_on_estimated_poses_and_reports_their_error() {
    let dir = tempfile::tempdir().unwrap();
    let scene: PathBuf = dir.path().join("scene");
    run(xtask()
        .args(["synth", "--preset", "tiny", "--pose-error", "16", "--out"])
        .arg(&scene));
    assert!(scene.join("poses_true.json").is_file());
    let out = dir.path().join("run");
    let stdout = run(xtask()
        .args(["reconstruct", "--pose-correction", "on", "--data"])
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .arg("--config")
        .arg(common::tiny_config(dir.path())));
    let line = stdout
        .lines()
        .find(|l| l.starts_with("pose error of the training frames"))
        .unwrap_or_else(|| panic!("no pose report:\n{stdout}"));
    assert!(
        line.contains(" → ") && line.contains("held-out frames"),
        "{line}"
    );
    let metrics = json(&out.join("metrics.json"));
    let report = &metrics["pose_error"];
    let given = report["given"]["joint_mean_deg"].as_f64().unwrap();
    let corrected = report["corrected"]["joint_mean_deg"].as_f64().unwrap();
    // 16° RMS per joint as generated; a few steps of correction move it, but not far.
    assert!(given > 5.0 && given < 30.0, "{given}");
    assert!((corrected - given).abs() < 5.0, "{given} → {corrected}");
    assert!(report["view"]["test_given"]["image_px"].as_f64().unwrap() > 0.0);

    // The step's breakdown from the run's checkpoint: every stage measured, the total their sum.
    let line = run(xtask()
        .args(["bench", "step", "--steps", "2", "--run"])
        .arg(&out)
        .arg("--data")
        .arg(&scene));
    let bench: serde_json::Value = serde_json::from_str(line.lines().last().unwrap()).unwrap();
    assert_eq!(bench["checkpoint_step"].as_u64(), Some(4), "{bench}");
    assert_eq!(
        bench["gaussians"].as_u64(),
        metrics["gaussians_human"]
            .as_u64()
            .zip(metrics["gaussians_scene"].as_u64())
            .map(|(h, s)| h + s)
    );
    let total = bench["total_ms"].as_f64().unwrap();
    assert!(
        total > 0.0 && bench["render_ms"].as_f64().unwrap() > 0.0,
        "{bench}"
    );
    // A preset names a default run, so it cannot be given with the run.
    let refused = xtask()
        .args(["bench", "step", "--preset", "full", "--run"])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success() && stderr.contains("cannot be used with"),
        "{stderr}"
    );
}

#[test]
fn the_blur_level_study_runs_on_the_slow_medium_and_fast_variants() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("study");
    run(xtask()
        .args(["ablate", "--blur-levels", "--blur-levels-preset", "tiny"])
        .args(["--only", "one-hot", "--out"])
        .arg(&out)
        .arg("--config")
        .arg(common::tiny_config(dir.path())));
    let rows = json(&out.join("ablation.json"));
    let rows = rows.as_array().unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r["run"].as_str().unwrap()).collect();
    assert_eq!(names, ["slow/one-hot", "medium/one-hot", "fast/one-hot"]);
    // The input frames blur more as the motion speeds up.
    let blurred: Vec<f64> = rows
        .iter()
        .map(|r| r["metrics"]["blurred_psnr_full"].as_f64().unwrap())
        .collect();
    assert!(
        blurred[0] > blurred[1] && blurred[1] > blurred[2],
        "{blurred:?}"
    );
    let md = std::fs::read_to_string(out.join("ablation.md")).unwrap();
    assert!(md.contains("| 3 | `fast/one-hot` |"), "{md}");
    assert!(out.join("ablation_grid.png").is_file());
}

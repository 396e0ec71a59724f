//! `cargo xtask import aedat4` on the committed DAVIS-like recording (`data-fixtures/import/davis`:
//! grey frames with their own exposures and events in one AEDAT 4 file, plus one pose per frame).
//! The scene it writes loads, has exactly the file's exposure times and frame pixels, puts every
//! event after the first frame's time in exactly one frame's file, and trains; a pose count that
//! differs is refused naming both counts.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

use common::fixture;

fn xtask() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_xtask"));
    c.env("RUST_BACKTRACE", "0");
    c
}

fn recording() -> PathBuf {
    common::import_fixtures().join("davis/rec.aedat4")
}

fn import(poses: &Path, out: &Path) -> std::process::Output {
    xtask()
        .args(["import", "aedat4", "--file"])
        .arg(recording())
        .arg("--poses")
        .arg(poses)
        .arg("--camera")
        .arg(fixture().join("scene.json"))
        .arg("--masks")
        .arg(fixture().join("masks"))
        .arg("--out")
        .arg(out)
        .output()
        .unwrap()
}

#[test]
fn a_davis_recording_becomes_a_grey_scene_with_its_exposures_and_events_that_trains() {
    let dir = tempfile::tempdir().unwrap();
    let (frames, _) = events::io::aedat4_frames::read_aedat4_frames(recording()).unwrap();
    let all = events::read_events(recording()).unwrap();
    let first_mid =
        frames[0].exposure_begin_us + (frames[0].exposure_end_us - frames[0].exposure_begin_us) / 2;
    let after = all.t.iter().filter(|&&t| t >= first_mid).count();
    let out = dir.path().join("scene");
    let o = import(&common::import_fixtures().join("davis/poses.json"), &out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = scene::load(&out).unwrap();
    assert_eq!(s.frames.len(), 15);
    assert!(s.images.is_grey());
    assert!((s.exposure_s - 0.032).abs() < 1e-9, "{}", s.exposure_s);
    assert_eq!(s.frames[3].exposure_s, Some(0.016));
    assert_eq!(s.frames[5].exposure_s, None);
    assert_eq!(
        s.frames[0].time_s, 0.016,
        "time 0 is the first exposure's start"
    );
    let mut total = 0;
    for (k, f) in s.frames.iter().enumerate() {
        let ev = events::read_events(out.join(f.events.as_ref().unwrap())).unwrap();
        let from = (f.time_s * 1e6).round() as i64;
        let to = s
            .frames
            .get(k + 1)
            .map_or(i64::MAX, |g| (g.time_s * 1e6).round() as i64);
        assert!(ev.t.iter().all(|&t| t >= from && t < to), "frame {k}");
        total += ev.len();
    }
    assert_eq!(total, after);
    println!(
        "{} frames, exposures {:?} µs; {total} of {} events in the frames' files",
        frames.len(),
        frames
            .iter()
            .map(|f| f.exposure_end_us - f.exposure_begin_us)
            .collect::<Vec<_>>(),
        all.len()
    );
    // Exactly the file's exposures and pixels.
    for (k, (f, g)) in s.frames.iter().zip(&frames).enumerate() {
        let e = (g.exposure_end_us - g.exposure_begin_us) as f64 * 1e-6;
        assert!((s.exposure_of(k) - e).abs() < 1e-12, "frame {k}");
        let img = scene::read_rgb(&out.join(&f.image), s.images).unwrap();
        let stored: Vec<f32> = g.pixels.iter().map(|&p| f32::from(p) / 255.0).collect();
        assert_eq!(img.data[..stored.len()], stored[..], "frame {k}");
    }
    // It trains: the exposure model over each frame's own exposure, with the event loss.
    let run = dir.path().join("run");
    let stdout = common::reconstruct(&out, &run, &common::tiny_config(dir.path()));
    assert!(stdout.contains("16.0–32.0 ms exposure"), "{stdout}");
    assert!(stdout.contains("event loss: "), "{stdout}");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["test_frames"].as_u64(), Some(3));
    assert!(metrics["test_psnr_full"].as_f64().unwrap().is_finite());
    // The report says what was imported.
    let html = std::fs::read_to_string(run.join("report.html")).unwrap();
    for needle in [
        "<h2>Data</h2>",
        "xtask import aedat4",
        "grey",
        "2 frames with their own exposure",
        "15 frames with events",
    ] {
        assert!(html.contains(needle), "report lacks {needle}");
    }
}

#[test]
fn a_pose_count_that_differs_is_refused_naming_both() {
    let dir = tempfile::tempdir().unwrap();
    let poses = dir.path().join("poses.json");
    common::write_poses(&poses, 12);
    let o = import(&poses, &dir.path().join("scene"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("12 poses") && err.contains("15 frames"),
        "{err}"
    );
}

#[test]
fn poses_at_their_own_times_are_interpolated_to_the_frames() {
    let dir = tempfile::tempdir().unwrap();
    let (frames, _) = events::io::aedat4_frames::read_aedat4_frames(recording()).unwrap();
    let tiny = common::tiny();
    // Poses stamped with the frames' exposure midpoints: the spline passes through them.
    let stamped = |shift: i64| -> Vec<serde_json::Value> {
        tiny.frames
            .iter()
            .zip(&frames)
            .map(|(f, g)| {
                let mid = g.exposure_begin_us + (g.exposure_end_us - g.exposure_begin_us) / 2;
                serde_json::json!({"pose": f.pose, "transl": f.transl, "t_us": mid + shift})
            })
            .collect()
    };
    let poses = dir.path().join("timed.json");
    std::fs::write(&poses, serde_json::to_string(&stamped(0)).unwrap()).unwrap();
    let out = dir.path().join("scene");
    let o = import(&poses, &out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = scene::load(&out).unwrap();
    for (f, t) in s.frames.iter().zip(&tiny.frames) {
        for (a, b) in f.transl.iter().zip(&t.transl) {
            assert!((a - b).abs() < 1e-5, "frame {}: {a} vs {b}", f.index);
        }
    }
    // Poses that do not cover the frames are refused, naming the frame.
    std::fs::write(&poses, serde_json::to_string(&stamped(1_000_000)).unwrap()).unwrap();
    let o = import(&poses, &dir.path().join("late"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("frame 0's exposure midpoint"),
        "{err}"
    );
}

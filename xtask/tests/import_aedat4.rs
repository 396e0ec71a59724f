//! `cargo xtask import aedat4` on a DAVIS-like recording made from the tiny fixture: grey frames
//! with their own exposures and the fixture's events in one AEDAT 4 file, plus one pose per frame.
//! The scene it writes loads, keeps each frame's exposure and every event after the first frame's
//! time, and trains; a pose count that differs is refused naming both counts.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

use events::io::aedat4::Compression;
use events::io::aedat4_frames::{write_aedat4_with_frames, ApsFrame, FrameFormat};

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data-fixtures/tiny")
}

fn xtask() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_xtask"));
    c.env("RUST_BACKTRACE", "0");
    c
}

/// Writes `rec.aedat4` (grey frames of the fixture's observed images, exposures shortened on
/// frames 3 and 4, the fixture's events) and `poses.json` (the first `poses` poses); returns the
/// number of events after the first frame's exposure midpoint.
fn write_recording(dir: &Path, poses: usize) -> usize {
    let fx = fixture();
    let tiny: scene::Scene =
        serde_json::from_str(&std::fs::read_to_string(fx.join("scene.json")).unwrap()).unwrap();
    let (w, h) = (tiny.camera.width, tiny.camera.height);
    let n = (w * h) as usize;
    let us = |t: f64| (t * 1e6).round() as i64;
    let t_base = 2_000_000; // a device clock that does not start at 0
    let mut frames = Vec::new();
    let mut all = events::EventStream::new();
    for (k, f) in tiny.frames.iter().enumerate() {
        let rgb = scene::read_rgb(&fx.join(&f.image), tiny.images).unwrap();
        let y = scene::image_io::luminance(&rgb.data, n);
        let half = if k == 3 || k == 4 { 8_000 } else { 16_000 };
        let mid = t_base + us(f.time_s);
        frames.push(ApsFrame {
            t_us: mid,
            exposure_begin_us: mid - half,
            exposure_end_us: mid + half,
            format: FrameFormat::Gray,
            width: w,
            height: h,
            offset_x: 0,
            offset_y: 0,
            pixels: y
                .iter()
                .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
                .collect(),
        });
        let mut ev = events::read_events(fx.join(f.events.as_ref().unwrap())).unwrap();
        ev.t.iter_mut().for_each(|t| *t += t_base);
        all.extend_from(&ev.as_slice());
    }
    let first_mid = frames[0].t_us;
    let after = all.t.iter().filter(|&&t| t >= first_mid).count();
    write_aedat4_with_frames(
        dir.join("rec.aedat4"),
        &all,
        &frames,
        events::SensorSize::new(w, h),
        Compression::Lz4,
    )
    .unwrap();
    let list: Vec<serde_json::Value> = tiny
        .frames
        .iter()
        .take(poses)
        .map(|f| serde_json::json!({"pose": f.pose, "transl": f.transl}))
        .collect();
    std::fs::write(
        dir.join("poses.json"),
        serde_json::to_string(&list).unwrap(),
    )
    .unwrap();
    after
}

fn import(dir: &Path, out: &Path) -> std::process::Output {
    xtask()
        .args(["import", "aedat4", "--file"])
        .arg(dir.join("rec.aedat4"))
        .arg("--poses")
        .arg(dir.join("poses.json"))
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
    let after = write_recording(dir.path(), 15);
    let out = dir.path().join("scene");
    let o = import(dir.path(), &out);
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
    // It trains: the exposure model over each frame's own exposure, with the event loss.
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
        .arg(&out)
        .arg("--out")
        .arg(&run)
        .arg("--config")
        .arg(&config)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
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
    write_recording(dir.path(), 12);
    let o = import(dir.path(), &dir.path().join("scene"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("12 poses") && err.contains("15 frames"),
        "{err}"
    );
}

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

/// SHA3-224 of bytes, as the reference decoder's tests record them.
fn sha3_224(bytes: &[u8]) -> String {
    use sha3::Digest;
    sha3::Sha3_224::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

#[test]
fn a_real_davis_recording_decodes_as_the_reference_decoder_does_and_imports_exactly() {
    // data-fixtures/import/davis-real/test_data.aedat4: a DAVIS346 recording shipped (MIT) with
    // the PyPI package `aedat` 2.3.0, whose tests record its decoding as SHA3-224 digests of the
    // events' fields (t as u64, x, y as u16, on as a byte, little-endian) and of the frames' pixels.
    let file = common::import_fixtures().join("davis-real/test_data.aedat4");
    let (frames, sensor) = events::io::aedat4_frames::read_aedat4_frames(&file).unwrap();
    let all = events::read_events(&file).unwrap();
    assert_eq!(sensor, Some(events::SensorSize::new(346, 260)));
    let pixels: Vec<u8> = frames
        .iter()
        .flat_map(|f| f.pixels.iter().copied())
        .collect();
    let field = |f: &dyn Fn(usize) -> Vec<u8>| -> String {
        sha3_224(&(0..all.len()).flat_map(f).collect::<Vec<u8>>())
    };
    assert_eq!(
        field(&|i| (all.t[i] as u64).to_le_bytes().to_vec()),
        "f1e093cad5afb6ecb971dfa2ef7646ab4ae0f467f73a48804e40bb68"
    );
    assert_eq!(
        field(&|i| all.x[i].to_le_bytes().to_vec()),
        "1d8ea97b0febadfde24dd0b9e608682fc6934fc88656823b15f0e7a7"
    );
    assert_eq!(
        field(&|i| all.y[i].to_le_bytes().to_vec()),
        "18f89da35f8f10b24c3407b03aa7f82bdd7c8e6ab5369e2c30f8bad0"
    );
    assert_eq!(
        field(&|i| vec![u8::from(all.p[i] > 0)]),
        "6f99cf01187da8a05e1a032f3782de51b87e51bdc31356669bdd7cb9"
    );
    assert_eq!(
        sha3_224(&pixels),
        "6dbd0c0ea251788515bce54edf50b9f29d1995a0330a8b623504379b"
    );
    assert_eq!((frames.len(), all.len()), (59, 78_830));

    // Imported with one (made-up) pose per frame and a pinhole camera of the sensor's size.
    let dir = tempfile::tempdir().unwrap();
    let tiny = common::tiny();
    let list: Vec<serde_json::Value> = (0..frames.len())
        .map(|k| {
            let f = &tiny.frames[k % tiny.frames.len()];
            serde_json::json!({"pose": f.pose, "transl": [0.0, 0.0, 3.0]})
        })
        .collect();
    let poses = dir.path().join("poses.json");
    std::fs::write(&poses, serde_json::to_string(&list).unwrap()).unwrap();
    let camera = dir.path().join("camera.json");
    std::fs::write(
        &camera,
        r#"{"width": 346, "height": 260, "fx": 280.0, "fy": 280.0, "cx": 173.0, "cy": 130.0,
            "world_to_camera": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}"#,
    )
    .unwrap();
    let out = dir.path().join("scene");
    let o = xtask()
        .args(["import", "aedat4", "--file"])
        .arg(&file)
        .arg("--poses")
        .arg(&poses)
        .arg("--camera")
        .arg(&camera)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = scene::load(&out).unwrap();
    assert_eq!(s.frames.len(), 59);
    let first_mid =
        frames[0].exposure_begin_us + (frames[0].exposure_end_us - frames[0].exposure_begin_us) / 2;
    let mut in_files = 0;
    for (k, (f, g)) in s.frames.iter().zip(&frames).enumerate() {
        // The file's own exposure and pixels, exactly.
        let e = (g.exposure_end_us - g.exposure_begin_us) as f64 * 1e-6;
        assert!((s.exposure_of(k) - e).abs() < 1e-12, "frame {k}");
        let mid = g.exposure_begin_us + (g.exposure_end_us - g.exposure_begin_us) / 2;
        assert_eq!(
            (f.time_s * 1e6).round() as i64,
            mid - frames[0].exposure_begin_us,
            "frame {k}"
        );
        let img = scene::read_rgb(&out.join(&f.image), s.images).unwrap();
        let stored: Vec<f32> = g.pixels.iter().map(|&p| f32::from(p) / 255.0).collect();
        assert_eq!(img.data[..stored.len()], stored[..], "frame {k}");
        in_files += events::read_events(out.join(f.events.as_ref().unwrap()))
            .unwrap()
            .len();
    }
    let after = all.t.iter().filter(|&&t| t >= first_mid).count();
    assert_eq!(
        in_files, after,
        "every event after the first frame's time in one file"
    );
    println!(
        "real DAVIS346 recording: {} frames, exposure {} µs, {} events, {after} after the first frame's midpoint, {in_files} in the frames' files",
        frames.len(),
        frames[0].exposure_end_us - frames[0].exposure_begin_us,
        all.len()
    );
    common::reconstruct(
        &out,
        &dir.path().join("run"),
        &common::tiny_config(dir.path()),
    );
}

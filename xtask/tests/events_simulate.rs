#![allow(clippy::unwrap_used)]
//! `cargo xtask events simulate` end to end through the binary: a directory of PNG frames in, an
//! event file out, with the analytic event count of a brightening step (σ = 0) and `events info`
//! reading the result back.

use std::process::Command;

fn xtask(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn simulate_turns_png_frames_into_the_expected_events() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = tmp.path().join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    let (w, h) = (8u32, 4u32);
    // Linear grey 0.2 everywhere; from frame 1 on, the right half is brighter by a log step of
    // ln((0.2·e^0.5 + 1e-3)/(0.2 + 1e-3)) ≈ 0.498: with C = 0.2 and σ = 0 that crosses 0.2 and 0.4,
    // two positive events per right-half pixel, all between frame 0 and frame 1.
    let dark = (0.2f64 * 65535.0).round() as u16;
    let bright = (0.2f64 * 0.5f64.exp() * 65535.0).round() as u16;
    for k in 0..3 {
        let img = image::ImageBuffer::from_fn(w, h, |x, _| {
            image::Luma([if k > 0 && x >= w / 2 { bright } else { dark }])
        });
        img.save(frames.join(format!("{k:03}.png"))).unwrap();
    }
    let out = tmp.path().join("events.npz");
    let o = xtask(&[
        "events",
        "simulate",
        frames.to_str().unwrap(),
        out.to_str().unwrap(),
        "--fps",
        "100",
        "--threshold",
        "0.2",
        "--sigma",
        "0",
    ]);
    assert!(
        o.status.success(),
        "simulate failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let s = events::read_events(&out).unwrap();
    let expected = 2 * (w / 2) as usize * h as usize;
    assert_eq!(s.len(), expected, "event count");
    for i in 0..s.len() {
        let e = s.get(i);
        assert!(
            e.x >= (w / 2) as u16,
            "event at x = {} on the unchanged half",
            e.x
        );
        assert_eq!(e.p, 1, "polarity");
        // Between frame 0 (t = 0) and frame 1 (t = 10 000 µs), linearly interpolated.
        assert!(e.t > 0 && e.t <= 10_000, "t = {} µs", e.t);
    }
    // `events info` reads it back as one JSON line.
    let o = xtask(&["events", "info", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let line = String::from_utf8_lossy(&o.stdout);
    let v: serde_json::Value = serde_json::from_str(line.trim()).unwrap();
    assert_eq!(v["events"], expected);
    assert_eq!(v["positive"], expected);
}

#[test]
fn simulate_refuses_a_directory_with_fewer_than_two_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("events.npz");
    let o = xtask(&[
        "events",
        "simulate",
        tmp.path().to_str().unwrap(),
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("need at least 2"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

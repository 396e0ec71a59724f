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

#[test]
fn convert_records_the_sensor_size_given_and_refuses_one_the_events_do_not_fit() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("events.npz");
    let mut s = events::EventStream::new();
    for (k, (x, y)) in [(0u16, 0u16), (5, 2), (9, 3)].into_iter().enumerate() {
        s.push(events::Event {
            t: 10 * k as i64,
            x,
            y,
            p: 1,
        });
    }
    events::write_events(&input, &s).unwrap();
    let info = |path: &std::path::Path| -> serde_json::Value {
        let o = xtask(&["events", "info", path.to_str().unwrap()]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_str(String::from_utf8_lossy(&o.stdout).trim()).unwrap()
    };
    // Without --sensor the AEDAT 4 file states the events' bounding box; with it, the given size.
    let bounding = tmp.path().join("bounding.aedat4");
    let o = xtask(&[
        "events",
        "convert",
        input.to_str().unwrap(),
        bounding.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = info(&bounding);
    assert_eq!(
        (v["width"].clone(), v["height"].clone()),
        (10.into(), 4.into())
    );
    let given = tmp.path().join("given.aedat4");
    let o = xtask(&[
        "events",
        "convert",
        input.to_str().unwrap(),
        given.to_str().unwrap(),
        "--sensor",
        "64x48",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = info(&given);
    assert_eq!(
        (v["width"].clone(), v["height"].clone()),
        (64.into(), 48.into())
    );
    assert_eq!(v["events"], 3);
    // An event at x = 9 does not fit an 8-pixel-wide sensor: a clear error, no file.
    let small = tmp.path().join("small.aedat4");
    let o = xtask(&[
        "events",
        "convert",
        input.to_str().unwrap(),
        small.to_str().unwrap(),
        "--sensor",
        "8x48",
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("outside the 8x48 sensor"), "{err}");
    assert!(!small.exists());
}

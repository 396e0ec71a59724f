#![allow(clippy::unwrap_used)]
//! `cargo xtask synth` end to end on a tiny configuration (writes `scene.json`, `preview.png`,
//! `stats.json` and the per-frame files), and its refusal of bad knobs with a message naming the
//! knob, through the real binary.

use std::path::Path;
use std::process::{Command, Output};

fn xtask(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(args)
        .env("RAYON_NUM_THREADS", "2")
        .output()
        .unwrap()
}

/// `synth` on the tiny preset cut to 3 frames of 32×24 with S = 2, with `set` replacing flag values.
fn tiny_args(out: &Path, set: &[(&str, &str)]) -> Vec<String> {
    let mut flags = vec![
        ("--preset", "tiny"),
        ("--frames", "3"),
        ("--width", "32"),
        ("--height", "24"),
        ("--subframes", "2"),
        ("--supersample", "1"),
    ];
    for &(f, v) in set {
        match flags.iter_mut().find(|(g, _)| *g == f) {
            Some(slot) => slot.1 = v,
            None => flags.push((f, v)),
        }
    }
    let mut args = vec!["synth".to_string()];
    for (f, v) in flags {
        args.extend([f.to_string(), v.to_string()]);
    }
    args.extend(["--out".to_string(), out.to_string_lossy().into_owned()]);
    args
}

#[test]
fn synth_writes_a_complete_scene_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("scene");
    let args = tiny_args(&out, &[]);
    let o = xtask(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "xtask synth failed: {}\n{stdout}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("blurred vs sharp PSNR"), "{stdout}");
    for f in ["scene.json", "preview.png", "stats.json"] {
        let p = out.join(f);
        assert!(
            std::fs::metadata(&p).unwrap().len() > 0,
            "{} is empty",
            p.display()
        );
    }
    let scene: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("scene.json")).unwrap()).unwrap();
    let frames = scene["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 3);
    for fr in frames {
        let img = fr["image"].as_str().unwrap();
        assert!(out.join(img).is_file(), "missing {img}");
    }
    for k in 0..3 {
        assert!(out.join(format!("images/{k:06}.png")).is_file());
        assert!(out.join(format!("sharp/{k:06}.png")).is_file());
        assert!(out.join(format!("masks/{k:06}.png")).is_file());
        assert!(out.join(format!("events/{k:06}.npz")).is_file());
    }
    for k in 0..2 {
        assert!(out.join(format!("flow/{k:06}.flo")).is_file());
    }
    let stats: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("stats.json")).unwrap()).unwrap();
    assert_eq!(stats["config"]["frames"], 3);
    assert_eq!(stats["config"]["width"], 32);
    assert_eq!(stats["flow"]["pairs"], 2);
    // The preview is a decodable PNG.
    let png = image::open(out.join("preview.png")).unwrap();
    assert!(png.width() > 32 && png.height() > 24);
    // The completeness stamp `reconstruct` checks: generator version and these settings.
    let stamp = std::fs::read_to_string(out.join(".complete")).unwrap();
    assert!(stamp.starts_with("generator "), "{stamp}");
    assert!(stamp.contains("\"frames\":3"), "{stamp}");
}

#[test]
fn synth_refuses_bad_knobs_with_a_message() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("refused");
    for (flag, value, knob) in [
        ("--frames", "0", "frames"),
        ("--subframes", "0", "subframes"),
        ("--width", "8193", "width"),
        ("--height", "9000", "height"),
    ] {
        let args = tiny_args(&out, &[(flag, value)]);
        let o = xtask(&args.iter().map(String::as_str).collect::<Vec<_>>());
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{flag} {value} was accepted");
        assert!(
            stderr.contains(&format!("invalid setting {knob} = {value}")),
            "{flag} {value}: unexpected message: {stderr}"
        );
        assert!(
            !out.join("scene.json").exists(),
            "{flag} {value}: wrote output before refusing"
        );
    }
}

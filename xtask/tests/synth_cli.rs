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

fn files(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

fn run_ok(args: &[String]) -> String {
    let o = xtask(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "xtask {args:?} failed: {}\n{stdout}",
        String::from_utf8_lossy(&o.stderr)
    );
    stdout
}

/// `--pose-error 0` is the benchmark without the flag, byte for byte (stamp included); a non-zero
/// value writes the estimate to scene.json, the truth to poses_true.json, the realised figures to
/// stats.json and the terminal, and only the SMPL parameters differ.
#[test]
fn synth_pose_error_flag() {
    let tmp = tempfile::tempdir().unwrap();
    let (plain, zero, on) = (
        tmp.path().join("plain"),
        tmp.path().join("zero"),
        tmp.path().join("on"),
    );
    run_ok(&tiny_args(&plain, &[]));
    run_ok(&tiny_args(&zero, &[("--pose-error", "0")]));
    assert!(
        files(&plain) == files(&zero),
        "--pose-error 0 changed bytes"
    );
    let stdout = run_ok(&tiny_args(&on, &[("--pose-error", "8")]));
    assert!(stdout.contains("pose error in scene.json"), "{stdout}");
    let (fp, fo) = (files(&plain), files(&on));
    assert!(fo.contains_key("poses_true.json"));
    for (k, v) in &fp {
        if ![".complete", "scene.json", "stats.json"].contains(&k.as_str()) {
            assert!(fo[k] == *v, "{k} changed with --pose-error 8");
        }
    }
    let stats: serde_json::Value = serde_json::from_slice(&fo["stats.json"]).unwrap();
    let rms = stats["pose_error"]["joint_rms_deg"].as_f64().unwrap();
    assert!((rms - 8.0).abs() < 0.05, "{rms}");
    // The root errors follow in the realistic preset's proportion (16° : 6° : 8 cm).
    let root = stats["pose_error"]["root_orient_rms_deg"].as_f64().unwrap();
    assert!((root - 3.0).abs() < 0.02, "{root}");
    let stamp = String::from_utf8_lossy(&fo[".complete"]).into_owned();
    assert!(stamp.contains("\"pose_error\""), "{stamp}");
    let truth: serde_json::Value = serde_json::from_slice(&fo["poses_true.json"]).unwrap();
    let scene_plain: serde_json::Value = serde_json::from_slice(&fp["scene.json"]).unwrap();
    for (t, s) in truth["frames"]
        .as_array()
        .unwrap()
        .iter()
        .zip(scene_plain["frames"].as_array().unwrap())
    {
        assert_eq!(t["pose"], s["pose"]);
        assert_eq!(t["transl"], s["transl"]);
    }
}

#[test]
fn synth_refuses_bad_pose_errors_and_documents_the_flag() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("refused");
    for (flag, value, knob) in [
        ("--pose-error", "-1", "pose-error"),
        ("--pose-error", "45", "pose-error"),
        ("--root-transl-error", "80", "root-transl-error"),
    ] {
        let args = tiny_args(&out, &[(flag, value)]);
        let o = xtask(&args.iter().map(String::as_str).collect::<Vec<_>>());
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{flag} {value} was accepted");
        assert!(
            stderr.contains(&format!("invalid setting {knob} = {value}")),
            "{flag} {value}: unexpected message: {stderr}"
        );
    }
    let help = xtask(&["synth", "--help"]);
    let text = String::from_utf8_lossy(&help.stdout);
    for needle in [
        "--pose-error <DEG>",
        "geodesic",
        "poses_true.json",
        "realistic",
    ] {
        assert!(text.contains(needle), "--help lacks {needle}: {text}");
    }
}

/// `synth --people 2` writes a version-3 scene whose terminal report gives each person's blurred
/// box, and `reconstruct` trains it with one class per person: `metrics.json` scores each person's
/// mask and box under its id, and each person has a posed PLY of its own; five people are refused
/// naming the knob.
#[test]
fn two_people_are_generated_and_reconstructed_person_by_person() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("people");
    let args = tiny_args(&out, &[("--people", "2"), ("--frames", "10")]);
    let o = xtask(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        stdout.contains("each person's own box: person 0"),
        "{stdout}"
    );
    let scene: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("scene.json")).unwrap()).unwrap();
    assert_eq!(scene["format_version"], 3);
    assert_eq!(scene["frames"][0]["people"][0]["id"], 1);
    let run = tmp.path().join("run");
    let o = xtask(&[
        "reconstruct",
        "--data",
        out.to_str().unwrap(),
        "--out",
        run.to_str().unwrap(),
        "--steps",
        "2",
        "--human-gaussians",
        "150",
        "--scene-gaussians",
        "300",
        "--deform-hidden",
        "16",
        "--skinning-samples",
        "32",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let metrics: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("metrics.json")).unwrap()).unwrap();
    let people = metrics["people"].as_array().unwrap();
    assert_eq!(people.len(), 2, "{metrics}");
    for (p, id) in people.iter().zip([0, 1]) {
        assert_eq!(p["id"], id);
        assert!(p["mask_iou"].as_f64().is_some_and(f64::is_finite), "{p}");
    }
    assert_eq!(metrics["person_class_changes"], 0, "{metrics}");
    let posed = |id: u32| {
        std::fs::read_dir(run.join("model"))
            .unwrap()
            .filter_map(Result::ok)
            .any(|e| {
                e.file_name()
                    .to_string_lossy()
                    .ends_with(&format!("_person_{id}.ply"))
            })
    };
    assert!(posed(0) && posed(1));
    // Person 1 walks the AMASS fixture while person 0 stands still; a motion without an id is
    // refused, naming the ids.
    let model = run.join("model");
    let walk = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data-fixtures/motion/walk_amass.npz");
    let gif = tmp.path().join("walk.gif");
    let animate = |motion: &str| {
        xtask(&[
            "render-pose",
            "--model",
            model.to_str().unwrap(),
            "--data",
            out.to_str().unwrap(),
            "--motion",
            motion,
            "--frames",
            "3",
            "--out",
            gif.to_str().unwrap(),
        ])
    };
    let o = animate(&format!("1={}", walk.display()));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(gif.is_file());
    let o = animate(walk.to_str().unwrap());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && stderr.contains("--motion ID=FILE") && stderr.contains("[0, 1]"),
        "{stderr}"
    );
    let args = tiny_args(&out, &[("--people", "5")]);
    let o = xtask(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && stderr.contains("invalid setting people = 5"),
        "{stderr}"
    );
}

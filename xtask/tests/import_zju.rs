//! `cargo xtask import zju` on a ZJU-MoCap-layout subject made from the tiny fixture (JPEG frames,
//! PNG masks, `cam_params.json` in OpenCV's pixel convention, `models/*.npz` fits): the scene it
//! writes has the camera in the scene's convention, the fits' poses, the blur windows and events
//! asked for, and trains; a missing view is refused by name.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data-fixtures/tiny")
}

fn xtask() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_xtask"));
    c.env("RUST_BACKTRACE", "0");
    c
}

/// Writes the subject under `root` (view "1"), with lens coefficients `d`; returns the fixture.
fn write_subject(root: &Path, d: [f64; 5]) -> scene::Scene {
    let fx = fixture();
    let tiny: scene::Scene =
        serde_json::from_str(&std::fs::read_to_string(fx.join("scene.json")).unwrap()).unwrap();
    let c = &tiny.camera;
    let m = c.world_to_camera;
    let cams = serde_json::json!({
        "all_cam_names": ["1"],
        "1": {
            "K": [[c.fx, 0.0, c.cx - 0.5], [0.0, c.fy, c.cy - 0.5], [0.0, 0.0, 1.0]],
            "D": [[d[0]], [d[1]], [d[2]], [d[3]], [d[4]]],
            "R": [[m[0][0], m[0][1], m[0][2]], [m[1][0], m[1][1], m[1][2]], [m[2][0], m[2][1], m[2][2]]],
            "T": [[m[0][3]], [m[1][3]], [m[2][3]]],
        }
    });
    std::fs::create_dir_all(root.join("1")).unwrap();
    std::fs::create_dir_all(root.join("models")).unwrap();
    std::fs::write(root.join("cam_params.json"), cams.to_string()).unwrap();
    for (k, f) in tiny.frames.iter().enumerate() {
        let rgb = scene::read_rgb(&fx.join(f.sharp.as_ref().unwrap()), tiny.images).unwrap();
        let n = (c.width * c.height) as usize;
        let bytes = scene::image_io::srgb8_interleaved(&rgb.data, n);
        image::save_buffer(
            root.join(format!("1/{k:06}.jpg")),
            &bytes,
            c.width,
            c.height,
            image::ExtendedColorType::Rgb8,
        )
        .unwrap();
        std::fs::copy(
            fx.join(f.mask.as_ref().unwrap()),
            root.join(format!("1/{k:06}.png")),
        )
        .unwrap();
        let pose: Vec<f32> = f.pose.iter().flatten().copied().collect();
        let file = std::fs::File::create(root.join(format!("models/{k:06}.npz"))).unwrap();
        let mut w = smpl_deform::npz::NpzWriter::new(file, false);
        w.add_f32("root_orient", &[1, 3], &pose[..3]).unwrap();
        w.add_f32("pose_body", &[1, 63], &pose[3..66]).unwrap();
        w.add_f32("pose_hand", &[1, 6], &pose[66..]).unwrap();
        w.add_f32("trans", &[1, 3], &f.transl).unwrap();
        w.add_f32("betas", &[1, 10], &[0.0; 10]).unwrap();
        w.finish().unwrap();
    }
    tiny
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
    let root = dir.path().join("CoreView_tiny");
    let tiny = write_subject(&root, [0.0; 5]);
    let out = dir.path().join("scene");
    let o = import(&root, &out, &["--blur", "3", "--events", "simulate"]);
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
    let config = dir.path().join("tiny.toml");
    std::fs::write(
        &config,
        "steps = 3\nhuman_gaussians = 200\nscene_gaussians = 400\nmax_gaussians = 2000\n\
         deform_hidden = 16\nskinning_until = 3\nskinning_samples = 32\nnonrigid_from = 2\n\
         densify_from = 8\ndensify_until = 8\n",
    )
    .unwrap();
    let o = xtask()
        .arg("reconstruct")
        .arg("--data")
        .arg(&out)
        .arg("--out")
        .arg(dir.path().join("run"))
        .arg("--config")
        .arg(&config)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn a_distorting_lens_changes_the_frames_and_a_missing_view_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("subject");
    write_subject(&root, [-0.3, 0.1, 0.0, 0.0, 0.0]);
    let (plain, bent) = (dir.path().join("plain"), dir.path().join("bent"));
    let o = import(&root, &bent, &["--max-frames", "2"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    write_subject(&dir.path().join("flat"), [0.0; 5]);
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
    let o = import(&root, &dir.path().join("x"), &["--view", "7"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("7"), "{err}");
    // Distortion coefficients that are not 5 are refused naming the file and the field.
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

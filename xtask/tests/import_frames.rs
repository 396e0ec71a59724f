//! `cargo xtask import frames` end to end on the tiny fixture's sharp frames and poses: the scene it
//! writes loads, holds what the flags asked for, and trains; count mismatches are refused naming
//! both counts.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::{Command, Output};

mod common;

use common::{fixture, reconstruct, tiny_config, write_poses};

fn xtask() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_xtask"));
    c.env("RUST_BACKTRACE", "0");
    c
}

fn import(out: &Path, poses: &Path, extra: &[&str]) -> Output {
    import_from(&fixture().join("sharp"), out, poses, extra)
}

fn import_from(images: &Path, out: &Path, poses: &Path, extra: &[&str]) -> Output {
    import_with(images, &fixture().join("scene.json"), out, poses, extra)
}

fn import_with(images: &Path, camera: &Path, out: &Path, poses: &Path, extra: &[&str]) -> Output {
    let fx = fixture();
    xtask()
        .args(["import", "frames", "--fps", "30", "--images"])
        .arg(images)
        .arg("--masks")
        .arg(fx.join("masks"))
        .arg("--camera")
        .arg(camera)
        .arg("--poses")
        .arg(poses)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

#[test]
fn frames_and_poses_become_a_scene_that_trains() {
    let dir = tempfile::tempdir().unwrap();
    // The committed fixture: the tiny benchmark's frames with its poses and camera.
    let committed = common::import_fixtures().join("frames");
    let poses = committed.join("poses.json");
    // The frames as observations: 15 frames, the 7/3 split, the given exposure.
    let plain = dir.path().join("plain");
    let o = import_with(
        &fixture().join("sharp"),
        &committed.join("camera.json"),
        &plain,
        &poses,
        &["--exposure-s", "0.02"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = scene::load(&plain).unwrap();
    assert_eq!(s.frames.len(), 15);
    assert!((s.exposure_s - 0.02).abs() < 1e-12);
    assert_eq!(
        s.frames
            .iter()
            .filter(|f| f.split == scene::Split::Test)
            .count(),
        3
    );
    assert!(s
        .frames
        .iter()
        .all(|f| f.mask.is_some() && f.sharp.is_none()));
    // The ZJU-MoCap-Blur recipe: windows of 3, events simulated.
    let blurred = dir.path().join("blurred");
    let o = import(&blurred, &poses, &["--blur", "3", "--events", "simulate"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = scene::load(&blurred).unwrap();
    assert_eq!(s.frames.len(), 5);
    assert!((s.exposure_s - 0.1).abs() < 1e-12);
    assert!(s
        .frames
        .iter()
        .all(|f| f.sharp.is_some() && f.events.is_some()));
    // With frames interpolated by the flow network in every gap (the paper's construction), the
    // windows average 3 + 2 frames and differ from the recorded frames' mean.
    let smooth = dir.path().join("smooth");
    let o = import(
        &smooth,
        &poses,
        &["--blur", "3", "--in-between", "1", "--events", "simulate"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let t = scene::load(&smooth).unwrap();
    let first = |d: &Path, s: &scene::Scene| {
        scene::read_rgb(&d.join(&s.frames[0].image), s.images)
            .unwrap()
            .data
    };
    let (plain_mean, smooth_mean) = (first(&blurred, &s), first(&smooth, &t));
    let moved = plain_mean
        .iter()
        .zip(&smooth_mean)
        .filter(|(a, b)| (*a - *b).abs() > 1e-3)
        .count();
    assert!(moved > 100, "{moved} values changed");
    // It trains (exposure model + event loss, the default) for a few steps.
    let config = tiny_config(dir.path());
    let run = dir.path().join("run");
    let out = reconstruct(&blurred, &run, &config);
    assert!(out.contains("event loss: "), "{out}");
    assert!(run.join("model").is_dir());
}

#[test]
fn grey_frames_make_a_grey_scene_that_trains_with_per_frame_exposures() {
    let dir = tempfile::tempdir().unwrap();
    let poses = dir.path().join("poses.json");
    write_poses(&poses, 15);
    // The fixture's sharp frames as 16-bit grey PNGs, as a DAVIS APS would record them.
    let fx = fixture();
    let text = std::fs::read_to_string(fx.join("scene.json")).unwrap();
    let tiny: scene::Scene = serde_json::from_str(&text).unwrap();
    let grey_dir = dir.path().join("grey");
    std::fs::create_dir_all(&grey_dir).unwrap();
    let grey = scene::ImageEncoding {
        channels: 1,
        ..tiny.images
    };
    for f in &tiny.frames {
        let rgb = scene::read_rgb(&fx.join(f.sharp.as_ref().unwrap()), tiny.images).unwrap();
        scene::write_rgb(&grey_dir.join(format!("{:06}.png", f.index)), &rgb, grey).unwrap();
    }
    let out = dir.path().join("scene");
    let o = import_from(
        &grey_dir,
        &out,
        &poses,
        &["--exposure-s", "0.03", "--events", "simulate"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut s = scene::load(&out).unwrap();
    assert!(s.images.is_grey());
    // Auto-exposure: frame 1 has its own, shorter exposure.
    s.frames[1].exposure_s = Some(0.015);
    s.write(&out).unwrap();
    assert_eq!(scene::load(&out).unwrap().exposure_of(1), 0.015);
    let run = dir.path().join("run");
    let stdout = reconstruct(&out, &run, &tiny_config(dir.path()));
    assert!(stdout.contains("15.0–30.0 ms exposure"), "{stdout}");
    // The test split (3 frames) is evaluated on the renders' luminance against the grey frames.
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["test_frames"].as_u64(), Some(3), "{metrics}");
    let psnr = metrics["test_psnr_full"].as_f64().unwrap();
    assert!(psnr.is_finite() && psnr > 5.0, "{metrics}");
    let html = std::fs::read_to_string(run.join("report.html")).unwrap();
    for needle in [
        "<h2>Data</h2>",
        "xtask import frames",
        "grey",
        "1 frames with their own exposure",
    ] {
        assert!(html.contains(needle), "report lacks {needle}");
    }
}

#[test]
fn mismatched_counts_and_settings_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let poses = dir.path().join("poses.json");
    write_poses(&poses, 14);
    let o = import(&dir.path().join("a"), &poses, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("14 poses") && err.contains("15 frames"),
        "{err}"
    );
    write_poses(&poses, 15);
    let o = import(&dir.path().join("b"), &poses, &["--blur", "4"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("blur"), "{err}");
    let o = import(
        &dir.path().join("c"),
        &poses,
        &["--blur", "3", "--exposure-s", "0.01"],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("exposure_s"), "{err}");
    assert!(!dir.path().join("a").join("scene.json").exists());
    // A pose file with the wrong shapes names the file and the array.
    let bad = dir.path().join("bad.npz");
    let mut w = smpl_deform::npz::NpzWriter::new(std::fs::File::create(&bad).unwrap(), false);
    w.add_f32("global_orient", &[15, 3], &[0.0; 45]).unwrap();
    w.add_f32("body_pose", &[15, 68], &vec![0.0; 15 * 68])
        .unwrap();
    w.add_f32("transl", &[15, 3], &[0.0; 45]).unwrap();
    w.finish().unwrap();
    let o = import(&dir.path().join("d"), &bad, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("bad.npz") && err.contains("body_pose"),
        "{err}"
    );
    // A camera whose size differs from the frames names the frame file and both sizes.
    let camera = dir.path().join("camera.json");
    std::fs::write(
        &camera,
        r#"{"width": 32, "height": 32, "fx": 40.0, "fy": 40.0, "cx": 16.0, "cy": 16.0,
            "world_to_camera": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]]}"#,
    )
    .unwrap();
    let o = import_with(
        &fixture().join("sharp"),
        &camera,
        &dir.path().join("e"),
        &poses,
        &[],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success()
            && err.contains("000000.png")
            && err.contains("64x64, the camera is 32x32"),
        "{err}"
    );
}

/// `--cameras`: a moving camera's pose per frame, from a JSON list (frame order) or a COLMAP text
/// model (matched by file name), written as scene format version 2 (each written frame takes the
/// pose of the middle frame of its blur window); the scene trains; a list of the wrong length and
/// intrinsics that are not `--camera`'s are refused.
#[test]
fn per_frame_cameras_make_a_moving_camera_scene_that_trains() {
    let dir = tempfile::tempdir().unwrap();
    let committed = common::import_fixtures().join("frames");
    let poses = committed.join("poses.json");
    let camera = scene::load(&fixture()).unwrap().camera;
    let shifted = |k: usize| {
        let mut c = camera.clone();
        c.world_to_camera[0][3] += 0.002 * k as f64;
        c
    };
    let camera_json = |c: &scene::Camera| {
        let rows: Vec<[f64; 4]> = c.world_to_camera[..3].to_vec();
        serde_json::json!({"width": c.width, "height": c.height, "fx": c.fx, "fy": c.fy,
            "cx": c.cx, "cy": c.cy, "world_to_camera": rows})
    };
    let list: Vec<_> = (0..15).map(|k| camera_json(&shifted(k))).collect();
    let list_path = dir.path().join("cameras.json");
    std::fs::write(&list_path, serde_json::to_string(&list).unwrap()).unwrap();
    let out = dir.path().join("moving");
    let o = import(
        &out,
        &poses,
        &["--blur", "3", "--events", "simulate", "--cameras"],
    );
    assert!(!o.status.success(), "--cameras needs its value");
    let o = xtask_import_with_cameras(&out, &poses, &list_path);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = scene::load(&out).unwrap();
    assert_eq!(s.format_version, scene::FORMAT_VERSION_MOVING_CAMERA);
    assert_eq!(s.frames.len(), 5);
    // (serde_json's float parsing is not correctly rounded: the JSON round trip may move a value
    // by an ulp.)
    for (j, f) in s.frames.iter().enumerate() {
        let (got, want) = (
            f.world_to_camera.unwrap(),
            shifted(3 * j + 1).world_to_camera,
        );
        let err = (0..3)
            .flat_map(|r| (0..4).map(move |c| (r, c)))
            .map(|(r, c)| (got[r][c] - want[r][c]).abs())
            .fold(0.0, f64::max);
        assert!(err < 1e-12, "frame {j}: {got:?} vs {want:?}");
    }
    let run = dir.path().join("run");
    let config = tiny_config(dir.path());
    let log = reconstruct(&out, &run, &config);
    assert!(run.join("model").is_dir(), "{log}");
    // The same poses from a COLMAP text model (identity rotations: only where the camera is).
    let colmap = dir.path().join("colmap");
    std::fs::create_dir_all(&colmap).unwrap();
    std::fs::write(
        colmap.join("cameras.txt"),
        format!(
            "# one camera\n1 PINHOLE {} {} {} {} {} {}\n",
            camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy
        ),
    )
    .unwrap();
    let mut images = String::from("# two lines per image\n");
    let names: Vec<String> = std::fs::read_dir(fixture().join("sharp"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    let mut names = names;
    names.sort();
    for (k, name) in names.iter().enumerate().rev() {
        images.push_str(&format!(
            "{} 1 0 0 0 {} 0.5 2 1 {name}\n\n",
            k + 1,
            0.01 * k as f64
        ));
    }
    std::fs::write(colmap.join("images.txt"), images).unwrap();
    let from_colmap = dir.path().join("from-colmap");
    let o = xtask_import_with_cameras(&from_colmap, &poses, &colmap);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let t = scene::load(&from_colmap).unwrap();
    let pose = t.frames[2].world_to_camera.unwrap();
    assert_eq!(pose[0][..3], [1.0, 0.0, 0.0]);
    assert!((pose[0][3] - 0.07).abs() < 1e-12, "{pose:?}");
    // Refusals: one camera short; intrinsics that are not --camera's.
    std::fs::write(&list_path, serde_json::to_string(&list[..14]).unwrap()).unwrap();
    let o = xtask_import_with_cameras(&dir.path().join("short"), &poses, &list_path);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("holds 14 cameras but there are 15 frames"),
        "{err}"
    );
    let mut wide = shifted(0);
    wide.fx *= 1.1;
    let mut other = list.clone();
    other[4] = camera_json(&wide);
    std::fs::write(&list_path, serde_json::to_string(&other).unwrap()).unwrap();
    let o = xtask_import_with_cameras(&dir.path().join("wide"), &poses, &list_path);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains(&names[4]) && err.contains("intrinsics"),
        "{err}"
    );
}

fn xtask_import_with_cameras(out: &Path, poses: &Path, cameras: &Path) -> Output {
    let blur = ["--blur", "3", "--events", "simulate", "--cameras"];
    let mut extra: Vec<&str> = blur.to_vec();
    let cameras = cameras.to_str().unwrap();
    extra.push(cameras);
    import(out, poses, &extra)
}

/// A COLMAP text model of cameras turned every which way (rotations up to 2.5 rad, written as
/// COLMAP's world-to-camera quaternions and translations) imports to the same cameras within 1e-9:
/// the rotation from the quaternion matches Rodrigues' formula of the same axis and angle.
#[test]
fn a_colmap_model_of_turned_cameras_imports_them_within_1e_9() {
    let dir = tempfile::tempdir().unwrap();
    let poses = common::import_fixtures().join("frames").join("poses.json");
    let camera = scene::load(&fixture()).unwrap().camera;
    let mut names: Vec<String> = std::fs::read_dir(fixture().join("sharp"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    // Per image an axis, an angle and a translation, varied deterministically.
    let truth: Vec<([f64; 3], f64, [f64; 3])> = (0..names.len())
        .map(|k| {
            let a = k as f64;
            let axis = [
                (1.3 * a).sin(),
                (0.7 * a + 1.0).cos(),
                0.4 + (2.1 * a).sin(),
            ];
            let n = axis.iter().map(|v| v * v).sum::<f64>().sqrt();
            let angle = 0.1 + 2.4 * (0.5 + 0.5 * (0.9 * a).sin());
            (
                axis.map(|v| v / n),
                angle,
                [0.1 * a - 0.5, 0.3 - 0.05 * a, 2.0 + 0.1 * a],
            )
        })
        .collect();
    let colmap = dir.path().join("colmap");
    std::fs::create_dir_all(&colmap).unwrap();
    std::fs::write(
        colmap.join("cameras.txt"),
        format!(
            "7 PINHOLE {} {} {} {} {} {}\n",
            camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy
        ),
    )
    .unwrap();
    let mut images = String::new();
    for (k, (name, (axis, angle, t))) in names.iter().zip(&truth).enumerate() {
        let (s, w) = ((angle / 2.0).sin(), (angle / 2.0).cos());
        images.push_str(&format!(
            "{} {w} {} {} {} {} {} {} 7 {name}\n\n",
            k + 1,
            s * axis[0],
            s * axis[1],
            s * axis[2],
            t[0],
            t[1],
            t[2]
        ));
    }
    std::fs::write(colmap.join("images.txt"), images).unwrap();
    let out = dir.path().join("turned");
    let o = import(&out, &poses, &["--cameras", colmap.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = scene::load(&out).unwrap();
    assert_eq!(s.frames.len(), names.len());
    for (f, (axis, angle, t)) in s.frames.iter().zip(&truth) {
        let rotation = rodrigues(*axis, *angle);
        let got = f.world_to_camera.unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let want = rotation[i][j];
                assert!(
                    (got[i][j] - want).abs() < 1e-9,
                    "frame {}: {got:?}",
                    f.index
                );
            }
            assert!(
                (got[i][3] - t[i]).abs() < 1e-9,
                "frame {}: {got:?}",
                f.index
            );
        }
    }
}

/// The rotation by `angle` (radians) about the unit `axis`, by Rodrigues' formula
/// I + sin θ K + (1 − cos θ) K² (an expansion independent of the importer's quaternion one).
fn rodrigues(axis: [f64; 3], angle: f64) -> [[f64; 3]; 3] {
    let k = [
        [0.0, -axis[2], axis[1]],
        [axis[2], 0.0, -axis[0]],
        [-axis[1], axis[0], 0.0],
    ];
    std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let k2: f64 = (0..3).map(|l| k[i][l] * k[l][j]).sum();
            f64::from(u8::from(i == j)) + angle.sin() * k[i][j] + (1.0 - angle.cos()) * k2
        })
    })
}

/// #46's COLMAP criterion end to end: the tiny benchmark filmed hand-held (`synth --camera-motion
/// handheld`), its true per-frame cameras written by this test as a COLMAP text model (OPENCV
/// intrinsics with zero distortion, quaternions and translations at full precision, the images
/// listed out of order), imported with its sharp frames by `import frames --cameras`: every
/// frame's camera is the model's within 1e-9 (the rotation of its written quaternion by
/// Rodrigues' formula, the translation as written, which is the truth's), and the scene trains.
/// The generator's rotations are f32-accurate, so the nearest exact rotation, which a quaternion
/// writes, is within 1e-6 of them.
#[test]
fn a_colmap_model_of_a_handheld_benchmarks_true_cameras_imports_them_and_trains() {
    let dir = tempfile::tempdir().unwrap();
    let bench = dir.path().join("handheld");
    let o = xtask()
        .args([
            "synth",
            "--preset",
            "tiny",
            "--camera-motion",
            "handheld",
            "--out",
        ])
        .arg(&bench)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let truth = scene::load(&bench).unwrap();
    assert!(truth.camera_moves());
    let c = &truth.camera;
    let colmap = dir.path().join("colmap");
    std::fs::create_dir_all(&colmap).unwrap();
    std::fs::write(
        colmap.join("cameras.txt"),
        format!(
            "# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n3 OPENCV {} {} {} {} {} {} 0 0 0 0\n",
            c.width, c.height, c.fx, c.fy, c.cx, c.cy
        ),
    )
    .unwrap();
    let mut images = String::from("# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n");
    let mut written = vec![[0.0; 4]; truth.frames.len()];
    for (k, f) in truth.frames.iter().enumerate().rev() {
        let m = truth.camera_of(k).world_to_camera;
        let rotation: [[f64; 3]; 3] = std::array::from_fn(|r| [m[r][0], m[r][1], m[r][2]]);
        written[k] = gaussians::covariance::quat_from_rotation(&rotation);
        let [w, x, y, z] = written[k];
        let name = Path::new(f.sharp.as_ref().unwrap()).file_name().unwrap();
        let t = [m[0][3], m[1][3], m[2][3]];
        images.push_str(&format!(
            "{} {w} {x} {y} {z} {} {} {} 3 {}\n0.0 0.0 -1\n",
            k + 10,
            t[0],
            t[1],
            t[2],
            name.to_string_lossy()
        ));
    }
    std::fs::write(colmap.join("images.txt"), images).unwrap();
    let poses = common::import_fixtures().join("frames").join("poses.json");
    let out = dir.path().join("imported");
    let o = xtask()
        .args(["import", "frames", "--fps", "30", "--images"])
        .arg(bench.join("sharp"))
        .arg("--masks")
        .arg(bench.join("masks"))
        .arg("--camera")
        .arg(bench.join("scene.json"))
        .arg("--poses")
        .arg(&poses)
        .arg("--cameras")
        .arg(&colmap)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let imported = scene::load(&out).unwrap();
    assert_eq!(imported.frames.len(), truth.frames.len());
    for (k, f) in imported.frames.iter().enumerate() {
        let (got, truth) = (
            f.world_to_camera.unwrap(),
            truth.camera_of(k).world_to_camera,
        );
        // The written quaternion's rotation from its axis and angle.
        let [w, x, y, z] = written[k];
        let sine = (x * x + y * y + z * z).sqrt();
        let axis = [x, y, z].map(|v| v / sine.max(f64::MIN_POSITIVE));
        let rotation = rodrigues(axis, 2.0 * sine.atan2(w));
        for r in 0..3 {
            for col in 0..3 {
                let (g, q, t) = (got[r][col], rotation[r][col], truth[r][col]);
                assert!(
                    (g - q).abs() < 1e-9,
                    "frame {k}: {got:?}, quaternion {q} at [{r}][{col}]"
                );
                assert!(
                    (q - t).abs() < 1e-6,
                    "frame {k}: truth {truth:?}, quaternion {q}"
                );
            }
            assert!(
                (got[r][3] - truth[r][3]).abs() < 1e-9,
                "frame {k}: {got:?} against the truth {truth:?}"
            );
        }
    }
    let run = dir.path().join("run");
    let log = reconstruct(&out, &run, &tiny_config(dir.path()));
    assert!(run.join("model").is_dir(), "{log}");
}

/// An EasyMocap `smpl/` folder of the fixture's 15 frames with people 4 and 9 in every frame and
/// person 2 in five: without `--person` the scene holds people 4 and 9 (format 3, each posed in
/// every frame, person 2 named in a note) that `reconstruct` trains with one semantic class per
/// person, reporting each under its id; `--person 9` makes a one-person scene of person 9.
#[test]
fn an_easymocap_folder_of_several_people_imports_every_person_seen_throughout() {
    let dir = tempfile::tempdir().unwrap();
    let smpl = dir.path().join("smpl");
    std::fs::create_dir(&smpl).unwrap();
    let tiny = common::tiny();
    for (k, f) in tiny.frames.iter().enumerate() {
        let flat: Vec<f32> = f.pose.iter().flatten().copied().collect();
        let person = |id: i64, dx: f32| {
            serde_json::json!({
                "id": id,
                "Rh": [[0.0, 0.0, 0.0]],
                "Th": [[f.transl[0] + dx, f.transl[1], f.transl[2]]],
                "poses": [flat],
                "shapes": [vec![0.1 * id as f32; 10]],
            })
        };
        let mut people = vec![person(4, 0.0), person(9, 0.6)];
        if k < 5 {
            people.push(person(2, -0.6));
        }
        let text = serde_json::Value::Array(people).to_string();
        std::fs::write(smpl.join(format!("{k:06}.json")), text).unwrap();
    }
    let out = dir.path().join("two");
    let o = import(&out, &smpl, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("person 2 is in 5 of the frames"), "{err}");
    assert!(err.contains("2 people in every frame (ids 4, 9)"), "{err}");
    let s = scene::load(&out).unwrap();
    assert_eq!(s.format_version, 3);
    assert_eq!(s.body.id, 4);
    assert_eq!(s.people.len(), 1);
    assert_eq!(s.people[0].id, 9);
    assert_eq!(s.people[0].betas, vec![0.1f32 * 9.0; 10]);
    for (f, given) in s.frames.iter().zip(&tiny.frames) {
        assert_eq!(f.people.len(), 1, "frame {}", f.index);
        assert_eq!(f.people[0].id, 9);
        let dx = f.people[0].transl[0] - f.transl[0];
        assert!((dx - 0.6).abs() < 1e-5, "frame {}: {dx}", f.index);
        assert_eq!(f.people[0].pose[5], f.pose[5], "frame {}", f.index);
        assert!(given.people.is_empty());
    }
    // Both people are reconstructed, each reported under its own id (no person-id images here,
    // so their masks are not scored).
    let run = dir.path().join("run");
    let r = xtask()
        .args(["reconstruct", "--data"])
        .arg(&out)
        .arg("--out")
        .arg(&run)
        .arg("--config")
        .arg(tiny_config(dir.path()))
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let metrics: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["people_count"], 2);
    let ids: Vec<_> = metrics["people"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["id"].as_u64().unwrap())
        .collect();
    assert_eq!(ids, vec![4, 9]);
    // `--person 9` keeps one person: the scene of before.
    let one = dir.path().join("one");
    let o = import(&one, &smpl, &["--person", "9"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = scene::load(&one).unwrap();
    assert!(s.people.is_empty() && s.frames.iter().all(|f| f.people.is_empty()));
    assert_eq!(s.body.id, 0);
    assert_eq!(s.body.betas, vec![0.1f32 * 9.0; 10]);
}

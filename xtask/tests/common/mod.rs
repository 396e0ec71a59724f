//! Writers of the importers' fixtures (`data-fixtures/import/`, made from the tiny benchmark
//! fixture): shared by the import tests and by the ignored test that regenerates the committed
//! files (`cargo test -p xtask --test import_fixtures -- --ignored`); and the tiny fixture edited,
//! trained a few steps by `reconstruct`.
#![allow(dead_code, clippy::unwrap_used)]

use std::path::{Path, PathBuf};

use events::io::aedat4::Compression;
use events::io::aedat4_frames::{write_aedat4_with_frames, ApsFrame, FrameFormat};

/// The tiny benchmark fixture.
pub fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data-fixtures/tiny")
}

/// The committed importer fixtures.
pub fn import_fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data-fixtures/import")
}

/// The fixture's scene description.
pub fn tiny() -> scene::Scene {
    serde_json::from_str(&std::fs::read_to_string(fixture().join("scene.json")).unwrap()).unwrap()
}

/// The first `count` poses of the fixture as a JSON list (the `--poses` layout).
pub fn write_poses(path: &Path, count: usize) {
    let list: Vec<serde_json::Value> = tiny()
        .frames
        .iter()
        .take(count)
        .map(|f| serde_json::json!({"pose": f.pose, "transl": f.transl}))
        .collect();
    std::fs::write(path, serde_json::to_string(&list).unwrap()).unwrap();
}

/// Writes `rec.aedat4` (grey frames of the fixture's observed images, exposures shortened on
/// frames 3 and 4, the fixture's events) and `poses.json` (the first `poses` poses); returns the
/// number of events after the first frame's exposure midpoint.
pub fn write_recording(dir: &Path, poses: usize) -> usize {
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
        Compression::Zstd,
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

/// Writes the subject under `root` (view "1"), with lens coefficients `d`; returns the fixture.
pub fn write_subject(root: &Path, d: [f64; 5]) -> scene::Scene {
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

/// A few-step training configuration for the tiny scenes, written into `dir`.
pub fn tiny_config(dir: &Path) -> PathBuf {
    let config = dir.join("tiny.toml");
    std::fs::write(
        &config,
        "steps = 4\nhuman_gaussians = 200\nscene_gaussians = 400\nmax_gaussians = 2000\n\
         deform_hidden = 16\nskinning_until = 4\nskinning_samples = 32\nnonrigid_from = 2\n\
         densify_from = 8\ndensify_until = 8\n",
    )
    .unwrap();
    config
}

/// Runs `reconstruct` and returns its standard output.
pub fn reconstruct(data: &Path, run: &Path, config: &Path) -> String {
    reconstruct_with(data, run, config, &[])
}

/// Runs `reconstruct` with `extra` options and returns its standard output.
pub fn reconstruct_with(data: &Path, run: &Path, config: &Path, extra: &[&str]) -> String {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_xtask"))
        .arg("reconstruct")
        .arg("--data")
        .arg(data)
        .arg("--out")
        .arg(run)
        .arg("--config")
        .arg(config)
        .args(extra)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Copies a directory tree.
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

/// A copy of the tiny fixture at `dir/name` whose `scene.json` `edit` has changed.
pub fn fixture_with_scene(
    dir: &Path,
    name: &str,
    edit: impl FnOnce(&mut serde_json::Value),
) -> PathBuf {
    let scene_dir = dir.join(name);
    copy_dir(&fixture(), &scene_dir);
    let path = scene_dir.join("scene.json");
    let mut scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    edit(&mut scene);
    std::fs::write(&path, scene.to_string()).unwrap();
    scene_dir
}

//! What the held-out frames' cameras can reach without their images: the bound a perfect camera
//! correction would leave. For a synthetic scene written with `--camera-error-deg/-cm`
//! (`ESTIMATED`, with its `cameras_true.json`) and the same scene with exact cameras (`EXACT`),
//! this takes every training frame's *perfect* correction — the twist that turns its given camera
//! into the true one — and gives each held-out frame the correction the trainer would give it
//! (`fitted_camera_correction`: the least-squares line, in frame number, through the training
//! frames nearest to it) applied to its own given camera. What remains is the part
//! of the tracker's error that the training frames cannot tell (the per-frame jitter), exactly as
//! a flawless corrector would leave it.
//!
//! It prints each held-out frame's remaining rotation (degrees), centre error (cm) and their image
//! motion at the scene's depth (px), and writes `OUT`: a copy of `EXACT` whose held-out cameras
//! carry that remainder (the data directories linked, not copied). Scoring a model trained on
//! `EXACT` there (`cargo xtask eval --model RUN/model --data OUT`) gives what the held-out frames
//! of a flawless corrector would score as trained, the bound for the "as trained" share.
//! With `SIGMA` (slots; default 0) the perfect corrections are first smoothed over the training
//! frames as `--camera-correction-smoothing SIGMA` smooths the learned ones (the six mid-exposure
//! values), which keeps the training frames' own jitter out of the held-out frames' cameras.
//!
//! ```text
//! cargo run --release -p train --example held_out_camera_bound -- ESTIMATED EXACT OUT [SIGMA]
//! ```

use std::path::Path;

use glam::{DMat3, DQuat};
use serde_json::Value;
use synth::camera_error::TrueCameras;
use train::pose::camera_correction::{
    corrected_world_to_camera, fitted_camera_correction, smoothed_corrections,
    CAMERA_CORRECTION_VALUES, TWIST_VALUES,
};

/// A 3×4 `world_to_camera` from JSON rows, as a 4×4 rigid transform.
fn rigid(rows: &Value) -> Option<[[f64; 4]; 4]> {
    let mut m = [
        [0.0, 0.0, 0.0, 0.0],
        [0.0; 4],
        [0.0; 4],
        [0.0, 0.0, 0.0, 1.0],
    ];
    for (i, row) in rows.as_array()?.iter().enumerate().take(3) {
        for (j, v) in row.as_array()?.iter().enumerate().take(4) {
            m[i][j] = v.as_f64()?;
        }
    }
    Some(m)
}

/// The rotation block of `m`.
fn rotation(m: &[[f64; 4]; 4]) -> DMat3 {
    DMat3::from_cols_array_2d(&[
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ])
}

/// The twist (ω, v) with `[Exp(ω) | v] · given = truth` (the correction that makes `given` exact).
fn perfect_twist(given: &[[f64; 4]; 4], truth: &[[f64; 4]; 4]) -> [f64; TWIST_VALUES] {
    let r = rotation(truth) * rotation(given).transpose();
    let (axis, angle) = DQuat::from_mat3(&r).to_axis_angle();
    let w = axis * angle;
    let t_given = glam::DVec3::new(given[0][3], given[1][3], given[2][3]);
    let t_true = glam::DVec3::new(truth[0][3], truth[1][3], truth[2][3]);
    let v = t_true - r * t_given;
    [w.x, w.y, w.z, v.x, v.y, v.z]
}

/// Rotation angle (degrees) and centre distance (cm) between two cameras.
fn camera_error(a: &[[f64; 4]; 4], b: &[[f64; 4]; 4]) -> (f64, f64) {
    let (ra, rb) = (rotation(a), rotation(b));
    let angle = DQuat::from_mat3(&(ra * rb.transpose())).to_axis_angle().1;
    let centre = |r: DMat3, m: &[[f64; 4]; 4]| {
        -(r.transpose() * glam::DVec3::new(m[0][3], m[1][3], m[2][3]))
    };
    (
        angle.to_degrees(),
        (centre(ra, a) - centre(rb, b)).length() * 100.0,
    )
}

/// Links directory `target` to `source` (a symbolic link; copying would duplicate gigabytes).
#[cfg(unix)]
fn link_dir(source: &Path, target: &Path) -> std::io::Result<()> {
    std::os::unix::fs::symlink(source, target)
}

/// Links directory `target` to `source` (a directory symbolic link; Windows may need developer mode).
#[cfg(windows)]
fn link_dir(source: &Path, target: &Path) -> std::io::Result<()> {
    std::os::windows::fs::symlink_dir(source, target)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (estimated, exact, out, sigma) = match args.as_slice() {
        [_, e, x, o] => (e, x, o, 0.0),
        [_, e, x, o, s] => (e, x, o, s.parse::<f32>()?),
        _ => return Err("usage: held_out_camera_bound ESTIMATED EXACT OUT [SIGMA]".into()),
    };
    let (estimated, exact, out) = (Path::new(estimated), Path::new(exact), Path::new(out));
    let given: Value =
        serde_json::from_str(&std::fs::read_to_string(estimated.join("scene.json"))?)?;
    let mut scene: Value =
        serde_json::from_str(&std::fs::read_to_string(exact.join("scene.json"))?)?;
    let truth = TrueCameras::read(estimated)?;
    let frames = given["frames"]
        .as_array()
        .ok_or("ESTIMATED/scene.json: no frames")?;
    if frames.len() != truth.frames.len() {
        return Err("cameras_true.json and scene.json differ in frame count".into());
    }
    let depth = scene["generator"]["config"]["camera_distance"]
        .as_f64()
        .unwrap_or(2.6);
    let focal = scene["camera"]["fx"]
        .as_f64()
        .ok_or("EXACT/scene.json: camera.fx")?;
    let mut given_cams = Vec::new();
    let mut true_cams = Vec::new();
    let (mut train_indices, mut corrections) = (Vec::new(), Vec::new());
    for (k, (frame, t)) in frames.iter().zip(&truth.frames).enumerate() {
        let g = rigid(&frame["world_to_camera"]).ok_or(format!("frame {k}: world_to_camera"))?;
        let mut tm = [
            [0.0, 0.0, 0.0, 0.0],
            [0.0; 4],
            [0.0; 4],
            [0.0, 0.0, 0.0, 1.0],
        ];
        tm[..3].copy_from_slice(&t.world_to_camera);
        let exact_cam = rigid(&scene["frames"][k]["world_to_camera"])
            .ok_or(format!("EXACT frame {k}: world_to_camera"))?;
        let (deg, cm) = camera_error(&exact_cam, &tm);
        if deg > 1e-6 || cm > 1e-6 {
            return Err(
                format!("EXACT frame {k}: its camera is not the truth ({deg}°, {cm} cm)").into(),
            );
        }
        if frame["split"].as_str() == Some("train") {
            train_indices.push(t.index);
            let mut row = [0.0f32; CAMERA_CORRECTION_VALUES];
            for (r, w) in row.iter_mut().zip(perfect_twist(&g, &tm)) {
                *r = w as f32;
            }
            corrections.extend(row);
        }
        given_cams.push(g);
        true_cams.push(tm);
    }
    let smoothed = smoothed_corrections(&corrections, sigma, TWIST_VALUES);
    let (mut sum_px, mut count) = (0.0, 0usize);
    for (k, frame) in frames.iter().enumerate() {
        if frame["split"].as_str() == Some("train") {
            continue;
        }
        let index = truth.frames[k].index;
        let correction = fitted_camera_correction(&train_indices, &smoothed, index);
        let twist: [f64; TWIST_VALUES] = std::array::from_fn(|i| f64::from(correction[i]));
        let camera = corrected_world_to_camera(&given_cams[k], &twist);
        let (deg, cm) = camera_error(&camera, &true_cams[k]);
        let px = focal * (deg.to_radians() + cm / 100.0 / depth);
        println!("frame {index:3}: {deg:.3}° {cm:.3} cm ≈ {px:.2} px");
        (sum_px, count) = (sum_px + px * px, count + 1);
        let rows: Vec<Value> = camera[..3]
            .iter()
            .map(|r| Value::from(r.to_vec()))
            .collect();
        scene["frames"][k]["world_to_camera"] = Value::Array(rows);
    }
    println!(
        "held-out frames: {count}, RMS ≈ {:.2} px",
        (sum_px / count.max(1) as f64).sqrt()
    );
    std::fs::create_dir_all(out)?;
    for entry in std::fs::read_dir(exact)? {
        let entry = entry?;
        let target = out.join(entry.file_name());
        if entry.file_type()?.is_dir() && !target.exists() {
            link_dir(&std::fs::canonicalize(entry.path())?, &target)?;
        }
    }
    std::fs::write(
        out.join("scene.json"),
        serde_json::to_string_pretty(&scene)? + "\n",
    )?;
    println!("wrote {}", out.join("scene.json").display());
    Ok(())
}

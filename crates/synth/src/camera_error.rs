//! Camera poses as a SLAM or SfM system would estimate them (`--camera-error-deg`,
//! `--camera-error-cm`): every frame's camera pose written to `scene.json` is the true one
//! composed with a smooth error — a slow drift (two sinusoids per axis between 0.05 and 0.3 Hz,
//! random phases) plus 10 % per-frame jitter, scaled so that over the clip the RMS rotation error
//! is `deg` degrees and the RMS centre error `cm` centimetres. The true poses go to
//! `cameras_true.json` beside it, for evaluation only: the trainer must never read them. Nothing
//! rendered changes.

use std::path::{Path, PathBuf};

use glam::{DMat3, DQuat, DVec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::Result;

/// Name of the file of true camera poses inside a scene directory.
pub const TRUE_CAMERAS_FILE: &str = "cameras_true.json";

/// One frame's true camera pose.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrueCamera {
    /// The frame's `index` in `scene.json`.
    pub index: u32,
    /// The true `world_to_camera` at mid exposure, 3 rows of `[R | t]`.
    pub world_to_camera: [[f64; 4]; 3],
}

impl TrueCamera {
    /// The true `world_to_camera` as a row-major 4×4 rigid transform.
    pub fn matrix(&self) -> [[f64; 4]; 4] {
        let r = &self.world_to_camera;
        [r[0], r[1], r[2], [0.0, 0.0, 0.0, 1.0]]
    }
}

/// The whole `cameras_true.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrueCameras {
    /// Always 1.
    pub format_version: u32,
    /// One entry per frame of `scene.json`, in the same order.
    pub frames: Vec<TrueCamera>,
}

impl TrueCameras {
    /// Path of the file in the scene directory `dir`.
    pub fn path(dir: &Path) -> PathBuf {
        dir.join(TRUE_CAMERAS_FILE)
    }

    /// Reads `dir/cameras_true.json`.
    pub fn read(dir: &Path) -> Result<Self> {
        crate::side_file::read_json(&Self::path(dir))
    }

    /// Writes `dir/cameras_true.json` (pretty JSON, trailing newline).
    pub fn write(&self, dir: &Path) -> Result<()> {
        crate::side_file::write_json(&Self::path(dir), self)
    }

    /// Removes `dir/cameras_true.json` if there is one.
    pub fn remove(dir: &Path) -> Result<()> {
        crate::side_file::remove(&Self::path(dir))
    }
}

/// Unit-RMS smooth error per axis at the given times: two slow sinusoids per axis plus 10 %
/// white jitter, normalised to RMS 1 over the times.
fn smooth_unit_error(rng: &mut ChaCha8Rng, times: &[f64]) -> Vec<DVec3> {
    let mut waves = Vec::new();
    for _ in 0..3 {
        let axis: Vec<(f64, f64)> = (0..2)
            .map(|_| {
                (
                    rng.gen_range(0.05..0.3),
                    rng.gen_range(0.0..std::f64::consts::TAU),
                )
            })
            .collect();
        waves.push(axis);
    }
    let mut raw: Vec<DVec3> = times
        .iter()
        .map(|&t| {
            let v = |a: usize| {
                waves[a]
                    .iter()
                    .map(|(hz, phase)| (std::f64::consts::TAU * hz * t + phase).sin())
                    .sum::<f64>()
            };
            DVec3::new(v(0), v(1), v(2))
        })
        .collect();
    for e in &mut raw {
        let jitter = DVec3::new(
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
        );
        *e += 0.1 * jitter;
    }
    let rms = (raw.iter().map(|e| e.length_squared()).sum::<f64>() / raw.len().max(1) as f64)
        .sqrt()
        .max(1e-12);
    raw.into_iter().map(|e| e / rms).collect()
}

/// Rigid 4×4 `[R | t]` from a rotation and a camera centre.
fn rigid(r: DQuat, centre: DVec3) -> [[f64; 4]; 4] {
    let m = DMat3::from_quat(r);
    let t = -(r * centre);
    let row = |k: usize| [m.col(0)[k], m.col(1)[k], m.col(2)[k], t[k]];
    [row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]]
}

/// Rotation and centre of a rigid `[R | t]`.
fn split(m: &[[f64; 4]; 4]) -> (DQuat, DVec3) {
    let r = DQuat::from_mat3(&DMat3::from_cols_array_2d(&[
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ]))
    .normalize();
    (r, -(r.inverse() * DVec3::new(m[0][3], m[1][3], m[2][3])))
}

/// Replaces the camera pose of every frame of `frames` (at `times`, seconds) by an estimate with
/// RMS errors `deg` and `cm`, and returns the true poses. Frames without a pose of their own take
/// `scene_camera`'s as the truth.
pub fn apply(
    frames: &mut [scene::Frame],
    scene_camera: &[[f64; 4]; 4],
    (deg, cm): (f64, f64),
    seed: u64,
) -> TrueCameras {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xCA3E_E220);
    let times: Vec<f64> = frames.iter().map(|f| f.time_s).collect();
    let rotation_error = smooth_unit_error(&mut rng, &times);
    let centre_error = smooth_unit_error(&mut rng, &times);
    let mut truth = Vec::with_capacity(frames.len());
    for (k, frame) in frames.iter_mut().enumerate() {
        let true_pose = frame.world_to_camera.unwrap_or(*scene_camera);
        let (r, centre) = split(&true_pose);
        // The unit errors have RMS length 1 over the clip: scaled, RMS angle `deg`, shift `cm`.
        let dr = DQuat::from_scaled_axis(rotation_error[k] * deg.to_radians());
        let estimate = rigid(dr * r, centre + centre_error[k] * (cm / 100.0));
        frame.world_to_camera = Some(estimate);
        truth.push(TrueCamera {
            index: frame.index,
            world_to_camera: [true_pose[0], true_pose[1], true_pose[2]],
        });
    }
    TrueCameras {
        format_version: 1,
        frames: truth,
    }
}

/// (RMS rotation error in degrees, RMS centre error in cm) of estimated poses against the truth.
pub fn rms_error(estimates: &[[[f64; 4]; 4]], truth: &TrueCameras) -> (f64, f64) {
    let n = estimates.len().min(truth.frames.len()).max(1) as f64;
    let (mut deg2, mut cm2) = (0.0, 0.0);
    for (e, t) in estimates.iter().zip(&truth.frames) {
        let ((re, ce), (rt, ct)) = (split(e), split(&t.matrix()));
        deg2 += re.angle_between(rt).to_degrees().powi(2);
        cm2 += (100.0 * (ce - ct).length()).powi(2);
    }
    ((deg2 / n).sqrt(), (cm2 / n).sqrt())
}

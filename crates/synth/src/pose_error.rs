//! Estimated poses as real data has them: the SMPL parameters a scene gives its trainer come from a
//! monocular fitter (ROMP, PARE, VIBE, HMR 2.0 ...) and are wrong by a few centimetres and a
//! dozen degrees, smoothly over time and worst at the extremities. With a [`PoseError`] that is not
//! zero, the generator writes such an estimate to `scene.json` and the truth to `poses_true.json`
//! ([`crate::true_poses`]).
//!
//! It must never touch what is rendered: images, sharp frames, masks, events and flows all come
//! from the true motion; only the per-frame `pose` and `transl` written to `scene.json` change.
//! With the error off nothing here runs and the output is byte-identical to a generator without it.
//!
//! The error model, per frame k at time `t_k` (seconds):
//! - every scalar error component is `√(1−J)·d(t) + √J·n_k`: a smooth drift `d`, the sum of three
//!   sinusoids of random amplitude in [0.5, 1], frequency in [0.1, 1.0] Hz and phase (unit expected
//!   variance), plus white jitter `n_k ~ N(0, 1)` with the variance share `J` = [`JITTER_SHARE`];
//! - body joint j (1..=23): rotation vector `w_j · (x, y, z)` of three such components (radians
//!   after scaling), composed on SO(3) with the true local rotation: `R_est = exp([e]ₓ) · R_true`
//!   (the error acts in the parent joint's frame); `w_j` is [`JOINT_WEIGHTS`];
//! - root orientation: the same with weight 1, composed in the world frame;
//! - root translation: three components along the camera ray through the true root joint (the
//!   depth a monocular fitter gets least right; [`DEPTH_SHARE`] of the variance) and the two
//!   directions across it.
//!
//! Each part is then scaled so that its realised RMS over the sequence is exactly the requested
//! figure: the RMS over body joints and frames of the geodesic angle (= the rotation vector's
//! length, below π) for `joint_rms_deg`, over frames for `root_orient_rms_deg`, and of the
//! translation error's length for `root_transl_rms_cm`. A rotation error is capped at
//! [`MAX_ERROR_DEG`], a safety net: a component is at most about 5 times its RMS, so within the
//! accepted settings the cap is reached only if a sequence of a few frames happens to draw errors
//! far below their typical size (then scaled up).
//!
//! Randomness: one ChaCha8 stream seeded with `seed ^` [`POSE_ERROR_STREAM`], drawn only when the
//! error is on, so turning it on changes no other random draw of the generator.

use glam::{DQuat, DVec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{Result, SynthError};
use crate::pose_metrics::quat_of;
use crate::true_poses::FramePose;

/// Mixed into the generator seed for the pose-error stream.
pub const POSE_ERROR_STREAM: u64 = 0x905E_E220_0000_0029;
/// Share of each error component's variance that is white per-frame jitter (the rest is drift):
/// 1 %, a jitter of 10 % of the error's RMS, which gives the acceleration error of a VIBE-class
/// fitter (see [`PoseError::REALISTIC`]).
pub const JITTER_SHARE: f64 = 0.01;
/// Share of the translation error's variance along the camera ray through the root.
pub const DEPTH_SHARE: f64 = 0.8;
/// Sinusoids per drift component.
pub const DRIFT_TERMS: usize = 3;
/// Frequency band of the drift sinusoids (Hz).
pub const DRIFT_HZ: [f64; 2] = [0.1, 1.0];
/// Cap of any rotation error (degrees), below the π where the geodesic angle folds back.
pub const MAX_ERROR_DEG: f64 = 170.0;
/// Largest accepted `joint_rms_deg` and `root_orient_rms_deg` (degrees).
pub const MAX_ROTATION_RMS_DEG: f32 = 30.0;
/// Largest accepted `root_transl_rms_cm` (cm).
pub const MAX_TRANSL_RMS_CM: f32 = 50.0;

/// Relative size of each SMPL joint's rotation error (joint 0, the root, has its own setting):
/// spine and collar joints, framed by the torso's large silhouette, err least; hips, knees,
/// shoulders and elbows, which set the limbs' 2D projection, are the reference; the distal joints
/// — ankles, feet, head, wrists, hands — are small in the image, self-occluded and free to twist,
/// so a fitter gets them wrong most. A judgement, not a fit: the overall scale is what the
/// published figures pin down (see [`PoseError::REALISTIC`]).
pub const JOINT_WEIGHTS: [f64; 24] = [
    0.0, // pelvis (root orientation: separate)
    0.8, 0.8, // hips
    0.5, // spine1
    0.9, 0.9, // knees
    0.5, // spine2
    1.3, 1.3, // ankles
    0.5, // spine3
    1.6, 1.6, // feet
    0.8, // neck
    0.6, 0.6, // collars
    1.3, // head
    1.0, 1.0, // shoulders
    1.0, 1.0, // elbows
    1.6, 1.6, // wrists
    1.8, 1.8, // hands
];

/// How wrong the SMPL parameters written to `scene.json` are (all zero: exact, the default).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseError {
    /// RMS over body joints 1..=23 and frames of the geodesic angle between the written and the
    /// true local joint rotation (degrees).
    pub joint_rms_deg: f32,
    /// RMS over frames of the geodesic angle of the root (global) orientation error (degrees).
    pub root_orient_rms_deg: f32,
    /// RMS over frames of the length of the root translation error (centimetres).
    pub root_transl_rms_cm: f32,
}

impl PoseError {
    /// No error: `scene.json` holds the true parameters.
    pub const OFF: Self = Self {
        joint_rms_deg: 0.0,
        root_orient_rms_deg: 0.0,
        root_transl_rms_cm: 0.0,
    };

    /// A VIBE / ROMP / PARE-class monocular fitter on 3DPW (the `realistic` preset).
    ///
    /// Published figures on the 3DPW test set: VIBE MPJPE 82.9 mm, PA-MPJPE 51.9 mm, acceleration
    /// error 23.4 mm/frame² (paperswithcode, VIBE, CVPR 2020); ROMP (HRNet-32) MPJPE 85.5 mm,
    /// PA-MPJPE 53.1 mm, and on the 3DPW challenge set MPJPE 82.7 mm, PA-MPJPE 60.5 mm, MPJAE 20.5°,
    /// PA-MPJAE 18.9° (`docs/romp_evaluation.md` of Arthur151/ROMP); PARE PA-MPJPE 50.9 mm (as
    /// quoted by MMHuman3D's v0.7.0 release notes).
    ///
    /// Chosen by measuring the benchmark's own motion (`cargo run -p synth --example pose_error`,
    /// mean over seeds 0..10, 100 frames; [`crate::pose_metrics`] follows the 3DPW protocol on the
    /// SMPL joints standing in for its 14): 16° per body joint gives PA-MPJPE 51.5 mm (published
    /// 51–53); 6° of root orientation then brings MPJPE to 84.3 mm (published 83–86: the 31–32 mm
    /// gap is mostly global rotation); MPJAE comes out at 16.4° (ROMP's 20.5° is on the harder
    /// challenge set, where its PA-MPJPE is 60.5 mm). The jitter share ([`JITTER_SHARE`]) gives an
    /// acceleration error of 20.6 mm/frame² on a still body, VIBE's 23.4 on everyday motion being
    /// mostly jitter. The translation: depth is what a monocular fitter observes least — a relative
    /// error s in the person's apparent size moves the body by s·d along the camera ray, and 3 % at
    /// the benchmark's 2.6 m is 8 cm. Newer fitters (HMR 2.0) do better: this is a typical, not the
    /// best, estimate.
    pub const REALISTIC: Self = Self {
        joint_rms_deg: 16.0,
        root_orient_rms_deg: 6.0,
        root_transl_rms_cm: 8.0,
    };

    /// True when every figure is zero: nothing is perturbed and nothing extra is written.
    pub fn is_off(&self) -> bool {
        self.joint_rms_deg == 0.0
            && self.root_orient_rms_deg == 0.0
            && self.root_transl_rms_cm == 0.0
    }

    /// The [`PoseError::REALISTIC`] shape scaled so that the per-joint RMS is `joint_rms_deg`
    /// (root orientation and translation in the same proportion): what `--pose-error DEG` sets.
    pub fn scaled_realistic(joint_rms_deg: f32) -> Self {
        let r = Self::REALISTIC;
        let k = joint_rms_deg / r.joint_rms_deg;
        Self {
            joint_rms_deg,
            root_orient_rms_deg: k * r.root_orient_rms_deg,
            root_transl_rms_cm: k * r.root_transl_rms_cm,
        }
    }

    /// Refuses negative, non-finite or too large figures, naming the command-line knob.
    pub fn validate(&self) -> Result<()> {
        for (knob, v, max, unit) in [
            (
                "pose-error",
                self.joint_rms_deg,
                MAX_ROTATION_RMS_DEG,
                "degrees",
            ),
            (
                "root-orient-error",
                self.root_orient_rms_deg,
                MAX_ROTATION_RMS_DEG,
                "degrees",
            ),
            (
                "root-transl-error",
                self.root_transl_rms_cm,
                MAX_TRANSL_RMS_CM,
                "cm",
            ),
        ] {
            if !(v.is_finite() && (0.0..=max).contains(&v)) {
                return Err(SynthError::Knob {
                    knob,
                    value: v.to_string(),
                    reason: format!("must be in 0..={max} {unit}"),
                });
            }
        }
        Ok(())
    }
}

/// One scalar error component: drift sinusoids (amplitude, frequency in Hz, phase in radians).
struct Drift {
    terms: [[f64; 3]; DRIFT_TERMS],
}

impl Drift {
    fn draw(rng: &mut ChaCha8Rng) -> Self {
        Self {
            terms: std::array::from_fn(|_| {
                [
                    rng.gen_range(0.5..=1.0),
                    rng.gen_range(DRIFT_HZ[0]..=DRIFT_HZ[1]),
                    rng.gen_range(0.0..std::f64::consts::TAU),
                ]
            }),
        }
    }

    /// Value at `t` seconds, unit expected variance over time.
    fn at(&self, t: f64) -> f64 {
        let power: f64 = self.terms.iter().map(|[a, _, _]| 0.5 * a * a).sum();
        let sum: f64 = self
            .terms
            .iter()
            .map(|[a, f, p]| a * (std::f64::consts::TAU * f * t + p).sin())
            .sum();
        sum / power.sqrt()
    }
}

/// A standard normal draw (Box–Muller, one of the pair).
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.gen_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.gen_range(0.0..1.0);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Number of scalar components: 3 per joint (joint 0 = root orientation), then 3 of translation.
const COMPONENTS: usize = 3 * 24 + 3;

/// The unscaled error components of every frame: `[frame][component]`, each component drift plus
/// jitter with unit expected variance.
fn components(times: &[f64], rng: &mut ChaCha8Rng) -> Vec<[f64; COMPONENTS]> {
    let drifts: Vec<Drift> = (0..COMPONENTS).map(|_| Drift::draw(rng)).collect();
    let (a, b) = ((1.0 - JITTER_SHARE).sqrt(), JITTER_SHARE.sqrt());
    times
        .iter()
        .map(|&t| std::array::from_fn(|c| a * drifts[c].at(t) + b * normal(rng)))
        .collect()
}

/// Scale making the RMS of the vectors' lengths `target` (0 when they are all zero).
fn rms_scale<'a>(vectors: impl Iterator<Item = &'a DVec3>, target: f64) -> f64 {
    let (mut sq, mut n) = (0.0f64, 0usize);
    for v in vectors {
        sq += v.length_squared();
        n += 1;
    }
    if n == 0 || sq == 0.0 {
        0.0
    } else {
        target / (sq / n as f64).sqrt()
    }
}

/// A rotation vector's rotation, its angle capped at [`MAX_ERROR_DEG`].
fn capped_rotation(e: DVec3) -> DQuat {
    let cap = MAX_ERROR_DEG.to_radians();
    let len = e.length();
    DQuat::from_scaled_axis(if len > cap { e * (cap / len) } else { e })
}

/// Axis-angle (radians, angle in [0, π]) of a rotation, in `f32` as `scene.json` stores it.
fn axis_angle(q: DQuat) -> [f32; 3] {
    let q = if q.w < 0.0 { -q } else { q };
    q.normalize().to_scaled_axis().as_vec3().to_array()
}

/// The estimate of `truth` with the error `err` drawn from `seed`'s pose-error stream.
/// `camera_centre` (world metres) and `root_rest` (the rest-pose root joint, metres; the root
/// joint is at `transl + root_rest`) give the camera ray along which most of the translation error
/// lies. Frames keep their index and time.
pub fn perturb(
    truth: &[FramePose],
    err: &PoseError,
    seed: u64,
    camera_centre: [f64; 3],
    root_rest: [f32; 3],
) -> Vec<FramePose> {
    if err.is_off() || truth.is_empty() {
        return truth.to_vec();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ POSE_ERROR_STREAM);
    let times: Vec<f64> = truth.iter().map(|f| f.time_s).collect();
    let x = components(&times, &mut rng);
    let vec3 = |c: &[f64; COMPONENTS], j: usize| DVec3::new(c[3 * j], c[3 * j + 1], c[3 * j + 2]);

    // Body joints: weighted, then one scale for all.
    let body: Vec<Vec<DVec3>> = x
        .iter()
        .map(|c| (1..24).map(|j| JOINT_WEIGHTS[j] * vec3(c, j)).collect())
        .collect();
    let k_body = rms_scale(
        body.iter().flatten(),
        f64::from(err.joint_rms_deg).to_radians(),
    );
    let root: Vec<DVec3> = x.iter().map(|c| vec3(c, 0)).collect();
    let k_root = rms_scale(root.iter(), f64::from(err.root_orient_rms_deg).to_radians());

    // Translation: depth along the camera ray through the true root, and across it.
    let centre = DVec3::from(camera_centre);
    let (depth, across) = (DEPTH_SHARE.sqrt(), (0.5 * (1.0 - DEPTH_SHARE)).sqrt());
    let transl: Vec<DVec3> = truth
        .iter()
        .zip(&x)
        .map(|(f, c)| {
            let root_world =
                DVec3::from(f.transl.map(f64::from)) + DVec3::from(root_rest.map(f64::from));
            let ray = (root_world - centre).normalize_or(DVec3::Z);
            let side = ray.cross(DVec3::Y).normalize_or(DVec3::X);
            let up = side.cross(ray);
            let t = vec3(c, 24);
            depth * t.x * ray + across * (t.y * side + t.z * up)
        })
        .collect();
    let k_transl = rms_scale(transl.iter(), f64::from(err.root_transl_rms_cm) / 100.0);

    truth
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let mut pose = Vec::with_capacity(f.pose.len());
            for (j, aa) in f.pose.iter().enumerate() {
                let e = match j {
                    0 => k_root * root[k],
                    1..=23 => k_body * body[k][j - 1],
                    _ => DVec3::ZERO,
                };
                // A part without error keeps the true values bit for bit (no round trip).
                pose.push(if e == DVec3::ZERO {
                    *aa
                } else {
                    axis_angle(capped_rotation(e) * quat_of(*aa))
                });
            }
            let d = k_transl * transl[k];
            let t = f.transl;
            FramePose {
                index: f.index,
                time_s: f.time_s,
                pose,
                transl: [
                    (f64::from(t[0]) + d.x) as f32,
                    (f64::from(t[1]) + d.y) as f32,
                    (f64::from(t[2]) + d.z) as f32,
                ],
            }
        })
        .collect()
}

/// Replaces the (true) `pose` and `transl` of the scene's `frames` by their estimate under
/// `cfg.pose_error`, writes the true ones to `out/poses_true.json` and returns the realised error,
/// measured on the values as written. `camera_centre` is in world metres.
pub(crate) fn apply(
    cfg: &crate::SynthConfig,
    body: &crate::body::DressedBody,
    camera_centre: glam::Vec3,
    frames: &mut [scene::Frame],
    out: &std::path::Path,
) -> Result<crate::PoseErrorStats> {
    let truth: Vec<FramePose> = frames
        .iter()
        .map(|f| FramePose {
            index: f.index,
            time_s: f.time_s,
            pose: f.pose.clone(),
            transl: f.transl,
        })
        .collect();
    crate::TruePoses {
        format_version: crate::true_poses::TRUE_POSES_VERSION,
        frames: truth.clone(),
    }
    .write(out)?;
    let joints_rest = body
        .model
        .rest_joints(&body.model.shaped_vertices(&body.betas)?);
    let est = perturb(
        &truth,
        &cfg.pose_error,
        cfg.seed,
        camera_centre.as_dvec3().to_array(),
        joints_rest[0],
    );
    for (f, e) in frames.iter_mut().zip(&est) {
        f.pose.clone_from(&e.pose);
        f.transl = e.transl;
    }
    Ok(crate::pose_metrics::measure(
        &truth,
        &est,
        &joints_rest,
        &body.model.parents,
    ))
}

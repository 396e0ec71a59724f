//! The realised error of estimated SMPL parameters against the true ones, measured on the values as
//! written (`f32` axis-angle), in the units of the monocular-fitter literature on 3DPW: geodesic
//! angles per joint (degrees), root translation (cm), MPJPE and PA-MPJPE (mm), MPJAE (degrees) and
//! the acceleration error (mm per frame²), so the benchmark's `realistic` pose error can be set
//! against published figures (`crate::pose_error`).
//!
//! It measures only: no random numbers, no change to any pose. Sums run sequentially in frame and
//! joint order, so the figures are the same bits whatever the thread count.

use glam::{DQuat, DVec3};
use serde::Serialize;
use smpl_deform::fk::forward_kinematics;

use crate::true_poses::FramePose;

/// The SMPL joints standing in for the 14 LSP joints of the 3DPW evaluation protocol (ankles,
/// knees, hips, wrists, elbows, shoulders, neck, head — SMPL's head joint sits at the base of the
/// skull, not the head top): hips 1, 2; knees 4, 5; ankles 7, 8; neck 12; head 15; shoulders 16,
/// 17; elbows 18, 19; wrists 20, 21. The pelvis of the protocol is the midpoint of the two hips.
pub const LSP14_JOINTS: [usize; 14] = [1, 2, 4, 5, 7, 8, 12, 15, 16, 17, 18, 19, 20, 21];

/// Joints whose *global* orientation the 3DPW challenge's MPJAE compares (as we read its
/// evaluation code's description): root, upper legs (hips), lower legs (knees), upper arms
/// (shoulders), lower arms (elbows), in SMPL numbering.
pub const MPJAE_JOINTS: [usize; 9] = [0, 1, 2, 4, 5, 16, 17, 18, 19];

/// Realised pose-error figures of a scene (`stats.json`, key `pose_error`). Angles in degrees,
/// lengths as named. "Body joints" are SMPL joints 1..=23 (local rotations in the parent's frame);
/// the root orientation (joint 0) is counted separately.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PoseErrorStats {
    /// Number of frames measured.
    pub frames: usize,
    /// Mean over body joints and frames of the geodesic angle between the written and the true
    /// local rotation (degrees).
    pub joint_mean_deg: f64,
    /// Root mean square of the same angle (degrees): what `--pose-error` sets.
    pub joint_rms_deg: f64,
    /// Largest such angle (degrees).
    pub joint_max_deg: f64,
    /// RMS angle per joint over frames (degrees), 24 values in SMPL order; entry 0 is the root
    /// (global) orientation.
    pub per_joint_rms_deg: Vec<f64>,
    /// Mean geodesic angle of the root orientation error over frames (degrees).
    pub root_orient_mean_deg: f64,
    /// RMS of that angle (degrees).
    pub root_orient_rms_deg: f64,
    /// Mean length of the translation error over frames (cm).
    pub root_transl_mean_cm: f64,
    /// RMS length of the translation error (cm).
    pub root_transl_rms_cm: f64,
    /// Temporal smoothness: RMS over body joints and consecutive frame pairs of the angle between
    /// the error rotations `R_est · R_trueᵀ` of the two frames (degrees). White noise of the same
    /// RMS would give about √2 · `joint_rms_deg`.
    pub joint_step_rms_deg: f64,
    /// RMS length of the change of the translation error between consecutive frames (cm).
    pub root_transl_step_rms_cm: f64,
    /// Mean per-joint position error of the [`LSP14_JOINTS`] after aligning the pelvis (their hips'
    /// midpoint) (mm; the 3DPW MPJPE protocol, which includes the root orientation error).
    pub mpjpe_mm: f64,
    /// The same after a per-frame similarity (Procrustes) alignment: rotation, translation, scale
    /// (mm; PA-MPJPE).
    pub pa_mpjpe_mm: f64,
    /// Mean geodesic angle between written and true *global* orientations of the 9 parts of
    /// [`MPJAE_JOINTS`] (degrees; the 3DPW challenge's MPJAE).
    pub mpjae_deg: f64,
    /// Mean over frames 1..N−2 and the pelvis-aligned [`LSP14_JOINTS`] of the length of the difference of
    /// second differences `x_{k+1} − 2x_k + x_{k−1}` (mm per frame²; the acceleration error of
    /// VIBE and later papers). 0 with fewer than 3 frames.
    pub accel_error_mm: f64,
    /// The acceleration error the same error rotations give on a body held still in the first
    /// frame's pose (mm per frame²): the estimate's own jitter, without the part a smooth error
    /// picks up from fast true motion (a constant error of a swinging arm's shoulder moves the
    /// hand's error as fast as the arm). The figure to set against papers' acceleration errors on
    /// everyday motion. 0 with fewer than 3 frames.
    pub accel_error_still_mm: f64,
}

/// Rotation of an axis-angle triple (radians), in f64.
pub fn quat_of(aa: [f32; 3]) -> DQuat {
    DQuat::from_scaled_axis(DVec3::new(
        f64::from(aa[0]),
        f64::from(aa[1]),
        f64::from(aa[2]),
    ))
}

/// Geodesic angle of a unit quaternion's rotation (radians, in `[0, π]`).
pub fn angle_of(q: DQuat) -> f64 {
    2.0 * DVec3::new(q.x, q.y, q.z).length().atan2(q.w.abs())
}

/// Measures `est` against `truth` (same frames, 24 joints each) on the skeleton `joints_rest`
/// (metres) with `parents` (SMPL tree).
///
/// # Panics
/// If the two sequences differ in length or a frame does not hold 24 joints (programming errors:
/// the generator makes both).
pub fn measure(
    truth: &[FramePose],
    est: &[FramePose],
    joints_rest: &[[f32; 3]],
    parents: &[Option<usize>],
) -> PoseErrorStats {
    assert_eq!(truth.len(), est.len(), "one estimate per frame");
    let nj = joints_rest.len();
    let n = truth.len();
    let rest64: Vec<[f64; 3]> = joints_rest.iter().map(|j| j.map(f64::from)).collect();
    let deg = f64::to_degrees;

    // Local rotation errors, per frame and joint: E = R_est · R_trueᵀ (the error as composed).
    let errors: Vec<Vec<DQuat>> = truth
        .iter()
        .zip(est)
        .map(|(t, e)| {
            assert_eq!(t.pose.len(), nj, "24 joints per frame");
            assert_eq!(e.pose.len(), nj, "24 joints per frame");
            (0..nj)
                .map(|j| (quat_of(e.pose[j]) * quat_of(t.pose[j]).inverse()).normalize())
                .collect()
        })
        .collect();

    let mut per_joint_sq = vec![0.0f64; nj];
    let (mut sum, mut sum_sq, mut max, mut count) = (0.0f64, 0.0f64, 0.0f64, 0usize);
    let (mut root_sum, mut root_sq) = (0.0f64, 0.0f64);
    for frame in &errors {
        for (j, q) in frame.iter().enumerate() {
            let a = deg(angle_of(*q));
            per_joint_sq[j] += a * a;
            if j == 0 {
                root_sum += a;
                root_sq += a * a;
            } else {
                sum += a;
                sum_sq += a * a;
                max = max.max(a);
                count += 1;
            }
        }
    }
    let (mut step_sq, mut step_count) = (0.0f64, 0usize);
    for pair in errors.windows(2) {
        for j in 1..nj {
            let a = deg(angle_of(pair[1][j] * pair[0][j].inverse()));
            step_sq += a * a;
            step_count += 1;
        }
    }

    let transl_err: Vec<DVec3> = truth
        .iter()
        .zip(est)
        .map(|(t, e)| DVec3::from(e.transl.map(f64::from)) - DVec3::from(t.transl.map(f64::from)))
        .collect();
    let cm = |d: DVec3| 100.0 * d.length();
    let (mut tr_sum, mut tr_sq) = (0.0f64, 0.0f64);
    for d in &transl_err {
        tr_sum += cm(*d);
        tr_sq += cm(*d).powi(2);
    }
    let mut tr_step_sq = 0.0f64;
    for pair in transl_err.windows(2) {
        tr_step_sq += cm(pair[1] - pair[0]).powi(2);
    }

    // Positions of the LSP-14 stand-ins (pelvis-aligned, metres) and global orientations.
    let skeleton = |f: &FramePose| -> (Vec<DVec3>, Vec<DQuat>) {
        let pose: Vec<f64> = f.pose.iter().flatten().map(|&v| f64::from(v)).collect();
        let fk = forward_kinematics(&pose, [0.0; 3], &rest64, parents);
        let at = |j: usize| DVec3::from(fk.joints_posed[j]);
        let pelvis = 0.5 * (at(1) + at(2));
        let joints = LSP14_JOINTS.iter().map(|&j| at(j) - pelvis).collect();
        let mut global: Vec<DQuat> = Vec::with_capacity(nj);
        for j in 0..nj {
            let local = quat_of(f.pose[j]);
            let g = match parents[j] {
                Some(p) => global[p] * local,
                None => local,
            };
            global.push(g.normalize());
        }
        (joints, global)
    };
    let sk_true: Vec<_> = truth.iter().map(skeleton).collect();
    let sk_est: Vec<_> = est.iter().map(skeleton).collect();
    let (mut mpjpe, mut pa, mut mpjae) = (0.0f64, 0.0f64, 0.0f64);
    for ((jt, gt), (je, ge)) in sk_true.iter().zip(&sk_est) {
        mpjpe += jt
            .iter()
            .zip(je)
            .map(|(a, b)| (*a - *b).length())
            .sum::<f64>()
            / jt.len() as f64;
        pa += procrustes_error(je, jt);
        mpjae += MPJAE_JOINTS
            .iter()
            .map(|&j| deg(angle_of(ge[j] * gt[j].inverse())))
            .sum::<f64>()
            / MPJAE_JOINTS.len() as f64;
    }
    let mut accel = 0.0f64;
    for k in 1..n.saturating_sub(1) {
        let acc = |s: &[(Vec<DVec3>, Vec<DQuat>)], j: usize| {
            s[k + 1].0[j] - 2.0 * s[k].0[j] + s[k - 1].0[j]
        };
        accel += (0..LSP14_JOINTS.len())
            .map(|j| (acc(&sk_est, j) - acc(&sk_true, j)).length())
            .sum::<f64>()
            / LSP14_JOINTS.len() as f64;
    }

    // The error rotations applied to the first frame's pose, held still.
    let mut accel_still = 0.0f64;
    if n >= 3 {
        let still: Vec<(Vec<DVec3>, Vec<DQuat>)> = errors
            .iter()
            .map(|e| {
                let pose = (0..nj)
                    .map(|j| {
                        let q = (e[j] * quat_of(truth[0].pose[j])).normalize();
                        q.to_scaled_axis().as_vec3().to_array()
                    })
                    .collect();
                skeleton(&FramePose {
                    pose,
                    ..truth[0].clone()
                })
            })
            .collect();
        for k in 1..n - 1 {
            accel_still += (0..LSP14_JOINTS.len())
                .map(|j| (still[k + 1].0[j] - 2.0 * still[k].0[j] + still[k - 1].0[j]).length())
                .sum::<f64>()
                / LSP14_JOINTS.len() as f64;
        }
    }

    let div = |a: f64, b: usize| if b > 0 { a / b as f64 } else { 0.0 };
    PoseErrorStats {
        frames: n,
        joint_mean_deg: div(sum, count),
        joint_rms_deg: div(sum_sq, count).sqrt(),
        joint_max_deg: max,
        per_joint_rms_deg: per_joint_sq.iter().map(|s| div(*s, n).sqrt()).collect(),
        root_orient_mean_deg: div(root_sum, n),
        root_orient_rms_deg: div(root_sq, n).sqrt(),
        root_transl_mean_cm: div(tr_sum, n),
        root_transl_rms_cm: div(tr_sq, n).sqrt(),
        joint_step_rms_deg: div(step_sq, step_count).sqrt(),
        root_transl_step_rms_cm: div(tr_step_sq, n.saturating_sub(1)).sqrt(),
        mpjpe_mm: 1000.0 * div(mpjpe, n),
        pa_mpjpe_mm: 1000.0 * div(pa, n),
        mpjae_deg: div(mpjae, n),
        accel_error_mm: 1000.0 * div(accel, n.saturating_sub(2)),
        accel_error_still_mm: 1000.0 * div(accel_still, n.saturating_sub(2)),
    }
}

/// How the posed joints' error looks from a camera: what a monocular method can see of it (across
/// the view ray, on the image) and what it can hardly see (along the ray).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ViewErrorStats {
    /// Mean over frames and the 24 joints of the distance between the written and the true joint
    /// projected into the image (pixels).
    pub image_px: f64,
    /// Mean of the joint position error's component across the view ray, the camera's x and y
    /// (mm; root translation included).
    pub across_mm: f64,
    /// Mean of the absolute component along the camera's z axis (mm).
    pub depth_mm: f64,
}

/// The [`ViewErrorStats`] of `est` against `truth` (24 world joints per frame, from
/// `forward_kinematics` with the translation) seen by the pinhole `camera`; joints behind the camera
/// are not projected (their image error is left out, their position error is kept). Sequential sums.
///
/// # Panics
/// If the two sequences differ in length or a frame does not hold one rotation per rest joint.
pub fn view_error(
    truth: &[FramePose],
    est: &[FramePose],
    joints_rest: &[[f32; 3]],
    parents: &[Option<usize>],
    camera: &scene::Camera,
) -> ViewErrorStats {
    assert_eq!(truth.len(), est.len(), "one estimate per frame");
    let rest64: Vec<[f64; 3]> = joints_rest.iter().map(|j| j.map(f64::from)).collect();
    let m = &camera.world_to_camera;
    let to_camera = |p: [f64; 3]| -> DVec3 {
        let row = |r: usize| m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3];
        DVec3::new(row(0), row(1), row(2))
    };
    let joints = |f: &FramePose| -> Vec<DVec3> {
        let pose: Vec<f64> = f.pose.iter().flatten().map(|&v| f64::from(v)).collect();
        let transl = f.transl.map(f64::from);
        forward_kinematics(&pose, transl, &rest64, parents)
            .joints_posed
            .into_iter()
            .map(to_camera)
            .collect()
    };
    let pixel = |c: DVec3| {
        (
            camera.fx * c.x / c.z + camera.cx,
            camera.fy * c.y / c.z + camera.cy,
        )
    };
    let (mut image, mut projected, mut across, mut depth, mut count) =
        (0.0, 0usize, 0.0, 0.0, 0usize);
    for (t, e) in truth.iter().zip(est) {
        for (a, b) in joints(t).into_iter().zip(joints(e)) {
            let d = b - a;
            across += d.truncate().length();
            depth += d.z.abs();
            count += 1;
            if a.z > 0.0 && b.z > 0.0 {
                let ((ax, ay), (bx, by)) = (pixel(a), pixel(b));
                image += (bx - ax).hypot(by - ay);
                projected += 1;
            }
        }
    }
    let div = |a: f64, b: usize| if b > 0 { a / b as f64 } else { 0.0 };
    ViewErrorStats {
        image_px: div(image, projected),
        across_mm: 1000.0 * div(across, count),
        depth_mm: 1000.0 * div(depth, count),
    }
}

/// Mean distance (metres) between `reference` and `points` after the similarity transform
/// (rotation, translation, scale) that best maps `points` onto `reference` in the least-squares
/// sense (Horn's closed form: the rotation is the top eigenvector of a 4×4 symmetric matrix built
/// from the cross-covariance; the scale then follows in closed form). Reflections are never used.
pub fn procrustes_error(points: &[DVec3], reference: &[DVec3]) -> f64 {
    let n = points.len().min(reference.len());
    if n == 0 {
        return 0.0;
    }
    let centre = |s: &[DVec3]| s[..n].iter().fold(DVec3::ZERO, |a, p| a + *p) / n as f64;
    let (cx, cy) = (centre(points), centre(reference));
    let xs: Vec<DVec3> = points[..n].iter().map(|p| *p - cx).collect();
    let ys: Vec<DVec3> = reference[..n].iter().map(|p| *p - cy).collect();
    let r = best_rotation(&xs, &ys);
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (x, y) in xs.iter().zip(&ys) {
        num += y.dot(r * *x);
        den += x.length_squared();
    }
    let s = if den > 0.0 { num / den } else { 1.0 };
    xs.iter()
        .zip(&ys)
        .map(|(x, y)| (s * (r * *x) - *y).length())
        .sum::<f64>()
        / n as f64
}

/// The rotation `R` maximising `Σ yᵢ · (R xᵢ)` for centred point sets (Horn 1987, unit
/// quaternions).
fn best_rotation(xs: &[DVec3], ys: &[DVec3]) -> DQuat {
    // Cross-covariance S_ab = Σ x_a y_b.
    let mut s = [[0.0f64; 3]; 3];
    for (x, y) in xs.iter().zip(ys) {
        let (x, y) = (x.to_array(), y.to_array());
        for a in 0..3 {
            for b in 0..3 {
                s[a][b] += x[a] * y[b];
            }
        }
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    let mut m = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let (values, vectors) = gaussians::covariance::symmetric_eigen(&mut m);
    let mut best = 0;
    for i in 1..4 {
        if values[i] > values[best] {
            best = i;
        }
    }
    let v = [
        vectors[0][best],
        vectors[1][best],
        vectors[2][best],
        vectors[3][best],
    ];
    DQuat::from_xyzw(v[1], v[2], v[3], v[0]).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_points(rng: &mut ChaCha8Rng, n: usize) -> Vec<DVec3> {
        (0..n)
            .map(|_| {
                DVec3::new(
                    rng.gen_range(-0.5..0.5),
                    rng.gen_range(-0.9..0.9),
                    rng.gen_range(-0.3..0.3),
                )
            })
            .collect()
    }

    fn random_rotation(rng: &mut ChaCha8Rng) -> DQuat {
        DQuat::from_xyzw(
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
        )
        .normalize()
    }

    /// An exact similarity copy aligns to zero error, whatever the rotation (including half
    /// turns, where a naive method picks a reflection or the wrong branch).
    #[test]
    fn procrustes_undoes_a_similarity_transform() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for case in 0..50 {
            let y = random_points(&mut rng, 24);
            let r = if case == 0 {
                DQuat::from_rotation_y(std::f64::consts::PI)
            } else {
                random_rotation(&mut rng)
            };
            let s = rng.gen_range(0.5..2.0);
            let t = DVec3::new(1.0, -2.0, 0.5);
            let x: Vec<DVec3> = y.iter().map(|p| s * (r * *p) + t).collect();
            let e = procrustes_error(&x, &y);
            assert!(e < 1e-9, "case {case}: {e}");
        }
    }

    /// Against a search: no random similarity transform does better than the closed form (mean
    /// distance is not the least-squares objective, so allow a hair), and the closed form beats
    /// pelvis-style centring alone.
    #[test]
    fn procrustes_is_no_worse_than_sampled_alignments() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for case in 0..10 {
            let y = random_points(&mut rng, 24);
            let r = random_rotation(&mut rng);
            let x: Vec<DVec3> = y
                .iter()
                .map(|p| 1.1 * (r * *p) + DVec3::new(rng.gen_range(-0.05..0.05), 0.0, 0.02))
                .collect();
            let best = procrustes_error(&x, &y);
            let cx = x.iter().fold(DVec3::ZERO, |a, p| a + *p) / 24.0;
            let cy = y.iter().fold(DVec3::ZERO, |a, p| a + *p) / 24.0;
            let rms = |q: DQuat, s: f64| {
                (x.iter()
                    .zip(&y)
                    .map(|(a, b)| (s * (q * (*a - cx)) - (*b - cy)).length_squared())
                    .sum::<f64>()
                    / 24.0)
                    .sqrt()
            };
            let mean = |q: DQuat, s: f64| {
                x.iter()
                    .zip(&y)
                    .map(|(a, b)| (s * (q * (*a - cx)) - (*b - cy)).length())
                    .sum::<f64>()
                    / 24.0
            };
            assert!(best < mean(DQuat::IDENTITY, 1.0), "case {case}");
            // Near the true inverse, every sampled transform is worse in RMS than the optimum's
            // RMS (which bounds its mean error from above).
            let opt_rms = {
                let rr = best_rotation(
                    &x.iter().map(|p| *p - cx).collect::<Vec<_>>(),
                    &y.iter().map(|p| *p - cy).collect::<Vec<_>>(),
                );
                let num: f64 = x
                    .iter()
                    .zip(&y)
                    .map(|(a, b)| (*b - cy).dot(rr * (*a - cx)))
                    .sum();
                let den: f64 = x.iter().map(|a| (*a - cx).length_squared()).sum();
                rms(rr, num / den)
            };
            for _ in 0..300 {
                let dq = DQuat::from_scaled_axis(DVec3::new(
                    rng.gen_range(-0.2..0.2),
                    rng.gen_range(-0.2..0.2),
                    rng.gen_range(-0.2..0.2),
                ));
                let q = dq * r.inverse();
                let s = rng.gen_range(0.8..1.0);
                assert!(rms(q, s) >= opt_rms - 1e-12, "case {case}");
            }
        }
    }

    #[test]
    fn the_view_error_splits_a_shift_across_and_along_the_view_ray() {
        let body = smpl_deform::BodyModel::builtin_makehuman().unwrap();
        let rest = body.rest_joints(&body.shaped_vertices(&[]).unwrap());
        // A camera 3 m in front of the body, looking along world −z (camera z = −world z).
        let camera = scene::Camera::new(
            256,
            256,
            300.0,
            300.0,
            128.0,
            128.0,
            [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, -1.0, 0.0, 0.0],
                [0.0, 0.0, -1.0, 3.0],
                [0.0, 0.0, 0.0, 1.0],
            ],
        )
        .unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let truth: Vec<FramePose> = (0..4)
            .map(|k| FramePose {
                index: k,
                time_s: f64::from(k) / 30.0,
                pose: (0..24)
                    .map(|_| [0; 3].map(|_| rng.gen_range(-0.3f32..0.3)))
                    .collect(),
                transl: [0.0, 0.0, 0.0],
            })
            .collect();
        // The truth moved by `transl` (world metres), seen from the camera.
        let moved_by = |transl: [f32; 3]| {
            let est: Vec<FramePose> = truth
                .iter()
                .map(|f| FramePose {
                    transl,
                    ..f.clone()
                })
                .collect();
            view_error(&truth, &est, &rest, &body.parents, &camera)
        };
        assert_eq!(moved_by([0.0; 3]), ViewErrorStats::default());
        // 2 cm along world x: across the ray, 300·0.02/z pixels per joint; no depth error.
        let v = moved_by([0.02, 0.0, 0.0]);
        assert!(
            (v.across_mm - 20.0).abs() < 1e-4 && v.depth_mm < 1e-6,
            "{v:?}"
        );
        let rest64: Vec<[f64; 3]> = rest.iter().map(|j| j.map(f64::from)).collect();
        let mut expected = 0.0;
        for f in &truth {
            let pose: Vec<f64> = f.pose.iter().flatten().map(|&x| f64::from(x)).collect();
            let fk = forward_kinematics(&pose, [0.0; 3], &rest64, &body.parents);
            for j in &fk.joints_posed {
                expected += 300.0 * 0.02 / (3.0 - j[2]);
            }
        }
        expected /= 4.0 * 24.0;
        assert!(
            (v.image_px - expected).abs() < 1e-6,
            "{} {expected}",
            v.image_px
        );
        // 5 cm along the ray: all depth, and a small image change only off the optical axis.
        let v = moved_by([0.0, 0.0, -0.05]);
        assert!(
            (v.depth_mm - 50.0).abs() < 1e-4 && v.across_mm < 1e-6,
            "{v:?}"
        );
        assert!(v.image_px > 0.0 && v.image_px < 1.0, "{v:?}");
    }

    #[test]
    fn angle_of_is_the_geodesic_angle() {
        for a in [0.0, 0.1, 1.0, 3.0, std::f64::consts::PI] {
            let q = DQuat::from_axis_angle(DVec3::new(0.0, 0.6, 0.8), a);
            assert!((angle_of(q) - a).abs() < 1e-12, "{a}");
            assert!((angle_of(-q) - a).abs() < 1e-12, "{a} (negated quaternion)");
        }
    }
}

//! Poses inside an exposure against the benchmark generator's true sub-frame poses: the default
//! benchmark's motion sampled at its frame times (what `scene.json` records), interpolated by
//! `train::pose::exposure::PoseTrack` at the 16 sub-frame times of every exposure the generator rendered,
//! and compared joint by joint with the generator's own pose at those times.
#![allow(clippy::unwrap_used)]

use glam::{DQuat, DVec3};
use smpl_deform::{BodyModel, SmplParams};
use synth::body::DressedBody;
use train::config::TrackTangents;
use train::pose::exposure::{subframe_times, CameraTrack, PoseTrack};

/// (mean, max) joint-rotation error in degrees over the 24 joints of two poses, and the
/// translation error in cm.
fn pose_error(a: &SmplParams, b: &SmplParams) -> (f64, f64, f64) {
    let quat = |p: &SmplParams, j: usize| {
        let r = &p.pose[3 * j..3 * j + 3];
        DQuat::from_scaled_axis(DVec3::new(r[0].into(), r[1].into(), r[2].into()))
    };
    let errs: Vec<f64> = (0..24)
        .map(|j| quat(a, j).angle_between(quat(b, j)).to_degrees())
        .collect();
    let mean = errs.iter().sum::<f64>() / 24.0;
    let max = errs.iter().copied().fold(0.0, f64::max);
    let dt: f64 = (0..3)
        .map(|k| (f64::from(a.transl[k]) - f64::from(b.transl[k])).powi(2))
        .sum::<f64>()
        .sqrt();
    (mean, max, 100.0 * dt)
}

/// Sub-frame body pose errors of the track through the generator's frame poses, tangents by
/// `rule`, over the interior frames' 16 sub-frame times: (mean per joint °, worst joint °, root cm,
/// the mid-exposure pose held over the exposure °, worst joint of the extrapolated end frames °).
fn sub_frame_pose_errors(rule: TrackTangents) -> (f64, f64, f64, f64, f64) {
    let cfg = synth::SynthConfig::preset(synth::Preset::Default);
    let body = DressedBody::new(BodyModel::builtin_makehuman().unwrap(), vec![0.0; 10]).unwrap();
    let motion = synth::generate::benchmark_motion(&cfg, &body).unwrap();
    let params = |t: f64| {
        let (pose, transl) = motion.at(t);
        SmplParams {
            pose,
            betas: vec![],
            transl,
        }
    };
    let frames = cfg.frames as usize;
    let keys: Vec<(f64, SmplParams)> = (0..frames)
        .map(|k| {
            let t = k as f64 / cfg.fps;
            (t, params(t))
        })
        .collect();
    let refs: Vec<(f64, &SmplParams)> = keys.iter().map(|(t, p)| (*t, p)).collect();
    let track = PoseTrack::new(&refs, rule);
    let exposure = cfg.exposure_fraction / cfg.fps;
    let (mut sum, mut worst, mut sum_cm, mut held_sum, mut n) = (0.0, 0.0f64, 0.0, 0.0, 0usize);
    let mut ends = 0.0f64;
    for (k, (tk, key)) in keys.iter().enumerate() {
        for t in subframe_times(*tk, exposure, cfg.subframes as usize) {
            if k == 0 || k + 1 == frames {
                // The first and last exposures reach beyond the recorded poses: extrapolated.
                ends = ends.max(pose_error(&track.at(t), &params(t)).1);
                continue;
            }
            let truth = params(t);
            let (mean, max, cm) = pose_error(&track.at(t), &truth);
            sum += mean;
            worst = worst.max(max);
            sum_cm += cm;
            // The pose held constant over the exposure (what training without the exposure model
            // assumes), for comparison.
            held_sum += pose_error(key, &truth).0;
            n += 1;
        }
    }
    let (mean, held, cm) = (sum / n as f64, held_sum / n as f64, sum_cm / n as f64);
    println!(
        "{rule:?}: sub-frame pose error over {n} samples of the interior frames: interpolated \
         {mean:.4}° mean per joint ({worst:.3}° worst joint), {cm:.4} cm root; the mid-exposure \
         pose held over the exposure {held:.3}°; first and last frames (extrapolated) {ends:.2}° \
         worst joint"
    );
    (mean, worst, cm, held, ends)
}

#[test]
fn interpolated_sub_frame_poses_match_the_generator() {
    let (mean, worst, cm, held, ends) = sub_frame_pose_errors(TrackTangents::Local);
    // Measured when written: 0.23° mean per joint against 2.18° for the held pose, 8.4° worst joint,
    // 0.05 cm root. The worst joints are the knees and hips: the generator lifts each thigh by
    // max(0, sin), a kink no curve through the frame poses can follow. The bounds leave a margin over
    // those figures and fail on a wrong tangent or a segment off by one (measured: a negated tangent
    // gives 1.47° mean, the next segment's curve 1.39°).
    assert!(mean < 0.15 * held, "interpolation {mean}° vs held {held}°");
    assert!(worst < 12.0, "worst joint {worst}°");
    assert!(cm < 0.1, "root {cm} cm");
    assert!(ends < 30.0, "extrapolated ends {ends}°");
}

#[test]
fn band_limited_body_tangents_follow_the_generator_closer_than_local_ones() {
    let local = sub_frame_pose_errors(TrackTangents::Local);
    let band = sub_frame_pose_errors(TrackTangents::BandLimited);
    // Measured when written: 0.193° mean per joint (7.38° worst) against the local rule's 0.230°
    // (8.40°). The bound asks for at least a tenth less mean error, which a flipped or truncated
    // differentiator does not give.
    assert!(
        band.0 < 0.9 * local.0,
        "band-limited {}° vs local {}°",
        band.0,
        local.0
    );
    assert!(band.1 < local.1, "worst joint {}° vs {}°", band.1, local.1);
    assert!(band.2 < 0.1, "root {} cm", band.2);
}

type Matrix = [[f64; 4]; 4];

fn rotation(m: &Matrix) -> DQuat {
    DQuat::from_mat3(&glam::DMat3::from_cols_array_2d(&[
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ]))
    .normalize()
}

fn centre(m: &Matrix) -> DVec3 {
    -(rotation(m).inverse() * DVec3::new(m[0][3], m[1][3], m[2][3]))
}

/// (degrees, cm) between two camera poses.
fn camera_error(a: &Matrix, b: &Matrix) -> (f64, f64) {
    (
        rotation(a).angle_between(rotation(b)).to_degrees(),
        100.0 * (centre(a) - centre(b)).length(),
    )
}

/// The world-to-camera matrix of rotation `r` and centre `c`.
fn matrix_of(r: DQuat, c: DVec3) -> Matrix {
    let m = glam::DMat3::from_quat(r);
    let t = -(r * c);
    let row = |k: usize| [m.col(0)[k], m.col(1)[k], m.col(2)[k], t[k]];
    [row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]]
}

/// The generator's handheld path (seed 0, the benchmark's) at 30 fps frame times, and the RMS and
/// worst rotation error of `interpolation` at the 16 sub-frame times of the interior exposures,
/// with the RMS and largest turn from mid exposure inside them (degrees), and the worst centre
/// error (cm).
fn handheld_track_error(interpolation: TrackTangents) -> [f64; 5] {
    use synth::camera::PinholeCamera;
    use synth::camera_motion::{CameraMotion, CameraPath};
    let (eye, target) = (
        glam::Vec3::new(0.5, 1.3, 2.6),
        glam::Vec3::new(0.0, 0.9, 0.0),
    );
    let base = PinholeCamera::look_at(256, 256, 0.8, eye, target);
    let path = CameraPath::new(CameraMotion::Handheld, base, (0.8, eye, target), 0);
    let matrix = |t: f64| path.at(t).to_scene().world_to_camera;
    let fps = 30.0;
    let keys: Vec<(f64, Matrix)> = (0..100)
        .map(|k| (k as f64 / fps, matrix(k as f64 / fps)))
        .collect();
    let track = CameraTrack::new(&keys, interpolation);
    for (t, m) in &keys {
        let (deg, cm) = camera_error(&track.at(*t), m);
        // The generator's cameras are f32: rotation rows orthonormal to ~1e-7, which the track's
        // quaternion round trip turns into sub-micrometre centre differences.
        assert!(deg < 1e-4 && cm < 1e-3, "key at {t} s: {deg}°, {cm} cm");
    }
    let [mut squared, mut worst, mut moved_squared, mut moved, mut worst_cm] = [0.0f64; 5];
    let mut count = 0.0;
    for k in 2..98 {
        let t = k as f64 / fps;
        for ts in subframe_times(t, 1.0 / fps, 16) {
            let (deg, cm) = camera_error(&track.at(ts), &matrix(ts));
            let turn = camera_error(&matrix(ts), &matrix(t)).0;
            squared += deg * deg;
            worst = worst.max(deg);
            moved_squared += turn * turn;
            moved = moved.max(turn);
            worst_cm = worst_cm.max(cm);
            count += 1.0;
        }
    }
    [
        (squared / count).sqrt(),
        worst,
        (moved_squared / count).sqrt(),
        moved,
        worst_cm,
    ]
}

/// A handheld camera (the generator's own path) sampled at 30 fps frame times and interpolated
/// by `CameraTrack` at the 16 sub-frame times of each exposure: through its keys exactly, and
/// within a small fraction of the motion in between. Measured when written (seed 0): RMS error
/// 0.0059° band-limited, 0.0523° local, of an RMS turn of 0.1415° from mid exposure; the bounds
/// fail on the local rule for the band-limited track and on a wrong sign of the differentiator's
/// alternation (measured: 0.085°).
#[test]
fn interpolated_sub_frame_cameras_follow_a_handheld_path() {
    let [rms, worst, moved_rms, moved, worst_cm] = handheld_track_error(TrackTangents::BandLimited);
    eprintln!(
        "band-limited: RMS {rms:.4}° (worst {worst:.4}°) of an RMS turn of {moved_rms:.4}° \
         (largest {moved:.4}°), worst centre {worst_cm:.4} cm"
    );
    assert!(moved > 0.02, "the camera turns {moved}° within an exposure");
    assert!(rms < 0.08 * moved_rms, "{rms}° against {moved_rms}°");
    assert!(worst < 0.15 * moved, "{worst}° against {moved}° of motion");
    assert!(worst_cm < 0.05, "{worst_cm} cm");
    let [rms, worst, moved_rms, moved, worst_cm] = handheld_track_error(TrackTangents::Local);
    eprintln!("local: RMS {rms:.4}° (worst {worst:.4}°) of {moved_rms:.4}°");
    assert!(
        rms < 0.45 * moved_rms && rms > 0.2 * moved_rms,
        "{rms}° against {moved_rms}°"
    );
    assert!(worst < 0.5 * moved, "{worst}° against {moved}° of motion");
    assert!(worst_cm < 0.05, "{worst_cm} cm");
}

/// A camera turning at a constant rate about a fixed axis while its centre moves at constant
/// velocity: both rules follow it exactly, inside the clip and past its ends; the band-limited
/// curve is C¹ across a key (one-sided difference quotients agree) and falls back to the local
/// rule where the keys are not evenly spaced.
#[test]
fn constant_camera_motion_is_followed_exactly_and_smoothly() {
    let axis = DVec3::new(0.3, 1.0, -0.2).normalize();
    let truth = |t: f64| {
        matrix_of(
            DQuat::from_axis_angle(axis, 0.4 * t),
            DVec3::new(0.5, 1.3, 2.6) + DVec3::new(0.2, -0.05, 0.1) * t,
        )
    };
    let keys: Vec<(f64, Matrix)> = (0..40)
        .map(|k| (k as f64 / 30.0, truth(k as f64 / 30.0)))
        .collect();
    for interpolation in [TrackTangents::BandLimited, TrackTangents::Local] {
        let track = CameraTrack::new(&keys, interpolation);
        for t in [-0.01, 0.004, 0.05, 0.4321, 1.0, 1.3, 1.31] {
            let (deg, cm) = camera_error(&track.at(t), &truth(t));
            assert!(
                deg < 1e-9 && cm < 1e-9,
                "{interpolation:?} at {t}: {deg}°, {cm} cm"
            );
        }
    }
    // A wobbling camera: the derivative from each side of key 10 agrees (one-sided second-order
    // difference quotients of the matrix entries; their own error is ~1e-5 of the derivative).
    let wobble = |t: f64| {
        matrix_of(
            DQuat::from_axis_angle(axis, 0.01 * (60.0 * t).sin()),
            DVec3::new(0.01 * (50.0 * t).cos(), 0.0, 0.0),
        )
    };
    let keys: Vec<(f64, Matrix)> = (0..40)
        .map(|k| (k as f64 / 30.0, wobble(k as f64 / 30.0)))
        .collect();
    let track = CameraTrack::new(&keys, TrackTangents::BandLimited);
    let (knot, d) = (10.0 / 30.0, 1e-4);
    let (at, before, after) = (
        track.at(knot),
        [track.at(knot - d), track.at(knot - 2.0 * d)],
        [track.at(knot + d), track.at(knot + 2.0 * d)],
    );
    let (mut largest, mut jump) = (0.0f64, 0.0f64);
    for r in 0..3 {
        for c in 0..4 {
            let left = (3.0 * at[r][c] - 4.0 * before[0][r][c] + before[1][r][c]) / (2.0 * d);
            let right = (-3.0 * at[r][c] + 4.0 * after[0][r][c] - after[1][r][c]) / (2.0 * d);
            largest = largest.max(left.abs());
            jump = jump.max((left - right).abs());
        }
    }
    assert!(
        largest > 0.1 && jump < 1e-3 * largest,
        "derivative {largest}, jump {jump}"
    );
    // Uneven keys: the band-limited track is the local one.
    let mut uneven = keys.clone();
    uneven[20].0 += 0.004;
    let (a, b) = (
        CameraTrack::new(&uneven, TrackTangents::BandLimited),
        CameraTrack::new(&uneven, TrackTangents::Local),
    );
    assert_eq!(a.at(0.69), b.at(0.69));
    assert_ne!(
        CameraTrack::new(&keys, TrackTangents::BandLimited).at(0.69),
        CameraTrack::new(&keys, TrackTangents::Local).at(0.69)
    );
}

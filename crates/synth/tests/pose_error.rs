#![allow(clippy::unwrap_used)]
//! Estimated poses (`synth::pose_error`): what is rendered does not change, the truth is written
//! beside the scene and equals the unperturbed parameters, the realised error is what was asked
//! for (measured here independently, on SO(3)), it is larger at the extremities, smooth in time
//! and deterministic for a seed.

use std::collections::BTreeMap;
use std::path::Path;

use glam::{DQuat, DVec3};
use synth::body::{capsule_body, DressedBody};
use synth::generate::benchmark_motion;
use synth::pose_error::perturb;
use synth::{
    generate_with_body, FramePose, PoseError, Preset, Speed, SynthConfig, SynthError, TruePoses,
    TRUE_POSES_FILE,
};

fn small() -> SynthConfig {
    SynthConfig {
        frames: 4,
        width: 40,
        height: 32,
        subframes: 2,
        supersample: 1,
        speed: Speed::Fast,
        event_flow: false,
        ..SynthConfig::preset(Preset::Tiny)
    }
}

fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
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

fn json(bytes: &[u8]) -> serde_json::Value {
    serde_json::from_slice(bytes).unwrap()
}

/// `[index, time, pose, transl]` of every frame of a `scene.json`.
fn scene_poses(scene: &serde_json::Value) -> Vec<FramePose> {
    scene["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| FramePose {
            index: serde_json::from_value(f["index"].clone()).unwrap(),
            time_s: f["time_s"].as_f64().unwrap(),
            pose: serde_json::from_value(f["pose"].clone()).unwrap(),
            transl: serde_json::from_value(f["transl"].clone()).unwrap(),
        })
        .collect()
}

#[test]
fn pose_error_changes_only_the_smpl_parameters_and_writes_the_truth() {
    let off = small();
    let on = SynthConfig {
        pose_error: PoseError {
            joint_rms_deg: 10.0,
            root_orient_rms_deg: 5.0,
            root_transl_rms_cm: 6.0,
        },
        ..small()
    };
    let (a, b, c) = (
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
    );
    let pool = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    generate_with_body(&off, capsule_body(), a.path(), &mut |_, _| {}).unwrap();
    let stats = pool(2)
        .install(|| generate_with_body(&on, capsule_body(), b.path(), &mut |_, _| {}))
        .unwrap();
    // Same seed, another thread count: the same bytes.
    pool(1)
        .install(|| generate_with_body(&on, capsule_body(), c.path(), &mut |_, _| {}))
        .unwrap();
    let (fa, fb, fc) = (files(a.path()), files(b.path()), files(c.path()));
    assert_eq!(fb, fc, "same settings, different bytes");

    // Every render, mask, flow and event file is the unperturbed benchmark's.
    let mut only_in_b: Vec<&String> = fb.keys().filter(|k| !fa.contains_key(*k)).collect();
    only_in_b.sort();
    assert_eq!(only_in_b, vec![&TRUE_POSES_FILE.to_string()]);
    for (k, v) in &fa {
        if k != "scene.json" && k != "stats.json" {
            assert!(fb[k] == *v, "{k} changed with the pose error on");
        }
    }

    // The truth file holds exactly the parameters the unperturbed scene.json holds.
    let truth = TruePoses::read(b.path()).unwrap();
    let unperturbed = scene_poses(&json(&fa["scene.json"]));
    assert_eq!(truth.frames, unperturbed);
    // The perturbed scene is valid scene format v1, says where the truth is, and differs from it.
    let loaded = scene::load(b.path()).unwrap();
    assert_eq!(loaded.frames.len(), 4);
    let scene_b = json(&fb["scene.json"]);
    assert_eq!(scene_b["generator"]["true_poses"], TRUE_POSES_FILE);
    assert!(json(&fa["scene.json"])["generator"]
        .get("true_poses")
        .is_none());
    let estimate = scene_poses(&scene_b);
    for (e, t) in estimate.iter().zip(&truth.frames) {
        assert_eq!((e.index, e.time_s), (t.index, t.time_s));
        assert_ne!(e.pose, t.pose);
        assert_ne!(e.transl, t.transl);
    }
    // stats.json records the realised error only when it is on.
    let e = stats.pose_error.as_ref().unwrap();
    assert!((e.joint_rms_deg - 10.0).abs() < 0.01, "{e:?}");
    assert!((e.root_orient_rms_deg - 5.0).abs() < 0.01, "{e:?}");
    assert!((e.root_transl_rms_cm - 6.0).abs() < 0.01, "{e:?}");
    assert!(json(&fb["stats.json"])["pose_error"]["joint_rms_deg"].is_f64());
    assert!(json(&fa["stats.json"]).get("pose_error").is_none());

    // Regenerating without the error into that directory leaves no stale truth file behind.
    generate_with_body(&off, capsule_body(), b.path(), &mut |_, _| {}).unwrap();
    assert!(
        files(b.path()) == fa,
        "regenerated without the error, other bytes"
    );
}

/// The benchmark motion's true parameters on the capsule body, `frames` frames at 30 fps.
fn truth_sequence(seed: u64, frames: u32) -> (Vec<FramePose>, [f32; 3]) {
    let cfg = SynthConfig {
        seed,
        frames,
        ..SynthConfig::preset(Preset::Default)
    };
    let body = DressedBody::new(capsule_body(), vec![0.0; 10]).unwrap();
    let motion = benchmark_motion(&cfg, &body).unwrap();
    let truth = (0..frames)
        .map(|k| {
            let t = f64::from(k) / cfg.fps;
            let (pose, transl) = motion.at(t);
            FramePose {
                index: k,
                time_s: t,
                pose: pose.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
                transl,
            }
        })
        .collect();
    (truth, body.model.joints_rest[0])
}

const CAMERA: [f64; 3] = [0.5, 1.3, 2.6];

fn rot(aa: [f32; 3]) -> DQuat {
    DQuat::from_scaled_axis(DVec3::new(aa[0].into(), aa[1].into(), aa[2].into()))
}

/// Geodesic angle (degrees) between two axis-angle rotations, from the rotation matrices' trace
/// (independent of the quaternion path the crate uses).
fn geodesic_deg(a: [f32; 3], b: [f32; 3]) -> f64 {
    let (ma, mb) = (
        glam::DMat3::from_quat(rot(a)),
        glam::DMat3::from_quat(rot(b)),
    );
    let rel = ma.transpose() * mb;
    let cos = 0.5 * (rel.x_axis.x + rel.y_axis.y + rel.z_axis.z - 1.0);
    cos.clamp(-1.0, 1.0).acos().to_degrees()
}

/// RMS geodesic angle over joints `js` and frames (degrees).
fn rms_deg(truth: &[FramePose], est: &[FramePose], js: &[usize]) -> f64 {
    let mut sq = 0.0;
    let mut n = 0;
    for (t, e) in truth.iter().zip(est) {
        for &j in js {
            sq += geodesic_deg(t.pose[j], e.pose[j]).powi(2);
            n += 1;
        }
    }
    (sq / n as f64).sqrt()
}

/// The written estimate has the requested RMS errors (tolerance 0.5 %: only f32 rounding of the
/// written values separates them), measured as geodesic angles on SO(3). The benchmark's joints
/// turn by up to 90° and more, where an error added to the axis-angle vector instead of composed
/// with the rotation would not have the requested geodesic size.
#[test]
fn realised_error_is_the_requested_one() {
    let body_joints: Vec<usize> = (1..24).collect();
    for (seed, deg, root_deg, cm) in [
        (0u64, 16.0f32, 6.0f32, 8.0f32),
        (1, 5.0, 0.0, 0.0),
        (2, 30.0, 30.0, 50.0),
        (3, 0.0, 4.0, 2.0),
    ] {
        let (truth, root_rest) = truth_sequence(seed, 100);
        let err = PoseError {
            joint_rms_deg: deg,
            root_orient_rms_deg: root_deg,
            root_transl_rms_cm: cm,
        };
        let est = perturb(&truth, &err, seed, CAMERA, root_rest);
        let close = |got: f64, want: f32, what: &str| {
            let want = f64::from(want);
            assert!(
                (got - want).abs() <= 0.005 * want + 1e-4,
                "seed {seed}: {what} RMS {got} for {want} requested"
            );
        };
        close(rms_deg(&truth, &est, &body_joints), deg, "body joint");
        close(rms_deg(&truth, &est, &[0]), root_deg, "root orientation");
        // A part asked to be exact is written exactly.
        for (t, e) in truth.iter().zip(&est) {
            if deg == 0.0 {
                assert_eq!(t.pose[1..], e.pose[1..], "seed {seed}");
            }
            if root_deg == 0.0 {
                assert_eq!(t.pose[0], e.pose[0], "seed {seed}");
            }
            if cm == 0.0 {
                assert_eq!(t.transl, e.transl, "seed {seed}");
            }
        }
        let transl_sq: f64 = truth
            .iter()
            .zip(&est)
            .map(|(t, e)| {
                (0..3)
                    .map(|i| (100.0 * f64::from(e.transl[i] - t.transl[i])).powi(2))
                    .sum::<f64>()
            })
            .sum();
        close((transl_sq / 100.0).sqrt(), cm, "root translation (cm)");
        // The crate's own figures agree with this measurement.
        let joints_rest = capsule_body().joints_rest;
        let parents = capsule_body().parents;
        let s = synth::pose_metrics::measure(&truth, &est, &joints_rest, &parents);
        close(s.joint_rms_deg, deg, "stats.json body joint");
        close(
            s.root_orient_rms_deg,
            root_deg,
            "stats.json root orientation",
        );
        close(s.root_transl_rms_cm, cm, "stats.json root translation");
        assert!(s.joint_mean_deg <= s.joint_rms_deg + 1e-9);
        if deg > 0.0 {
            assert!(s.pa_mpjpe_mm > 0.0 && s.mpjpe_mm > 0.0 && s.mpjae_deg > 0.0);
        }
    }
}

/// Every joint turned by about 2.5 rad (where adding the error to the axis-angle vector would
/// miss the requested geodesic size by far): the composed error still has the requested size.
#[test]
fn error_composes_on_so3_for_large_true_rotations() {
    let (mut truth, root_rest) = truth_sequence(4, 60);
    for (k, f) in truth.iter_mut().enumerate() {
        for (j, aa) in f.pose.iter_mut().enumerate() {
            let axis = DVec3::new(1.0, (j as f64).sin(), (0.1 * k as f64).cos()).normalize();
            *aa = (2.5 * axis).as_vec3().to_array();
        }
    }
    let err = PoseError {
        joint_rms_deg: 12.0,
        root_orient_rms_deg: 12.0,
        root_transl_rms_cm: 0.0,
    };
    let est = perturb(&truth, &err, 4, CAMERA, root_rest);
    let all: Vec<usize> = (0..24).collect();
    let got = rms_deg(&truth, &est, &all);
    assert!((got - 12.0).abs() < 0.06, "{got}");
}

/// Wrists, hands, ankles, feet and head err more than the spine (pooled over seeds), and the
/// translation error lies mostly along the camera ray.
#[test]
fn error_is_largest_at_the_extremities_and_in_depth() {
    let (mut distal, mut spine) = (0.0, 0.0);
    let (mut along, mut total) = (0.0, 0.0);
    for seed in 0..5 {
        let (truth, root_rest) = truth_sequence(seed, 100);
        let est = perturb(&truth, &PoseError::REALISTIC, seed, CAMERA, root_rest);
        distal += rms_deg(&truth, &est, &[7, 8, 10, 11, 15, 20, 21, 22, 23]);
        spine += rms_deg(&truth, &est, &[3, 6, 9]);
        for (t, e) in truth.iter().zip(&est) {
            let root = DVec3::from(t.transl.map(f64::from)) + DVec3::from(root_rest.map(f64::from));
            let ray = (root - DVec3::from(CAMERA)).normalize();
            let d = DVec3::from(e.transl.map(f64::from)) - DVec3::from(t.transl.map(f64::from));
            along += d.dot(ray).powi(2);
            total += d.length_squared();
        }
    }
    assert!(distal > 2.0 * spine, "distal {distal} vs spine {spine}");
    let share = along / total;
    assert!(share > 0.6, "depth share of the translation error {share}");
}

/// Smooth in time: the error rotation changes from frame to frame by a fraction of its size
/// (white noise of the same size would change by about √2 times it), and so does the translation.
#[test]
fn error_is_smooth_in_time() {
    for seed in 0..3 {
        let (truth, root_rest) = truth_sequence(seed, 100);
        let est = perturb(&truth, &PoseError::REALISTIC, seed, CAMERA, root_rest);
        let err = |k: usize, j: usize| rot(est[k].pose[j]) * rot(truth[k].pose[j]).inverse();
        let (mut step_sq, mut n) = (0.0, 0);
        for k in 1..truth.len() {
            for j in 1..24 {
                let d = err(k, j) * err(k - 1, j).inverse();
                step_sq += (2.0 * DVec3::new(d.x, d.y, d.z).length().atan2(d.w.abs()))
                    .to_degrees()
                    .powi(2);
                n += 1;
            }
        }
        let step = (step_sq / f64::from(n)).sqrt();
        let size = f64::from(PoseError::REALISTIC.joint_rms_deg);
        assert!(step < 0.3 * size, "seed {seed}: step {step}° for {size}°");
        let stats = synth::pose_metrics::measure(
            &truth,
            &est,
            &capsule_body().joints_rest,
            &capsule_body().parents,
        );
        assert!((stats.joint_step_rms_deg - step).abs() < 1e-6 * step);
        assert!(
            stats.root_transl_step_rms_cm < 0.3 * stats.root_transl_rms_cm,
            "{stats:?}"
        );
    }
}

/// Same seed, same estimate; another seed, another one; off, the truth itself.
#[test]
fn estimate_is_deterministic_for_the_seed() {
    let (truth, root_rest) = truth_sequence(0, 30);
    let e = PoseError::REALISTIC;
    let a = perturb(&truth, &e, 5, CAMERA, root_rest);
    assert_eq!(a, perturb(&truth, &e, 5, CAMERA, root_rest));
    assert_ne!(a, perturb(&truth, &e, 6, CAMERA, root_rest));
    assert_eq!(
        perturb(&truth, &PoseError::OFF, 5, CAMERA, root_rest),
        truth
    );
}

#[test]
fn bad_pose_error_settings_are_refused_with_the_knob_name() {
    for (err, knob) in [
        (
            PoseError {
                joint_rms_deg: -1.0,
                ..PoseError::OFF
            },
            "pose-error",
        ),
        (
            PoseError {
                joint_rms_deg: 31.0,
                ..PoseError::OFF
            },
            "pose-error",
        ),
        (
            PoseError {
                root_orient_rms_deg: f32::NAN,
                ..PoseError::OFF
            },
            "root-orient-error",
        ),
        (
            PoseError {
                root_transl_rms_cm: 51.0,
                ..PoseError::OFF
            },
            "root-transl-error",
        ),
    ] {
        let cfg = SynthConfig {
            pose_error: err,
            ..small()
        };
        match cfg.validate() {
            Err(SynthError::Knob { knob: k, .. }) => assert_eq!(k, knob),
            other => panic!("{knob}: expected a knob error, got {other:?}"),
        }
    }
}

#[test]
fn true_poses_reader_refuses_what_it_does_not_write() {
    let dir = tempfile::tempdir().unwrap();
    let (truth, _) = truth_sequence(0, 3);
    let mut poses = TruePoses {
        format_version: 1,
        frames: truth,
    };
    poses.write(dir.path()).unwrap();
    assert_eq!(TruePoses::read(dir.path()).unwrap(), poses);
    poses.frames[1].pose.pop();
    poses.write(dir.path()).unwrap();
    let err = TruePoses::read(dir.path()).unwrap_err().to_string();
    assert!(err.contains("frames[1].pose has 23 joints"), "{err}");
    poses.frames[1].pose.push([0.0; 3]);
    poses.format_version = 2;
    poses.write(dir.path()).unwrap();
    let err = TruePoses::read(dir.path()).unwrap_err().to_string();
    assert!(err.contains("format_version 2"), "{err}");
    std::fs::remove_file(dir.path().join(TRUE_POSES_FILE)).unwrap();
    assert!(matches!(
        TruePoses::read(dir.path()),
        Err(SynthError::Io { .. })
    ));
}

/// The `realistic` preset is the default benchmark plus the pose error: nothing else differs.
#[test]
fn realistic_preset_is_the_default_with_estimated_poses() {
    let r = SynthConfig::preset(Preset::Realistic);
    assert_eq!(r.pose_error, PoseError::REALISTIC);
    assert_eq!(
        SynthConfig {
            pose_error: PoseError::OFF,
            ..r
        },
        SynthConfig::preset(Preset::Default)
    );
    // Off, the setting is not serialised (settings without it keep their bytes).
    let text = serde_json::to_string(&SynthConfig::preset(Preset::Default)).unwrap();
    assert!(!text.contains("pose_error"), "{text}");
    assert!(
        serde_json::to_string(&SynthConfig::preset(Preset::Realistic))
            .unwrap()
            .contains("\"pose_error\":{\"joint_rms_deg\":16.0")
    );
}

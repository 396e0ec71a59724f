#![allow(clippy::unwrap_used)]
//! End-to-end generation on a small capsule body: the output loads (format version 1, or 2 with a moving camera), the
//! statistics are sane, bad knobs are refused, and bytes do not depend on the thread count.

use std::collections::BTreeMap;
use std::path::Path;

use synth::body::capsule_body;
use synth::{generate_with_body, Preset, Speed, SynthConfig, SynthError};

fn small() -> SynthConfig {
    SynthConfig {
        frames: 4,
        width: 48,
        height: 40,
        subframes: 4,
        supersample: 3,
        speed: Speed::Fast,
        event_flow: true,
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

#[test]
fn small_run_loads_and_is_thread_independent() {
    let cfg = small();
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let two = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let sa = one
        .install(|| generate_with_body(&cfg, capsule_body(), a.path(), &mut |_, _| {}))
        .unwrap();
    let sb = two
        .install(|| generate_with_body(&cfg, capsule_body(), b.path(), &mut |_, _| {}))
        .unwrap();
    assert_eq!(sa, sb);
    let (fa, fb) = (files(a.path()), files(b.path()));
    assert_eq!(fa.keys().collect::<Vec<_>>(), fb.keys().collect::<Vec<_>>());
    for (k, v) in &fa {
        assert!(fb[k] == *v, "{k} differs between 1 and 2 threads");
    }
    // 4 frames: images, sharp, masks, events x4; GT flows + validity + CM flows x3; scene,
    // stats, preview.
    assert_eq!(
        fa.len(),
        4 * 4 + 3 * 3 + 3,
        "{:?}",
        fa.keys().collect::<Vec<_>>()
    );

    let s = scene::load(a.path()).unwrap();
    assert_eq!(s.frames.len(), 4);
    assert_eq!(s.camera.width, 48);
    assert!(s.frames[3].flow_to_next.is_empty());
    assert_eq!(
        s.frames[0].flow(scene::FlowKind::GroundTruth).unwrap().path,
        "flow/000000.flo"
    );
    assert_eq!(
        s.frames[2].flow(scene::FlowKind::EventsCm).unwrap().path,
        "flow/000002_cm.flo"
    );
    assert!(sa.events_cm_flow.computed);
    // The person is visible and moving; the GT flow explains the motion better than zero flow.
    let f = &sa.flow;
    assert!(f.valid_fraction > 0.5, "{f:?}");
    assert!(f.human_fraction_above_1px > 0.0, "{f:?}");
    assert!(
        f.moving_human_warp_mae < 0.5 * f.moving_human_identity_mae,
        "{f:?}"
    );
    assert!(sa.events.count > 0);
    let p = &sa.psnr_blurred_vs_sharp;
    assert!(p.human_box_db < p.outside_human_box_db, "{p:?}");
}

#[test]
fn bad_knobs_are_refused_with_the_knob_name() {
    let out = tempfile::tempdir().unwrap();
    let cases: Vec<(SynthConfig, &str)> = vec![
        (
            SynthConfig {
                frames: 0,
                ..small()
            },
            "frames",
        ),
        (
            SynthConfig {
                subframes: 0,
                ..small()
            },
            "subframes",
        ),
        (
            SynthConfig {
                width: 9000,
                ..small()
            },
            "width",
        ),
        (
            SynthConfig {
                height: 8193,
                ..small()
            },
            "height",
        ),
        (
            SynthConfig {
                supersample: 2,
                ..small()
            },
            "supersample",
        ),
        (
            SynthConfig {
                event_threshold: 0.0,
                ..small()
            },
            "event-threshold",
        ),
        (
            SynthConfig {
                camera_distance: f32::NAN,
                ..small()
            },
            "camera-distance",
        ),
    ];
    for (cfg, knob) in cases {
        let err = generate_with_body(&cfg, capsule_body(), out.path(), &mut |_, _| {}).unwrap_err();
        match &err {
            SynthError::Knob { knob: k, .. } => assert_eq!(*k, knob, "{err}"),
            other => panic!("expected a knob error for {knob}, got {other}"),
        }
        assert!(err.to_string().contains(knob));
    }
    // Nothing was written for refused settings.
    assert!(std::fs::read_dir(out.path()).unwrap().next().is_none());
}

/// A handheld camera: every frame carries its own camera pose (format version 2), the poses
/// differ by centimetres, the room blurs (the blurred frames are further from the sharp ones
/// outside the person than with a static camera), more events fire, and the bytes are still
/// independent of the thread count.
#[test]
fn a_handheld_camera_writes_its_poses_and_blurs_the_room() {
    let still = tempfile::tempdir().unwrap();
    let held = tempfile::tempdir().unwrap();
    let handheld = SynthConfig {
        camera_motion: synth::CameraMotion::Handheld,
        ..small()
    };
    let s_still =
        generate_with_body(&small(), capsule_body(), still.path(), &mut |_, _| {}).unwrap();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let s_held = one
        .install(|| generate_with_body(&handheld, capsule_body(), held.path(), &mut |_, _| {}))
        .unwrap();
    let scene = scene::load(held.path()).unwrap();
    assert_eq!(scene.format_version, scene::FORMAT_VERSION_MOVING_CAMERA);
    assert!(scene.frames.iter().all(|f| f.world_to_camera.is_some()));
    let centre = |k: usize| {
        let m = scene.camera_of(k).world_to_camera;
        // −Rᵀ t
        (0..3)
            .map(|c| -(0..3).map(|r| m[r][c] * m[r][3]).sum::<f64>())
            .collect::<Vec<f64>>()
    };
    let shift: f64 = (0..3)
        .map(|c| (centre(0)[c] - centre(3)[c]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!((0.001..0.2).contains(&shift), "the camera moved {shift} m");
    let still_scene = scene::load(still.path()).unwrap();
    assert_eq!(still_scene.format_version, scene::FORMAT_VERSION);
    assert!(!still_scene.camera_moves());
    let outside = |s: &synth::Stats| s.psnr_blurred_vs_sharp.outside_human_box_db;
    assert!(
        outside(&s_held) < outside(&s_still) - 1.0,
        "outside the person: {} dB handheld vs {} dB static",
        outside(&s_held),
        outside(&s_still)
    );
    assert!(s_held.events.count > s_still.events.count);
    let two = tempfile::tempdir().unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    pool.install(|| generate_with_body(&handheld, capsule_body(), two.path(), &mut |_, _| {}))
        .unwrap();
    assert_eq!(files(held.path()), files(two.path()));
}

/// `camera_error_deg` / `camera_error_cm`: scene.json holds estimated camera poses with exactly
/// the asked RMS errors against `cameras_true.json`, which holds the poses written without the
/// error; every other file is unchanged.
#[test]
fn camera_errors_change_only_the_written_poses_and_keep_the_truth_aside() {
    let exact = tempfile::tempdir().unwrap();
    let noisy = tempfile::tempdir().unwrap();
    let handheld = SynthConfig {
        camera_motion: synth::CameraMotion::Handheld,
        ..small()
    };
    let with_error = SynthConfig {
        camera_error_deg: 0.5,
        camera_error_cm: 1.0,
        ..handheld.clone()
    };
    generate_with_body(&handheld, capsule_body(), exact.path(), &mut |_, _| {}).unwrap();
    generate_with_body(&with_error, capsule_body(), noisy.path(), &mut |_, _| {}).unwrap();
    let (a, b) = (files(exact.path()), files(noisy.path()));
    for (name, bytes) in &a {
        if !["scene.json", "stats.json"].contains(&name.as_str()) {
            assert_eq!(Some(bytes), b.get(name), "{name} changed");
        }
    }
    let truth = synth::camera_error::TrueCameras::read(noisy.path()).unwrap();
    let exact_scene = scene::load(exact.path()).unwrap();
    let noisy_scene = scene::load(noisy.path()).unwrap();
    for (t, f) in truth.frames.iter().zip(&exact_scene.frames) {
        let w = f.world_to_camera.unwrap();
        assert_eq!(t.world_to_camera, [w[0], w[1], w[2]]);
    }
    let estimates: Vec<_> = noisy_scene
        .frames
        .iter()
        .map(|f| f.world_to_camera.unwrap())
        .collect();
    let (deg, cm) = synth::camera_error::rms_error(&estimates, &truth);
    assert!(
        (deg - 0.5).abs() < 1e-6 && (cm - 1.0).abs() < 1e-6,
        "{deg}° {cm} cm"
    );
    assert!(!exact
        .path()
        .join(synth::camera_error::TRUE_CAMERAS_FILE)
        .exists());
}

#[test]
fn the_recorded_motion_is_the_generators_and_bad_configs_are_refused_by_field() {
    let scene = Path::new("scene.json");
    let cfg = SynthConfig::preset(Preset::Default);
    let generator = serde_json::json!({ "config": cfg });
    let motion = synth::generate::recorded_motion(scene, Some(&generator)).unwrap();
    let body = synth::body::DressedBody::new(
        smpl_deform::BodyRef::parse(&cfg.body)
            .unwrap()
            .load()
            .unwrap(),
        vec![0.0; 10],
    )
    .unwrap();
    let direct = synth::generate::benchmark_motion(&cfg, &body).unwrap();
    assert_eq!(motion.at(0.37), direct.at(0.37));
    for (generator, needle) in [
        (None, "absent"),
        (
            Some(serde_json::json!({ "config": { "frames": "many" } })),
            "expected u32",
        ),
        (
            Some(serde_json::json!({ "config": SynthConfig { people: 2, ..cfg.clone() } })),
            "one person",
        ),
    ] {
        let e = synth::generate::recorded_motion(scene, generator.as_ref()).unwrap_err();
        let text = e.to_string();
        assert!(text.contains("scene.json: generator.config"), "{text}");
        assert!(text.contains(needle), "{text}");
    }
}

//! The exposure model with a moving camera (#46) on the tiny fixture, its frames' cameras moved
//! along a path: every sub-exposure render is drawn from the camera interpolated at its time
//! (`CameraTrack`), with the events between the renders and each frame's camera corrected; the
//! run gives the same bits on one and two threads and resumes bit for bit. And a scene of format
//! 2 whose frames all give the scene camera's pose is a fixed camera: it trains the bits of the
//! same scene in format 1.
#![allow(clippy::unwrap_used)]

use train::config::TrainConfig;
use train::data::{load_dataset, TrainingData};
use train::trainer::Trainer;

mod common;
use common::*;

/// The fixture with its frames filmed along a path: each frame's camera shifted by a few
/// centimetres (sideways on a sine, upwards steadily) and turned by a growing yaw.
fn moving_context(config: &TrainConfig) -> TrainingData {
    let mut data = load_dataset(&fixture()).unwrap();
    for (k, frame) in data.frames.iter_mut().enumerate() {
        let m = &mut frame.camera.world_to_camera;
        let yaw = 0.004 * k as f64;
        let (s, c) = yaw.sin_cos();
        for col in 0..4 {
            let (x, z) = (m[0][col], m[2][col]);
            m[0][col] = c * x + s * z;
            m[2][col] = -s * x + c * z;
        }
        m[0][3] += 0.02 * (0.7 * k as f64).sin();
        m[1][3] += 0.003 * k as f64;
    }
    data.camera_moves = true;
    exposure_data(&data, builtin_body(&data), config)
}

#[test]
fn a_moving_camera_trains_alike_on_any_thread_count_and_resumes_bit_for_bit() {
    let config = camera_config(12);
    let ctx = moving_context(&config);
    // The sub-exposure renders of a frame have cameras of their own (its first and last differ).
    let cameras = &ctx.exposure_cameras;
    assert_eq!(cameras.len(), ctx.frames.len());
    let pose = |slot: usize, s: usize| cameras[slot][s].world_to_camera;
    assert!(cameras.iter().all(|c| c.len() == config.subframes));
    assert!((0..cameras.len()).all(|slot| pose(slot, 0) != pose(slot, config.subframes - 1)));
    let one = trained_alike_on_one_and_two_threads(&ctx, &config, 12);
    // It learned: the parameters moved, none is NaN, and the cameras were corrected.
    let start = bits(&Trainer::new(&ctx, config.clone()).unwrap());
    assert_ne!(bits(&one), start);
    assert!(bits(&one).iter().all(|&b| f32::from_bits(b).is_finite()));
    assert!(one.model.camera_corrections.iter().any(|&v| v != 0.0));
    resume_is_bit_identical(&ctx, camera_config(16));
}

/// Trains `steps` steps of the exposure model with events on the scene at `dir` (fixed camera or
/// not) and returns the bits.
fn trained_bits(dir: &std::path::Path, steps: usize) -> Vec<u32> {
    let config = exposure_events_config(steps);
    let data = load_dataset(dir).unwrap();
    let ctx = exposure_data(&data, builtin_body(&data), &config);
    let mut t = Trainer::new(&ctx, config).unwrap();
    t.run(&ctx, steps, |_, _| Ok(())).unwrap();
    bits(&t)
}

#[test]
fn a_format_2_scene_whose_frames_keep_the_scene_camera_trains_the_format_1_bits() {
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("tiny-v2");
    copy_dir(&fixture(), &copy);
    let path = copy.join("scene.json");
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let pose = json["camera"]["world_to_camera"].clone();
    json["format_version"] = serde_json::json!(scene::FORMAT_VERSION_MOVING_CAMERA);
    for frame in json["frames"].as_array_mut().unwrap() {
        frame["world_to_camera"] = pose.clone();
    }
    std::fs::write(&path, serde_json::to_string(&json).unwrap()).unwrap();
    let v2 = load_dataset(&copy).unwrap();
    assert_eq!(v2.scene.format_version, scene::FORMAT_VERSION_MOVING_CAMERA);
    assert!(v2.scene.frames.iter().all(|f| f.world_to_camera.is_some()));
    assert!(!v2.camera_moves);
    assert_same_bits(&trained_bits(&fixture(), 8), &trained_bits(&copy, 8));
}

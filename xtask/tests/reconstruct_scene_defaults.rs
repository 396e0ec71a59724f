//! `cargo xtask reconstruct`'s defaults that depend on the scene, on edited copies of the tiny
//! fixture: a scene without events trains the exposure model alone, and a sensor recorded without
//! a refractory period holds mixed-polarity pixels to their counts and bounds a count of n by n − 1
//! thresholds (one with a refractory period reads each event as 1.25 thresholds, unless the camera
//! moves), and a moving camera is corrected from the images and its scene Gaussians start on
//! swept surfaces, unless the user says otherwise.
#![allow(clippy::unwrap_used)]

mod common;

use common::{fixture_with_scene, reconstruct_with, tiny_config};

/// Runs `reconstruct` with 3 renders per exposure and `extra` on `scene` into `out`: its standard
/// output and the configuration it used (`config.json`).
fn run_three_renders(
    scene: &std::path::Path,
    out: &std::path::Path,
    config: &std::path::Path,
    extra: &[&str],
) -> (String, String) {
    let args = [&["--subframes", "3"], extra].concat();
    let stdout = reconstruct_with(scene, out, config, &args);
    let used = std::fs::read_to_string(out.join("config.json")).unwrap();
    (stdout, used)
}

#[test]
fn a_scene_without_events_trains_the_exposure_model_alone_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let scene_dir = fixture_with_scene(dir.path(), "no-events", |scene| {
        for frame in scene["frames"].as_array_mut().unwrap() {
            frame.as_object_mut().unwrap().remove("events");
        }
    });
    std::fs::remove_dir_all(scene_dir.join("events")).unwrap();
    let out = dir.path().join("out");
    let stdout = reconstruct_with(&scene_dir, &out, &tiny_config(dir.path()), &[]);
    assert!(
        stdout.contains("the scene has no events") && stdout.contains("exposure model alone"),
        "{stdout}"
    );
    let metrics = std::fs::read_to_string(out.join("metrics.json")).unwrap();
    assert!(metrics.contains("\"event_loss\": false"), "{metrics}");
    assert!(metrics.contains("\"event_modulation\": false"), "{metrics}");
}

#[test]
fn a_sensor_without_a_refractory_period_holds_mixed_pixels_to_their_counts() {
    let dir = tempfile::tempdir().unwrap();
    let config = tiny_config(dir.path());
    let scene_dir = fixture_with_scene(dir.path(), "ideal-sensor", |scene| {
        scene["generator"]["config"]["refractory_us"] = serde_json::json!(0);
    });
    let run = |name: &str, extra: &[&str]| {
        run_three_renders(&scene_dir, &dir.path().join(name), &config, extra)
    };
    let (stdout, used) = run("default", &[]);
    assert!(stdout.contains("no refractory period"), "{stdout}");
    assert!(used.contains("\"event_ignore_mixed\": false"), "{used}");
    assert!(stdout.contains("n - 1"), "{stdout}");
    assert!(used.contains("\"event_bound_margin\": 1.0"), "{used}");
    assert!(used.contains("\"event_threshold_scale\": 1.0"), "{used}");
    assert!(!stdout.contains("read as 1.25 thresholds"), "{stdout}");
    // The user's choices win over the scene's defaults, each on its own.
    let (stdout, used) = run("chosen", &["--event-ignore-mixed", "on"]);
    assert!(!stdout.contains("no refractory period"), "{stdout}");
    assert!(used.contains("\"event_ignore_mixed\": true"), "{used}");
    assert!(used.contains("\"event_bound_margin\": 1.0"), "{used}");
    let (stdout, used) = run("margin", &["--event-bound-margin", "0.5"]);
    assert!(!stdout.contains("n - 1"), "{stdout}");
    assert!(used.contains("\"event_bound_margin\": 0.5"), "{used}");
}

#[test]
fn a_sensor_with_a_refractory_period_reads_each_event_as_more_than_a_threshold() {
    // The tiny fixture's generator recorded a 1 ms refractory period.
    let dir = tempfile::tempdir().unwrap();
    let config = tiny_config(dir.path());
    let run = |name: &str, extra: &[&str]| {
        run_three_renders(&common::fixture(), &dir.path().join(name), &config, extra)
    };
    let (stdout, used) = run("default", &[]);
    assert!(stdout.contains("read as 1.25 thresholds"), "{stdout}");
    assert!(used.contains("\"event_threshold_scale\": 1.25"), "{used}");
    let (stdout, used) = run("chosen", &["--event-threshold-scale", "1"]);
    assert!(!stdout.contains("read as 1.25 thresholds"), "{stdout}");
    assert!(used.contains("\"event_threshold_scale\": 1.0"), "{used}");
}

/// A copy of the tiny fixture whose camera moves: scene format 2, each frame's camera the scene's
/// shifted sideways by 2 mm per frame.
fn moving_camera_fixture(dir: &std::path::Path) -> std::path::PathBuf {
    fixture_with_scene(dir, "moving-camera", |scene| {
        scene["format_version"] = serde_json::json!(2);
        let pose = scene["camera"]["world_to_camera"].clone();
        for (i, frame) in scene["frames"]
            .as_array_mut()
            .unwrap()
            .iter_mut()
            .enumerate()
        {
            let mut own = pose.clone();
            let t = own[0][3].as_f64().unwrap() + 0.002 * i as f64;
            own[0][3] = serde_json::json!(t);
            frame["world_to_camera"] = own;
        }
    })
}

#[test]
fn a_moving_camera_is_corrected_and_its_scene_swept_unless_the_user_chooses() {
    let dir = tempfile::tempdir().unwrap();
    let config = tiny_config(dir.path());
    let scene_dir = moving_camera_fixture(dir.path());
    let run = |name: &str, extra: &[&str]| {
        run_three_renders(&scene_dir, &dir.path().join(name), &config, extra)
    };
    let (stdout, used) = run("default", &[]);
    assert!(stdout.contains("camera is corrected"), "{stdout}");
    assert!(used.contains("\"camera_correction\": true"), "{used}");
    assert!(stdout.contains("plane sweep"), "{stdout}");
    assert!(used.contains("\"scene_init\": \"stereo\""), "{used}");
    // Its events are mostly the room's, read as the sensor's thresholds.
    assert!(!stdout.contains("read as 1.25 thresholds"), "{stdout}");
    assert!(used.contains("\"event_threshold_scale\": 1.0"), "{used}");
    let (stdout, used) = run("given", &["--camera-correction", "off"]);
    assert!(!stdout.contains("camera is corrected"), "{stdout}");
    assert!(used.contains("\"camera_correction\": false"), "{used}");
    assert!(used.contains("\"scene_init\": \"stereo\""), "{used}");
    let (stdout, used) = run("volume", &["--scene-init", "volume"]);
    assert!(!stdout.contains("plane sweep"), "{stdout}");
    assert!(used.contains("\"scene_init\": \"volume\""), "{used}");
    assert!(used.contains("\"camera_correction\": true"), "{used}");
    // A camera that stays put keeps the given cameras.
    let (stdout, used) =
        run_three_renders(&common::fixture(), &dir.path().join("static"), &config, &[]);
    assert!(!stdout.contains("the camera moves"), "{stdout}");
    assert!(used.contains("\"camera_correction\": false"), "{used}");
    assert!(used.contains("\"scene_init\": \"volume\""), "{used}");
}

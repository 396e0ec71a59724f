//! Several people in one model, on the tiny fixture made a two-person scene (a second person,
//! its own betas, walking the first one's poses 0.6 m to the side): each person's Gaussians start
//! on its own class, a run trains the same bits on one and two threads and resumes bit for bit,
//! and no Gaussian changes person.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use train::data::{load_dataset, TrainingData};
use train::trainer::Trainer;

mod common;
use common::*;

/// The fixture with a second person (id 7, other betas) beside the first in every frame.
fn two_people_scene(dir: &Path) {
    copy_dir(&fixture(), dir);
    let path = dir.join("scene.json");
    let mut scene: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    scene["format_version"] = 3.into();
    let betas: Vec<f32> = vec![0.3; 10];
    scene["people"] = serde_json::json!([{ "id": 7, "betas": betas }]);
    for frame in scene["frames"].as_array_mut().unwrap() {
        let mut transl = frame["transl"].clone();
        transl[0] = (transl[0].as_f64().unwrap() + 0.6).into();
        frame["people"] = serde_json::json!([{
            "id": 7,
            "pose": frame["pose"].clone(),
            "transl": transl,
        }]);
    }
    std::fs::write(&path, serde_json::to_vec_pretty(&scene).unwrap()).unwrap();
}

/// The two-person scene's training data with the exposure model and its events.
fn two_people_context(dir: &Path, config: &train::config::TrainConfig) -> TrainingData {
    two_people_scene(dir);
    let data = load_dataset(dir).unwrap();
    assert_eq!(data.people(), 2);
    exposure_data(&data, data.body().unwrap(), config)
}

#[test]
fn each_person_starts_on_its_own_class() {
    let dir = tempfile::tempdir().unwrap();
    let config = exposure_events_config(4);
    let ctx = two_people_context(dir.path(), &config);
    let t = Trainer::new(&ctx, config.clone()).unwrap();
    let model = &t.model;
    assert_eq!((model.people(), model.set.semantic_classes), (2, 3));
    assert_eq!(model.render_channels(), 6);
    let of = |person: usize| {
        (0..model.set.len())
            .filter(|&i| model.probability(i) >= 0.5 && model.person_of(i) == person)
            .count()
    };
    assert_eq!(
        (of(0), of(1)),
        (config.human_gaussians, config.human_gaussians)
    );
    // The second person's samples are drawn on its own body with a seed of its own.
    let first = &model.set.means[..config.human_gaussians];
    let second = &model.set.means[config.human_gaussians..2 * config.human_gaussians];
    assert_ne!(first, second);
}

#[test]
fn two_people_train_alike_on_one_and_two_threads_and_keep_their_classes() {
    let dir = tempfile::tempdir().unwrap();
    let config = exposure_events_config(12);
    let ctx = two_people_context(dir.path(), &config);
    let run = |threads: usize| {
        with_threads(threads, || {
            let mut t = Trainer::new(&ctx, config.clone()).unwrap();
            t.run(&ctx, 12, |_, _| Ok(())).unwrap();
            t
        })
    };
    let (one, two) = (run(1), run(2));
    assert_same_bits(&bits(&one), &bits(&two));
    assert!(bits(&one).iter().all(|&b| f32::from_bits(b).is_finite()));
    assert_eq!(one.person_changes, 0);
}

#[test]
fn two_people_resume_bit_identically() {
    let dir = tempfile::tempdir().unwrap();
    let config = exposure_events_config(16);
    let ctx = two_people_context(dir.path(), &config);
    resume_is_bit_identical(&ctx, config);
}

#[test]
fn pose_correction_and_learned_exposure_motion_with_two_people_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let config = train::config::TrainConfig {
        pose_correction: true,
        ..exposure_events_config(4)
    };
    let ctx = two_people_context(dir.path(), &config);
    let Err(e) = Trainer::new(&ctx, config) else {
        panic!("pose correction of two people was accepted");
    };
    assert!(e.to_string().contains("corrects one person"), "{e}");
    let learned_motion = train::config::TrainConfig {
        exposure_motion: train::config::ExposureMotion::Learned,
        ..exposure_events_config(4)
    };
    let Err(e) = Trainer::new(&ctx, learned_motion) else {
        panic!("the learned in-exposure motion of two people was accepted");
    };
    assert!(e.to_string().contains("--exposure-motion learned"), "{e}");
}

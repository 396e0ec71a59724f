//! Helpers shared by the trainer's integration tests: the tiny fixture, a tiny configuration, the
//! bits of every learnable value, thread pools and the resume check.
#![allow(dead_code, clippy::unwrap_used)]

use smpl_deform::BodyModel;
use std::path::PathBuf;
use train::config::{Preset, TrainConfig};
use train::data::TrainingData;
use train::data::{load_dataset, Dataset};
use train::pose::body::Body;
use train::pose::exposure::TrackRules;
use train::trainer::Trainer;

/// The tiny checked-in scene.
pub fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data-fixtures/tiny")
}

/// The fixture's training data with the built-in body.
pub fn context() -> TrainingData {
    let data = load_dataset(&fixture()).unwrap();
    TrainingData::new(&data, builtin_body(&data), 0).unwrap()
}

/// Copies the directory `from` into `to` (files and folders).
pub fn copy_dir(from: &std::path::Path, to: &std::path::Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

/// A configuration small enough for a test: `steps` steps of a few hundred Gaussians.
pub fn tiny_config(steps: usize) -> TrainConfig {
    TrainConfig {
        steps,
        human_gaussians: 400,
        scene_gaussians: 800,
        max_gaussians: 4000,
        deform_hidden: 16,
        skinning_until: steps / 2,
        skinning_samples: 64,
        nonrigid_from: 4,
        densify_from: 6,
        densify_until: steps,
        densify_every: 6,
        densify_grad_threshold: 1e-5,
        opacity_reset_every: 0,
        checkpoint_every: 0,
        // One render per frame: these tests prepare no sub-exposure poses (and event losses pair
        // consecutive frames, at the weight measured for that pairing).
        blur_model: train::config::BlurModel::None,
        event_pairs: train::config::EventPairs::Frames,
        event_weight: 3.0,
        ..TrainConfig::preset(Preset::Quick)
    }
}

/// [`tiny_config`] with the exposure model (3 renders per exposure) and the event loss between
/// its consecutive renders, at the default weight.
pub fn exposure_events_config(steps: usize) -> TrainConfig {
    TrainConfig {
        blur_model: train::config::BlurModel::Exposure,
        subframes: 3,
        event_loss: true,
        event_pairs: train::config::EventPairs::Exposure,
        event_weight: 0.3,
        ..tiny_config(steps)
    }
}

/// Every learnable value of a trainer as bits.
pub fn bits(t: &Trainer) -> Vec<u32> {
    let s = &t.model.set;
    s.means
        .iter()
        .flatten()
        .chain(s.log_scales.iter().flatten())
        .chain(s.quats.iter().flatten())
        .chain(&s.opacity_logits)
        .chain(&s.features)
        .chain(&s.semantic_logits)
        .chain(&t.model.nets.nonrigid.mlp.params)
        .chain(&t.model.nets.skinning.mlp.params)
        .chain(&t.model.nets.human_colour.mlp.params)
        .chain(&t.model.nets.scene_colour.mlp.params)
        .chain(&t.model.latents)
        .chain(&t.model.pose_corrections)
        .chain(&t.model.camera_corrections)
        .chain(&t.model.camera_gauge)
        .map(|v| v.to_bits())
        .collect()
}

/// Runs `f` on a pool of `threads` threads.
pub fn with_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// Asserts bit equality, reporting the first difference instead of both vectors.
/// Panics at the first value where `a` and `b` differ.
pub fn assert_same_bits(a: &[u32], b: &[u32]) {
    assert_eq!(a.len(), b.len(), "different parameter counts");
    if let Some(i) = (0..a.len()).find(|&i| a[i] != b[i]) {
        panic!(
            "first difference at value {i} of {}: {} vs {}",
            a.len(),
            f32::from_bits(a[i]),
            f32::from_bits(b[i])
        );
    }
}

/// A context with sub-exposure poses and the events between them.
pub fn exposure_context(config: &TrainConfig) -> TrainingData {
    let data = load_dataset(&fixture()).unwrap();
    exposure_data(&data, builtin_body(&data), config)
}

/// The built-in body with the scene's shape.
pub fn builtin_body(data: &Dataset) -> Body {
    Body::new(
        BodyModel::builtin_makehuman().unwrap(),
        data.scene.body.betas.clone(),
    )
    .unwrap()
}

/// The training data of `data` posed with `body`, with the sub-exposure poses (and cameras,
/// when the camera moves) of `config`'s exposure model and the events between them.
pub fn exposure_data(data: &Dataset, body: Body, config: &TrainConfig) -> TrainingData {
    let mut ctx = TrainingData::new(data, body, 0).unwrap();
    ctx.enable_exposure(data, config.subframes, TrackRules::of(config))
        .unwrap();
    ctx.enable_exposure_events(data, config).unwrap();
    ctx
}

/// 16 steps straight and 9 + a checkpoint + 7 end in the same bits.
pub fn resume_is_bit_identical(ctx: &TrainingData, config: TrainConfig) {
    let ctx = ctx.clone();
    let mut straight = Trainer::new(&ctx, config.clone()).unwrap();
    straight.run(&ctx, 16, |_, _| Ok(())).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ck.safetensors");
    let mut first = Trainer::new(&ctx, config).unwrap();
    first.run(&ctx, 9, |_, _| Ok(())).unwrap();
    first.save_checkpoint(&path).unwrap();
    drop(first);
    let mut resumed = Trainer::load_checkpoint(&path, &ctx).unwrap();
    assert_eq!(resumed.step, 9);
    resumed.run(&ctx, 16, |_, _| Ok(())).unwrap();
    assert_same_bits(&bits(&resumed), &bits(&straight));
}

/// Camera correction from step 2 on the exposure model's three renders per frame.
pub fn camera_config(steps: usize) -> TrainConfig {
    TrainConfig {
        camera_correction: true,
        camera_correction_from: 2,
        ..exposure_events_config(steps)
    }
}

/// A trainer run `steps` steps of `config` on one thread, after checking that two threads train
/// the same bits.
pub fn trained_alike_on_one_and_two_threads(
    ctx: &TrainingData,
    config: &TrainConfig,
    steps: usize,
) -> Trainer {
    let run = |threads: usize| {
        with_threads(threads, || {
            let mut t = Trainer::new(ctx, config.clone()).unwrap();
            t.run(ctx, steps, |_, _| Ok(())).unwrap();
            t
        })
    };
    let (one, two) = (run(1), run(2));
    assert_same_bits(&bits(&one), &bits(&two));
    one
}

//! The full E-Sem3DGS loop on the tiny checked-in fixture: it learns, resumes bit for bit from a
//! checkpoint, and gives identical bits with 1 and 2 threads.
#![allow(clippy::unwrap_used)]

use smpl_deform::BodyModel;
use std::path::PathBuf;
use train::config::{Preset, TrainConfig};
use train::data::load_dataset;
use train::trainer::{Body, TrainContext, Trainer};

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data-fixtures/tiny")
}

fn context() -> TrainContext {
    let data = load_dataset(&fixture()).unwrap();
    let body = Body::new(
        BodyModel::builtin_makehuman().unwrap(),
        data.scene.body.betas.clone(),
    )
    .unwrap();
    TrainContext::new(&data, body, 0).unwrap()
}

fn tiny_config(steps: usize) -> TrainConfig {
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
        ..TrainConfig::preset(Preset::Quick)
    }
}

/// Every learnable value of a trainer as bits.
fn bits(t: &Trainer) -> Vec<u32> {
    let s = &t.set;
    s.means
        .iter()
        .flatten()
        .chain(s.log_scales.iter().flatten())
        .chain(s.quats.iter().flatten())
        .chain(&s.opacity_logits)
        .chain(&s.features)
        .chain(&s.semantic_logits)
        .chain(&t.nets.nonrigid.mlp.params)
        .chain(&t.nets.skinning.mlp.params)
        .chain(&t.nets.human_colour.mlp.params)
        .chain(&t.nets.scene_colour.mlp.params)
        .chain(&t.latents)
        .map(|v| v.to_bits())
        .collect()
}

/// Asserts bit equality, reporting the first difference instead of both vectors.
fn assert_same_bits(a: &[u32], b: &[u32]) {
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

#[test]
fn training_reduces_the_loss_on_the_tiny_fixture() {
    let ctx = context();
    let mut t = Trainer::new(&ctx, tiny_config(60)).unwrap();
    let mut losses = Vec::new();
    t.run(&ctx, 60, |_, r| {
        assert!(r.loss.is_finite());
        losses.push(r.loss);
        Ok(())
    })
    .unwrap();
    let first: f32 = losses[..10].iter().sum::<f32>() / 10.0;
    let last: f32 = losses[50..].iter().sum::<f32>() / 10.0;
    assert!(last < 0.8 * first, "loss {first} → {last}");
    // Densification ran and kept the semantic classes.
    assert!(t.set.len() != 1200, "density control changed nothing");
    assert!(t.human_count() > 0);
}

#[test]
fn resume_from_a_checkpoint_is_bit_identical() {
    let ctx = context();
    let config = tiny_config(16);
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

#[test]
fn one_and_two_threads_give_identical_bits() {
    let ctx = context();
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let mut t = Trainer::new(&ctx, tiny_config(8)).unwrap();
                t.run(&ctx, 8, |_, _| Ok(())).unwrap();
                bits(&t)
            })
    };
    assert_same_bits(&run(1), &run(2));
}

//! `Model::forward` → `FramePass::backward` on the tiny fixture: the pass's gradients agree with central
//! differences of the model's own f32 render, for the three kinds of parameter the pass reaches by
//! different routes — the frame latent (human colour network), colour features (both colour networks)
//! and opacity logits (rasterizer only).
//!
//! This checks the wiring of the pass (which cotangent goes where), not the exactness of the pieces:
//! `gradient-checks` proves the posing chain and the rasterizer in f64. Here everything is f32, so the
//! tolerance is set by f32 rounding: the loss Σ W·image over 4 × 64² values carries an absolute error of
//! about 1e-5, which a step h = 1e-2 turns into ≈ 1e-3 in the quotient; truncation (h²·L‴) is below that
//! for these smooth directions. |num − ana| ≤ 3e-3 + 5e-2·|ana| passes a correct pass and fails a
//! wrong sign, a missing or doubled term (all probed gradients are required to be well above the
//! tolerance's absolute part).
#![allow(clippy::unwrap_used)]

use rand::{Rng, SeedableRng};
use smpl_deform::BodyModel;
use std::path::PathBuf;
use train::config::{Preset, TrainConfig};
use train::data::{load_dataset, TrainingData};
use train::model::{mean_rgb, Model, RENDER_CHANNELS};
use train::pose::body::Body;
use train::trainer::Trainer;

fn model_and_data() -> (Model, TrainingData) {
    model_and_data_with(|_, _| ())
}

/// The tiny fixture's model and training data, `prepare` run on the data first.
fn model_and_data_with(
    prepare: impl FnOnce(&mut TrainingData, &train::data::Dataset),
) -> (Model, TrainingData) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data-fixtures/tiny");
    let data = load_dataset(&dir).unwrap();
    let body = Body::new(
        BodyModel::builtin_makehuman().unwrap(),
        data.scene.body.betas.clone(),
    )
    .unwrap();
    let mut training = TrainingData::new(&data, body, 0).unwrap();
    prepare(&mut training, &data);
    let config = TrainConfig {
        human_gaussians: 300,
        scene_gaussians: 300,
        max_gaussians: 1000,
        deform_hidden: 16,
        skinning_warmup_steps: 20,
        // One render per frame: these tests prepare no sub-exposure poses.
        blur_model: train::config::BlurModel::None,
        ..TrainConfig::preset(Preset::Quick)
    };
    let mut model = Trainer::new(&training, config).unwrap().model;
    // A non-zero latent and opaque Gaussians, so that every probed route carries gradient.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    for v in &mut model.latents {
        *v = rng.gen_range(-0.5..0.5);
    }
    for v in &mut model.set.opacity_logits {
        *v = 1.0;
    }
    (model, training)
}

/// Σ W·image of the model's render of training frame 0, in f64.
fn loss(model: &Model, data: &TrainingData, weights: &[f32]) -> f64 {
    let frame = &data.frames[0];
    let pass = model
        .forward(&data.camera, &frame.pose.prepared, model.latent(0))
        .unwrap();
    pass.out
        .image
        .iter()
        .zip(weights)
        .map(|(&x, &w)| f64::from(x) * f64::from(w))
        .sum()
}

/// The central difference (h = 1e-2) of `loss` along `perturb(model, ±h)`.
fn central_difference(
    model: &Model,
    perturb: &dyn Fn(&mut Model, f32),
    loss: impl Fn(&Model) -> f64,
) -> f64 {
    let h = 1e-2f32;
    let mut plus = model.clone();
    perturb(&mut plus, h);
    let mut minus = model.clone();
    perturb(&mut minus, -h);
    (loss(&plus) - loss(&minus)) / (2.0 * f64::from(h))
}

/// The indices of the `k` largest magnitudes of `g`.
fn top(g: &[f32], k: usize) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..g.len()).collect();
    idx.sort_by(|&a, &b| g[b].abs().total_cmp(&g[a].abs()));
    idx.truncate(k);
    idx
}

fn check(name: &str, numeric: f64, analytic: f64) {
    assert!(
        analytic.abs() > 2e-2,
        "{name}: gradient {analytic} too small to test"
    );
    assert!(
        (numeric - analytic).abs() <= 3e-3 + 5e-2 * analytic.abs(),
        "{name}: finite differences {numeric} vs pass {analytic}"
    );
}

#[test]
fn frame_pass_gradients_match_central_differences_of_the_render() {
    let (model, data) = model_and_data();
    let hw = data.pixels();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let weights: Vec<f32> = (0..RENDER_CHANNELS * hw)
        .map(|_| rng.gen_range(-1.0..1.0))
        .collect();
    let frame = &data.frames[0];
    let pass = model
        .forward(&data.camera, &frame.pose.prepared, model.latent(0))
        .unwrap();
    let (grads, posed) = pass.backward(&weights).unwrap();
    drop(pass);
    let central = |perturb: &dyn Fn(&mut Model, f32)| {
        central_difference(&model, perturb, |m| loss(m, &data, &weights))
    };
    // The latent entries with the largest gradients (the human colour network's route).
    for j in top(&grads.latent, 3) {
        let numeric = central(&|m, d| m.latents[j] += d);
        check(&format!("latent {j}"), numeric, f64::from(grads.latent[j]));
    }
    // Colour features and opacity logits with the largest gradients.
    for j in top(&grads.features, 3) {
        let numeric = central(&|m, d| m.set.features[j] += d);
        check(
            &format!("feature {j}"),
            numeric,
            f64::from(grads.features[j]),
        );
    }
    for i in top(&posed.opacity_logits, 3) {
        let numeric = central(&|m, d| m.set.opacity_logits[i] += d);
        check(
            &format!("opacity {i}"),
            numeric,
            f64::from(posed.opacity_logits[i]),
        );
    }
}

/// Σ W·mean(renders at the sub-exposure poses of training frame 1), in f64.
fn exposure_loss(model: &Model, data: &TrainingData, weights: &[f32]) -> f64 {
    let passes: Vec<_> = data.exposure_poses[1]
        .iter()
        .map(|pose| {
            model
                .forward(&data.camera, &pose.prepared, model.latent(1))
                .unwrap()
        })
        .collect();
    mean_rgb(&passes)
        .iter()
        .zip(weights)
        .map(|(&x, &w)| f64::from(x) * f64::from(w))
        .sum()
}

/// The exposure model's prediction (the mean of three sub-exposure renders at interpolated poses):
/// each pass's backward of the cotangent scaled by 1/S, summed, against central differences of the
/// mean (same tolerance and reasoning as above).
#[test]
fn the_sub_exposure_mean_backward_matches_central_differences() {
    let (model, data) = model_and_data_with(|training, dataset| {
        training
            .enable_exposure(dataset, 3, Default::default())
            .unwrap();
    });
    let hw = data.pixels();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let weights: Vec<f32> = (0..3 * hw).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let mut d_image = vec![0.0f32; RENDER_CHANNELS * hw];
    for (d, &w) in d_image.iter_mut().zip(&weights) {
        *d = w / 3.0;
    }
    let (mut latent, mut features) = (
        vec![0.0f32; model.latent(1).len()],
        vec![0.0f32; model.set.features.len()],
    );
    for pose in &data.exposure_poses[1] {
        let pass = model
            .forward(&data.camera, &pose.prepared, model.latent(1))
            .unwrap();
        let (g, _) = pass.backward(&d_image).unwrap();
        latent.iter_mut().zip(&g.latent).for_each(|(a, &b)| *a += b);
        features
            .iter_mut()
            .zip(&g.features)
            .for_each(|(a, &b)| *a += b);
    }
    let central = |perturb: &dyn Fn(&mut Model, f32)| {
        central_difference(&model, perturb, |m| exposure_loss(m, &data, &weights))
    };
    let d = model.config.latent_dim;
    for j in top(&latent, 3) {
        let numeric = central(&|m, e| m.latents[d + j] += e);
        check(&format!("latent {j}"), numeric, f64::from(latent[j]));
    }
    for j in top(&features, 3) {
        let numeric = central(&|m, e| m.set.features[j] += e);
        check(&format!("feature {j}"), numeric, f64::from(features[j]));
    }
}

//! A posed frame re-posed at other bones, sharing every network evaluation of the frame: the
//! exposure model's cheap sub-exposure passes (`exposure_networks = once`).
//!
//! Within one exposure only the bones move appreciably. [`repose_frame`] takes a frame posed by
//! [`pose_frame_gated`](crate::pose::posing::pose_frame_gated) at its reference pose (mid exposure) and
//! poses it with other bones: the non-rigid offsets (at the reference pose code), the skinning
//! weights, the human colours (canonicalised view direction of the reference pose) and the scene
//! colours are the reference's; only linear blend skinning, the deformed covariances and the blend
//! are redone. The function computed is therefore "every sub-exposure pass uses the reference's
//! network outputs", and its gradients are exact for that function: [`repose_frame_backward`] turns
//! a re-posed pass's cotangents into [`ReposeCotangents`] — cotangents of the reference's internal
//! quantities — which, summed over the re-posings, enter the reference's one backward
//! ([`pose_frame_backward_with`](crate::pose::posing::pose_frame_backward_with)). S sub-exposure passes
//! then cost one network forward and backward plus S cheap re-posings, instead of S of each.

use crate::blend::{blend, BlendInputs, SemanticMode};
use crate::pose::posing::PeopleRepose;
pub use crate::pose::posing::ReposeCotangents;
use crate::pose::posing::{
    blend_backward_active, deformed_covariance, FrameCache, FrameCotangents, GaussianParams,
    PosedFrame, StaticCotangents,
};
use crate::TrainError;
use nn::Real;
use smpl_deform::math::Affine;

/// What [`repose_frame_backward`] needs of a re-posed pass.
#[derive(Clone, Debug)]
pub struct ReposedCache<T> {
    active: Vec<usize>,
    repose: PeopleRepose<T>,
    posed_mats: Vec<[T; 9]>,
    inputs: Vec<BlendInputs<T>>,
}

impl<T> ReposedCache<T> {
    /// Indices of the Gaussians whose human branch was evaluated (those of the reference pass).
    pub fn active(&self) -> &[usize] {
        &self.active
    }
}

/// The frame `reference` (posed with `reference_cache`) posed with other `bones` (24
/// `frame_from_canonical` transforms per person), sharing every network output of the reference (see the
/// module documentation). With the reference's own bones the result is the reference, bit for bit.
pub fn repose_frame<T: Real>(
    reference: &PosedFrame<T>,
    reference_cache: &FrameCache<T>,
    bones: &[Affine<T>],
) -> Result<(PosedFrame<T>, ReposedCache<T>), TrainError> {
    let (reposed, repose) = reference_cache.deform.repose(bones)?;
    let mut out = reference.clone();
    let mut inputs = Vec::with_capacity(reference_cache.active.len());
    for (a, &i) in reference_cache.active.iter().enumerate() {
        let input = BlendInputs {
            x_def: reposed.positions[a],
            cov_def: deformed_covariance(&reposed.mats[a], &reference_cache.posed_log_scales[a]),
            ..reference_cache.inputs[a]
        };
        let b = blend(out.human_probability[i], &input);
        out.means[i] = b.x;
        out.covariances[i] = b.cov;
        out.colours[i * 3..i * 3 + 3].copy_from_slice(&b.c);
        inputs.push(input);
    }
    Ok((
        out,
        ReposedCache {
            active: reference_cache.active.clone(),
            repose,
            posed_mats: reposed.mats,
            inputs,
        },
    ))
}

/// Backward of [`repose_frame`]: the reference's internal cotangents and ∂L/∂`bones`.
pub fn repose_frame_backward<T: Real>(
    mode: SemanticMode,
    g: &GaussianParams<'_, T>,
    reference_cache: &FrameCache<T>,
    bones: &[Affine<T>],
    cache: &ReposedCache<T>,
    cot: &FrameCotangents<'_, T>,
) -> Result<(ReposeCotangents<T>, Vec<Affine<T>>), TrainError> {
    // Inactive Gaussians are static: their cotangents are the outputs'. Active ones are overwritten
    // with the blend's shares.
    let mut means = cot.means.to_vec();
    let mut covariances = cot.covariances.to_vec();
    let mut scene_colours = cot.colours.to_vec();
    let mut human_probability = cot.human_probability.to_vec();
    let person_probability = cot.person_probability.to_vec();
    let active = blend_backward_active(
        mode,
        g.semantic_logits,
        &cache.active,
        &cache.inputs,
        &cache.posed_mats,
        &reference_cache.posed_log_scales,
        cot,
        StaticCotangents {
            means: &mut means,
            covariances: &mut covariances,
            scene_rgb: &mut scene_colours,
            probability: &mut human_probability,
        },
    );
    let (moved, d_bones) = reference_cache.deform.repose_backward(
        bones,
        &cache.repose,
        &active.x_def,
        &active.mats,
    )?;
    let d = ReposeCotangents {
        means,
        covariances,
        scene_colours,
        human_probability,
        person_probability,
        human_colours: active.human_rgb,
        log_scales: active.log_scales,
        moved,
    };
    Ok((d, d_bones))
}

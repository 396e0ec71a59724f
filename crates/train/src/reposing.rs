//! A posed frame re-posed at other bones, sharing every network evaluation of the frame: the
//! exposure model's cheap sub-exposure passes (`exposure_networks = once`).
//!
//! Within one exposure only the bones move appreciably. [`repose_frame`] takes a frame posed by
//! [`pose_frame_gated`](crate::posing::pose_frame_gated) at its reference pose (mid exposure) and
//! poses it with other bones: the non-rigid offsets (at the reference pose code), the skinning
//! weights, the human colours (canonicalised view direction of the reference pose) and the scene
//! colours are the reference's; only linear blend skinning, the deformed covariances and the blend
//! are redone. The function computed is therefore "every sub-exposure pass uses the reference's
//! network outputs", and its gradients are exact for that function: [`repose_frame_backward`] turns
//! a re-posed pass's cotangents into [`ReposeCotangents`] — cotangents of the reference's internal
//! quantities — which, summed over the re-posings, enter the reference's one backward
//! ([`pose_frame_backward_with`](crate::posing::pose_frame_backward_with)). S sub-exposure passes
//! then cost one network forward and backward plus S cheap re-posings, instead of S of each.

use crate::blend::{blend, BlendInputs, SemanticMode};
use crate::posing::{
    blend_backward_active, deformed_covariance, FrameCache, FrameCotangents, GaussianParams,
    PosedFrame, StaticCotangents,
};
use crate::TrainError;
use nn::Real;
use smpl_deform::deform_net::{MovedCotangents, ReposeCache};
use smpl_deform::math::Affine;

/// What [`repose_frame_backward`] needs of a re-posed pass.
#[derive(Clone, Debug)]
pub struct ReposedCache<T> {
    active: Vec<usize>,
    repose: ReposeCache<T>,
    posed_mats: Vec<[T; 9]>,
    inputs: Vec<BlendInputs<T>>,
}

impl<T> ReposedCache<T> {
    /// Indices of the Gaussians whose human branch was evaluated (those of the reference pass).
    pub fn active(&self) -> &[usize] {
        &self.active
    }
}

/// Cotangents of a frame pass's internal quantities coming from its re-posings (summed over them);
/// [`pose_frame_backward_with`](crate::posing::pose_frame_backward_with) adds them to its own.
#[derive(Clone, Debug, PartialEq)]
pub struct ReposeCotangents<T> {
    /// ∂L/∂ stored means through the static path, N.
    pub means: Vec<[T; 3]>,
    /// ∂L/∂ static covariances, N.
    pub covariances: Vec<[[T; 3]; 3]>,
    /// ∂L/∂ scene colours, N × 3.
    pub scene_colours: Vec<T>,
    /// ∂L/∂ human probability, N.
    pub human_probability: Vec<T>,
    /// ∂L/∂ human colours of the active Gaussians, active × 3.
    pub human_colours: Vec<T>,
    /// ∂L/∂ deformed log-scales of the active Gaussians.
    pub log_scales: Vec<[T; 3]>,
    /// ∂L/∂ moved Gaussians (the inputs of LBS) of the active Gaussians.
    pub moved: MovedCotangents<T>,
}

impl<T: Real> ReposeCotangents<T> {
    /// Zero cotangents of `n` Gaussians of which `active` have a human branch.
    pub fn zeros(n: usize, active: usize) -> Self {
        Self {
            means: vec![[T::zero(); 3]; n],
            covariances: vec![[[T::zero(); 3]; 3]; n],
            scene_colours: vec![T::zero(); n * 3],
            human_probability: vec![T::zero(); n],
            human_colours: vec![T::zero(); active * 3],
            log_scales: vec![[T::zero(); 3]; active],
            moved: MovedCotangents::zeros(active),
        }
    }

    /// Adds `other` element by element.
    pub fn add(&mut self, other: &Self) {
        fn add<T: Real>(a: &mut [T], b: &[T]) {
            a.iter_mut().zip(b).for_each(|(x, &y)| *x = *x + y);
        }
        add(self.means.as_flattened_mut(), other.means.as_flattened());
        add(
            self.covariances.as_flattened_mut().as_flattened_mut(),
            other.covariances.as_flattened().as_flattened(),
        );
        add(&mut self.scene_colours, &other.scene_colours);
        add(&mut self.human_probability, &other.human_probability);
        add(&mut self.human_colours, &other.human_colours);
        add(
            self.log_scales.as_flattened_mut(),
            other.log_scales.as_flattened(),
        );
        self.moved.add(&other.moved);
    }

    /// Checks the lengths against a frame of `n` Gaussians with `active` human branches.
    pub(crate) fn check(&self, n: usize, active: usize) -> Result<(), TrainError> {
        let lengths = [
            ("re-posing cotangent means", n, self.means.len()),
            ("re-posing cotangent covariances", n, self.covariances.len()),
            (
                "re-posing cotangent scene colours",
                n * 3,
                self.scene_colours.len(),
            ),
            (
                "re-posing cotangent probability",
                n,
                self.human_probability.len(),
            ),
            (
                "re-posing cotangent human colours",
                active * 3,
                self.human_colours.len(),
            ),
            (
                "re-posing cotangent log-scales",
                active,
                self.log_scales.len(),
            ),
            (
                "re-posing cotangent moved positions",
                active,
                self.moved.positions.len(),
            ),
        ];
        for (what, expected, found) in lengths {
            if expected != found {
                return Err(TrainError::Shape {
                    what: what.into(),
                    expected,
                    found,
                });
            }
        }
        Ok(())
    }
}

/// The frame `reference` (posed with `reference_cache`) posed with other `bones` (24
/// `frame_from_canonical` transforms), sharing every network output of the reference (see the
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
        human_colours: active.human_rgb,
        log_scales: active.log_scales,
        moved,
    };
    Ok((d, d_bones))
}

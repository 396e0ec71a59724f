//! One differentiable photometric step for statically coloured Gaussians: per-Gaussian colour from the
//! scene-colour network, rasterization, L1 + λ·D-SSIM against a target frame, and the backward pass to
//! every Gaussian parameter, the features and the network weights.
//!
//! This is the scene branch of E-Sem3DGS's rendering step and the composition the full step builds on
//! (the human branch adds deformation and the semantic blend before rasterization). Generic over the
//! float type so the whole chain is finite-difference checked in f64.

use crate::colour::{ColourInputs, ColourNet};
use crate::image_loss::{l1, ssim, ImageShape};
use crate::TrainError;
use rasterize_cpu::{render, render_backward, Camera, Cotangents, RenderSettings, Splats};

/// Stored parameters of N statically coloured Gaussians (same conventions as `gaussians::GaussianSet`).
#[derive(Clone, Copy, Debug)]
pub struct StaticGaussians<'a, T> {
    /// Means in world space (m).
    pub means: &'a [[T; 3]],
    /// Log-scales (ln m).
    pub log_scales: &'a [[T; 3]],
    /// Unnormalised (w, x, y, z) quaternions.
    pub quats: &'a [[T; 4]],
    /// Opacity logits.
    pub opacity_logits: &'a [T],
    /// Colour features, N × `feature_dim` of the colour network.
    pub features: &'a [T],
}

/// Gradients of a step w.r.t. the Gaussians and the colour network.
#[derive(Clone, Debug, PartialEq)]
pub struct StaticGradients<T> {
    /// dL/d means.
    pub means: Vec<[T; 3]>,
    /// dL/d log-scales.
    pub log_scales: Vec<[T; 3]>,
    /// dL/d quaternions.
    pub quats: Vec<[T; 4]>,
    /// dL/d opacity logits.
    pub opacity_logits: Vec<T>,
    /// dL/d features.
    pub features: Vec<T>,
    /// dL/d colour-network parameters.
    pub colour_params: Vec<T>,
    /// dL/d screen-space means in pixels (density-control statistic).
    pub means_2d: Vec<[T; 2]>,
}

/// Result of [`photometric_step`].
#[derive(Clone, Debug)]
pub struct StepOutput<T> {
    /// Total loss (1 − λ)·L1 + λ·(1 − SSIM).
    pub loss: T,
    /// The L1 term.
    pub l1: T,
    /// The SSIM value (not 1 − SSIM).
    pub ssim: T,
    /// The rendered image, (3, H, W).
    pub image: Vec<T>,
    /// Screen radius per Gaussian (pixels, 0 = culled).
    pub radii: Vec<u32>,
    /// Gradients (None when not requested).
    pub grads: Option<StaticGradients<T>>,
}

/// Renders the Gaussians coloured by `net` (view direction = mean − camera centre, differentiated) from
/// `camera` and compares with `target` (3, H, W) using (1 − `ssim_weight`)·L1 + `ssim_weight`·(1 − SSIM).
/// With `with_grads` the backward runs through SSIM/L1, the rasterizer and the colour network.
pub fn photometric_step<T>(
    camera: &Camera,
    gaussians: &StaticGaussians<'_, T>,
    net: &ColourNet<T>,
    target: &[T],
    ssim_weight: T,
    settings: &RenderSettings,
    with_grads: bool,
) -> Result<StepOutput<T>, TrainError>
where
    T: nn::Real + rasterize_cpu::Real,
{
    let n = gaussians.means.len();
    let centre = camera.center_world();
    let centre: [T; 3] = centre.map(<T as nn::Real>::of);
    let directions: Vec<[T; 3]> = gaussians
        .means
        .iter()
        .map(|m| [m[0] - centre[0], m[1] - centre[1], m[2] - centre[2]])
        .collect();
    let inputs = ColourInputs {
        features: gaussians.features,
        directions: &directions,
        extra: &[],
        latent: &[],
    };
    let (rgb, colour_cache) = net.forward(&inputs)?;
    let splats = Splats {
        means: gaussians.means,
        log_scales: gaussians.log_scales,
        quats: gaussians.quats,
        opacity_logits: gaussians.opacity_logits,
        channels: &rgb,
        num_channels: 3,
    };
    let out = render(camera, &splats, settings)?;
    let shape = ImageShape {
        channels: 3,
        height: camera.height as usize,
        width: camera.width as usize,
    };
    if target.len() != shape.len() {
        return Err(TrainError::Shape {
            what: "target image".into(),
            expected: shape.len(),
            found: target.len(),
        });
    }
    let one = T::one();
    let mut d_l1 = if with_grads {
        vec![T::zero(); shape.len()]
    } else {
        Vec::new()
    };
    let mut d_ssim = if with_grads {
        vec![T::zero(); shape.len()]
    } else {
        Vec::new()
    };
    let l1_value = l1(&out.image, target, with_grads.then_some(&mut d_l1[..]));
    let ssim_value = ssim(
        &out.image,
        target,
        shape,
        with_grads.then_some(&mut d_ssim[..]),
    );
    let loss = (one - ssim_weight) * l1_value + ssim_weight * (one - ssim_value);
    let grads = if with_grads {
        let d_image: Vec<T> = d_l1
            .iter()
            .zip(&d_ssim)
            .map(|(&a, &b)| (one - ssim_weight) * a - ssim_weight * b)
            .collect();
        let cot = Cotangents {
            image: &d_image,
            alpha: None,
            depth: None,
        };
        let g = render_backward(camera, &splats, settings, &out, &cot)?;
        let cg = net.backward(&colour_cache, &g.channels)?;
        debug_assert_eq!(g.means.len(), n);
        // The view direction is mean − camera centre, so its gradient adds to the means'.
        let mut means = g.means;
        for (m, d) in means.iter_mut().zip(&cg.directions) {
            for a in 0..3 {
                m[a] = m[a] + d[a];
            }
        }
        Some(StaticGradients {
            means,
            log_scales: g.log_scales,
            quats: g.quats,
            opacity_logits: g.opacity_logits,
            features: cg.features,
            colour_params: cg.params,
            means_2d: g.means_2d,
        })
    } else {
        None
    };
    Ok(StepOutput {
        loss,
        l1: l1_value,
        ssim: ssim_value,
        image: out.image,
        radii: out.radii,
        grads,
    })
}

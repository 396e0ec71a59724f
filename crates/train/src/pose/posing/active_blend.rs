//! The semantic blend's backward over a posed frame's active Gaussians (those with a human
//! branch), with the deformed covariance it blends: shared by a frame's own pass and its
//! re-posings (`crate::pose::reposing`).

use super::FrameCotangents;
use crate::blend::{blend_backward, BlendInputs, Blended, SemanticMode};
use nn::Real;
use rayon::prelude::*;
use smpl_deform::math::Mat3;

/// Σ = M diag(e^{2s}) Mᵀ for a row-major M.
pub(crate) fn deformed_covariance<T: Real>(m: &Mat3<T>, s: &[T; 3]) -> [[T; 3]; 3] {
    let d = s.map(|v| (v + v).exp());
    std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            (0..3).fold(T::zero(), |acc, k| acc + m[i * 3 + k] * d[k] * m[j * 3 + k])
        })
    })
}

/// Backward of [`deformed_covariance`]: (dL/dM, dL/ds).
pub(crate) fn deformed_covariance_backward<T: Real>(
    m: &Mat3<T>,
    s: &[T; 3],
    g: &[[T; 3]; 3],
) -> (Mat3<T>, [T; 3]) {
    let d = s.map(|v| (v + v).exp());
    let two = T::one() + T::one();
    let mut d_m = [T::zero(); 9];
    for i in 0..3 {
        for k in 0..3 {
            // ∂/∂M_ik of Σ_ab G_ab M_ak d_k M_bk = d_k (Σ_b G_ib M_bk + Σ_a G_ai M_ak).
            let mut acc = T::zero();
            for b in 0..3 {
                acc = acc + (g[i][b] + g[b][i]) * m[b * 3 + k];
            }
            d_m[i * 3 + k] = acc * d[k];
        }
    }
    let d_s = std::array::from_fn(|k| {
        let mut acc = T::zero();
        for a in 0..3 {
            for b in 0..3 {
                acc = acc + g[a][b] * m[a * 3 + k] * m[b * 3 + k];
            }
        }
        acc * two * d[k]
    });
    (d_m, d_s)
}

/// Cotangents of the active Gaussians' human branch, out of the blend and the deformed covariance.
pub(crate) struct ActiveBlendGrads<T> {
    /// dL/d deformed position.
    pub x_def: Vec<[T; 3]>,
    /// dL/d deformed matrix M (Σ = M diag(e^{2s}) Mᵀ).
    pub mats: Vec<Mat3<T>>,
    /// dL/d deformed log-scales.
    pub log_scales: Vec<[T; 3]>,
    /// dL/d human colours, active × 3.
    pub human_rgb: Vec<T>,
}

/// The per-Gaussian cotangents of the static branch and of the probability that the blend's
/// backward writes (static mean, static covariance, scene colour: replaced for active Gaussians)
/// or adds to (probability).
pub(crate) struct StaticCotangents<'a, T> {
    pub means: &'a mut [[T; 3]],
    pub covariances: &'a mut [[[T; 3]; 3]],
    pub scene_rgb: &'a mut [T],
    pub probability: &'a mut [T],
}

/// Backward of the blend and of the deformed covariance for the `active` Gaussians of a posed frame
/// (`inputs`, `posed_mats`, `posed_log_scales` in active order) from the outputs' cotangents `cot`;
/// shared by a frame's own pass and its re-posings (`crate::pose::reposing`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn blend_backward_active<T: Real>(
    mode: SemanticMode,
    semantic_logits: &[T],
    active: &[usize],
    inputs: &[BlendInputs<T>],
    posed_mats: &[Mat3<T>],
    posed_log_scales: &[[T; 3]],
    cot: &FrameCotangents<'_, T>,
    out: StaticCotangents<'_, T>,
) -> ActiveBlendGrads<T> {
    let k = semantic_logits
        .len()
        .checked_div(out.probability.len())
        .unwrap_or(0);
    let na = active.len();
    // Every active Gaussian's backward in parallel, then written in order (the serial bits).
    let per_active: Vec<_> = active
        .par_iter()
        .enumerate()
        .map(|(a, &i)| {
            let p = mode.probability(&semantic_logits[i * k..(i + 1) * k]);
            let d_out = Blended {
                x: cot.means[i],
                cov: cot.covariances[i],
                c: [
                    cot.colours[i * 3],
                    cot.colours[i * 3 + 1],
                    cot.colours[i * 3 + 2],
                ],
            };
            let (dp, d_in) = blend_backward(p, &inputs[a], &d_out);
            let (dm, ds) =
                deformed_covariance_backward(&posed_mats[a], &posed_log_scales[a], &d_in.cov_def);
            (dp, d_in, dm, ds)
        })
        .collect();
    let mut grads = ActiveBlendGrads {
        x_def: Vec::with_capacity(na),
        mats: Vec::with_capacity(na),
        log_scales: Vec::with_capacity(na),
        human_rgb: Vec::with_capacity(na * 3),
    };
    for (&i, (dp, d_in, dm, ds)) in active.iter().zip(per_active) {
        out.probability[i] = out.probability[i] + dp;
        grads.x_def.push(d_in.x_def);
        grads.mats.push(dm);
        grads.log_scales.push(ds);
        grads.human_rgb.extend_from_slice(&d_in.c_human);
        out.scene_rgb[i * 3..i * 3 + 3].copy_from_slice(&d_in.c_scene);
        out.means[i] = d_in.x_static;
        out.covariances[i] = d_in.cov_static;
    }
    grads
}

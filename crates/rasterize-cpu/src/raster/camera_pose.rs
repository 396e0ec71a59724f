//! The gradient of a render with respect to its camera's pose, from the render's gradients with
//! respect to its world-space inputs.
//!
//! A camera moved by a twist ξ = (ω, v) in its own coordinates, `T' = exp(ξ^)·T` (ω radians,
//! v metres), sees every point exactly where the unmoved camera sees the point moved by
//! `T⁻¹·exp(ξ^)·T`: the render depends on the inputs only through camera-space means
//! `p_c = R·p + t` and covariances `Σ_c = R·Σ·Rᵀ`. To first order that moves a mean by
//! `Rᵀ(ω × p_c + v)` and a covariance by `Rᵀ(ω^·Σ_c − Σ_c·ω^)R`, so with `g` = dL/dp and
//! `G` = dL/dΣ (world; the nine entries independent, as `render_cov_backward` returns them),
//! `g_c = R·g`, `G_c = R·G·Rᵀ` and `M = Σ_c·G_cᵀ − G_cᵀ·Σ_c`:
//!
//! - dL/dv = Σᵢ g_c,i
//! - dL/dω = Σᵢ p_c,i × g_c,i + (M₁₂ − M₂₁, M₂₀ − M₀₂, M₀₁ − M₁₀)ᵢ
//!
//! Exact wherever the render is differentiable (the same discrete decisions on both sides).

use gaussians::covariance::Mat3;

use crate::{Camera, RasterError, Real};
use rayon::prelude::*;

/// dL/dξ = (dL/dω, dL/dv) of a render from `camera` of Gaussians with world `means` and
/// `covariances`, given the render's gradients with respect to them, `d_means` and
/// `d_covariances` (from [`super::render_cov_backward`]; each pass of
/// [`super::render_cov_shared_backward`] alike). ξ perturbs the camera on the left,
/// `world_to_camera' = exp(ξ^)·world_to_camera`, in camera coordinates (radians, metres).
/// Summed in fixed chunks of Gaussians, in order: the same bits whatever the thread count.
pub fn camera_pose_gradient<T: Real>(
    camera: &Camera,
    means: &[[T; 3]],
    covariances: &[Mat3<T>],
    d_means: &[[T; 3]],
    d_covariances: &[Mat3<T>],
) -> Result<[f64; 6], RasterError> {
    let n = means.len();
    if covariances.len() != n || d_means.len() != n || d_covariances.len() != n {
        return Err(RasterError::InvalidSettings(format!(
            "camera pose gradient: {n} means, {} covariances, {} mean and {} covariance gradients",
            covariances.len(),
            d_means.len(),
            d_covariances.len()
        )));
    }
    // Summed in world coordinates and rotated once: with R a rotation, p_c × g_c =
    // R(p × g) + t × (R g), and M_c = R (Σ Gᵀ − Gᵀ Σ) Rᵀ, whose spin vector is R times the world
    // one's.
    const CHUNK: usize = 4096;
    let partials: Vec<[f64; 6]> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let range = c * CHUNK..((c + 1) * CHUNK).min(n);
            let mut out = [0.0f64; 6];
            for i in range {
                let g =
                    world_twist_terms(&means[i], &covariances[i], &d_means[i], &d_covariances[i]);
                for (o, v) in out.iter_mut().zip(g) {
                    *o += v;
                }
            }
            out
        })
        .collect();
    let mut sum = [0.0f64; 6];
    for p in partials {
        for (o, v) in sum.iter_mut().zip(p) {
            *o += v;
        }
    }
    let w = &camera.world_to_camera;
    let rotate =
        |v: &[f64]| -> [f64; 3] { std::array::from_fn(|i| (0..3).map(|j| w[i][j] * v[j]).sum()) };
    let (turn, shift) = (rotate(&sum[..3]), rotate(&sum[3..]));
    let t = [w[0][3], w[1][3], w[2][3]];
    Ok([
        turn[0] + t[1] * shift[2] - t[2] * shift[1],
        turn[1] + t[2] * shift[0] - t[0] * shift[2],
        turn[2] + t[0] * shift[1] - t[1] * shift[0],
        shift[0],
        shift[1],
        shift[2],
    ])
}

/// One Gaussian's world-coordinate terms of [`camera_pose_gradient`]: `p × g` plus the spin
/// vector of `M = Σ Gᵀ − Gᵀ Σ`, then `g` (zero when its gradients are).
fn world_twist_terms<T: Real>(
    mean: &[T; 3],
    covariance: &Mat3<T>,
    d_mean: &[T; 3],
    d_covariance: &Mat3<T>,
) -> [f64; 6] {
    let f = |x: T| x.to_f64().unwrap_or(f64::NAN);
    if d_mean
        .iter()
        .chain(d_covariance.as_flattened())
        .all(|&v| f(v) == 0.0)
    {
        return [0.0; 6];
    }
    let (p, g) = (mean.map(f), d_mean.map(f));
    let (sigma, grad) = (covariance.map(|r| r.map(f)), d_covariance.map(|r| r.map(f)));
    // M = Σ Gᵀ − Gᵀ Σ: (Σ Gᵀ)_ab = Σ_k Σ_ak G_bk, (Gᵀ Σ)_ab = Σ_k G_ka Σ_kb.
    let m = |a: usize, b: usize| -> f64 {
        (0..3)
            .map(|k| sigma[a][k] * grad[b][k] - grad[k][a] * sigma[k][b])
            .sum()
    };
    [
        p[1] * g[2] - p[2] * g[1] + m(1, 2) - m(2, 1),
        p[2] * g[0] - p[0] * g[2] + m(2, 0) - m(0, 2),
        p[0] * g[1] - p[1] * g[0] + m(0, 1) - m(1, 0),
        g[0],
        g[1],
        g[2],
    ]
}

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
    const CHUNK: usize = 4096;
    let partials: Vec<[f64; 6]> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let range = c * CHUNK..((c + 1) * CHUNK).min(n);
            let mut out = [0.0f64; 6];
            for i in range {
                let g = gaussian_twist_gradient(
                    &camera.world_to_camera,
                    &means[i],
                    &covariances[i],
                    &d_means[i],
                    &d_covariances[i],
                );
                for (o, v) in out.iter_mut().zip(g) {
                    *o += v;
                }
            }
            out
        })
        .collect();
    let mut out = [0.0f64; 6];
    for p in partials {
        for (o, v) in out.iter_mut().zip(p) {
            *o += v;
        }
    }
    Ok(out)
}

/// One Gaussian's share of [`camera_pose_gradient`] (zero when its gradients are).
fn gaussian_twist_gradient<T: Real>(
    w: &[[f64; 4]; 4],
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
    let r = |i: usize, j: usize| w[i][j];
    let rotate =
        |v: [f64; 3]| -> [f64; 3] { std::array::from_fn(|i| (0..3).map(|j| r(i, j) * v[j]).sum()) };
    let p = mean.map(f);
    let pc: [f64; 3] = std::array::from_fn(|a| rotate(p)[a] + w[a][3]);
    let gc = rotate(d_mean.map(f));
    let cross = [
        pc[1] * gc[2] - pc[2] * gc[1],
        pc[2] * gc[0] - pc[0] * gc[2],
        pc[0] * gc[1] - pc[1] * gc[0],
    ];
    // Σ_c = R Σ Rᵀ and G_c = R G Rᵀ.
    let conj = |m: &Mat3<T>| -> [[f64; 3]; 3] {
        std::array::from_fn(|a| {
            std::array::from_fn(|b| {
                (0..3)
                    .map(|k| (0..3).map(|l| r(a, k) * f(m[k][l]) * r(b, l)).sum::<f64>())
                    .sum()
            })
        })
    };
    let (sc, gcov) = (conj(covariance), conj(d_covariance));
    // M = Σ_c G_cᵀ − G_cᵀ Σ_c.
    let m: [[f64; 3]; 3] = std::array::from_fn(|a| {
        std::array::from_fn(|b| {
            (0..3)
                .map(|k| sc[a][k] * gcov[b][k] - gcov[k][a] * sc[k][b])
                .sum()
        })
    });
    let spin = [m[1][2] - m[2][1], m[2][0] - m[0][2], m[0][1] - m[1][0]];
    let mut out = [0.0; 6];
    for a in 0..3 {
        out[a] = cross[a] + spin[a];
        out[3 + a] = gc[a];
    }
    out
}

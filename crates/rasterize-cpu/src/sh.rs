//! SH → colour → raster composition: renders Gaussians whose colour is given by spherical-harmonics
//! coefficients (the 3DGS PLY layout) and differentiates end to end, including the gradient through
//! the view direction (camera centre → mean) into the means.
//!
//! SH evaluation itself lives in `gaussians::sh`; this module only wires it to the rasterizer and
//! must not duplicate that math.

use gaussians::sh::{num_sh_coeffs, sh_to_color, sh_to_color_backward, MAX_SH_DEGREE};
use rayon::prelude::*;

use crate::{
    lit, render, render_backward, Camera, Cotangents, RasterError, Real, RenderOutput,
    RenderSettings, Splats,
};

/// Gaussians coloured by SH coefficients.
#[derive(Clone, Copy, Debug)]
pub struct ShSplats<'a, T> {
    /// Means in world space (metres).
    pub means: &'a [[T; 3]],
    /// Log-scales (natural log of metres).
    pub log_scales: &'a [[T; 3]],
    /// Unnormalised quaternions (w, x, y, z).
    pub quats: &'a [[T; 4]],
    /// Opacity logits.
    pub opacity_logits: &'a [T],
    /// SH coefficients, N × K × 3, coefficient-major per Gaussian (`sh[i*K*3 + k*3 + c]`),
    /// K = (sh_degree + 1)².
    pub sh: &'a [T],
    /// SH degree 0..=3.
    pub sh_degree: usize,
}

/// Output of [`render_sh`]: the raster output (3 channels, RGB) and the per-Gaussian colours used.
#[derive(Clone, Debug)]
pub struct ShRender<T> {
    /// Raster output with C = 3.
    pub output: RenderOutput<T>,
    /// Evaluated colours, N × 3.
    pub colors: Vec<T>,
}

/// Gradients of [`render_sh_backward`], same layouts as [`ShSplats`].
#[derive(Clone, Debug, PartialEq)]
pub struct ShGradients<T> {
    /// dL/d means (projection and view-direction paths).
    pub means: Vec<[T; 3]>,
    /// dL/d log-scales.
    pub log_scales: Vec<[T; 3]>,
    /// dL/d unnormalised quaternions.
    pub quats: Vec<[T; 4]>,
    /// dL/d opacity logits.
    pub opacity_logits: Vec<T>,
    /// dL/d SH coefficients, N × K × 3.
    pub sh: Vec<T>,
    /// dL/d screen-space means (pixels), for density control.
    pub means_2d: Vec<[T; 2]>,
}

fn check_sh<T>(s: &ShSplats<'_, T>) -> Result<usize, RasterError> {
    if s.sh_degree > MAX_SH_DEGREE {
        return Err(RasterError::InvalidShDegree {
            degree: s.sh_degree,
        });
    }
    let k = num_sh_coeffs(s.sh_degree);
    let expected = s.means.len() * k * 3;
    if s.sh.len() != expected {
        return Err(RasterError::LengthMismatch {
            field: "sh",
            got: s.sh.len(),
            expected,
        });
    }
    Ok(k)
}

fn centre<T: Real>(camera: &Camera) -> [T; 3] {
    camera.center_world().map(|v| lit(v))
}

/// Evaluates SH colours for the view of `camera` and renders them (C = 3).
pub fn render_sh<T: Real>(
    camera: &Camera,
    splats: &ShSplats<'_, T>,
    settings: &RenderSettings,
) -> Result<ShRender<T>, RasterError> {
    let k = check_sh(splats)?;
    let eye = centre::<T>(camera);
    let n = splats.means.len();
    if let Some(i) = (0..n).into_par_iter().find_first(|&i| {
        !splats.sh[i * k * 3..(i + 1) * k * 3]
            .iter()
            .all(|v| v.is_finite())
    }) {
        return Err(RasterError::NonFiniteParameter {
            index: i,
            field: "sh",
        });
    }
    let mut colors = vec![T::zero(); n * 3];
    colors.par_chunks_mut(3).enumerate().for_each(|(i, out)| {
        let m = splats.means[i];
        let dir = [m[0] - eye[0], m[1] - eye[1], m[2] - eye[2]];
        let rgb = sh_to_color(
            splats.sh_degree,
            &splats.sh[i * k * 3..(i + 1) * k * 3],
            dir,
        );
        out.copy_from_slice(&rgb);
    });
    let output = render(
        camera,
        &Splats {
            means: splats.means,
            log_scales: splats.log_scales,
            quats: splats.quats,
            opacity_logits: splats.opacity_logits,
            channels: &colors,
            num_channels: 3,
        },
        settings,
    )?;
    Ok(ShRender { output, colors })
}

/// Backward of [`render_sh`]: gradients w.r.t. means (through the projection and the view direction),
/// log-scales, quaternions, opacity logits and SH coefficients.
pub fn render_sh_backward<T: Real>(
    camera: &Camera,
    splats: &ShSplats<'_, T>,
    settings: &RenderSettings,
    forward: &ShRender<T>,
    cot: &Cotangents<'_, T>,
) -> Result<ShGradients<T>, RasterError> {
    let k = check_sh(splats)?;
    let g = render_backward(
        camera,
        &Splats {
            means: splats.means,
            log_scales: splats.log_scales,
            quats: splats.quats,
            opacity_logits: splats.opacity_logits,
            channels: &forward.colors,
            num_channels: 3,
        },
        settings,
        &forward.output,
        cot,
    )?;
    let eye = centre::<T>(camera);
    let n = splats.means.len();
    let mut d_sh = vec![T::zero(); n * k * 3];
    let mut means = g.means;
    d_sh.par_chunks_mut(k * 3)
        .zip(means.par_iter_mut())
        .enumerate()
        .for_each(|(i, (dsh, dm))| {
            let m = splats.means[i];
            let dir = [m[0] - eye[0], m[1] - eye[1], m[2] - eye[2]];
            let dc = [
                g.channels[i * 3],
                g.channels[i * 3 + 1],
                g.channels[i * 3 + 2],
            ];
            let dd = sh_to_color_backward(
                splats.sh_degree,
                &splats.sh[i * k * 3..(i + 1) * k * 3],
                dir,
                dc,
                dsh,
            );
            for j in 0..3 {
                dm[j] = dm[j] + dd[j];
            }
        });
    Ok(ShGradients {
        means,
        log_scales: g.log_scales,
        quats: g.quats,
        opacity_logits: g.opacity_logits,
        sh: d_sh,
        means_2d: g.means_2d,
    })
}

//! The rasterizer's public input, settings and output types, and the checks of a request (lengths,
//! finite parameters, non-zero quaternions, symmetric covariances, settings) that run before any
//! work. [`Inputs`] is the one internal form of both input kinds ([`Splats`], [`CovSplats`]), so
//! the forward and backward drivers never branch on the kind except where Σ comes from.

use rayon::prelude::*;

use gaussians::covariance::Mat3;

use super::forward::ForwardState;
use crate::project::{project, project_cov, project_cov_smeared, CameraParams, Projected};
use crate::{lit, RasterError, Real};

/// Gaussians to splat, as structure-of-arrays slices of equal length N.
#[derive(Clone, Copy, Debug)]
pub struct Splats<'a, T> {
    /// Means in world space (metres).
    pub means: &'a [[T; 3]],
    /// Log-scales (natural log of metres).
    pub log_scales: &'a [[T; 3]],
    /// Unnormalised quaternions (w, x, y, z); zero quaternions are rejected.
    pub quats: &'a [[T; 4]],
    /// Opacity logits (opacity = sigmoid(logit)).
    pub opacity_logits: &'a [T],
    /// Per-Gaussian channels, N × C row-major (`channels[i * C + c]`).
    pub channels: &'a [T],
    /// Number of channels C (may be 0).
    pub num_channels: usize,
}

impl<T> Splats<'_, T> {
    /// Number of Gaussians N.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// True when there are no Gaussians.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }
}

/// Gaussians given by precomputed world-frame 3D covariances instead of log-scales and quaternions
/// (e.g. blended covariances Σ = p·Σ_a + (1 − p)·Σ_b), as structure-of-arrays slices of equal
/// length N. Rendered by [`render_cov`] / [`render_cov_backward`] with exactly the rules of
/// [`render`]: `render_cov` with Σ = `covariance_3d(log_scale, quat)` gives the same bits as
/// `render`.
///
/// [`render`]: super::render
/// [`render_cov`]: super::render_cov
/// [`render_cov_backward`]: super::render_cov_backward
#[derive(Clone, Copy, Debug)]
pub struct CovSplats<'a, T> {
    /// Means in world space (metres).
    pub means: &'a [[T; 3]],
    /// World-frame 3D covariances Σ (m², row-major `[row][col]`). Each must be finite and symmetric
    /// up to rounding: |Σ_ij − Σ_ji| ≤ 1e-4 · max_k |Σ_kk| (see
    /// [`RasterError::NonSymmetricCovariance`]). All nine entries are used as given.
    pub covariances: &'a [[[T; 3]; 3]],
    /// Opacity logits (opacity = sigmoid(logit)).
    pub opacity_logits: &'a [T],
    /// Per-Gaussian channels, N × C row-major (`channels[i * C + c]`).
    pub channels: &'a [T],
    /// Number of channels C (may be 0).
    pub num_channels: usize,
    /// Per-Gaussian motion within the render's time slice, or `None`: the world covariance of
    /// each Gaussian's positions over the slice (m², symmetric like `covariances`; u uᵀ/12 for a
    /// displacement u at constant speed). The render is then the slice's time average, each
    /// Gaussian blurred along its motion with its screen-space mass kept
    /// ([`crate::project::project_cov_smeared`]); a zero smear renders as without one.
    pub smears: Option<&'a [[[T; 3]; 3]]>,
}

impl<T> CovSplats<'_, T> {
    /// Number of Gaussians N.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// True when there are no Gaussians.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }
}

/// Relative asymmetry |Σ_ij − Σ_ji| / max_k |Σ_kk| above which a covariance is rejected. Rounding of
/// any reasonable f32 construction is ~1e-7; finite-difference probes of single entries stay below.
pub const COVARIANCE_SYMMETRY_TOLERANCE: f64 = 1e-4;

/// Where a Gaussian's 3D shape comes from: the only difference between [`render`] and
/// [`render_cov`].
///
/// [`render`]: super::render
/// [`render_cov`]: super::render_cov
#[derive(Clone, Copy, Debug)]
pub(super) enum Shapes<'a, T> {
    /// Log-scales and unnormalised quaternions; Σ = `covariance_3d`.
    ScaleRot {
        log_scales: &'a [[T; 3]],
        quats: &'a [[T; 4]],
    },
    /// Precomputed covariances.
    Cov(&'a [[[T; 3]; 3]]),
}

/// The rasterizer's input, whatever the shape source.
#[derive(Clone, Copy, Debug)]
pub(super) struct Inputs<'a, T> {
    pub(super) means: &'a [[T; 3]],
    pub(super) shapes: Shapes<'a, T>,
    pub(super) opacity_logits: &'a [T],
    pub(super) channels: &'a [T],
    pub(super) num_channels: usize,
    pub(super) smears: Option<&'a [Mat3<T>]>,
}

impl<'a, T: Real> Inputs<'a, T> {
    pub(super) fn len(&self) -> usize {
        self.means.len()
    }

    #[inline]
    pub(super) fn project(&self, cam: &CameraParams<T>, i: usize) -> Option<Projected<T>> {
        match self.shapes {
            Shapes::ScaleRot { log_scales, quats } => project(
                cam,
                self.means[i],
                log_scales[i],
                quats[i],
                self.opacity_logits[i],
            ),
            Shapes::Cov(covs) => match self.smears {
                None => project_cov(cam, self.means[i], &covs[i], self.opacity_logits[i]),
                Some(smears) => project_cov_smeared(
                    cam,
                    self.means[i],
                    &covs[i],
                    &smears[i],
                    self.opacity_logits[i],
                ),
            },
        }
    }
}

impl<'a, T> From<&Splats<'a, T>> for Inputs<'a, T> {
    fn from(s: &Splats<'a, T>) -> Self {
        Self {
            means: s.means,
            shapes: Shapes::ScaleRot {
                log_scales: s.log_scales,
                quats: s.quats,
            },
            opacity_logits: s.opacity_logits,
            channels: s.channels,
            num_channels: s.num_channels,
            smears: None,
        }
    }
}

impl<'a, T> From<&CovSplats<'a, T>> for Inputs<'a, T> {
    fn from(s: &CovSplats<'a, T>) -> Self {
        Self {
            means: s.means,
            shapes: Shapes::Cov(s.covariances),
            opacity_logits: s.opacity_logits,
            channels: s.channels,
            num_channels: s.num_channels,
            smears: s.smears,
        }
    }
}

/// Default near plane of [`RenderSettings`] (metres of view depth): INRIA 3DGS's 0.2.
pub const DEFAULT_NEAR_PLANE: f64 = 0.2;

/// Render settings.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Near plane: Gaussians with view depth z ≤ near (metres) are culled. Default
    /// [`DEFAULT_NEAR_PLANE`] (INRIA's 0.2).
    pub near_plane: f64,
    /// Background value per channel, composited with the final transmittance. Empty = all zeros;
    /// otherwise exactly C values.
    pub background: Vec<f64>,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            near_plane: DEFAULT_NEAR_PLANE,
            background: Vec::new(),
        }
    }
}

/// Forward output.
#[derive(Clone, Debug)]
pub struct RenderOutput<T> {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Channels C.
    pub num_channels: usize,
    /// Planar image (C, H, W), background composited.
    pub image: Vec<T>,
    /// Accumulated alpha 1 − T_final, (H, W).
    pub alpha: Vec<T>,
    /// Alpha-weighted view depth Σ wᵢ zᵢ (metres), (H, W); divide by `alpha` for expected depth.
    pub depth: Vec<T>,
    /// INRIA screen radius per input Gaussian (pixels); 0 = culled.
    pub radii: Vec<u32>,
    /// Number of (tile, Gaussian) pairs blended (a cost measure).
    pub num_pairs: usize,
    pub(super) state: ForwardState<T>,
}

/// Cotangents (dL/d output) for [`render_backward`].
///
/// [`render_backward`]: super::render_backward
#[derive(Clone, Copy, Debug)]
pub struct Cotangents<'a, T> {
    /// dL/d image, (C, H, W).
    pub image: &'a [T],
    /// dL/d alpha, (H, W), if the loss uses it.
    pub alpha: Option<&'a [T]>,
    /// dL/d depth, (H, W), if the loss uses it.
    pub depth: Option<&'a [T]>,
}

/// Gradients w.r.t. every input of [`render`] (or [`render_cov`]), same layouts as [`Splats`]
/// (or [`CovSplats`]).
///
/// [`render`]: super::render
/// [`render_cov`]: super::render_cov
#[derive(Clone, Debug, PartialEq)]
pub struct Gradients<T> {
    /// dL/d means (world).
    pub means: Vec<[T; 3]>,
    /// dL/d log-scales ([`super::render_backward`] only; empty from
    /// [`super::render_cov_backward`]).
    pub log_scales: Vec<[T; 3]>,
    /// dL/d unnormalised quaternions ([`super::render_backward`] only; empty from
    /// [`super::render_cov_backward`]).
    pub quats: Vec<[T; 4]>,
    /// dL/d covariances, N × 3 × 3, the nine entries treated as independent variables of
    /// cov2d = J W Σ Wᵀ Jᵀ (not symmetrised: chain entry by entry). [`super::render_cov_backward`]
    /// only; empty from [`super::render_backward`].
    pub covariances: Vec<Mat3<T>>,
    /// dL/d smears, N × 3 × 3, entries independent like `covariances`; empty without smears.
    pub smears: Vec<Mat3<T>>,
    /// dL/d opacity logits.
    pub opacity_logits: Vec<T>,
    /// dL/d channels, N × C.
    pub channels: Vec<T>,
    /// dL/d screen-space mean (per pixel; multiply by (W/2, H/2) for INRIA's NDC-space gradient),
    /// for density control.
    pub means_2d: Vec<[T; 2]>,
    /// dL/d background, C values.
    pub background: Vec<T>,
}

pub(super) fn validate<T: Real>(splats: &Inputs<'_, T>) -> Result<(), RasterError> {
    let n = splats.len();
    let check_len = |field, got| {
        if got == n {
            Ok(())
        } else {
            Err(RasterError::LengthMismatch {
                field,
                got,
                expected: n,
            })
        }
    };
    match splats.shapes {
        Shapes::ScaleRot { log_scales, quats } => {
            check_len("log_scales", log_scales.len())?;
            check_len("quats", quats.len())?;
        }
        Shapes::Cov(covs) => check_len("covariances", covs.len())?,
    }
    check_len("opacity_logits", splats.opacity_logits.len())?;
    if let Some(smears) = splats.smears {
        check_len("smears", smears.len())?;
    }
    let expected = n * splats.num_channels;
    if splats.channels.len() != expected {
        return Err(RasterError::LengthMismatch {
            field: "channels",
            got: splats.channels.len(),
            expected,
        });
    }
    if n > u32::MAX as usize {
        return Err(RasterError::InvalidSettings(format!(
            "{n} Gaussians exceed the supported maximum {}",
            u32::MAX
        )));
    }
    // Report the first bad Gaussian (lowest index), found in parallel.
    let first_error = (0..n)
        .into_par_iter()
        .map(|i| check_gaussian(splats, i))
        .find_first(Result::is_err);
    match first_error {
        Some(e) => e,
        None => Ok(()),
    }
}

/// Checks Gaussian `i`'s parameters: all finite, quaternion non-zero, covariance symmetric.
fn check_gaussian<T: Real>(splats: &Inputs<'_, T>, i: usize) -> Result<(), RasterError> {
    let finite = |v: &[T]| v.iter().all(|x| x.is_finite());
    let bad = |field| Err(RasterError::NonFiniteParameter { index: i, field });
    if !finite(&splats.means[i]) {
        return bad("means");
    }
    match splats.shapes {
        Shapes::ScaleRot { log_scales, quats } => {
            if !finite(&log_scales[i]) {
                return bad("log_scales");
            }
            if !finite(&quats[i]) {
                return bad("quats");
            }
        }
        Shapes::Cov(covs) => {
            if !covs[i].iter().all(|row| finite(row)) {
                return bad("covariances");
            }
            if !splats
                .smears
                .is_none_or(|m| m[i].iter().all(|row| finite(row)))
            {
                return bad("smears");
            }
        }
    }
    if !splats.opacity_logits[i].is_finite() {
        return bad("opacity_logits");
    }
    let c = splats.num_channels;
    if !finite(&splats.channels[i * c..(i + 1) * c]) {
        return bad("channels");
    }
    match splats.shapes {
        Shapes::ScaleRot { quats, .. } => {
            if quats[i].iter().all(|v| *v == T::zero()) {
                return Err(RasterError::ZeroQuaternion { index: i });
            }
        }
        Shapes::Cov(covs) => {
            check_symmetric(&covs[i], i, "covariances")?;
            if let Some(smears) = splats.smears {
                check_symmetric(&smears[i], i, "smears")?;
            }
        }
    }
    Ok(())
}

/// Checks that Gaussian `index`'s matrix `m` of `field` is symmetric up to rounding.
fn check_symmetric<T: Real>(
    m: &Mat3<T>,
    index: usize,
    field: &'static str,
) -> Result<(), RasterError> {
    let scale = m[0][0].abs().max(m[1][1].abs()).max(m[2][2].abs());
    let tol = scale * lit(COVARIANCE_SYMMETRY_TOLERANCE);
    for (r, col) in [(0, 1), (0, 2), (1, 2)] {
        let diff = (m[r][col] - m[col][r]).abs();
        if !(diff <= tol) {
            return Err(RasterError::NonSymmetricCovariance {
                index,
                field,
                row: r,
                col,
                asymmetry: diff.to_f64().unwrap_or(f64::NAN),
                scale: scale.to_f64().unwrap_or(f64::NAN),
            });
        }
    }
    Ok(())
}

pub(super) fn background<T: Real>(
    settings: &RenderSettings,
    c: usize,
) -> Result<Vec<T>, RasterError> {
    if !(settings.near_plane.is_finite() && settings.near_plane > 0.0) {
        return Err(RasterError::InvalidSettings(format!(
            "near_plane {} must be finite and positive",
            settings.near_plane
        )));
    }
    if settings.background.is_empty() {
        return Ok(vec![T::zero(); c]);
    }
    if settings.background.len() != c {
        return Err(RasterError::LengthMismatch {
            field: "background",
            got: settings.background.len(),
            expected: c,
        });
    }
    if let Some(v) = settings.background.iter().find(|v| !v.is_finite()) {
        return Err(RasterError::InvalidSettings(format!(
            "background value {v} is not finite"
        )));
    }
    Ok(settings.background.iter().map(|&v| lit(v)).collect())
}

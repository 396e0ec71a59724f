//! Tile binning, depth sort, front-to-back blending and its analytic backward.
//!
//! Forward (INRIA rules): every visible Gaussian is duplicated once per 16×16 tile of its rectangle;
//! the pairs are ordered by tile, then view depth (ties by input index, which is what INRIA's stable
//! radix sort does); each tile blends its list front to back with α = min(0.99, o·exp(power)),
//! skipping power > 0 and α < 1/255, and a pixel stops when T·(1 − α) < 1e-4 (that splat excluded).
//! Output per pixel: `image_c = Σ wᵢ cᵢ + T_final · bg_c`, `alpha = 1 − T_final`,
//! `depth = Σ wᵢ zᵢ` with `wᵢ = αᵢ Tᵢ` (divide depth by alpha for the expected depth of what is hit).
//!
//! Backward: each tile replays its list front to back (recomputing every Tᵢ exactly as the forward
//! did, instead of recovering it by division) and gets the colour behind each splat from the stored
//! final sums. Where α is clamped at 0.99 its derivative w.r.t. opacity and power is zero (the true
//! derivative of the clamp). Per-(tile, Gaussian) contributions are written in sorted order and then
//! summed per Gaussian in tile order, so gradients are bit-identical for any thread count.
//!
//! Hot loops are splat-major: after sorting, each pair's 2D parameters and channels are gathered into
//! contiguous per-pair arrays (so a tile streams its list), and each tile row of a splat's
//! (margin-padded) box where α can reach 1/255 is processed as groups of 4 lanes (one per pixel
//! column) in select-only loops that the compiler vectorises (SSE2 baseline). The backward replays
//! the forward's exact α, T and stop decisions (same lane code), so it needs no per-pixel record of
//! the last contributor. They never allocate.

use rayon::prelude::*;

use gaussians::covariance::{covariance_3d_backward, Mat3};

use crate::lanes::Lanes;

#[cfg(target_arch = "x86_64")]
mod avx512;
use crate::project::{
    project, project_cov, project_cov_backward, CameraParams, Projected, ProjectedGrad,
};
use crate::{camera, lit, Camera, RasterError, Real, TILE_PIXELS, TILE_SIZE};

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
#[derive(Clone, Copy, Debug)]
enum Shapes<'a, T> {
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
struct Inputs<'a, T> {
    means: &'a [[T; 3]],
    shapes: Shapes<'a, T>,
    opacity_logits: &'a [T],
    channels: &'a [T],
    num_channels: usize,
}

impl<'a, T: Real> Inputs<'a, T> {
    fn len(&self) -> usize {
        self.means.len()
    }

    #[inline]
    fn project(&self, cam: &CameraParams<T>, i: usize) -> Option<Projected<T>> {
        match self.shapes {
            Shapes::ScaleRot { log_scales, quats } => project(
                cam,
                self.means[i],
                log_scales[i],
                quats[i],
                self.opacity_logits[i],
            ),
            Shapes::Cov(covs) => project_cov(cam, self.means[i], &covs[i], self.opacity_logits[i]),
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
        }
    }
}

/// Render settings.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Near plane: Gaussians with view depth z ≤ near (metres) are culled. INRIA default 0.2.
    pub near_plane: f64,
    /// Background value per channel, composited with the final transmittance. Empty = all zeros;
    /// otherwise exactly C values.
    pub background: Vec<f64>,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            near_plane: 0.2,
            background: Vec::new(),
        }
    }
}

/// The part of a [`Projected`] Gaussian the tile kernels read, copied per (tile, Gaussian) pair in
/// sorted order so that each tile streams its list from contiguous memory.
#[derive(Clone, Copy, Debug)]
struct PairSplat<T> {
    mean2d: [T; 2],
    conic: [T; 3],
    opacity: T,
    depth: T,
    extent: [T; 2],
}

/// Everything the backward pass needs from the forward pass.
#[derive(Clone, Debug)]
struct ForwardState<T> {
    /// Visible Gaussians (compact order = increasing input index).
    visible: Vec<Projected<T>>,
    /// Input index of each visible Gaussian.
    visible_ids: Vec<u32>,
    /// Offsets of each tile's list in `tile_list` (length tiles + 1).
    tile_offsets: Vec<usize>,
    /// Compact indices, sorted by tile then depth.
    tile_list: Vec<u32>,
    /// What the tile kernels read of each pair's Gaussian, gathered in `tile_list` order.
    pair_splats: Vec<PairSplat<T>>,
    /// Each pair's channels, pairs × C, in `tile_list` order.
    pair_channels: Vec<T>,
    /// Per tile, tile-major pixels: [T_final (256) | depth (256) | channel sums C × 256].
    tile_buf: Vec<T>,
    /// Per tile: number of list entries the forward blended before every pixel had stopped (the
    /// list length if some pixel never stopped). The backward replays exactly these.
    used: Vec<u32>,
    /// Background in working precision (C values).
    background: Vec<T>,
    /// Number of input Gaussians.
    n: usize,
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
    state: ForwardState<T>,
}

/// Cotangents (dL/d output) for [`render_backward`].
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
#[derive(Clone, Debug, PartialEq)]
pub struct Gradients<T> {
    /// dL/d means (world).
    pub means: Vec<[T; 3]>,
    /// dL/d log-scales ([`render_backward`] only; empty from [`render_cov_backward`]).
    pub log_scales: Vec<[T; 3]>,
    /// dL/d unnormalised quaternions ([`render_backward`] only; empty from [`render_cov_backward`]).
    pub quats: Vec<[T; 4]>,
    /// dL/d covariances, N × 3 × 3, the nine entries treated as independent variables of
    /// cov2d = J W Σ Wᵀ Jᵀ (not symmetrised: chain entry by entry). [`render_cov_backward`] only;
    /// empty from [`render_backward`].
    pub covariances: Vec<Mat3<T>>,
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

/// One Gaussian's gradients: (mean, Σ, opacity logit, screen mean).
type GaussianGrad<T> = ([T; 3], Mat3<T>, T, [T; 2]);

const BUF_T: usize = 0;
const BUF_D: usize = TILE_PIXELS;
const BUF_C: usize = 2 * TILE_PIXELS;

fn validate<T: Real>(splats: &Inputs<'_, T>) -> Result<(), RasterError> {
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
            let m = &covs[i];
            let scale = m[0][0].abs().max(m[1][1].abs()).max(m[2][2].abs());
            let tol = scale * lit(COVARIANCE_SYMMETRY_TOLERANCE);
            for (r, col) in [(0, 1), (0, 2), (1, 2)] {
                let diff = (m[r][col] - m[col][r]).abs();
                if !(diff <= tol) {
                    return Err(RasterError::NonSymmetricCovariance {
                        index: i,
                        row: r,
                        col,
                        asymmetry: diff.to_f64().unwrap_or(f64::NAN),
                        scale: scale.to_f64().unwrap_or(f64::NAN),
                    });
                }
            }
        }
    }
    Ok(())
}

fn background<T: Real>(settings: &RenderSettings, c: usize) -> Result<Vec<T>, RasterError> {
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

/// Range of pixel columns (or rows) `[lo, hi)` within a tile side of `len` pixels starting at
/// `origin` whose centres lie within `half` of `mean`: lo = ⌈mean − half − ½ − origin⌉ and
/// hi = ⌊mean + half − ½ − origin⌋ + 1, clamped to [0, len] (NaN gives len). Floor and ceiling are
/// taken by truncation inside the clamp range, where the values are positive, so that the tile
/// kernels call no libm rounding function (baseline x86-64 has no rounding instruction).
#[inline(always)]
fn pixel_span<T: Real>(mean: T, half: T, origin: T, len: usize) -> (usize, usize) {
    let h: T = lit(0.5);
    let len_t: T = lit(len as f64);
    let lo = mean - half - h - origin;
    let hi = mean + half - h - origin;
    let trunc = |v: T| v.to_usize().unwrap_or(len);
    let lo = if lo <= T::zero() {
        0
    } else if !(lo < len_t) {
        len
    } else {
        let t = trunc(lo);
        t + usize::from(lit::<T>(t as f64) < lo)
    };
    let hi = if hi < T::zero() {
        0
    } else if !(hi < len_t) {
        len
    } else {
        (trunc(hi) + 1).min(len)
    };
    (lo, hi)
}

/// Renders the Gaussians `splats` from `camera` (see the module docs for the rules and outputs).
pub fn render<T: Real>(
    camera: &Camera,
    splats: &Splats<'_, T>,
    settings: &RenderSettings,
) -> Result<RenderOutput<T>, RasterError> {
    render_inputs(camera, &Inputs::from(splats), settings)
}

/// Renders Gaussians given by precomputed 3D covariances, with exactly the rules and outputs of
/// [`render`] (which equals this with Σ = `covariance_3d(log_scale, quat)`, bit for bit).
pub fn render_cov<T: Real>(
    camera: &Camera,
    splats: &CovSplats<'_, T>,
    settings: &RenderSettings,
) -> Result<RenderOutput<T>, RasterError> {
    render_inputs(camera, &Inputs::from(splats), settings)
}

fn render_inputs<T: Real>(
    camera: &Camera,
    splats: &Inputs<'_, T>,
    settings: &RenderSettings,
) -> Result<RenderOutput<T>, RasterError> {
    camera::check_image_size(camera.width.into(), camera.height.into())?;
    validate(splats)?;
    let c = splats.num_channels;
    let bg = background::<T>(settings, c)?;
    let cam = CameraParams::<T>::new(camera, settings.near_plane);
    let n = splats.len();
    let (width, height) = (camera.width as usize, camera.height as usize);
    let [gx, gy] = cam.grid;
    let (gx, gy) = (gx as usize, gy as usize);
    let n_tiles = gx * gy;

    // 1. Project (parallel, order-preserving).
    let projected: Vec<Option<Projected<T>>> = (0..n)
        .into_par_iter()
        .map(|i| splats.project(&cam, i))
        .collect();
    let mut radii = vec![0u32; n];
    let mut visible = Vec::new();
    let mut visible_ids = Vec::new();
    for (i, p) in projected.into_iter().enumerate() {
        if let Some(p) = p {
            radii[i] = p.radius;
            visible.push(p);
            visible_ids.push(i as u32);
        }
    }

    // 2. Bin into tiles: counting sort by tile (stable in input order), then sort each tile by
    //    (depth, input index), which equals INRIA's stable radix sort on (tile, depth).
    let (tile_offsets, tile_list) = bin_and_sort(&visible, gx, n_tiles);
    let num_pairs = tile_list.len();
    let pair_splats: Vec<PairSplat<T>> = tile_list
        .par_iter()
        .map(|&ci| {
            let p = &visible[ci as usize];
            PairSplat {
                mean2d: p.mean2d,
                conic: p.conic,
                opacity: p.opacity,
                depth: p.depth,
                extent: p.extent,
            }
        })
        .collect();
    let mut pair_channels = vec![T::zero(); num_pairs * c];
    if c > 0 {
        pair_channels
            .par_chunks_mut(c)
            .zip(tile_list.par_iter())
            .for_each(|(dst, &ci)| {
                let g = visible_ids[ci as usize] as usize;
                dst.copy_from_slice(&splats.channels[g * c..(g + 1) * c]);
            });
    }

    // 3. Blend every tile.
    let stride = (2 + c) * TILE_PIXELS;
    let mut tile_buf = vec![T::zero(); n_tiles * stride];
    let mut used = vec![0u32; n_tiles];
    tile_buf
        .par_chunks_mut(stride)
        .zip(used.par_iter_mut())
        .enumerate()
        .for_each(|(tile, (buf, used))| {
            let range = tile_offsets[tile]..tile_offsets[tile + 1];
            let origin = [(tile % gx) * TILE_SIZE, (tile / gx) * TILE_SIZE];
            let size = [
                TILE_SIZE.min(width - origin[0]),
                TILE_SIZE.min(height - origin[1]),
            ];
            forward_tile_dispatch(
                &pair_splats,
                &pair_channels,
                range,
                c,
                origin,
                size,
                buf,
                used,
            );
        });

    // 4. Planar outputs.
    let hw = width * height;
    let mut image = vec![T::zero(); c * hw];
    let mut alpha = vec![T::zero(); hw];
    let mut depth = vec![T::zero(); hw];
    let tile_px = |x: usize, y: usize| {
        let tile = (y / TILE_SIZE) * gx + x / TILE_SIZE;
        (tile * stride, (y % TILE_SIZE) * TILE_SIZE + x % TILE_SIZE)
    };
    image
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(row, out)| {
            let (ch, y) = (row / height, row % height);
            for (x, o) in out.iter_mut().enumerate() {
                let (base, p) = tile_px(x, y);
                *o = tile_buf[base + BUF_C + ch * TILE_PIXELS + p]
                    + tile_buf[base + BUF_T + p] * bg[ch];
            }
        });
    alpha
        .par_chunks_mut(width)
        .zip(depth.par_chunks_mut(width))
        .enumerate()
        .for_each(|(y, (a, d))| {
            for x in 0..width {
                let (base, p) = tile_px(x, y);
                a[x] = T::one() - tile_buf[base + BUF_T + p];
                d[x] = tile_buf[base + BUF_D + p];
            }
        });

    Ok(RenderOutput {
        width: camera.width,
        height: camera.height,
        num_channels: c,
        image,
        alpha,
        depth,
        radii,
        num_pairs,
        state: ForwardState {
            visible,
            visible_ids,
            tile_offsets,
            tile_list,
            pair_splats,
            pair_channels,
            tile_buf,
            used,
            background: bg,
            n,
        },
    })
}

/// Visible Gaussians per binning job of [`bin_and_sort`]: at least this many.
const BIN_CHUNK: usize = 4096;
/// Upper bound on the number of binning jobs.
const MAX_BIN_JOBS: usize = 32;
/// Upper bound on the per-tile counters of all binning jobs together (each job holds one per
/// tile), so that huge images get fewer jobs rather than large count arrays.
const BIN_COUNTER_BUDGET: usize = 1 << 20;

/// One binning job's entries (depth keys, see [`Real::depth_key`]) grouped by tile, and where each
/// tile's group starts (n_tiles + 1 offsets).
type BinJob<K> = (Vec<usize>, Vec<K>);

/// Tile lists: for every tile, the indices of the visible Gaussians overlapping it sorted by
/// (view depth, index), as offsets into one list. Equals INRIA's stable radix sort on
/// (tile, depth).
///
/// Parallel: jobs over contiguous chunks of `visible` bin their Gaussians by tile (a local counting
/// sort); every tile then gathers its entries from the jobs and sorts them. The key (depth, index)
/// is a total order, so the lists are the same for any chunking and thread count.
fn bin_and_sort<T: Real>(
    visible: &[Projected<T>],
    gx: usize,
    n_tiles: usize,
) -> (Vec<usize>, Vec<u32>) {
    let max_jobs = (BIN_COUNTER_BUDGET / (n_tiles + 1)).clamp(1, MAX_BIN_JOBS);
    let chunk = BIN_CHUNK.max(visible.len().div_ceil(max_jobs));
    // 1. Per job: its entries grouped by tile, and where each tile's group starts.
    let jobs: Vec<BinJob<T::DepthKey>> = visible
        .par_chunks(chunk)
        .enumerate()
        .map(|(job, part)| {
            let mut starts = vec![0usize; n_tiles + 1];
            for p in part {
                for ty in p.rect[1]..p.rect[3] {
                    let row = ty as usize * gx;
                    for tx in p.rect[0]..p.rect[2] {
                        starts[row + tx as usize + 1] += 1;
                    }
                }
            }
            for t in 0..n_tiles {
                starts[t + 1] += starts[t];
            }
            let mut cursor = starts.clone();
            let mut entries = vec![T::DepthKey::default(); starts[n_tiles]];
            for (j, p) in part.iter().enumerate() {
                // View depth is > near > 0, so its bit pattern orders like the value.
                let key = T::depth_key(p.depth, (job * chunk + j) as u32);
                for ty in p.rect[1]..p.rect[3] {
                    let row = ty as usize * gx;
                    for tx in p.rect[0]..p.rect[2] {
                        let t = row + tx as usize;
                        entries[cursor[t]] = key;
                        cursor[t] += 1;
                    }
                }
            }
            (starts, entries)
        })
        .collect();
    // 2. Tile offsets in the global list.
    let mut offsets = vec![0usize; n_tiles + 1];
    for t in 0..n_tiles {
        let count: usize = jobs
            .iter()
            .map(|(starts, _)| starts[t + 1] - starts[t])
            .sum();
        offsets[t + 1] = offsets[t] + count;
    }
    // 3. Every tile gathers its entries from the jobs and sorts them.
    let mut entries = vec![T::DepthKey::default(); offsets[n_tiles]];
    let mut slices = Vec::with_capacity(n_tiles);
    let mut rest: &mut [T::DepthKey] = &mut entries;
    for t in 0..n_tiles {
        let (head, tail) = rest.split_at_mut(offsets[t + 1] - offsets[t]);
        slices.push(head);
        rest = tail;
    }
    slices.into_par_iter().enumerate().for_each(|(t, dst)| {
        let mut at = 0;
        for (starts, part) in &jobs {
            let group = &part[starts[t]..starts[t + 1]];
            dst[at..at + group.len()].copy_from_slice(group);
            at += group.len();
        }
        dst.sort_unstable();
    });
    let list = entries.par_iter().map(|&key| T::key_index(key)).collect();
    (offsets, list)
}

/// Per-splat constants of the tile kernels, relative to the tile origin.
#[derive(Clone, Copy)]
struct SplatLanes<T> {
    mx: T,
    my: T,
    conic: [T; 3],
    opacity: T,
    /// Lane x is in the splat's pixel box iff lo < x + 0.5 < hi.
    lo: T,
    hi: T,
    /// Quads (groups of [`QUAD`] lanes) overlapping the box: q0..q1.
    q0: usize,
    q1: usize,
}

/// Lanes per group in the tile kernels' row loops: `for q in q0..q1 { … }` visits only the groups
/// overlapping a splat's box, each as one [`Lanes`] value (an SSE register for f32 on x86-64).
const QUAD: usize = 4;
/// Quads per tile row (loops bound their quad index by it so the compiler can drop bounds checks).
const QUADS: usize = TILE_SIZE / QUAD;

/// Per-lane predicate of the working precision's lanes.
type LaneMask<T> = <<T as Real>::V4 as Lanes<T>>::Mask;

/// Constants of the lane functions, splatted once per tile.
struct LaneConsts<T: Real> {
    zero: T::V4,
    one: T::V4,
    neg_half: T::V4,
    max_alpha: T::V4,
    min_alpha: T::V4,
    min_t: T::V4,
}

impl<T: Real> LaneConsts<T> {
    fn new() -> Self {
        let v = |x: f64| T::V4::splat(lit(x));
        Self {
            zero: v(0.0),
            one: v(1.0),
            neg_half: v(-0.5),
            max_alpha: v(0.99),
            min_alpha: v(1.0 / 255.0),
            min_t: v(1e-4),
        }
    }
}

/// Lane values of one splat on one quad of a tile row: (exp(power), o·exp(power), the α that
/// blends: 0 outside the box, for power > 0 and for α < 1/255). `cx` are the lanes' pixel-centre
/// x, `dy` = mean y − pixel-centre y and `cc_dy_dy` = (conic c · dy) · dy of the row. One function
/// for forward and backward, so that both make bit-identical decisions.
#[inline(always)]
fn lane_alpha<T: Real>(
    s: &SplatLanes<T>,
    cx: T::V4,
    dy: T,
    cc_dy_dy: T,
    k: &LaneConsts<T>,
) -> (T::V4, T::V4, T::V4) {
    let v = T::V4::splat;
    let [ca, cb, _] = s.conic;
    let dx = v(s.mx) - cx;
    let power = k.neg_half * (v(ca) * dx * dx + v(cc_dy_dy)) - v(cb) * dx * v(dy);
    let gauss = power.exp();
    let raw = v(s.opacity) * gauss;
    let a = T::V4::select(raw.lt(k.max_alpha), raw, k.max_alpha);
    let ok = cx.gt(v(s.lo)) & cx.lt(v(s.hi)) & power.le(k.zero) & a.ge(k.min_alpha);
    (gauss, raw, T::V4::select(ok, a, k.zero))
}

/// Lane step of the blend state shared by forward and backward: with `a` the lanes' α (0 = skip)
/// and `alive` 1/0, returns (weight α·T, new T, new alive, stopped). A stopping splat is excluded.
#[inline(always)]
fn lane_blend<T: Real>(
    a: T::V4,
    t: T::V4,
    alive: T::V4,
    k: &LaneConsts<T>,
) -> (T::V4, T::V4, T::V4, LaneMask<T>) {
    let live = alive.gt(k.zero) & a.gt(k.zero);
    let test_t = t * (k.one - a);
    let stop = live & test_t.lt(k.min_t);
    let contrib = live & !stop;
    (
        T::V4::select(contrib, a * t, k.zero),
        T::V4::select(contrib, test_t, t),
        T::V4::select(stop, k.zero, alive),
        stop,
    )
}

/// Values of one splat at one pixel: the power, exp(power), o·exp(power) and the α that blends (0
/// outside the box, for power > 0 and for α < 1/255). The scalar definition of [`lane_alpha`], which
/// the forward kernel uses (its loops over 16-lane rows auto-vectorise); both give the same bits
/// (unit test), so forward and backward make identical decisions.
#[inline(always)]
fn pixel_alpha<T: Real>(s: &SplatLanes<T>, cx: T, dy: T) -> (T, T, T, T) {
    let half: T = lit(0.5);
    let max_alpha: T = lit(0.99);
    let min_alpha: T = lit(1.0 / 255.0);
    let [ca, cb, cc] = s.conic;
    let dx = s.mx - cx;
    let power = -half * (ca * dx * dx + cc * dy * dy) - cb * dx * dy;
    let gauss = power.splat_exp();
    let raw = s.opacity * gauss;
    let a = if raw < max_alpha { raw } else { max_alpha };
    let ok = (cx > s.lo) & (cx < s.hi) & (power <= T::zero()) & (a >= min_alpha);
    (power, gauss, raw, if ok { a } else { T::zero() })
}

/// Blend step of one pixel: with `a` its α (0 = skip) and `alive` 1/0, returns (weight α·T, new T,
/// new alive, stopped). A stopping splat is excluded. The scalar definition of [`lane_blend`]
/// (same bits, unit test).
#[inline(always)]
fn pixel_blend<T: Real>(a: T, t: T, alive: T) -> (T, T, T, bool) {
    let min_t: T = lit(1e-4);
    let live = (alive > T::zero()) & (a > T::zero());
    let test_t = t * (T::one() - a);
    let stop = live & (test_t < min_t);
    let contrib = live & !stop;
    (
        if contrib { a * t } else { T::zero() },
        if contrib { test_t } else { t },
        if stop { T::zero() } else { alive },
        stop,
    )
}

/// The splat's lane constants and pixel box (rows y0..y1) in a tile, or `None` if the box is empty.
#[inline(always)]
fn splat_lanes<T: Real>(
    p: &PairSplat<T>,
    ox: T,
    oy: T,
    size: [usize; 2],
) -> Option<(SplatLanes<T>, usize, usize)> {
    let (x0, x1) = pixel_span(p.mean2d[0], p.extent[0], ox, size[0]);
    let (y0, y1) = pixel_span(p.mean2d[1], p.extent[1], oy, size[1]);
    if x0 >= x1 || y0 >= y1 {
        return None;
    }
    Some((
        SplatLanes {
            mx: p.mean2d[0] - ox,
            my: p.mean2d[1] - oy,
            conic: p.conic,
            opacity: p.opacity,
            lo: lit(x0 as f64),
            hi: lit(x1 as f64),
            q0: x0 / QUAD,
            q1: x1.div_ceil(QUAD).min(QUADS),
        },
        y0,
        y1,
    ))
}

/// Pixel-centre offsets 0.5, 1.5, … within a tile.
fn centres<T: Real>() -> [T; TILE_SIZE] {
    std::array::from_fn(|i| lit(i as f64 + 0.5))
}

/// Pixel-centre x offsets of each quad's lanes.
fn quad_centres<T: Real>() -> [T::V4; QUADS] {
    let c = centres::<T>();
    std::array::from_fn(|q| T::V4::load(&c[q * QUAD..]))
}

/// [`forward_tile`] of the pairs `range`: the AVX-512 kernel when the CPU has AVX-512F and `T` is
/// f32 (same bits, faster), else the portable one. `pair_splats` is a `&Vec`, not a slice, so that it
/// can be downcast to the f32 kernel's type.
#[allow(clippy::too_many_arguments, clippy::ptr_arg)]
fn forward_tile_dispatch<T: Real>(
    pair_splats: &Vec<PairSplat<T>>,
    pair_channels: &[T],
    range: std::ops::Range<usize>,
    c: usize,
    origin: [usize; 2],
    size: [usize; 2],
    buf: &mut [T],
    used: &mut u32,
) {
    let channels = &pair_channels[range.start * c..range.end * c];
    #[cfg(target_arch = "x86_64")]
    {
        use std::any::Any;
        let splats32 = (pair_splats as &dyn Any).downcast_ref::<Vec<PairSplat<f32>>>();
        if let (Some(splats), Some(channels), Some(buf)) =
            (splats32, T::as_f32(channels), T::as_f32_mut(&mut *buf))
        {
            let list = &splats[range.clone()];
            if avx512::try_forward_tile(list, channels, c, origin, size, buf, used) {
                return;
            }
        }
    }
    forward_tile(&pair_splats[range], channels, c, origin, size, buf, used);
}

/// Blends one tile front to back into `buf` ([T | depth | channels] × 256); `used` receives the
/// number of list entries blended before every pixel stopped.
///
/// Splat-major: each row of a splat's (margin-padded) pixel box is a few fixed 16-lane passes (one
/// lane per pixel column; lanes outside the box, already stopped, with power > 0 or α < 1/255 get
/// weight 0), written as simple select-only loops so that the compiler vectorises them. Adding a
/// zero weight leaves every sum bit-identical to skipping the pixel (all values are finite).
#[allow(clippy::too_many_arguments)]
fn forward_tile<T: Real>(
    list: &[PairSplat<T>],
    channels: &[T],
    c: usize,
    origin: [usize; 2],
    size: [usize; 2],
    buf: &mut [T],
    used: &mut u32,
) {
    buf[BUF_T..BUF_T + TILE_PIXELS].fill(T::one());
    *used = list.len() as u32;
    if list.is_empty() {
        return;
    }
    let (tbuf, rest) = buf.split_at_mut(BUF_D);
    let (dbuf, cbuf) = rest.split_at_mut(TILE_PIXELS);
    // 1 while a pixel still blends, 0 once it stopped (a T so that every lane is T-wide).
    let mut alive = [T::one(); TILE_PIXELS];
    let mut n_done = 0u32;
    let n_pixels = (size[0] * size[1]) as u32;
    let ox: T = lit(origin[0] as f64);
    let oy: T = lit(origin[1] as f64);
    let centre = centres::<T>();
    let mut w = [T::zero(); TILE_SIZE];
    let mut alpha = [T::zero(); TILE_SIZE];
    for (k, p) in list.iter().enumerate() {
        let Some((sl, y0, y1)) = splat_lanes(p, ox, oy, size) else {
            continue;
        };
        let ch = &channels[k * c..(k + 1) * c];
        let z = p.depth;
        for y in y0..y1 {
            let dy = sl.my - centre[y];
            let row = y * TILE_SIZE;
            for q in sl.q0..sl.q1.min(QUADS) {
                for l in 0..QUAD {
                    let x = q * QUAD + l;
                    alpha[x] = pixel_alpha(&sl, centre[x], dy).3;
                }
            }
            let t_row = &mut tbuf[row..row + TILE_SIZE];
            let alive_row = &mut alive[row..row + TILE_SIZE];
            let mut stops = 0u32;
            for q in sl.q0..sl.q1.min(QUADS) {
                for l in 0..QUAD {
                    let x = q * QUAD + l;
                    let (wx, t, al, stop) = pixel_blend(alpha[x], t_row[x], alive_row[x]);
                    w[x] = wx;
                    t_row[x] = t;
                    alive_row[x] = al;
                    stops += u32::from(stop);
                }
            }
            n_done += stops;
            for (j, &v) in ch.iter().enumerate() {
                let dst = &mut cbuf[j * TILE_PIXELS + row..j * TILE_PIXELS + row + TILE_SIZE];
                for q in sl.q0..sl.q1.min(QUADS) {
                    for l in 0..QUAD {
                        let x = q * QUAD + l;
                        dst[x] = dst[x] + w[x] * v;
                    }
                }
            }
            let dst = &mut dbuf[row..row + TILE_SIZE];
            for q in sl.q0..sl.q1.min(QUADS) {
                for l in 0..QUAD {
                    let x = q * QUAD + l;
                    dst[x] = dst[x] + w[x] * z;
                }
            }
        }
        if n_done == n_pixels {
            *used = k as u32 + 1;
            break;
        }
    }
}

/// Analytic backward of [`render`]: gradients of a scalar loss L w.r.t. every input, given
/// `cot` = dL/d(image, alpha, depth). `forward` must be the output of `render` for the same camera,
/// splats and settings. `Gradients::covariances` is left empty.
pub fn render_backward<T: Real>(
    camera: &Camera,
    splats: &Splats<'_, T>,
    settings: &RenderSettings,
    forward: &RenderOutput<T>,
    cot: &Cotangents<'_, T>,
) -> Result<Gradients<T>, RasterError> {
    backward_inputs(camera, &Inputs::from(splats), settings, forward, cot)
}

/// Analytic backward of [`render_cov`]: as [`render_backward`], with dL/dΣ in
/// `Gradients::covariances` (nine independent entries) and `log_scales`/`quats` left empty.
/// `forward` must be the output of `render_cov` for the same camera, splats and settings.
pub fn render_cov_backward<T: Real>(
    camera: &Camera,
    splats: &CovSplats<'_, T>,
    settings: &RenderSettings,
    forward: &RenderOutput<T>,
    cot: &Cotangents<'_, T>,
) -> Result<Gradients<T>, RasterError> {
    backward_inputs(camera, &Inputs::from(splats), settings, forward, cot)
}

fn backward_inputs<T: Real>(
    camera: &Camera,
    splats: &Inputs<'_, T>,
    settings: &RenderSettings,
    forward: &RenderOutput<T>,
    cot: &Cotangents<'_, T>,
) -> Result<Gradients<T>, RasterError> {
    let c = splats.num_channels;
    let st = &forward.state;
    if forward.width != camera.width
        || forward.height != camera.height
        || forward.num_channels != c
        || st.n != splats.len()
    {
        return Err(RasterError::ForwardMismatch(format!(
            "forward was {}x{} with {} channels and {} Gaussians, request is {}x{} with {} and {}",
            forward.width,
            forward.height,
            forward.num_channels,
            st.n,
            camera.width,
            camera.height,
            c,
            splats.len()
        )));
    }
    let (width, height) = (camera.width as usize, camera.height as usize);
    let hw = width * height;
    let check = |field, got: usize, expected: usize| {
        if got == expected {
            Ok(())
        } else {
            Err(RasterError::LengthMismatch {
                field,
                got,
                expected,
            })
        }
    };
    check("d_image", cot.image.len(), c * hw)?;
    if let Some(a) = cot.alpha {
        check("d_alpha", a.len(), hw)?;
    }
    if let Some(d) = cot.depth {
        check("d_depth", d.len(), hw)?;
    }
    let cam = CameraParams::<T>::new(camera, settings.near_plane);
    let gx = cam.grid[0] as usize;
    let n_tiles = st.tile_offsets.len() - 1;
    let stride = (2 + c) * TILE_PIXELS;
    let slot = 7 + c;

    // 1. Per (tile, Gaussian) pair contributions, in sorted order.
    let mut pair_grads = vec![T::zero(); st.tile_list.len() * slot];
    let mut slices = Vec::with_capacity(n_tiles);
    let mut rest: &mut [T] = &mut pair_grads;
    for t in 0..n_tiles {
        let (head, tail) = rest.split_at_mut((st.tile_offsets[t + 1] - st.tile_offsets[t]) * slot);
        slices.push(head);
        rest = tail;
    }
    slices.into_par_iter().enumerate().for_each_init(
        || BackwardScratch::new(c),
        |scratch, (tile, out)| {
            let range = st.tile_offsets[tile]..st.tile_offsets[tile + 1];
            if range.is_empty() {
                return;
            }
            let origin = [(tile % gx) * TILE_SIZE, (tile / gx) * TILE_SIZE];
            let size = [
                TILE_SIZE.min(width - origin[0]),
                TILE_SIZE.min(height - origin[1]),
            ];
            backward_tile_dispatch(st, tile, c, origin, size, width, cot, scratch, out);
        },
    );

    // 2. Per visible Gaussian: its pair positions in tile order (counting sort, deterministic).
    let nv = st.visible.len();
    let mut offsets = vec![0usize; nv + 1];
    for &ci in &st.tile_list {
        offsets[ci as usize + 1] += 1;
    }
    for i in 0..nv {
        offsets[i + 1] += offsets[i];
    }
    let mut cursor = offsets.clone();
    let mut positions = vec![0u32; st.tile_list.len()];
    for (pos, &ci) in st.tile_list.iter().enumerate() {
        positions[cursor[ci as usize]] = pos as u32;
        cursor[ci as usize] += 1;
    }

    // 3. Reduce in fixed order and chain through the projection.
    let mut compact = vec![u32::MAX; st.n];
    for (ci, &id) in st.visible_ids.iter().enumerate() {
        compact[id as usize] = ci as u32;
    }
    let zero3 = [T::zero(); 3];
    let zero33 = [zero3; 3];
    // One pass per Gaussian gathers its pair slots (geometry and channels together) in tile order.
    let mut per_gaussian: Vec<GaussianGrad<T>> =
        vec![(zero3, zero33, T::zero(), [T::zero(); 2]); st.n];
    let mut d_channels = vec![T::zero(); st.n * c];
    let reduce = |i: usize, out: &mut GaussianGrad<T>, d_ch: &mut [T]| {
        let ci = compact[i];
        if ci == u32::MAX {
            return;
        }
        let ci = ci as usize;
        let mut acc = [T::zero(); 7];
        for &pos in &positions[offsets[ci]..offsets[ci + 1]] {
            let s = &pair_grads[pos as usize * slot..(pos as usize + 1) * slot];
            for j in 0..7 {
                acc[j] = acc[j] + s[j];
            }
            for (d, &g) in d_ch.iter_mut().zip(&s[7..]) {
                *d = *d + g;
            }
        }
        let g = ProjectedGrad {
            mean2d: [acc[0], acc[1]],
            conic: [acc[2], acc[3], acc[4]],
            opacity: acc[5],
            depth: acc[6],
        };
        let sigma = match splats.shapes {
            Shapes::ScaleRot { log_scales, quats } => {
                gaussians::covariance::covariance_3d(log_scales[i], quats[i])
            }
            Shapes::Cov(covs) => covs[i],
        };
        let (dm, d_sigma, dl) =
            project_cov_backward(&cam, splats.means[i], &sigma, splats.opacity_logits[i], &g);
        *out = (dm, d_sigma, dl, g.mean2d);
    };
    if c > 0 {
        per_gaussian
            .par_iter_mut()
            .zip(d_channels.par_chunks_mut(c))
            .enumerate()
            .for_each(|(i, (out, d_ch))| reduce(i, out, d_ch));
    } else {
        per_gaussian
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, out)| reduce(i, out, &mut []));
    }
    // dL/d background_c = Σ_pixels dL/dimage_c · T_final, rows in order.
    let mut d_bg = vec![T::zero(); c];
    for (ch, d) in d_bg.iter_mut().enumerate() {
        let mut acc = T::zero();
        for y in 0..height {
            for x in 0..width {
                let tile = (y / TILE_SIZE) * gx + x / TILE_SIZE;
                let p = (y % TILE_SIZE) * TILE_SIZE + x % TILE_SIZE;
                acc = acc
                    + cot.image[ch * hw + y * width + x] * st.tile_buf[tile * stride + BUF_T + p];
            }
        }
        *d = acc;
    }
    let mut out = Gradients {
        means: Vec::with_capacity(st.n),
        log_scales: Vec::new(),
        quats: Vec::new(),
        covariances: Vec::new(),
        opacity_logits: Vec::with_capacity(st.n),
        channels: d_channels,
        means_2d: Vec::with_capacity(st.n),
        background: d_bg,
    };
    for &(dm, _, dl, d2) in &per_gaussian {
        out.means.push(dm);
        out.opacity_logits.push(dl);
        out.means_2d.push(d2);
    }
    match splats.shapes {
        // Chain dΣ into the log-scales and quaternions (zero for culled Gaussians, like before).
        Shapes::ScaleRot { log_scales, quats } => {
            let chained: Vec<([T; 3], [T; 4])> = per_gaussian
                .par_iter()
                .enumerate()
                .map(|(i, g)| {
                    if compact[i] == u32::MAX {
                        (zero3, [T::zero(); 4])
                    } else {
                        covariance_3d_backward(log_scales[i], quats[i], &g.1)
                    }
                })
                .collect();
            (out.log_scales, out.quats) = chained.into_iter().unzip();
        }
        Shapes::Cov(_) => out.covariances = per_gaussian.iter().map(|g| g.1).collect(),
    }
    Ok(out)
}

/// Per-thread scratch of the backward tile kernels (allocated once per rayon job split, not per
/// pixel).
struct BackwardScratch<T: Real> {
    t: Vec<T>,
    alive: Vec<T>,
    pre: Vec<T>,
    g_img: Vec<T>,
    g_alpha: Vec<T>,
    g_depth: Vec<T>,
    /// Per-column channel-gradient accumulators of the current pair, C × [`TILE_SIZE`] (column x
    /// sums the pair's pixels in tile column x).
    acc_channels: Vec<T>,
    /// Tile rows with a non-zero cotangent (image, alpha or depth). A row whose cotangents are all
    /// zero adds only exact zeros to every gradient, so the kernels skip it: same bits, less work
    /// when a loss reads a subset of the pixels (the flow loss's 1/4 resize reads half the rows).
    live_rows: [bool; TILE_SIZE],
    /// `false` only in tests, to compare with the kernels that replay every row.
    skip_zero_rows: bool,
}

impl<T: Real> BackwardScratch<T> {
    fn new(c: usize) -> Self {
        Self {
            t: vec![T::zero(); TILE_PIXELS],
            alive: vec![T::zero(); TILE_PIXELS],
            pre: vec![T::zero(); (c + 1) * TILE_PIXELS],
            g_img: vec![T::zero(); c * TILE_PIXELS],
            g_alpha: vec![T::zero(); TILE_PIXELS],
            g_depth: vec![T::zero(); TILE_PIXELS],
            acc_channels: vec![T::zero(); c * TILE_SIZE],
            live_rows: [false; TILE_SIZE],
            skip_zero_rows: true,
        }
    }

    /// Resets the blend state and copies the tile's cotangents into tile-major rows.
    fn prepare(
        &mut self,
        c: usize,
        origin: [usize; 2],
        size: [usize; 2],
        width: usize,
        cot: &Cotangents<'_, T>,
    ) {
        let hw = cot.image.len() / c.max(1);
        self.t.fill(T::one());
        self.alive.fill(T::one());
        self.pre.fill(T::zero());
        self.g_img.fill(T::zero());
        self.g_alpha.fill(T::zero());
        self.g_depth.fill(T::zero());
        for y in 0..size[1] {
            let idx = y * TILE_SIZE;
            let pix = (origin[1] + y) * width + origin[0];
            for j in 0..c {
                self.g_img[j * TILE_PIXELS + idx..j * TILE_PIXELS + idx + size[0]]
                    .copy_from_slice(&cot.image[j * hw + pix..j * hw + pix + size[0]]);
            }
            if let Some(a) = cot.alpha {
                self.g_alpha[idx..idx + size[0]].copy_from_slice(&a[pix..pix + size[0]]);
            }
            if let Some(d) = cot.depth {
                self.g_depth[idx..idx + size[0]].copy_from_slice(&d[pix..pix + size[0]]);
            }
        }
        for (y, live) in self.live_rows.iter_mut().enumerate() {
            let row = y * TILE_SIZE..(y + 1) * TILE_SIZE;
            let nonzero = |v: &[T]| v.iter().any(|&x| x != T::zero());
            *live = !self.skip_zero_rows
                || nonzero(&self.g_alpha[row.clone()])
                || nonzero(&self.g_depth[row.clone()])
                || (0..c).any(|j| nonzero(&self.g_img[j * TILE_PIXELS..][row.clone()]));
        }
    }
}

/// One tile's backward (`tile`'s pairs of `st`, `out` their gradient slots): the AVX-512 kernel
/// when the CPU has AVX-512F and `T` is f32 (same bits, faster), else the portable
/// [`backward_tile`].
#[allow(clippy::too_many_arguments)]
fn backward_tile_dispatch<T: Real>(
    st: &ForwardState<T>,
    tile: usize,
    c: usize,
    origin: [usize; 2],
    size: [usize; 2],
    width: usize,
    cot: &Cotangents<'_, T>,
    s: &mut BackwardScratch<T>,
    out: &mut [T],
) {
    let range = st.tile_offsets[tile]..st.tile_offsets[tile + 1];
    let stride = (2 + c) * TILE_PIXELS;
    let buf = tile * stride..(tile + 1) * stride;
    let used = st.used[tile] as usize;
    #[cfg(target_arch = "x86_64")]
    {
        use std::any::Any;
        let st32 = (st as &dyn Any).downcast_ref::<ForwardState<f32>>();
        let s32 = (&mut *s as &mut dyn Any).downcast_mut::<BackwardScratch<f32>>();
        if let (Some(st), Some(s), Some(image), Some(out)) =
            (st32, s32, T::as_f32(cot.image), T::as_f32_mut(&mut *out))
        {
            let cot = Cotangents {
                image,
                alpha: cot.alpha.and_then(T::as_f32),
                depth: cot.depth.and_then(T::as_f32),
            };
            if avx512::try_backward_tile(
                &st.pair_splats[range.clone()],
                &st.pair_channels[range.start * c..range.end * c],
                &st.background,
                c,
                origin,
                size,
                width,
                &st.tile_buf[buf.clone()],
                used,
                &cot,
                s,
                out,
            ) {
                return;
            }
        }
    }
    backward_tile(
        &st.pair_splats[range.clone()],
        &st.pair_channels[range.start * c..range.end * c],
        &st.background,
        c,
        origin,
        size,
        width,
        &st.tile_buf[buf],
        used,
        cot,
        s,
        out,
    );
}

/// Sum of a pair's per-column partial sums in column order, starting from zero: the fixed
/// reduction order of every backward kernel, so that they all give the same bits.
#[inline(always)]
fn column_sum<T: Real>(columns: &[T]) -> T {
    columns.iter().fold(T::zero(), |s, &x| s + x)
}

/// Replays one tile front to back (the forward's first `used` list entries, with bit-identical
/// α, T and stop decisions) and writes each pair's gradient slot
/// [mean2d x, y | conic a, b, c | opacity | depth | channels C].
///
/// Every row of a pair is a few quads of four lanes, each quad one pass through α, blend state,
/// dL/dα and per-column accumulators; each pair's per-column partial sums are reduced in column
/// order at the end of the pair, so the result does not depend on threads — nor on the lane width:
/// the AVX-512 kernel (16 lanes, one register per row) gives the same bits.
#[allow(clippy::too_many_arguments)]
fn backward_tile<T: Real>(
    list: &[PairSplat<T>],
    channels: &[T],
    bg: &[T],
    c: usize,
    origin: [usize; 2],
    size: [usize; 2],
    width: usize,
    buf: &[T],
    used: usize,
    cot: &Cotangents<'_, T>,
    s: &mut BackwardScratch<T>,
    out: &mut [T],
) {
    let slot = 7 + c;
    s.prepare(c, origin, size, width, cot);
    let t_final = &buf[BUF_T..BUF_T + TILE_PIXELS];
    let d_final = &buf[BUF_D..BUF_D + TILE_PIXELS];
    let c_final = &buf[BUF_C..];
    let ox: T = lit(origin[0] as f64);
    let oy: T = lit(origin[1] as f64);
    let centre = centres::<T>();
    let cx = quad_centres::<T>();
    let k = LaneConsts::<T>::new();
    let v = T::V4::splat;
    let half = v(lit(0.5));
    let has_alpha = cot.alpha.is_some();
    let has_depth = cot.depth.is_some();
    for (idx, p) in list.iter().enumerate().take(used) {
        let Some((sl, y0, y1)) = splat_lanes(p, ox, oy, size) else {
            continue;
        };
        let ch = &channels[idx * c..(idx + 1) * c];
        let [ca, cb, cc] = p.conic;
        let (v_ca, v_cb, v_mx) = (v(ca), v(cb), v(sl.mx));
        let z = v(p.depth);
        s.acc_channels.fill(T::zero());
        // Per-column accumulators: mean x, y, conic a, b, c, opacity, depth; quad q holds columns
        // 4q..4q+4.
        let mut geo = [[k.zero; QUADS]; 7];
        for y in (y0..y1).filter(|&y| s.live_rows[y]) {
            let dy = sl.my - centre[y];
            let cc_dy_dy = cc * dy * dy;
            let (v_dy, v_cb_dy, v_cc_dy) = (v(dy), v(cb * dy), v(cc * dy));
            let row = y * TILE_SIZE;
            for (q, &cxq) in cx.iter().enumerate().take(sl.q1).skip(sl.q0) {
                let at = row + q * QUAD;
                let (gauss, raw, a) = lane_alpha(&sl, cxq, dy, cc_dy_dy, &k);
                // α where the clamp is inactive (else 0): dα/dpower = α there.
                let slope = T::V4::select(raw.lt(k.max_alpha), a, k.zero);
                let t_old = T::V4::load(&s.t[at..]);
                let alive = T::V4::load(&s.alive[at..]);
                let (w, t_new, alive, stop) = lane_blend(a, t_old, alive, &k);
                // Non-contributing lanes: w = 0 and T unchanged.
                let contrib = w.ne(k.zero);
                if T::V4::count(contrib | stop) == 0 {
                    // Nothing changes in this quad and every gradient term below is a zero (the
                    // accumulators start at +0 and are never −0, so adding ±0 is a no-op).
                    continue;
                }
                t_new.store(&mut s.t[at..]);
                alive.store(&mut s.alive[at..]);
                let inv = k.one / (k.one - T::V4::select(contrib, a, k.zero));
                let tn = T::V4::load(&t_final[at..]);
                // dL/dα per lane, accumulated over alpha, channels and depth.
                let mut d_alpha = if has_alpha {
                    T::V4::load(&s.g_alpha[at..]) * tn * inv
                } else {
                    k.zero
                };
                for (j, acc) in s.acc_channels.chunks_exact_mut(TILE_SIZE).enumerate() {
                    let (value, b) = (v(ch[j]), v(bg[j]));
                    let o = j * TILE_PIXELS + at;
                    let pre = T::V4::load(&s.pre[o..]) + w * value;
                    pre.store(&mut s.pre[o..]);
                    let behind = T::V4::load(&c_final[o..]) - pre + tn * b;
                    let gi = T::V4::load(&s.g_img[o..]);
                    d_alpha = d_alpha + gi * (t_old * value - behind * inv);
                    let acc = &mut acc[q * QUAD..];
                    (T::V4::load(acc) + w * gi).store(acc);
                }
                // Without a depth cotangent the depth terms are exact zeros: skip them.
                if has_depth {
                    let o = c * TILE_PIXELS + at;
                    let pre = T::V4::load(&s.pre[o..]) + w * z;
                    pre.store(&mut s.pre[o..]);
                    let behind = T::V4::load(&d_final[at..]) - pre;
                    let gd = T::V4::load(&s.g_depth[at..]);
                    d_alpha = d_alpha + gd * (t_old * z - behind * inv);
                    geo[6][q] = geo[6][q] + w * gd;
                }
                // Only contributing lanes carry a gradient; where α is clamped at 0.99 its
                // derivative w.r.t. opacity and power is zero.
                let dx = v_mx - cxq;
                let da = T::V4::select(contrib, d_alpha, k.zero);
                let d_power = slope * da;
                geo[0][q] = geo[0][q] - d_power * (v_ca * dx + v_cb_dy);
                geo[1][q] = geo[1][q] - d_power * (v_cc_dy + v_cb * dx);
                geo[2][q] = geo[2][q] - half * d_power * dx * dx;
                geo[3][q] = geo[3][q] - d_power * dx * v_dy;
                geo[4][q] = geo[4][q] - half * d_power * v_dy * v_dy;
                geo[5][q] = geo[5][q] + T::V4::select(slope.ne(k.zero), gauss * da, k.zero);
            }
        }
        let dst = &mut out[idx * slot..(idx + 1) * slot];
        for (d, quads) in dst.iter_mut().zip(&geo) {
            let columns: [T; TILE_SIZE] =
                std::array::from_fn(|x| quads[x / QUAD].to_array()[x % QUAD]);
            *d = column_sum(&columns);
        }
        for (d, columns) in dst[7..]
            .iter_mut()
            .zip(s.acc_channels.chunks_exact(TILE_SIZE))
        {
            *d = column_sum(columns);
        }
    }
}

#[cfg(test)]
mod tests {
    /// The forward kernel decides per pixel with the scalar `pixel_alpha` / `pixel_blend`, the
    /// backward per quad with `lane_alpha` / `lane_blend`: every output must be the same bits, or
    /// the backward would replay a different blend than the forward rendered.
    #[test]
    fn lane_and_pixel_decisions_are_bit_identical() {
        use super::*;
        let mut state = 0x0dd5_eed5_u64;
        let mut uniform = |lo: f32, hi: f32| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            lo + (hi - lo) * ((state >> 40) as f32 / (1u64 << 24) as f32)
        };
        let k = LaneConsts::<f32>::new();
        let centre = centres::<f32>();
        let cx = quad_centres::<f32>();
        let mut decisions = [0usize; 3];
        for _ in 0..20_000 {
            let (a, b) = (uniform(0.01, 3.0), uniform(0.01, 3.0));
            let cb = uniform(-0.9, 0.9) * (a * b).sqrt();
            let lo = uniform(-2.0, 10.0).floor().max(0.0);
            let sl = SplatLanes {
                mx: uniform(-4.0, 20.0),
                my: uniform(-4.0, 20.0),
                conic: [a, cb, b],
                opacity: uniform(0.0, 1.0).powi(3).max(uniform(0.95, 1.0) * 1.001),
                lo,
                hi: lo + uniform(1.0, 12.0).floor(),
                q0: 0,
                q1: QUADS,
            };
            let y = (uniform(0.0, 16.0) as usize).min(TILE_SIZE - 1);
            let dy = sl.my - centre[y];
            let cc_dy_dy = sl.conic[2] * dy * dy;
            for (q, &cxq) in cx.iter().enumerate() {
                let t: [f32; 4] = std::array::from_fn(|_| uniform(0.0, 1.0).powi(4));
                let alive: [f32; 4] = std::array::from_fn(|_| f32::from(uniform(0.0, 1.0) < 0.8));
                let (gauss, raw, alpha) = lane_alpha(&sl, cxq, dy, cc_dy_dy, &k);
                let (w, t_new, alive_new, stop) =
                    lane_blend(alpha, <f32 as Real>::V4::load(&t), Lanes::load(&alive), &k);
                let stops = <f32 as Real>::V4::count(stop);
                let mut pixel_stops = 0;
                for l in 0..QUAD {
                    let (_, g, r, al) = pixel_alpha(&sl, centre[q * QUAD + l], dy);
                    assert_eq!(g.to_bits(), gauss.to_array()[l].to_bits());
                    assert_eq!(r.to_bits(), raw.to_array()[l].to_bits());
                    assert_eq!(al.to_bits(), alpha.to_array()[l].to_bits());
                    let (pw, pt, pa, ps) = pixel_blend(al, t[l], alive[l]);
                    assert_eq!(pw.to_bits(), w.to_array()[l].to_bits());
                    assert_eq!(pt.to_bits(), t_new.to_array()[l].to_bits());
                    assert_eq!(pa.to_bits(), alive_new.to_array()[l].to_bits());
                    pixel_stops += u32::from(ps);
                    decisions[usize::from(al > 0.0) + usize::from(ps)] += 1;
                }
                assert_eq!(stops, pixel_stops);
            }
        }
        // The random lanes reach all three outcomes: skipped, blended and stopping.
        assert!(decisions.iter().all(|&d| d > 100), "{decisions:?}");
    }

    /// The AVX-512 kernels give the portable kernels' bits, tile by tile: the image buffers and
    /// stop counts of the forward, and every pair's gradient slot of the backward with image,
    /// alpha and depth cotangents, on scenes whose size leaves partial tiles at the borders.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx512_kernels_equal_the_portable_kernels_bit_for_bit() {
        use super::*;
        use crate::synthetic::SyntheticScene;
        if !avx512::available() {
            eprintln!("skipped: this CPU has no AVX-512F");
            return;
        }
        for (seed, n, w, h) in [
            (1u64, 3000usize, 53u32, 37u32),
            (2, 800, 40, 70),
            (3, 6000, 64, 48),
        ] {
            let scene = SyntheticScene::new(n, w, h, seed).expect("scene");
            let out =
                render(&scene.camera, &scene.splats(), &RenderSettings::default()).expect("render");
            let st = &out.state;
            let c = 3;
            let stride = (2 + c) * TILE_PIXELS;
            let gx = (w as usize).div_ceil(TILE_SIZE);
            let (width, height) = (w as usize, h as usize);
            let hw = width * height;
            let mut state = seed;
            let mut noise = |len: usize| -> Vec<f32> {
                (0..len)
                    .map(|_| {
                        state = state
                            .wrapping_mul(6_364_136_223_846_793_005)
                            .wrapping_add(1_442_695_040_888_963_407);
                        (state >> 40) as f32 / (1u64 << 23) as f32 - 1.0
                    })
                    .collect()
            };
            let (mut d_image, mut d_alpha, mut d_depth) = (noise(c * hw), noise(hw), noise(hw));
            // Rows 2, 3, 6, 7, ... have no cotangent (as where the flow loss's 1/4 resize reads
            // nothing), so the kernels' zero-row skip is exercised.
            for y in (0..height).filter(|y| y % 4 >= 2) {
                let row = y * width..(y + 1) * width;
                d_alpha[row.clone()].fill(0.0);
                d_depth[row.clone()].fill(0.0);
                for j in 0..c {
                    d_image[j * hw..][row.clone()].fill(0.0);
                }
            }
            let cot = Cotangents {
                image: &d_image,
                alpha: Some(&d_alpha),
                depth: Some(&d_depth),
            };
            let (mut checked_pairs, mut skipped_rows) = (0, 0);
            for tile in 0..st.used.len() {
                let range = st.tile_offsets[tile]..st.tile_offsets[tile + 1];
                let origin = [(tile % gx) * TILE_SIZE, (tile / gx) * TILE_SIZE];
                let size = [
                    TILE_SIZE.min(width - origin[0]),
                    TILE_SIZE.min(height - origin[1]),
                ];
                let list = &st.pair_splats[range.clone()];
                let channels = &st.pair_channels[range.start * c..range.end * c];
                let (mut buf_p, mut buf_v) = (vec![0.0f32; stride], vec![0.0f32; stride]);
                let (mut used_p, mut used_v) = (0u32, 0u32);
                forward_tile(list, channels, c, origin, size, &mut buf_p, &mut used_p);
                assert!(avx512::try_forward_tile(
                    list,
                    channels,
                    c,
                    origin,
                    size,
                    &mut buf_v,
                    &mut used_v
                ));
                assert_eq!(used_p, used_v, "tile {tile}");
                assert!(buf_p
                    .iter()
                    .zip(&buf_v)
                    .all(|(a, b)| a.to_bits() == b.to_bits()));
                let slots = range.len() * (7 + c);
                let (mut out_p, mut out_v) = (vec![0.0f32; slots], vec![0.0f32; slots]);
                let (mut s_p, mut s_v) = (BackwardScratch::new(c), BackwardScratch::new(c));
                let args = (&st.background, &buf_p, used_p as usize);
                backward_tile(
                    list, channels, args.0, c, origin, size, width, args.1, args.2, &cot, &mut s_p,
                    &mut out_p,
                );
                assert!(avx512::try_backward_tile(
                    list, channels, args.0, c, origin, size, width, args.1, args.2, &cot, &mut s_v,
                    &mut out_v,
                ));
                let same_bits =
                    |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
                assert!(same_bits(&out_p, &out_v), "tile {tile}");
                // Skipping the rows without a cotangent gives the bits of replaying every row.
                let mut out_all = vec![0.0f32; slots];
                let mut s_all = BackwardScratch::new(c);
                s_all.skip_zero_rows = false;
                backward_tile(
                    list,
                    channels,
                    args.0,
                    c,
                    origin,
                    size,
                    width,
                    args.1,
                    args.2,
                    &cot,
                    &mut s_all,
                    &mut out_all,
                );
                assert!(
                    same_bits(&out_p, &out_all),
                    "tile {tile}: skipping zero rows changed the gradients"
                );
                skipped_rows += s_p.live_rows[..size[1]].iter().filter(|&&l| !l).count();
                checked_pairs += out_p
                    .chunks(7 + c)
                    .filter(|g| g.iter().any(|&v| v != 0.0))
                    .count();
            }
            // The comparison is not vacuous: many pairs carry gradients, and rows were skipped.
            assert!(
                checked_pairs > n / 4,
                "{checked_pairs} pairs with gradients"
            );
            assert!(skipped_rows > 0, "no row was skipped");
        }
    }

    /// The span by the rounding-function definition it replaces.
    fn span_by_rounding(mean: f32, half: f32, origin: f32, len: usize) -> (usize, usize) {
        let lo = (mean - half - 0.5 - origin).ceil();
        let hi = (mean + half - 0.5 - origin).floor() + 1.0;
        let clamp = |v: f32| {
            if v <= 0.0 {
                0
            } else if v.is_nan() {
                len
            } else {
                (v as usize).min(len)
            }
        };
        (clamp(lo), clamp(hi))
    }

    #[test]
    fn pixel_span_equals_the_ceil_floor_definition() {
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut cases = vec![
            (f32::NAN, 1.0, 0.0),
            (8.0, f32::NAN, 0.0),
            (1e30, 1.0, 0.0),
            (-1e30, 1.0, 0.0),
            (16.5, 0.0, 0.0),
            (0.5, 0.0, 0.0),
            (-0.5, 0.0, 0.0),
            (16.0, 0.5, 16.0),
        ];
        for _ in 0..200_000 {
            // Integers and half-integers often, to hit the rounding edges exactly.
            let snap = |v: f32, k: f32| if k < 0.3 { (v * 2.0).round() / 2.0 } else { v };
            let mean = snap(next() * 80.0 - 20.0, next());
            let half = snap(next() * 20.0, next());
            let origin = 16.0 * (next() * 4.0).floor();
            cases.push((mean, half, origin));
        }
        for (mean, half, origin) in cases {
            for len in [1, 7, 16] {
                assert_eq!(
                    super::pixel_span(mean, half, origin, len),
                    span_by_rounding(mean, half, origin, len),
                    "mean {mean}, half {half}, origin {origin}, len {len}"
                );
            }
        }
    }

    /// INRIA's order by its definition: every (tile, Gaussian) pair in input order, stably sorted
    /// by (tile, depth).
    fn bin_by_definition(
        visible: &[super::Projected<f32>],
        gx: usize,
        n_tiles: usize,
    ) -> (Vec<usize>, Vec<u32>) {
        let mut pairs = Vec::new();
        for (ci, p) in visible.iter().enumerate() {
            for ty in p.rect[1]..p.rect[3] {
                for tx in p.rect[0]..p.rect[2] {
                    pairs.push((ty as usize * gx + tx as usize, p.depth, ci as u32));
                }
            }
        }
        pairs.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
        let mut offsets = vec![0usize; n_tiles + 1];
        for &(t, _, _) in &pairs {
            offsets[t + 1] += 1;
        }
        for t in 0..n_tiles {
            offsets[t + 1] += offsets[t];
        }
        (offsets, pairs.iter().map(|p| p.2).collect())
    }

    #[test]
    fn parallel_binning_equals_the_stable_sort_definition() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = |k: u32| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 32) as u32 % k
        };
        // Enough Gaussians for several binning jobs, few distinct depths (ties must keep the
        // input order), rectangles from one tile to a third of the grid, some empty.
        let (gx, gy) = (20usize, 13usize);
        let visible: Vec<super::Projected<f32>> = (0..3 * super::BIN_CHUNK + 123)
            .map(|_| {
                let (x0, y0) = (next(gx as u32), next(gy as u32));
                let x1 = (x0 + next(7)).min(gx as u32);
                let y1 = (y0 + next(5)).min(gy as u32);
                super::Projected {
                    mean2d: [0.0; 2],
                    conic: [1.0, 0.0, 1.0],
                    depth: 0.5 + next(50) as f32 * 0.25,
                    opacity: 0.5,
                    extent: [1.0; 2],
                    rect: [x0, y0, x1, y1],
                    radius: 1,
                }
            })
            .collect();
        let n_tiles = gx * gy;
        let expected = bin_by_definition(&visible, gx, n_tiles);
        assert!(
            expected.1.len() > 4 * super::BIN_CHUNK,
            "too few pairs to test"
        );
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("thread pool");
            let got = pool.install(|| super::bin_and_sort(&visible, gx, n_tiles));
            assert_eq!(got, expected, "{threads} threads");
        }
    }
}

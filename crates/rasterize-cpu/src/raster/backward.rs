//! The backward driver: check the request against the forward output, replay every tile's list
//! (in parallel, one gradient slot per (tile, Gaussian) pair in sorted order), then reduce each
//! Gaussian's slots in tile order and chain them through the projection (and, for [`Splats`],
//! through Σ = R S Sᵀ Rᵀ into log-scales and quaternions). The fixed order makes the gradients
//! bit-identical for any thread count.

use rayon::iter::Either;
use rayon::prelude::*;

use gaussians::covariance::{covariance_3d_backward, Mat3};

use super::forward::ForwardState;
use super::inputs::{Inputs, Shapes};
use super::kernels::{backward_tile, BackwardScratch, BUF_T};
use super::layer::StaticLayer;
use super::{Cotangents, CovSplats, Gradients, RenderOutput, RenderSettings, Splats};
use crate::project::{
    project_cov_backward, project_cov_smeared_backward, CameraParams, ProjectedGrad,
};
use crate::{Camera, RasterError, Real, TILE_PIXELS, TILE_SIZE};

#[cfg(target_arch = "x86_64")]
use super::{avx2, avx512};

/// One Gaussian's gradients: (mean, Σ, opacity logit, screen mean).
type GaussianGrad<T> = ([T; 3], Mat3<T>, T, [T; 2]);

/// Analytic backward of [`render`]: gradients of a scalar loss L w.r.t. every input, given
/// `cot` = dL/d(image, alpha, depth). `forward` must be the output of `render` for the same camera,
/// splats and settings. `Gradients::covariances` is left empty.
///
/// [`render`]: super::render
pub fn render_backward<T: Real>(
    camera: &Camera,
    splats: &Splats<'_, T>,
    settings: &RenderSettings,
    forward: &RenderOutput<T>,
    cot: &Cotangents<'_, T>,
) -> Result<Gradients<T>, RasterError> {
    backward_inputs(
        camera,
        &Inputs::from(splats),
        settings,
        forward,
        cot,
        SharedTiles::None,
    )
}

/// Analytic backward of [`render_cov`]: as [`render_backward`], with dL/dΣ in
/// `Gradients::covariances` (nine independent entries) and `log_scales`/`quats` left empty.
/// `forward` must be the output of `render_cov` for the same camera, splats and settings.
///
/// [`render_cov`]: super::render_cov
pub fn render_cov_backward<T: Real>(
    camera: &Camera,
    splats: &CovSplats<'_, T>,
    settings: &RenderSettings,
    forward: &RenderOutput<T>,
    cot: &Cotangents<'_, T>,
) -> Result<Gradients<T>, RasterError> {
    backward_inputs(
        camera,
        &Inputs::from(splats),
        settings,
        forward,
        cot,
        SharedTiles::None,
    )
}

/// Which cotangent a tile's replay reads when its forward was shared between several renders of one
/// camera (`super::shared`): the backward is linear in the cotangent, so the renders' shared
/// tiles are replayed once, by the render that blended them, with the sum of their cotangents.
#[derive(Clone, Copy)]
pub(super) enum SharedTiles<'a, T> {
    /// Every tile reads `cot` (an ordinary backward).
    None,
    /// The tiles marked in `shared` read `summed` (the owner's replay), or are skipped (`None`:
    /// another render replays them); the others read `cot`.
    Some {
        shared: &'a [bool],
        summed: Option<&'a Cotangents<'a, T>>,
        /// The owner's replay of the static layers (`super::layer`); `None` for the others.
        layer: Option<LayerReplay<'a, T>>,
    },
}

/// What the owner's backward needs to replay the static layers once (`super::layer`).
pub(super) struct LayerReplay<'a, T> {
    pub(super) layer: &'a StaticLayer<T>,
    pub(super) cot: &'a Cotangents<'a, T>,
    pub(super) background: &'a [T],
}

impl<T> Clone for LayerReplay<'_, T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for LayerReplay<'_, T> {}

impl<'a, T> SharedTiles<'a, T> {
    /// The layer replay of the owner's backward, if any.
    fn layer(&self) -> Option<LayerReplay<'a, T>> {
        match *self {
            SharedTiles::Some { layer, .. } => layer,
            SharedTiles::None => None,
        }
    }

    /// The cotangent tile `tile` replays with, or `None` when it is skipped.
    fn cotangent(&self, tile: usize, cot: &'a Cotangents<'a, T>) -> Option<&'a Cotangents<'a, T>> {
        match *self {
            SharedTiles::Some { shared, summed, .. } if shared[tile] => summed,
            _ => Some(cot),
        }
    }
}

pub(super) fn backward_inputs<'a, T: Real>(
    camera: &Camera,
    splats: &Inputs<'_, T>,
    settings: &RenderSettings,
    forward: &RenderOutput<T>,
    cot: &'a Cotangents<'a, T>,
    tiles: SharedTiles<'a, T>,
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
    if st.partial_lists && matches!(tiles, SharedTiles::None) {
        return Err(RasterError::ForwardMismatch(
            "this render's shared tiles were binned by another render of its exposure \
             (SharedOutputs::OwnerLists): differentiate it with render_cov_shared_backward"
                .into(),
        ));
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
    // Zeroed in parallel: at the step's sizes (megabytes per render) a serial fill shows in the
    // profile. Slots the kernels skip (pairs beyond `used`, shared tiles) stay zero.
    let mut pair_grads = Vec::new();
    pair_grads.par_extend(rayon::iter::repeat_n(T::zero(), st.tile_list.len() * slot));
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
            let Some(cot) = tiles.cotangent(tile, cot) else {
                return;
            };
            if range.is_empty() {
                return;
            }
            let origin = [(tile % gx) * TILE_SIZE, (tile / gx) * TILE_SIZE];
            let size = [
                TILE_SIZE.min(width - origin[0]),
                TILE_SIZE.min(height - origin[1]),
            ];
            let geometry = TileGeometry {
                c,
                origin,
                size,
                width,
            };
            let buf = &st.tile_buf[tile * stride..(tile + 1) * stride];
            let used = st.used[tile] as usize;
            let replay = TileReplay {
                range: range.clone(),
                buf,
                used,
                background: &st.background,
            };
            backward_tile_dispatch(st, &replay, &geometry, cot, scratch, out);
            let Some(lr) = tiles.layer() else {
                return;
            };
            if let Some((head, buf, used)) = lr.layer.tile(tile, c) {
                let replay = TileReplay {
                    range: range.start + head..range.end,
                    buf,
                    used,
                    background: lr.background,
                };
                backward_tile_dispatch(
                    st,
                    &replay,
                    &geometry,
                    lr.cot,
                    scratch,
                    &mut out[head * slot..],
                );
            }
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
    let mut d_smears = vec![zero33; if splats.smears.is_some() { st.n } else { 0 }];
    let reduce =
        |i: usize, out: &mut GaussianGrad<T>, d_ch: &mut [T], d_smear: Option<&mut Mat3<T>>| {
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
            // A zero screen-space gradient (a Gaussian without pairs in this render, such as a static
            // one whose tiles another render of its exposure owns, or whose pairs all lie in such
            // tiles) leaves its zeros standing, without the projection's backward: the same values,
            // whether or not the render binned the tiles it does not own.
            if acc.iter().all(|&v| v == T::zero()) {
                return;
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
            let (mean, logit) = (splats.means[i], splats.opacity_logits[i]);
            match (splats.smears, d_smear) {
                (Some(smears), Some(d_smear)) => {
                    let (dm, d_sigma, ds, dl) =
                        project_cov_smeared_backward(&cam, mean, &sigma, &smears[i], logit, &g);
                    *out = (dm, d_sigma, dl, g.mean2d);
                    *d_smear = ds;
                }
                _ => {
                    let (dm, d_sigma, dl) = project_cov_backward(&cam, mean, &sigma, logit, &g);
                    *out = (dm, d_sigma, dl, g.mean2d);
                }
            }
        };
    // Each Gaussian's smear gradient slot, or `None` for every Gaussian without smears.
    let smear_slots = if d_smears.is_empty() {
        Either::Right((0..st.n).into_par_iter().map(|_| None))
    } else {
        Either::Left(d_smears.par_iter_mut().map(Some))
    };
    if c > 0 {
        per_gaussian
            .par_iter_mut()
            .zip(d_channels.par_chunks_mut(c))
            .zip(smear_slots)
            .enumerate()
            .for_each(|(i, ((out, d_ch), d_smear))| reduce(i, out, d_ch, d_smear));
    } else {
        per_gaussian
            .par_iter_mut()
            .zip(smear_slots)
            .enumerate()
            .for_each(|(i, (out, d_smear))| reduce(i, out, &mut [], d_smear));
    }
    // dL/d background_c = Σ_pixels dL/dimage_c · T_final, rows in order.
    let mut d_bg = vec![T::zero(); c];
    d_bg.par_iter_mut().enumerate().for_each(|(ch, d)| {
        let mut acc = T::zero();
        for y in 0..height {
            for x in 0..width {
                let tile = (y / TILE_SIZE) * gx + x / TILE_SIZE;
                let p = (y % TILE_SIZE) * TILE_SIZE + x % TILE_SIZE;
                let Some(cot) = tiles.cotangent(tile, cot) else {
                    continue;
                };
                acc = acc
                    + cot.image[ch * hw + y * width + x] * st.tile_buf[tile * stride + BUF_T + p];
            }
        }
        *d = acc;
    });
    let mut out = Gradients {
        means: Vec::with_capacity(st.n),
        log_scales: Vec::new(),
        quats: Vec::new(),
        covariances: Vec::new(),
        smears: d_smears,
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

/// Where a tile's replay sits: the image's channels, the tile's origin and size, the image width.
struct TileGeometry {
    c: usize,
    origin: [usize; 2],
    size: [usize; 2],
    width: usize,
}

/// One replay of a tile: the pairs `range` of the forward's lists, the blend's buffer `buf`, the
/// entries it used and the background it was blended against.
struct TileReplay<'a, T> {
    range: std::ops::Range<usize>,
    buf: &'a [T],
    used: usize,
    background: &'a [T],
}

/// One tile's backward (`replay`'s pairs of `st`, `out` their gradient slots): the AVX-512 kernel
/// when the CPU has AVX-512F and `T` is f32 (same bits, faster), else the portable
/// [`backward_tile`].
fn backward_tile_dispatch<T: Real>(
    st: &ForwardState<T>,
    replay: &TileReplay<'_, T>,
    g: &TileGeometry,
    cot: &Cotangents<'_, T>,
    s: &mut BackwardScratch<T>,
    out: &mut [T],
) {
    let (range, c) = (replay.range.clone(), g.c);
    #[cfg(target_arch = "x86_64")]
    {
        use std::any::Any;
        let st32 = (st as &dyn Any).downcast_ref::<ForwardState<f32>>();
        let s32 = (&mut *s as &mut dyn Any).downcast_mut::<BackwardScratch<f32>>();
        if let (Some(st), Some(s), Some(image), Some(out), Some(buf), Some(bg)) = (
            st32,
            s32,
            T::as_f32(cot.image),
            T::as_f32_mut(&mut *out),
            T::as_f32(replay.buf),
            T::as_f32(replay.background),
        ) {
            let cot = Cotangents {
                image,
                alpha: cot.alpha.and_then(T::as_f32),
                depth: cot.depth.and_then(T::as_f32),
            };
            let list = &st.pair_splats[range.clone()];
            let channels = &st.pair_channels[range.start * c..range.end * c];
            let (origin, size, width, used) = (g.origin, g.size, g.width, replay.used);
            if avx512::try_backward_tile(
                list, channels, bg, c, origin, size, width, buf, used, &cot, s, out,
            ) || avx2::try_backward_tile(
                list, channels, bg, c, origin, size, width, buf, used, &cot, s, out,
            ) {
                return;
            }
        }
    }
    backward_tile(
        &st.pair_splats[range.clone()],
        &st.pair_channels[range.start * c..range.end * c],
        replay.background,
        c,
        g.origin,
        g.size,
        g.width,
        replay.buf,
        replay.used,
        cot,
        s,
        out,
    );
}

//! The forward driver: validate, project every Gaussian, bin the visible ones into tile lists,
//! gather each (tile, Gaussian) pair's data in list order, blend every tile in parallel and lay the
//! tiles out as planar images. What the backward needs is kept in [`ForwardState`] inside the
//! returned [`RenderOutput`].

use rayon::prelude::*;

use super::binning::{bin_and_sort, trim_rect};
use super::inputs::{background, validate, Inputs};
use super::kernels::{forward_tile, PairSplat, BUF_C, BUF_D, BUF_T};
use super::layer::LayerView;
use super::{CovSplats, RenderOutput, RenderSettings, Splats};
use crate::project::{CameraParams, Projected};
use crate::{Camera, RasterError, Real, TILE_PIXELS, TILE_SIZE};

#[cfg(target_arch = "x86_64")]
use super::{avx2, avx512};

/// Everything the backward pass needs from the forward pass.
#[derive(Clone, Debug)]
pub(super) struct ForwardState<T> {
    /// Visible Gaussians (compact order = increasing input index).
    pub(super) visible: Vec<Projected<T>>,
    /// Input index of each visible Gaussian.
    pub(super) visible_ids: Vec<u32>,
    /// Offsets of each tile's list in `tile_list` (length tiles + 1).
    pub(super) tile_offsets: Vec<usize>,
    /// Compact indices, sorted by tile then depth.
    pub(super) tile_list: Vec<u32>,
    /// What the tile kernels read of each pair's Gaussian, gathered in `tile_list` order.
    pub(super) pair_splats: Vec<PairSplat<T>>,
    /// Each pair's channels, pairs × C, in `tile_list` order.
    pub(super) pair_channels: Vec<T>,
    /// Per tile, tile-major pixels: [T_final (256) | depth (256) | channel sums C × 256].
    pub(super) tile_buf: Vec<T>,
    /// Per tile: number of list entries the forward blended before every pixel had stopped (the
    /// list length if some pixel never stopped). The backward replays exactly these.
    pub(super) used: Vec<u32>,
    /// Background in working precision (C values).
    pub(super) background: Vec<T>,
    /// Number of input Gaussians.
    pub(super) n: usize,
    /// The tiles another render of the same camera blended have no list here: only the renders'
    /// joint backward (`super::shared`) may differentiate this output.
    pub(super) partial_lists: bool,
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
    let binned = bin_pass(camera, splats, settings)?;
    let (tile_buf, used, _) = blend_tiles(&binned, None, None);
    Ok(binned.into_output(tile_buf, used))
}

/// A request projected, binned into depth-sorted tile lists and gathered in list order: everything
/// of the forward before blending.
pub(super) struct Binned<T> {
    width: usize,
    height: usize,
    /// Tiles per row.
    gx: usize,
    /// Channels C.
    c: usize,
    projection: Projection<T>,
    pub(super) tile_offsets: Vec<usize>,
    tile_list: Vec<u32>,
    pair_splats: Vec<PairSplat<T>>,
    pair_channels: Vec<T>,
    background: Vec<T>,
    n: usize,
    /// Some tiles were skipped (see [`ForwardState::partial_lists`]).
    partial_lists: bool,
}

/// Every Gaussian of a request projected: its INRIA radius (0 when culled) and the visible ones in
/// increasing input order (their compact order).
pub(super) struct Projection<T> {
    radii: Vec<u32>,
    visible: Vec<Projected<T>>,
    visible_ids: Vec<u32>,
    /// The visible Gaussians' INRIA tile rectangles, before [`trim_rect`].
    inria_rects: Vec<[u32; 4]>,
}

/// Tiles whose blend is copied from another render of the same camera instead of recomputed.
pub(super) struct ReusedTiles<'a, T> {
    /// Per tile: copy it (its list holds the same Gaussians with the same inputs in both renders).
    pub(super) reuse: &'a [bool],
    /// The other render's tile buffers and used counts.
    pub(super) tile_buf: &'a [T],
    pub(super) used: &'a [u32],
}

/// A render whose Gaussians not flagged `moving` have bitwise the inputs they have in `reference`
/// (another render of the same camera), so their projections are copied from it.
pub(super) struct ReusedProjection<'a, T> {
    pub(super) reference: &'a Binned<T>,
    /// Per input Gaussian: its compact index in `reference` (`u32::MAX`: culled there).
    pub(super) reference_compact: &'a [u32],
    pub(super) moving: &'a [bool],
}

/// Validates the request, projects every Gaussian (parallel, order-preserving), bins the visible
/// ones into tiles and gathers each pair's data in list order.
pub(super) fn bin_pass<T: Real>(
    camera: &Camera,
    splats: &Inputs<'_, T>,
    settings: &RenderSettings,
) -> Result<Binned<T>, RasterError> {
    Ok(project_pass(camera, splats, settings, None)?.bin(camera, splats, None, None))
}

/// A request checked and projected, not yet binned.
pub(super) struct ProjectedPass<T> {
    cam: CameraParams<T>,
    background: Vec<T>,
    pub(super) projection: Projection<T>,
}

/// Checks the request (image size, inputs, background) and projects every Gaussian (parallel,
/// order-preserving) — or with `reused` only the moving ones, the others' projections copied from
/// the reference render bit for bit.
pub(super) fn project_pass<T: Real>(
    camera: &Camera,
    splats: &Inputs<'_, T>,
    settings: &RenderSettings,
    reused: Option<&ReusedProjection<'_, T>>,
) -> Result<ProjectedPass<T>, RasterError> {
    pinhole::check_image_size(camera.width.into(), camera.height.into())?;
    validate(splats)?;
    let background = background::<T>(settings, splats.num_channels)?;
    let cam = CameraParams::<T>::new(camera, settings.near_plane);
    let n = splats.len();
    let (width, height) = (camera.width as usize, camera.height as usize);
    let projected: Vec<Option<(Projected<T>, [u32; 4])>> = (0..n)
        .into_par_iter()
        .map(|i| {
            if let Some(r) = reused.filter(|r| !r.moving[i]) {
                let ci = r.reference_compact[i] as usize;
                let p = &r.reference.projection;
                return p.visible.get(ci).map(|&v| (v, p.inria_rects[ci]));
            }
            let mut p = splats.project(&cam, i)?;
            let inria_rect = p.rect;
            trim_rect(&mut p, width, height);
            Some((p, inria_rect))
        })
        .collect();
    let mut projection = Projection {
        radii: vec![0u32; n],
        visible: Vec::new(),
        visible_ids: Vec::new(),
        inria_rects: Vec::new(),
    };
    for (i, p) in projected.into_iter().enumerate() {
        if let Some((p, inria_rect)) = p {
            projection.radii[i] = p.radius;
            projection.visible.push(p);
            projection.visible_ids.push(i as u32);
            projection.inria_rects.push(inria_rect);
        }
    }
    Ok(ProjectedPass {
        cam,
        background,
        projection,
    })
}

impl<T: Real> ProjectedPass<T> {
    /// Bins the projection into tiles (no list for the tiles flagged in `skip`: another render
    /// blends and differentiates them; with `cut`, no entry deeper than the tile's cut: another
    /// render blends those) and gathers each pair's data in list order.
    pub(super) fn bin(
        self,
        camera: &Camera,
        splats: &Inputs<'_, T>,
        skip: Option<&[bool]>,
        cut: Option<&[T]>,
    ) -> Binned<T> {
        bin_projected(
            camera,
            &self.cam,
            splats,
            self.projection,
            self.background,
            (skip, cut),
        )
    }
}

impl<T> Projection<T> {
    /// The visible Gaussians' input indices and their INRIA tile rectangles `[x0, y0, x1, y1)`.
    pub(super) fn visible_rects(&self) -> impl Iterator<Item = (u32, [u32; 4])> + '_ {
        self.visible_ids
            .iter()
            .zip(&self.inria_rects)
            .map(|(&id, &rect)| (id, rect))
    }

    /// Raises `deepest[tile]` to the view depth of every visible Gaussian flagged in `moving`
    /// whose (trimmed) rectangle holds the tile; `gx` tiles per row.
    pub(super) fn raise_moving_depths(&self, moving: &[bool], gx: usize, deepest: &mut [Option<T>])
    where
        T: Real,
    {
        for (p, &id) in self.visible.iter().zip(&self.visible_ids) {
            if !moving[id as usize] {
                continue;
            }
            for ty in p.rect[1]..p.rect[3] {
                for tx in p.rect[0]..p.rect[2] {
                    let d = &mut deepest[ty as usize * gx + tx as usize];
                    if d.is_none_or(|d| p.depth > d) {
                        *d = Some(p.depth);
                    }
                }
            }
        }
    }

    /// Per input Gaussian (`n` of them): its compact index (`u32::MAX` where culled).
    pub(super) fn compact_indices(&self, n: usize) -> Vec<u32> {
        let mut compact = vec![u32::MAX; n];
        for (ci, &id) in self.visible_ids.iter().enumerate() {
            compact[id as usize] = ci as u32;
        }
        compact
    }
}

/// Bins a projection into tiles (no list for the tiles flagged in `skip`) and gathers each pair's
/// data in list order.
fn bin_projected<T: Real>(
    camera: &Camera,
    cam: &CameraParams<T>,
    splats: &Inputs<'_, T>,
    projection: Projection<T>,
    background: Vec<T>,
    (skip, cut): (Option<&[bool]>, Option<&[T]>),
) -> Binned<T> {
    let c = splats.num_channels;
    let [gx, gy] = cam.grid;
    let (gx, gy) = (gx as usize, gy as usize);
    // Counting sort by tile (stable in input order), then each tile by (depth, input index),
    // which equals INRIA's stable radix sort on (tile, depth).
    let (tile_offsets, tile_list) = bin_and_sort(&projection.visible, gx, gx * gy, skip, cut);
    let visible = &projection.visible;
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
    let mut pair_channels = vec![T::zero(); tile_list.len() * c];
    if c > 0 {
        let ids = &projection.visible_ids;
        pair_channels
            .par_chunks_mut(c)
            .zip(tile_list.par_iter())
            .for_each(|(dst, &ci)| {
                let g = ids[ci as usize] as usize;
                dst.copy_from_slice(&splats.channels[g * c..(g + 1) * c]);
            });
    }
    Binned {
        width: camera.width as usize,
        height: camera.height as usize,
        gx,
        c,
        projection,
        tile_offsets,
        tile_list,
        pair_splats,
        pair_channels,
        background,
        n: splats.len(),
        partial_lists: skip.is_some() || cut.is_some(),
    }
}

impl<T> Binned<T> {
    /// The visible Gaussians' input indices and their INRIA tile rectangles `[x0, y0, x1, y1)`
    /// (untrimmed: the tiles shared between renders keep INRIA's rule, so the order in which a
    /// static Gaussian's gradients are summed does not depend on the trim).
    pub(super) fn visible_rects(&self) -> impl Iterator<Item = (u32, [u32; 4])> + '_ {
        self.projection.visible_rects()
    }

    /// Per input Gaussian: its compact index in this render (`u32::MAX` where culled).
    pub(super) fn compact_indices(&self) -> Vec<u32> {
        self.projection.compact_indices(self.n)
    }

    /// Tiles per row and number of tiles.
    pub(super) fn grid(&self) -> (usize, usize) {
        (self.gx, self.tile_offsets.len() - 1)
    }

    /// The request's projection.
    pub(super) fn projection(&self) -> &Projection<T> {
        &self.projection
    }

    /// Length of tile `tile`'s list.
    pub(super) fn list_len(&self, tile: usize) -> usize {
        self.tile_offsets[tile + 1] - self.tile_offsets[tile]
    }

    /// Marks every tile's list as unusable by this render's own backward (its outputs hold work
    /// another render's backward differentiates).
    pub(super) fn mark_partial(&mut self) {
        self.partial_lists = true;
    }
}

impl<T: Real> Binned<T> {
    /// How many entries of tile `tile`'s list lie at view depth ≤ `depth` (a prefix: the list is
    /// sorted by depth).
    pub(super) fn entries_within(&self, tile: usize, depth: T) -> usize {
        let range = self.tile_offsets[tile]..self.tile_offsets[tile + 1];
        self.pair_splats[range].partition_point(|p| p.depth <= depth)
    }

    /// Blends the entries `entries` of tile `tile`'s list (indices within the list) into `buf`
    /// ([`forward_tile`]'s outputs, `alive` included).
    pub(super) fn blend_entries(
        &self,
        tile: usize,
        entries: std::ops::Range<usize>,
        buf: &mut [T],
        used: &mut u32,
        alive: &mut [T],
    ) {
        let start = self.tile_offsets[tile];
        let origin = [(tile % self.gx) * TILE_SIZE, (tile / self.gx) * TILE_SIZE];
        let size = [
            TILE_SIZE.min(self.width - origin[0]),
            TILE_SIZE.min(self.height - origin[1]),
        ];
        forward_tile_dispatch(
            &self.pair_splats,
            &self.pair_channels,
            start + entries.start..start + entries.end,
            self.c,
            origin,
            size,
            buf,
            used,
            alive,
        );
    }
}

/// Blends every tile in parallel into per-tile buffers ([T_final | depth | channel sums] per
/// pixel) and the count of list entries each used; `reused` tiles are copied instead. With `layer`,
/// a layered tile blends only its head and composites the static layer behind it; the third vector
/// then holds, per tile × 256 pixels, the transmittance with which each pixel sees its layer
/// (`super::layer`; empty without `layer`).
pub(super) fn blend_tiles<T: Real>(
    b: &Binned<T>,
    reused: Option<&ReusedTiles<'_, T>>,
    layer: Option<&LayerView<'_, T>>,
) -> (Vec<T>, Vec<u32>, Vec<T>) {
    let stride = (2 + b.c) * TILE_PIXELS;
    let n_tiles = b.tile_offsets.len() - 1;
    let mut tile_buf = vec![T::zero(); n_tiles * stride];
    let mut used = vec![0u32; n_tiles];
    let mut weights = vec![
        T::zero();
        if layer.is_some() {
            n_tiles * TILE_PIXELS
        } else {
            0
        }
    ];
    let weight_chunks: Vec<&mut [T]> = if layer.is_some() {
        weights.chunks_mut(TILE_PIXELS).collect()
    } else {
        (0..n_tiles).map(|_| &mut [][..]).collect()
    };
    tile_buf
        .par_chunks_mut(stride)
        .zip(used.par_iter_mut())
        .zip(weight_chunks)
        .enumerate()
        .for_each(|(tile, ((buf, used), weights))| {
            if let Some(r) = reused.filter(|r| r.reuse[tile]) {
                buf.copy_from_slice(&r.tile_buf[tile * stride..(tile + 1) * stride]);
                *used = r.used[tile];
                return;
            }
            let mut alive = [T::zero(); TILE_PIXELS];
            let entries = layer.map_or(b.list_len(tile), |l| l.head(tile, b.list_len(tile)));
            b.blend_entries(tile, 0..entries, buf, used, &mut alive);
            if let Some(l) = layer {
                l.composite(tile, buf, &alive, weights);
            }
        });
    (tile_buf, used, weights)
}

impl<T: Real> Binned<T> {
    /// Lays the blended tiles out as planar images and keeps what the backward needs.
    pub(super) fn into_output(self, tile_buf: Vec<T>, used: Vec<u32>) -> RenderOutput<T> {
        let (width, height, gx, c) = (self.width, self.height, self.gx, self.c);
        let stride = (2 + c) * TILE_PIXELS;
        let bg = &self.background;
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
        RenderOutput {
            width: width as u32,
            height: height as u32,
            num_channels: c,
            image,
            alpha,
            depth,
            radii: self.projection.radii,
            num_pairs: self.tile_list.len(),
            state: ForwardState {
                visible: self.projection.visible,
                visible_ids: self.projection.visible_ids,
                tile_offsets: self.tile_offsets,
                tile_list: self.tile_list,
                pair_splats: self.pair_splats,
                pair_channels: self.pair_channels,
                tile_buf,
                used,
                background: self.background,
                n: self.n,
                partial_lists: self.partial_lists,
            },
        }
    }
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
    alive: &mut [T],
) {
    let channels = &pair_channels[range.start * c..range.end * c];
    #[cfg(target_arch = "x86_64")]
    {
        use std::any::Any;
        let splats32 = (pair_splats as &dyn Any).downcast_ref::<Vec<PairSplat<f32>>>();
        if let (Some(splats), Some(channels), Some(buf), Some(alive)) = (
            splats32,
            T::as_f32(channels),
            T::as_f32_mut(&mut *buf),
            T::as_f32_mut(&mut *alive),
        ) {
            let list = &splats[range.clone()];
            if avx512::try_forward_tile(list, channels, c, origin, size, buf, used, alive)
                || avx2::try_forward_tile(list, channels, c, origin, size, buf, used, alive)
            {
                return;
            }
        }
    }
    forward_tile(
        &pair_splats[range],
        channels,
        c,
        origin,
        size,
        buf,
        used,
        alive,
    );
}

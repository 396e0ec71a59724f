//! The static layer of renders that share their static Gaussians (`super::shared` with
//! [`super::SharedOutputs::Layered`]).
//!
//! In a tile some moving Gaussian reaches, the static Gaussians deeper than every moving one (view
//! depth above the deepest moving Gaussian's in that tile's list, in any render) form the same
//! list tail in every render. That tail is blended once, alone, from transmittance 1: the *layer*,
//! with colour sums C_s, depth D_s and transmittance T_s per pixel. Each render blends only its
//! list's *head* in front of it (C_h, D_h, T_h) and composites the layer behind:
//! C = C_h + T_h C_s, D = D_h + T_h D_s, T = T_h T_s; a pixel that stopped within its head sees
//! nothing behind it, as when blended alone.
//!
//! This is blending each render's whole list, except where a pixel's transmittance would fall
//! below 1e-4 inside the layer: blended alone, the pixel stops where T_h T_s (1 − α) < 1e-4; in the
//! layer it stops where T_s (1 − α) < 1e-4, so at most T_h · T_s of further colour enters there. A
//! pixel whose head leaves T_h = 1 (no Gaussian in front of the layer covers it) gets the same bits.
//!
//! Backward: the layer enters render r linearly, with the weight w_r = T_h (0 where the head
//! stopped the pixel), so it is replayed once, by the owner, against a zero background with the
//! cotangents dL/dC_s = Σ_r w_r dL/dC_r, dL/dα_s = Σ_r w_r (dL/dα_r − Σ_c bg_c dL/dC_r,c) and
//! dL/dD_s = Σ_r w_r dL/dD_r. Each render's head replays against its composited buffers, whose
//! colour behind every entry already holds the layer.

use rayon::prelude::*;

use super::forward::{Binned, Projection};
use super::kernels::{BUF_C, BUF_D, BUF_T};
use super::Cotangents;
use crate::{Real, TILE_PIXELS, TILE_SIZE};

/// The static layers of one exposure's renders (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct StaticLayer<T> {
    /// Per tile: its index among the layered tiles, or `u32::MAX` (no layer).
    index: Vec<u32>,
    /// Per layered tile: the owner's list entries before the layer (the other renders' lists
    /// stop at the cut, so they blend the whole of theirs).
    owner_heads: Vec<u32>,
    /// Per layered tile: the layer blended alone, [T | depth | channel sums] × 256 pixels.
    tile_buf: Vec<T>,
    /// Per layered tile: the layer's entries blended before every pixel stopped.
    used: Vec<u32>,
    /// Per render, per tile × 256 pixels: the transmittance with which the pixel sees its layer
    /// (T_h; 0 where the head stopped the pixel or the tile has no layer).
    weights: Vec<Vec<T>>,
}

impl<T> StaticLayer<T> {
    /// Fraction of the tiles whose static tail is blended once as a layer.
    pub fn layered_fraction(&self) -> f64 {
        let layered = self.index.iter().filter(|&&i| i != u32::MAX).count();
        layered as f64 / self.index.len().max(1) as f64
    }
}

/// What one render's blend needs of the layer: the owner's heads (`None` for another render)
/// and the layer's buffers.
pub(super) struct LayerView<'a, T> {
    owner_heads: Option<&'a [u32]>,
    index: &'a [u32],
    tile_buf: &'a [T],
    c: usize,
}

impl<T: Real> LayerView<'_, T> {
    /// The entries of tile `tile` the render blends itself (`len`: its list's length).
    pub(super) fn head(&self, tile: usize, len: usize) -> usize {
        match (self.owner_heads, self.layer_of(tile)) {
            (Some(heads), Some(k)) => heads[k] as usize,
            _ => len,
        }
    }

    /// Composites tile `tile`'s layer behind the head just blended into `buf` (`alive` from that
    /// blend) and writes each pixel's weight; a tile without a layer is left as blended.
    pub(super) fn composite(&self, tile: usize, buf: &mut [T], alive: &[T], weights: &mut [T]) {
        let Some(k) = self.layer_of(tile) else {
            return;
        };
        let stride = (2 + self.c) * TILE_PIXELS;
        let layer = &self.tile_buf[k * stride..(k + 1) * stride];
        for p in 0..TILE_PIXELS {
            if alive[p] <= T::zero() {
                continue;
            }
            let t_head = buf[BUF_T + p];
            weights[p] = t_head;
            buf[BUF_D + p] = buf[BUF_D + p] + t_head * layer[BUF_D + p];
            for j in 0..self.c {
                let o = BUF_C + j * TILE_PIXELS + p;
                buf[o] = buf[o] + t_head * layer[o];
            }
            buf[BUF_T + p] = t_head * layer[BUF_T + p];
        }
    }

    fn layer_of(&self, tile: usize) -> Option<usize> {
        let k = self.index[tile];
        (k != u32::MAX).then_some(k as usize)
    }
}

/// Per tile, the view depth at which the renders' lists split into head and layer: the deepest
/// moving Gaussian's over every render's `projections` (−∞ where none reaches the tile, so that
/// the whole list is the layer); +∞ in the `shared` tiles (no layer). `gx` tiles per row.
pub(super) fn layer_cuts<T: Real>(
    projections: &[&Projection<T>],
    moving: &[bool],
    shared: &[bool],
    gx: usize,
) -> Vec<T> {
    let mut deepest = vec![None; shared.len()];
    for p in projections {
        p.raise_moving_depths(moving, gx, &mut deepest);
    }
    deepest
        .into_iter()
        .zip(shared)
        .map(|(d, &s)| {
            if s {
                T::infinity()
            } else {
                d.unwrap_or(T::neg_infinity())
            }
        })
        .collect()
}

impl<T: Real> StaticLayer<T> {
    /// Splits the owner's lists `own` (every entry; the other renders' lists stop at the cut) at
    /// `cuts` ([`layer_cuts`]) and blends the layers once, from those lists. A tile whose owner
    /// list has nothing behind the cut has no layer.
    pub(super) fn blend(own: &Binned<T>, cuts: &[T], c: usize) -> Self {
        let mut index = vec![u32::MAX; cuts.len()];
        let (mut layered, mut owner_heads) = (Vec::new(), Vec::new());
        for (tile, &cut) in cuts.iter().enumerate() {
            let head = own.entries_within(tile, cut);
            if head < own.list_len(tile) {
                index[tile] = layered.len() as u32;
                layered.push(tile);
                owner_heads.push(head as u32);
            }
        }
        let stride = (2 + c) * TILE_PIXELS;
        let mut tile_buf = vec![T::zero(); layered.len() * stride];
        let mut used = vec![0u32; layered.len()];
        tile_buf
            .par_chunks_mut(stride)
            .zip(used.par_iter_mut())
            .zip(layered.par_iter().zip(&owner_heads))
            .for_each(|((buf, used), (&tile, &head))| {
                let mut alive = [T::zero(); TILE_PIXELS];
                own.blend_entries(
                    tile,
                    head as usize..own.list_len(tile),
                    buf,
                    used,
                    &mut alive,
                );
            });
        Self {
            index,
            owner_heads,
            tile_buf,
            used,
            weights: Vec::new(),
        }
    }

    /// A render's view of the layer, for its blend (`owner`: the render whose lists hold the
    /// layers' entries).
    pub(super) fn view(&self, owner: bool, c: usize) -> LayerView<'_, T> {
        LayerView {
            owner_heads: owner.then_some(&self.owner_heads[..]),
            index: &self.index,
            tile_buf: &self.tile_buf,
            c,
        }
    }

    /// Keeps each render's weights (from its blend, render order) for the backward.
    pub(super) fn set_weights(&mut self, weights: Vec<Vec<T>>) {
        self.weights = weights;
    }

    /// Tile `tile`'s layer, if it has one: the owner's entries before it, the layer's tile buffer
    /// and its used count.
    pub(super) fn tile(&self, tile: usize, c: usize) -> Option<(usize, &[T], usize)> {
        let k = self.index[tile];
        if k == u32::MAX {
            return None;
        }
        let (k, stride) = (k as usize, (2 + c) * TILE_PIXELS);
        Some((
            self.owner_heads[k] as usize,
            &self.tile_buf[k * stride..(k + 1) * stride],
            self.used[k] as usize,
        ))
    }

    /// The layer's cotangents, image-sized planes (zero outside layered tiles): the renders'
    /// cotangents `cots` weighted by each pixel's weight and summed in render order (module
    /// documentation); `bg` is the renders' background, `width` × `height` the image.
    pub(super) fn cotangents(
        &self,
        cots: &[Cotangents<'_, T>],
        bg: &[T],
        width: usize,
        height: usize,
    ) -> LayerCotangents<T> {
        let (c, hw) = (bg.len(), width * height);
        let gx = width.div_ceil(TILE_SIZE);
        let mut image = vec![T::zero(); c * hw];
        let mut alpha = vec![T::zero(); hw];
        let mut depth = vec![T::zero(); hw];
        let has_depth = cots.iter().any(|k| k.depth.is_some());
        let mut image_rows: Vec<Vec<&mut [T]>> = (0..height).map(|_| Vec::new()).collect();
        for plane in image.chunks_mut(hw) {
            for (y, row) in plane.chunks_mut(width).enumerate() {
                image_rows[y].push(row);
            }
        }
        image_rows
            .into_par_iter()
            .zip(alpha.par_chunks_mut(width))
            .zip(depth.par_chunks_mut(width))
            .enumerate()
            .for_each(|(y, ((mut image_row, alpha_row), depth_row))| {
                for x in 0..width {
                    let tile = (y / TILE_SIZE) * gx + x / TILE_SIZE;
                    if self.index[tile] == u32::MAX {
                        continue;
                    }
                    let at = tile * TILE_PIXELS + (y % TILE_SIZE) * TILE_SIZE + x % TILE_SIZE;
                    let pix = y * width + x;
                    for (weights, cot) in self.weights.iter().zip(cots) {
                        let w = weights[at];
                        if w == T::zero() {
                            continue;
                        }
                        let mut d_alpha = cot.alpha.map_or(T::zero(), |a| a[pix]);
                        for (j, row) in image_row.iter_mut().enumerate() {
                            let g = cot.image[j * hw + pix];
                            row[x] = row[x] + w * g;
                            d_alpha = d_alpha - bg[j] * g;
                        }
                        alpha_row[x] = alpha_row[x] + w * d_alpha;
                        if let Some(d) = cot.depth {
                            depth_row[x] = depth_row[x] + w * d[pix];
                        }
                    }
                }
            });
        LayerCotangents {
            image,
            alpha,
            depth: has_depth.then_some(depth),
            background: vec![T::zero(); c],
        }
    }
}

/// The layer's cotangent planes and its (zero) background.
pub(super) struct LayerCotangents<T> {
    image: Vec<T>,
    alpha: Vec<T>,
    depth: Option<Vec<T>>,
    pub(super) background: Vec<T>,
}

impl<T> LayerCotangents<T> {
    pub(super) fn as_cotangents(&self) -> Cotangents<'_, T> {
        Cotangents {
            image: &self.image,
            alpha: Some(&self.alpha),
            depth: self.depth.as_deref(),
        }
    }
}

//! Several renders from one camera that share most of their Gaussians: the renders of one exposure,
//! where only some Gaussians move between them (the caller says which; the rasterizer does not
//! know why).
//!
//! A tile that no moving Gaussian reaches in any render holds the same list, with the same inputs,
//! in every render, so it is blended once (by the *owner* render) and copied into the others: the
//! outputs are bit-identical to rendering each alone. The backward is linear in the cotangent, so
//! such a tile is replayed once, by the owner, with the sum of the renders' cotangents; its
//! contributions go to the owner's gradients and the other renders' gradients get none from it.
//! Summed over the renders, the gradients equal the separate backwards' sum up to the rounding of
//! summing cotangents before instead of gradients after.

use rayon::prelude::*;

use super::backward::{backward_inputs, LayerReplay, SharedTiles};
use super::forward::{bin_pass, blend_tiles, project_pass, ReusedProjection, ReusedTiles};
use super::inputs::Inputs;
use super::layer::{layer_cuts, StaticLayer};
use super::{Cotangents, CovSplats, Gradients, RenderOutput, RenderSettings};
use crate::{Camera, RasterError, Real};

/// The renders of [`render_cov_shared`].
#[derive(Clone, Debug)]
pub struct SharedRenders<T> {
    /// One output per render: complete with [`SharedOutputs::Complete`] (its own
    /// [`super::render_cov_backward`] works); with [`SharedOutputs::OwnerLists`] only the owner's
    /// is, and the others are differentiated by [`render_cov_shared_backward`] alone.
    pub outputs: Vec<RenderOutput<T>>,
    /// Which tiles were blended once, and by which render.
    pub sharing: TileSharing<T>,
}

/// Which tiles several renders of one camera share, and which render blends and differentiates
/// them.
#[derive(Clone, Debug, PartialEq)]
pub struct TileSharing<T = f32> {
    /// Per tile (row-major, 16×16 pixels): no moving Gaussian reaches it in any render, so it
    /// was blended once, by the owner.
    pub shared_tiles: Vec<bool>,
    /// The render that blends and differentiates the shared tiles.
    pub owner: usize,
    /// With [`SharedOutputs::Layered`]: the static layers blended once behind the moving tiles'
    /// lists (`None` otherwise).
    pub layer: Option<StaticLayer<T>>,
}

impl<T> TileSharing<T> {
    /// Fraction of the tiles blended once for all renders.
    pub fn shared_fraction(&self) -> f64 {
        let shared = self.shared_tiles.iter().filter(|&&s| s).count();
        shared as f64 / self.shared_tiles.len().max(1) as f64
    }

    /// Fraction of the tiles whose static Gaussians behind every moving one were blended once as
    /// a layer (0 without [`SharedOutputs::Layered`]).
    pub fn layered_fraction(&self) -> f64 {
        self.layer
            .as_ref()
            .map_or(0.0, StaticLayer::layered_fraction)
    }
}

/// What the renders other than the owner keep of the shared tiles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SharedOutputs {
    /// Every output is complete, with the shared tiles' lists: each render's own
    /// [`super::render_cov_backward`] works.
    Complete,
    /// The other renders keep no list for the shared tiles (they are binned once, by the owner):
    /// only [`render_cov_shared_backward`] differentiates them. Same images, same gradients.
    OwnerLists,
    /// As [`SharedOutputs::OwnerLists`], and in the other tiles the static Gaussians behind every
    /// moving one are blended once, as a layer each render composites behind its own list
    /// (`raster::layer`): the images differ from separate renders only where a pixel's
    /// transmittance would fall below 1e-4 inside the layer. Only [`render_cov_shared_backward`]
    /// differentiates any of the outputs.
    Layered,
}

/// Renders `renders` (each as [`super::render_cov`] would) from one camera, where every Gaussian
/// not flagged in `moving` has bitwise the same inputs in every render; tiles only such Gaussians
/// reach are blended once, by render `owner`. `moving` has one flag per Gaussian. The static
/// Gaussians are projected once, by the owner; with [`SharedOutputs::OwnerLists`] the shared tiles
/// are also binned only by it.
pub fn render_cov_shared<T: Real>(
    camera: &Camera,
    renders: &[CovSplats<'_, T>],
    moving: &[bool],
    owner: usize,
    settings: &RenderSettings,
    outputs: SharedOutputs,
) -> Result<SharedRenders<T>, RasterError> {
    check_renders(renders, moving, owner)?;
    let owner_binned = bin_pass(camera, &Inputs::from(&renders[owner]), settings)?;
    let reused = ReusedProjection {
        reference: &owner_binned,
        reference_compact: &owner_binned.compact_indices(),
        moving,
    };
    // The renders are independent: one task each (their tiles balance across the threads better
    // than one render's few moving tiles do), collected in render order.
    let projected = renders
        .par_iter()
        .enumerate()
        .map(|(r, splats)| {
            (r != owner)
                .then(|| project_pass(camera, &Inputs::from(splats), settings, Some(&reused)))
                .transpose()
        })
        .collect::<Result<Vec<_>, _>>()?;
    let (gx, n_tiles) = owner_binned.grid();
    let mut shared_tiles = vec![true; n_tiles];
    let rects = projected
        .iter()
        .flatten()
        .flat_map(|p| p.projection.visible_rects())
        .chain(owner_binned.visible_rects());
    for (id, rect) in rects {
        if !moving[id as usize] {
            continue;
        }
        for ty in rect[1]..rect[3] {
            for tx in rect[0]..rect[2] {
                shared_tiles[ty as usize * gx + tx as usize] = false;
            }
        }
    }
    let skip = (outputs != SharedOutputs::Complete).then_some(&shared_tiles[..]);
    let cuts = (outputs == SharedOutputs::Layered).then(|| {
        let projections: Vec<_> = projected
            .iter()
            .flatten()
            .map(|p| &p.projection)
            .chain([owner_binned.projection()])
            .collect();
        layer_cuts(&projections, moving, &shared_tiles, gx)
    });
    let mut binned: Vec<_> = projected
        .into_par_iter()
        .zip(renders)
        .map(|(p, splats)| p.map(|p| p.bin(camera, &Inputs::from(splats), skip, cuts.as_deref())))
        .collect();
    binned[owner] = Some(owner_binned);
    // Every entry is `Some` now: the owner's was just put back.
    let mut binned: Vec<_> = binned.into_iter().flatten().collect();
    let c = renders[owner].num_channels;
    let mut layer = cuts.map(|cuts| StaticLayer::blend(&binned[owner], &cuts, c));
    let (owner_buf, owner_used, owner_weights) = blend_tiles(
        &binned[owner],
        None,
        layer.as_ref().map(|l| l.view(true, c)).as_ref(),
    );
    let mut buffers: Vec<_> = binned
        .par_iter()
        .enumerate()
        .map(|(r, b)| {
            (r != owner).then(|| {
                let reused = ReusedTiles {
                    reuse: &shared_tiles,
                    tile_buf: &owner_buf,
                    used: &owner_used,
                };
                let view = layer.as_ref().map(|l| l.view(false, c));
                blend_tiles(b, Some(&reused), view.as_ref())
            })
        })
        .collect();
    buffers[owner] = Some((owner_buf, owner_used, owner_weights));
    let (buffers, weights): (Vec<_>, Vec<_>) = buffers
        .into_iter()
        .map(|b| {
            let (tile_buf, used, weights) = b.unwrap_or_default();
            ((tile_buf, used), weights)
        })
        .unzip();
    if let Some(l) = layer.as_mut() {
        l.set_weights(weights);
        for b in &mut binned {
            b.mark_partial();
        }
    }
    let outputs = binned
        .into_iter()
        .zip(buffers)
        .map(|(b, (tile_buf, used))| b.into_output(tile_buf, used))
        .collect();
    Ok(SharedRenders {
        outputs,
        sharing: TileSharing {
            shared_tiles,
            owner,
            layer,
        },
    })
}

/// Backward of [`render_cov_shared`]: each render's gradients for its cotangent `cots[r]` (as
/// [`super::render_cov_backward`] gives them), except that the shared tiles are replayed once, by
/// the owner, with the cotangents' sum (see the module documentation). `outputs` and `sharing`
/// are the forward's, in render order.
pub fn render_cov_shared_backward<T: Real>(
    camera: &Camera,
    renders: &[CovSplats<'_, T>],
    settings: &RenderSettings,
    outputs: &[&RenderOutput<T>],
    sharing: &TileSharing<T>,
    cots: &[Cotangents<'_, T>],
) -> Result<Vec<Gradients<T>>, RasterError> {
    let tiles = outputs.first().map(|o| o.state.tile_offsets.len() - 1);
    if renders.len() != outputs.len()
        || cots.len() != renders.len()
        || sharing.owner >= renders.len()
        || tiles != Some(sharing.shared_tiles.len())
    {
        return Err(RasterError::ForwardMismatch(format!(
            "{} renders, {} forward outputs, {} cotangents, owner {}, {} shared-tile flags",
            renders.len(),
            outputs.len(),
            cots.len(),
            sharing.owner,
            sharing.shared_tiles.len()
        )));
    }
    let summed = SummedCotangents::of(cots)?;
    let summed = summed.as_cotangents();
    let owner_out = outputs[sharing.owner];
    let layer_cot = sharing.layer.as_ref().map(|l| {
        let (w, h) = (owner_out.width as usize, owner_out.height as usize);
        l.cotangents(cots, &owner_out.state.background, w, h)
    });
    let layer_cot_refs = layer_cot.as_ref().map(|l| l.as_cotangents());
    let layer_replay = sharing
        .layer
        .as_ref()
        .zip(layer_cot.as_ref().zip(layer_cot_refs.as_ref()))
        .map(|(layer, (lc, cot))| LayerReplay {
            layer,
            cot,
            background: &lc.background,
        });
    renders
        .par_iter()
        .zip(outputs)
        .zip(cots)
        .enumerate()
        .map(|(r, ((splats, out), cot))| {
            let tiles = SharedTiles::Some {
                shared: &sharing.shared_tiles,
                summed: (r == sharing.owner).then_some(&summed),
                layer: layer_replay.filter(|_| r == sharing.owner),
            };
            backward_inputs(camera, &Inputs::from(splats), settings, out, cot, tiles)
        })
        .collect()
}

/// The renders' cotangents summed pixel by pixel, in render order.
struct SummedCotangents<T> {
    image: Vec<T>,
    alpha: Option<Vec<T>>,
    depth: Option<Vec<T>>,
}

impl<T: Real> SummedCotangents<T> {
    fn of(cots: &[Cotangents<'_, T>]) -> Result<Self, RasterError> {
        let sum = |field: &'static str, planes: Vec<Option<&[T]>>| {
            let len = planes.iter().flatten().map(|p| p.len()).max();
            let Some(len) = len else {
                return Ok(None);
            };
            let mut out = vec![T::zero(); len];
            for plane in planes.into_iter().flatten() {
                if plane.len() != len {
                    return Err(RasterError::LengthMismatch {
                        field,
                        got: plane.len(),
                        expected: len,
                    });
                }
                out.par_iter_mut()
                    .zip(plane)
                    .for_each(|(o, &v)| *o = *o + v);
            }
            Ok(Some(out))
        };
        let image = sum("d_image", cots.iter().map(|c| Some(c.image)).collect())?;
        Ok(Self {
            image: image.unwrap_or_default(),
            alpha: sum("d_alpha", cots.iter().map(|c| c.alpha).collect())?,
            depth: sum("d_depth", cots.iter().map(|c| c.depth).collect())?,
        })
    }

    fn as_cotangents(&self) -> Cotangents<'_, T> {
        Cotangents {
            image: &self.image,
            alpha: self.alpha.as_deref(),
            depth: self.depth.as_deref(),
        }
    }
}

/// The renders agree on N and C, `moving` has N flags, `owner` is a render, and every Gaussian
/// not flagged moving has the same inputs in every render.
fn check_renders<T: Real>(
    renders: &[CovSplats<'_, T>],
    moving: &[bool],
    owner: usize,
) -> Result<(), RasterError> {
    let Some(first) = renders.get(owner) else {
        return Err(RasterError::InvalidSettings(format!(
            "shared renders: owner {owner} of {} renders",
            renders.len()
        )));
    };
    let n = first.len();
    if moving.len() != n {
        return Err(RasterError::LengthMismatch {
            field: "moving",
            got: moving.len(),
            expected: n,
        });
    }
    for r in renders {
        if r.len() != n || r.num_channels != first.num_channels {
            return Err(RasterError::InvalidSettings(format!(
                "shared renders: a render has {} Gaussians with {} channels, the owner {n} with {}",
                r.len(),
                r.num_channels,
                first.num_channels
            )));
        }
    }
    let c = first.num_channels;
    let differs = |r: &CovSplats<'_, T>, i: usize| {
        r.means.get(i) != first.means.get(i)
            || r.covariances.get(i) != first.covariances.get(i)
            || r.opacity_logits.get(i) != first.opacity_logits.get(i)
            || r.channels.get(i * c..(i + 1) * c) != first.channels.get(i * c..(i + 1) * c)
    };
    for (index, r) in renders
        .iter()
        .enumerate()
        .filter(|&(index, _)| index != owner)
    {
        let changed = (0..n)
            .into_par_iter()
            .find_first(|&i| !moving[i] && differs(r, i));
        if let Some(gaussian) = changed {
            return Err(RasterError::InvalidSettings(format!(
                "shared renders: Gaussian {gaussian} is not flagged moving but its inputs differ \
                 between render {owner} and render {index}"
            )));
        }
    }
    Ok(())
}

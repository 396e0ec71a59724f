//! Tile binning, depth sort, front-to-back blending and its analytic backward.
//!
//! Forward (INRIA rules): every visible Gaussian is duplicated once per 16×16 tile of its rectangle
//! (trimmed to the tiles where alpha can reach 1/255 at some pixel, which changes no output);
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
//!
//! The code follows these steps, one module each: `inputs` (the public input, settings and output
//! types and their validation), `binning` (tile lists sorted by depth), `kernels` (the per-tile
//! blend loops of forward and backward and the lane arithmetic they share; `avx512` holds their
//! 16-lane twins, `avx2` their 8-lane ones), `forward` (projection, binning and blending into the
//! outputs) and `backward` (replay of every tile and the fixed-order reduction per Gaussian);
//! `shared` renders several passes of one camera that share their static Gaussians, blending and
//! replaying the tiles only those reach once, and `layer` blends once the static Gaussians behind
//! every moving one in the other tiles.

mod backward;
mod binning;
mod camera_pose;
mod forward;
mod inputs;
mod kernels;
mod layer;
mod shared;

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;

pub use backward::{render_backward, render_cov_backward};
pub use camera_pose::camera_pose_gradient;
pub use forward::{render, render_cov};
pub use inputs::{
    Cotangents, CovSplats, Gradients, RenderOutput, RenderSettings, Splats,
    COVARIANCE_SYMMETRY_TOLERANCE, DEFAULT_NEAR_PLANE,
};
pub use layer::StaticLayer;
pub use shared::{
    render_cov_shared, render_cov_shared_backward, SharedOutputs, SharedRenders, TileSharing,
};

/// A xorshift generator of uniform f32 values in [0, 1) for the raster module's tests
/// (deterministic from `seed`, no crate).
#[cfg(test)]
fn test_uniform(seed: u64) -> impl FnMut() -> f32 {
    let mut state = seed;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    }
}

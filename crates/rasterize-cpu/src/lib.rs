//! Tile-sorted, rayon-parallel CPU rasterizer for 3D Gaussians with C arbitrary per-Gaussian channels
//! and an analytic backward pass.
//!
//! It follows the INRIA 3DGS rules exactly (see [`project`] and [`raster`]), so PLYs trained with the
//! reference CUDA rasterizer render the same here. It knows nothing of humans, semantics or training:
//! it splats N Gaussians given as plain structure-of-arrays slices and returns a planar (C, H, W)
//! image, accumulated alpha and alpha-weighted depth, and (backward) gradients w.r.t. every input.
//! [`sh`] composes SH colour evaluation (from `gaussians`) with the rasterizer so that a 3DGS PLY can
//! be rendered and differentiated end to end.
//!
//! Everything is generic over [`Real`] (f32 for rendering, f64 for gradient checks). Results are
//! bit-identical whatever the number of rayon threads: every floating-point reduction runs in a fixed
//! order (per tile in depth order, then per Gaussian in tile order).

pub mod camera;
pub mod error;
pub mod project;
pub mod raster;
pub mod sh;
pub mod synthetic;

pub use camera::{Camera, CameraJson, InriaCameraJson, MAX_IMAGE_SIDE};
pub use error::RasterError;
pub use raster::{
    render, render_backward, Cotangents, Gradients, RenderOutput, RenderSettings, Splats,
};
pub use sh::{render_sh, render_sh_backward, ShGradients, ShRender, ShSplats};

/// Tile side (pixels), as in INRIA 3DGS.
pub const TILE_SIZE: usize = 16;
/// Pixels per tile.
pub const TILE_PIXELS: usize = TILE_SIZE * TILE_SIZE;

/// Floating-point type the rasterizer runs in: `f32` (rendering) or `f64` (gradient checks).
pub trait Real: num_traits::Float + Send + Sync + std::fmt::Debug + Default + 'static {}
impl Real for f32 {}
impl Real for f64 {}

/// Converts an f64 literal to the working precision (exact for f64, rounded once for f32).
#[inline]
pub(crate) fn lit<T: Real>(v: f64) -> T {
    T::from(v).unwrap_or_else(T::zero)
}

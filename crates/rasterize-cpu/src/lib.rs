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

pub mod error;
pub mod lanes;
pub mod project;
pub mod raster;
pub mod sh;
pub mod synthetic;

pub use error::RasterError;
/// The pinhole camera renders are made from (the workspace's one camera type, `pinhole`'s).
pub use pinhole::{Camera, CameraError, MAX_IMAGE_SIDE};
pub use raster::{
    camera_pose_gradient, render, render_backward, render_cov, render_cov_backward,
    render_cov_shared, render_cov_shared_backward, Cotangents, CovSplats, Gradients, RenderOutput,
    RenderSettings, SharedOutputs, SharedRenders, Splats, TileSharing, DEFAULT_NEAR_PLANE,
};
pub use sh::{render_sh, render_sh_backward, ShGradients, ShRender, ShSplats};

/// Tile side (pixels), as in INRIA 3DGS.
pub const TILE_SIZE: usize = 16;
/// Pixels per tile.
pub const TILE_PIXELS: usize = TILE_SIZE * TILE_SIZE;

/// Floating-point type the rasterizer runs in: `f32` (rendering) or `f64` (gradient checks).
pub trait Real: num_traits::Float + Send + Sync + std::fmt::Debug + Default + 'static {
    /// `exp` as used for Gaussian falloff in the blending kernels, for arguments ≤ 0. f64 uses the
    /// correctly rounded-ish libm `exp` (gradient checks); f32 uses a branch-free polynomial
    /// (relative error < 3e-7, i.e. a few ulp) that the compiler can vectorise.
    fn splat_exp(self) -> Self;

    /// Four lanes of this type for the tile kernels (SSE2 registers for f32 on x86-64).
    type V4: lanes::Lanes<Self>;

    /// Tile-list sort key of a Gaussian: orders by view `depth` (> 0), then by `index`, as one
    /// integer (the depth's bit pattern above the index; positive floats order like their bits).
    type DepthKey: Ord + Copy + Send + Sync + Default;
    /// The key of (`depth`, `index`); see [`Real::DepthKey`].
    fn depth_key(depth: Self, index: u32) -> Self::DepthKey;
    /// The index stored in `key`.
    fn key_index(key: Self::DepthKey) -> u32;

    /// `s` as f32 if `Self` is f32, else `None` (lets generic code pick an f32-only kernel).
    fn as_f32(s: &[Self]) -> Option<&[f32]>;
    /// `s` as f32 if `Self` is f32, else `None`.
    fn as_f32_mut(s: &mut [Self]) -> Option<&mut [f32]>;
}

impl Real for f32 {
    #[inline(always)]
    fn splat_exp(self) -> f32 {
        fast_exp_f32(self)
    }

    #[cfg(target_arch = "x86_64")]
    type V4 = lanes::F32x4;
    #[cfg(not(target_arch = "x86_64"))]
    type V4 = lanes::Arr4<f32>;

    type DepthKey = u64;
    #[inline(always)]
    fn depth_key(depth: f32, index: u32) -> u64 {
        (u64::from(depth.to_bits()) << 32) | u64::from(index)
    }
    #[inline(always)]
    fn key_index(key: u64) -> u32 {
        key as u32
    }
    #[inline(always)]
    fn as_f32(s: &[f32]) -> Option<&[f32]> {
        Some(s)
    }
    #[inline(always)]
    fn as_f32_mut(s: &mut [f32]) -> Option<&mut [f32]> {
        Some(s)
    }
}

impl Real for f64 {
    #[inline(always)]
    fn splat_exp(self) -> f64 {
        self.exp()
    }

    type V4 = lanes::Arr4<f64>;

    type DepthKey = u128;
    #[inline(always)]
    fn depth_key(depth: f64, index: u32) -> u128 {
        (u128::from(depth.to_bits()) << 32) | u128::from(index)
    }
    #[inline(always)]
    fn key_index(key: u128) -> u32 {
        key as u32
    }
    #[inline(always)]
    fn as_f32(_: &[f64]) -> Option<&[f32]> {
        None
    }
    #[inline(always)]
    fn as_f32_mut(_: &mut [f64]) -> Option<&mut [f32]> {
        None
    }
}

/// Branch-free exp for f32 (Cody–Waite reduction to |r| ≤ ln2/2, degree-6 Taylor polynomial,
/// exponent by bit construction). Inputs are clamped to [−87, 0] (the kernels only need x ≤ 0;
/// below −87 the result, < 2e-38, is far under the 1/255 alpha cut anyway). Written with selects
/// and integer bit operations only (no float→int cast) so that loops calling it vectorise.
#[inline(always)]
pub fn fast_exp_f32(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    const ROUND: f32 = 12_582_912.0; // 1.5·2^23: adding and subtracting rounds to an integer.
                                     // ROUND + k for an integer k in [−126, 0] has the bit pattern ROUND_BITS + k.
    const ROUND_BITS: u32 = 0x4B40_0000;
    let x = if x < -87.0 { -87.0 } else { x };
    let x = if x > 0.0 { 0.0 } else { x };
    let kr = x * LOG2E + ROUND;
    let k = kr - ROUND;
    let r = x - k * LN2_HI - k * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    // Biased exponent k + 127 in bits 23..31.
    let scale = f32::from_bits(kr.to_bits().wrapping_sub(ROUND_BITS - 127) << 23);
    p * scale
}

/// Converts an f64 literal to the working precision (exact for f64, rounded once for f32).
#[inline]
pub(crate) fn lit<T: Real>(v: f64) -> T {
    T::from(v).unwrap_or_else(T::zero)
}

#[cfg(test)]
mod tests {
    #[test]
    fn fast_exp_is_accurate_on_the_kernel_range() {
        let mut worst = 0.0f64;
        for i in 0..=200_000 {
            let x = -30.0 * f64::from(i) / 200_000.0;
            let got = f64::from(super::fast_exp_f32(x as f32));
            let want = f64::from(x as f32).exp();
            worst = worst.max(((got - want) / want).abs());
        }
        assert!(worst < 3e-7, "worst relative error {worst:e}");
        assert_eq!(super::fast_exp_f32(0.0), 1.0);
        assert!(super::fast_exp_f32(-200.0) >= 0.0);
    }
}

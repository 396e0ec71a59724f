//! Supporting neural-network building blocks for the workspace: dense layers on batches, activations,
//! 2-D convolution (stride 1, and strided by polyphase decomposition), 2×2 average pooling, max
//! pooling, bilinear resize, backward warping by a flow field and Adam.
//!
//! Every op has a forward and a backward pass (w.r.t. inputs and weights) and is generic over
//! [`Real`] (`f32` for work, `f64` for the finite-difference checks in `tests/gradient-checks`).
//!
//! Conventions shared by all ops:
//! - tensors are plain slices in row-major order with the shape passed explicitly; images are planar
//!   `(B, C, H, W)` with the batch leading (a single image is `B = 1`);
//! - backward functions that produce a gradient w.r.t. an *input* overwrite their output slice;
//!   functions that produce gradients w.r.t. *weights* accumulate (`+=`) so that gradients can be summed
//!   over several calls;
//! - parallel work (rayon) is split into chunks whose boundaries do not depend on the number of threads,
//!   and every reduction runs in a fixed order: results are bit-identical for any `RAYON_NUM_THREADS`.
//!
//! This crate knows nothing about flow networks, Gaussians or the method; it must never read files.

mod activation;
mod adam;
mod conv;
mod conv_strided;
mod dense;
mod gemm;
mod gemm_packing_free;
pub mod mlp;
mod pool;
mod resize;
#[cfg(feature = "safetensors")]
pub mod tensors;
mod warp;

pub use activation::{
    leaky_relu_backward, leaky_relu_forward, relu_backward, relu_forward, sigmoid_backward,
    sigmoid_forward, softplus_backward, softplus_forward,
};
pub use adam::{adam_update, Adam, AdamConfig, RowAdam};
pub use conv::{
    conv2d_backward_input, conv2d_backward_weight, conv2d_forward, conv2d_reference, Conv2dShape,
};
pub use dense::{dense_backward, dense_forward, DenseShape};
pub use gemm::gemm;
pub use pool::{
    avg_pool2x2_backward, avg_pool2x2_forward, max_pool2d_backward, max_pool2d_forward,
    pooled_size, MaxPool2dShape,
};
pub use resize::{resize_bilinear_backward, resize_bilinear_forward};
pub use warp::{warp_backward, warp_forward};

/// Errors of the `nn` crate: shape mismatches between the declared shape and the slices passed in.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum NnError {
    /// A slice does not have the length its declared shape implies.
    #[error("{name}: expected {expected} elements, got {actual}")]
    Length {
        /// Which argument (e.g. `"conv2d weight"`).
        name: &'static str,
        /// Length implied by the shape.
        expected: usize,
        /// Length of the slice passed in.
        actual: usize,
    },
    /// A shape is invalid on its own (e.g. a kernel larger than the padded image).
    #[error("invalid shape: {0}")]
    Shape(String),
}

/// Checks that `slice_len == expected`, naming the argument otherwise.
pub(crate) fn check_len(name: &'static str, expected: usize, actual: usize) -> Result<(), NnError> {
    if expected == actual {
        Ok(())
    } else {
        Err(NnError::Length {
            name,
            expected,
            actual,
        })
    }
}

/// Floating-point scalar the kernels are generic over: `f32` (storage and hot loops) or `f64`
/// (finite-difference checks). Adds the GEMM dispatch and lossless constant conversion to
/// [`num_traits::Float`].
pub trait Real:
    num_traits::Float + Send + Sync + Default + std::fmt::Debug + std::iter::Sum + 'static
{
    /// Converts an `f64` constant (rounds to nearest for `f32`).
    fn of(x: f64) -> Self;
    /// Converts to `f64` (exact).
    fn as_f64(self) -> f64;
    /// Raw GEMM `C = alpha·A·B + beta·C` with strided row-major/column-major views; bounds are checked
    /// by [`gemm`] before this is called.
    #[doc(hidden)]
    fn gemm_unchecked(
        m: usize,
        k: usize,
        n: usize,
        alpha: Self,
        a: &[Self],
        rsa: isize,
        csa: isize,
        b: &[Self],
        rsb: isize,
        csb: isize,
        beta: Self,
        c: &mut [Self],
        rsc: isize,
        csc: isize,
    );
}

//! SPyNet-style optical-flow pyramid (Ranjan & Black 2017) with exact gradients w.r.t. both input
//! images, for use as a *frozen* flow estimator inside a differentiable loss, plus weight gradients for
//! training the project's own weights.
//!
//! # Network
//! Both RGB images (planar `(3, H, W)`, linear `[0, 1]`) are normalised with the ImageNet mean
//! `(0.485, 0.456, 0.406)` and std `(0.229, 0.224, 0.225)`, then reduced to a pyramid of `L` levels by
//! repeated 2×2 average pooling. Level 0 is the coarsest. At level `l` the module
//! `conv7×7(8→32) ReLU conv(32→64) ReLU conv(64→32) ReLU conv(32→16) ReLU conv(16→2)` (stride 1,
//! padding 3) sees `[img1_l, warp(img2_l, U_l), U_l]` (8 channels) and outputs the residual added to
//! `U_l`, where `U_l = up(flow_{l−1})` is the bilinear ×2 upsampling with `align_corners = true`,
//! values ×2, replicate-padded by one row/column if sizes differ (`U_0 = 0`). Images whose sides are
//! not multiples of `2^(L−1)` are resized up to the next multiple (bilinear, `align_corners = false`);
//! the flow is resized back and its components rescaled by the size ratios. (`2^(L−1)` is what `L − 1`
//! poolings need; the reference PyTorch port uses 32 for its 6 levels, i.e. the same rule.)
//!
//! Flow is `(2, H, W)` in pixels, channel 0 = u (+x right), channel 1 = v (+y down), forward flow from
//! image 1 to image 2: image 1 at `x` matches image 2 at `x + F(x)`.
//!
//! # Weights file (safetensors)
//! One F32 tensor per convolution weight and bias:
//! `level{l}.conv{i}.weight` with shape `[c_out, c_in, 7, 7]` and `level{l}.conv{i}.bias` with shape
//! `[c_out]`, for `l = 0..L` (0 = coarsest) and `i = 0..5` (`(c_in, c_out)` = (8,32), (32,64), (64,32),
//! (32,16), (16,2)). The number of levels is the number of consecutive `level{l}` groups present.
//!
//! # Original SPyNet weights
//! The authors' Torch7 files (`modelL{level}_{F|C|K|3|4}-{conv}-{weight|bias}.t7`, levels from 1 =
//! coarsest, convs 1..5) are licensed for non-commercial use and are never shipped with this project.
//! A user who holds them converts them with
//! `cargo xtask flow-import-t7 --dir DIR --variant F --out spynet-F.safetensors` (see [`t7`]).
//!
//! This crate knows nothing about events, Gaussians or the training losses of the method.

pub mod interpolate;
mod net;
pub mod synthetic;
pub mod t7;
pub mod train;
mod weights;

pub use net::{
    PyramidDepth, SpyNet, Tape, IMAGENET_MEAN, IMAGENET_STD, KERNEL, LAYER_CHANNELS,
    PAIRED_DIFF_GAIN,
};
pub use weights::{
    load_safetensors, read_safetensors, save_safetensors, write_safetensors, PYRAMID_KEY,
};

/// Errors of the `flow` crate.
#[derive(Debug, thiserror::Error)]
pub enum FlowError {
    /// A shape error from an `nn` op.
    #[error(transparent)]
    Nn(#[from] nn::NnError),
    /// The two images (or an image and its declared size) do not agree.
    #[error("image size mismatch: {0}")]
    Size(String),
    /// A tensor required by the network is absent from a weights file.
    #[error("missing tensor {name}")]
    MissingTensor {
        /// Tensor name (e.g. `level2.conv0.weight` or a Torch7 file name).
        name: String,
    },
    /// A tensor has the wrong shape.
    #[error("tensor {name}: expected shape {expected:?}, found {actual:?}")]
    WrongShape {
        /// Tensor name.
        name: String,
        /// Shape the network needs.
        expected: Vec<usize>,
        /// Shape found in the file.
        actual: Vec<usize>,
    },
    /// A tensor has an unsupported element type.
    #[error("tensor {name}: unsupported dtype {dtype}")]
    WrongDtype {
        /// Tensor name.
        name: String,
        /// Element type found.
        dtype: String,
    },
    /// A weights file's metadata entry has a value this crate does not know.
    #[error("metadata entry `{key}` is `{value}`; expected {expected}")]
    Metadata {
        /// The metadata key.
        key: String,
        /// The value found.
        value: String,
        /// What the key may hold.
        expected: String,
    },
    /// A weights file has no level at all.
    #[error("weights contain no level (no tensor named level0.conv0.weight)")]
    NoLevels,
    /// Error of the safetensors container.
    #[error("safetensors: {0}")]
    Safetensors(#[from] safetensors::SafeTensorError),
    /// A malformed or truncated Torch7 file.
    #[error("torch7 tensor {name}: {message}")]
    Torch7 {
        /// File or tensor name.
        name: String,
        /// What is wrong.
        message: String,
    },
    /// An I/O error on a named file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The underlying error.
        source: std::io::Error,
    },
}

impl From<nn::tensors::TensorError> for FlowError {
    fn from(e: nn::tensors::TensorError) -> Self {
        use nn::tensors::TensorError as T;
        match e {
            T::Missing { name } => Self::MissingTensor { name },
            T::WrongDtype { name, dtype } => Self::WrongDtype { name, dtype },
            T::WrongShape {
                name,
                expected,
                actual,
            } => Self::WrongShape {
                name,
                expected,
                actual,
            },
        }
    }
}

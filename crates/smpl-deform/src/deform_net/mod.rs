//! The two deformation networks of 3DGS-Avatar, on `nn::Mlp`, and the full Gaussian deformation
//! (non-rigid offsets, then linear blend skinning with learned weights) with its backward pass.
//!
//! - Input encoding (`encoding`): canonical xyz normalised by the canonical body's bounding box
//!   (centre, half extent × 1.1: 10% padding) to roughly [−1, 1], then a frequency encoding
//!   `[x, sin(2^k π x), cos(2^k π x)]_{k<L}` (L = [`NUM_FREQS`] = 4, 27 values). It replaces
//!   3DGS-Avatar's GPU hash grid: no table lookups, cheap on a CPU, smooth (C∞) for FD checks.
//! - Skinning field (`skinning`): encoding → MLP (4 hidden layers, LeakyReLU 0.01) → softmax over
//!   24 bones (the flat softmax; the hierarchical variant is not implemented).
//! - Non-rigid network (`nonrigid`): encoding ⊕ pose code (the 207-value SMPL pose feature
//!   `R_j − I` of joints 1..23) → MLP (3 hidden layers, LeakyReLU) → Δx (3), Δlog-scale (3),
//!   Δrotation (3: the vector part of a quaternion whose w is fixed to 1), feature (16). Its last
//!   layer starts at zero, so the initial deformation is the identity (as in 3DGS-Avatar).
//! - Deformation (`deform`), in 3DGS-Avatar's order: `x_nr = x + Δx`, `s' = s + Δs`,
//!   `q' = q ⊗ (1, Δr)` (Hamilton product), weights `w = field(x_nr)`, then LBS of `x_nr` and `q'`
//!   with the frame's bone transforms.
//! - Execution: rows are processed in fixed-size chunks (`batch_mlp`), every product a GEMM on the
//!   chunk, the whole pipeline fused per chunk and run in parallel over chunks; parameter and bone
//!   gradients are summed over a fixed number of groups in order, so results are bit-identical for
//!   any thread count. Hidden post-activations are cached for the backward pass.
//!
//! The public items live in the submodules and are re-exported here (`smpl_deform::deform_net::X`).
//! This module holds what the submodules share: the chunk size, the backward scratch buffers and the
//! shape checks. It never reads files and knows nothing of rasterization or losses other than the
//! skinning loss.

use nn::mlp::{Activation, Mlp};
use nn::Real;

use crate::batch_mlp;

mod deform;
mod encoding;
mod nonrigid;
mod repose;
mod skinning;
#[cfg(test)]
mod tests;

pub use deform::{
    deform_gaussians, deform_gaussians_backward, deform_gaussians_backward_with_moved, quat_mul,
    CanonicalGaussians, DeformCache, DeformGrad, PosedGaussians,
};
pub use encoding::{encode, encode_backward_from, Normalizer, ENC_DIM, NUM_FREQS};
pub use nonrigid::{pose_code, NonRigidNet, NR_FEATURE_DIM, NR_OUT_DIM};
pub use repose::{MovedCotangents, ReposeCache, Reposed};
pub use skinning::{skinning_loss, SkinningCache, SkinningField};

/// LeakyReLU slope of both networks (PyTorch's default).
pub const LEAKY_SLOPE: f64 = 0.01;
/// Hidden width the project uses for both networks: 64, half of 3DGS-Avatar's 128, because at 128
/// the two MLPs alone cost ≈ 28 GFLOP per forward + backward of 50k Gaussians, beyond the CPU
/// budget (see docs/notes/benchmarks-history.md, "deformation"). The constructors take any width.
pub const DEFAULT_HIDDEN: usize = 64;

/// Rows per chunk of the chunked passes of both networks (a function of their widths only).
fn rows_per_chunk<T: Real>(a: &Mlp<T>, b: &Mlp<T>) -> usize {
    batch_mlp::chunk_rows(batch_mlp::widest(a).max(batch_mlp::widest(b)))
}

/// Per-group buffers of the backward passes (allocated once per group, reused across its chunks).
#[derive(Default)]
struct ChunkBuffers<T> {
    mlp: batch_mlp::Scratch<T>,
    d_logits: Vec<T>,
    d_enc: Vec<T>,
    d_enc2: Vec<T>,
    d_nr_out: Vec<T>,
    d_t: Vec<T>,
    d_w: Vec<T>,
    d_x_field: Vec<[T; 3]>,
}

fn grow<T: Clone + Default>(v: &mut Vec<T>, len: usize) -> &mut [T] {
    if v.len() < len {
        v.resize(len, T::default());
    }
    &mut v[..len]
}

fn check_len(name: &'static str, expected: usize, actual: usize) -> Result<(), nn::NnError> {
    if expected == actual {
        Ok(())
    } else {
        Err(nn::NnError::Length {
            name,
            expected,
            actual,
        })
    }
}

/// Checks that `mlp` has the input and output widths its network needs and a complete parameter
/// vector (the fields are public, so a caller may have replaced them).
fn check_mlp<T: Real>(
    mlp: &Mlp<T>,
    what: &str,
    inputs: usize,
    outputs: usize,
) -> Result<(), nn::NnError> {
    if let Activation::LeakyRelu(s) = mlp.activation {
        if !(s >= 0.0) {
            return Err(nn::NnError::Shape(format!(
                "{what}: LeakyReLU slope {s} must be ≥ 0"
            )));
        }
    }
    if mlp.sizes.len() < 2
        || mlp.input_dim() != inputs
        || mlp.output_dim() != outputs
        || mlp.sizes.contains(&0)
    {
        return Err(nn::NnError::Shape(format!(
            "{what}: layer sizes {:?} must run {inputs} → … → {outputs}",
            mlp.sizes
        )));
    }
    check_len(
        "deformation network params",
        mlp.num_params(),
        mlp.params.len(),
    )
}

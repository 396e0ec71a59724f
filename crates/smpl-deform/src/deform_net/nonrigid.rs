//! The pose-conditioned non-rigid deformation network (position encoding ⊕ pose code → Δx,
//! Δlog-scale, Δrotation, feature), its chunk passes with the pose code folded into the first
//! layer's bias, and the pose code itself.

use nn::mlp::{Activation, Mlp};
use nn::Real;

use super::encoding::{encode_rows, encode_rows_backward, Normalizer, ENC_DIM};
use super::{check_len, check_mlp, grow, ChunkBuffers, LEAKY_SLOPE};
use crate::batch_mlp;
use crate::math::Mat3;
use crate::skeleton::NUM_POSE_FEATURES;

/// Width of the non-rigid network's feature output.
pub const NR_FEATURE_DIM: usize = 16;
/// Outputs of the non-rigid network: Δx 3, Δlog-scale 3, Δrotation 3, feature 16.
pub const NR_OUT_DIM: usize = 9 + NR_FEATURE_DIM;

/// The pose-conditioned non-rigid deformation network.
#[derive(Clone, Debug)]
pub struct NonRigidNet<T: Real> {
    /// The MLP `ENC_DIM + 207 → hidden × 3 → 25`.
    pub mlp: Mlp<T>,
    /// Input normalisation (canonical body box).
    pub norm: Normalizer<T>,
}

/// One chunk of a non-rigid forward pass.
#[derive(Clone, Debug)]
pub(super) struct NrChunk<T> {
    enc: Vec<T>,
    pre: Vec<T>,
}

impl<T: Real> NonRigidNet<T> {
    /// A network with `hidden`-wide layers (128 in 3DGS-Avatar; see
    /// [`DEFAULT_HIDDEN`](super::DEFAULT_HIDDEN)), PyTorch init from `seed` except the last layer,
    /// which is zero (identity deformation at the start).
    pub fn new(
        canonical_vertices: &[[f32; 3]],
        hidden: usize,
        seed: u64,
    ) -> Result<Self, nn::NnError> {
        let sizes = [
            ENC_DIM + NUM_POSE_FEATURES,
            hidden,
            hidden,
            hidden,
            NR_OUT_DIM,
        ];
        let mut mlp = Mlp::new(&sizes, Activation::LeakyRelu(LEAKY_SLOPE), seed)?;
        let last = NR_OUT_DIM * (hidden + 1);
        let n = mlp.params.len();
        for p in &mut mlp.params[n - last..] {
            *p = T::zero();
        }
        Ok(Self {
            mlp,
            norm: Normalizer::from_vertices(canonical_vertices),
        })
    }

    pub(super) fn check(&self, pose_code: &[T]) -> Result<(), nn::NnError> {
        check_mlp(
            &self.mlp,
            "non-rigid network",
            ENC_DIM + NUM_POSE_FEATURES,
            NR_OUT_DIM,
        )?;
        check_len("non-rigid pose code", NUM_POSE_FEATURES, pose_code.len())
    }

    /// Forward of one chunk with the folded network (`wt`: its transposed weights); writes the
    /// outputs to `out`.
    pub(super) fn chunk_forward(
        &self,
        folded: &Mlp<T>,
        wt: &[T],
        points: &[[T; 3]],
        out: &mut [T],
    ) -> NrChunk<T> {
        let r = points.len();
        let mut enc = vec![T::zero(); r * ENC_DIM];
        encode_rows(&self.norm, points, &mut enc);
        let mut pre = vec![T::zero(); r * batch_mlp::hidden_total(folded)];
        batch_mlp::forward_chunk(folded, wt, &enc, r, &mut pre, out);
        NrChunk { enc, pre }
    }

    /// Backward of one chunk: accumulates the *folded* network's parameter gradient into
    /// `d_folded` and writes `∂L/∂points` to `d_points`.
    pub(super) fn chunk_backward(
        &self,
        folded: &Mlp<T>,
        c: &NrChunk<T>,
        d_out: &[T],
        d_folded: &mut [T],
        d_points: &mut [[T; 3]],
        buf: &mut ChunkBuffers<T>,
    ) {
        let r = d_points.len();
        let d_enc = grow(&mut buf.d_enc2, r * ENC_DIM);
        batch_mlp::backward_chunk(
            folded,
            &c.enc,
            &c.pre,
            r,
            d_out,
            d_folded,
            Some(d_enc),
            &mut buf.mlp,
        );
        encode_rows_backward(&self.norm, &c.enc, d_enc, d_points);
    }

    /// The network with the pose code folded into the first layer's bias: the code is the same for
    /// every point, so its share of the first layer (`W_pose · code`) is a bias, computed once per
    /// frame; the folded network's input is the 27-value position encoding only (8.7× fewer
    /// first-layer multiply-adds).
    pub(super) fn fold(&self, pose_code: &[T]) -> Mlp<T> {
        let full_in = ENC_DIM + NUM_POSE_FEATURES;
        let h = self.mlp.sizes[1];
        let mut sizes = self.mlp.sizes.clone();
        sizes[0] = ENC_DIM;
        let full0 = h * (full_in + 1);
        let mut params = Vec::with_capacity(self.mlp.params.len() - h * NUM_POSE_FEATURES);
        for r in 0..h {
            params.extend_from_slice(&self.mlp.params[r * full_in..r * full_in + ENC_DIM]);
        }
        for r in 0..h {
            let w = &self.mlp.params[r * full_in + ENC_DIM..(r + 1) * full_in];
            let mut b = self.mlp.params[h * full_in + r];
            for (wc, c) in w.iter().zip(pose_code) {
                b = b + *wc * *c;
            }
            params.push(b);
        }
        params.extend_from_slice(&self.mlp.params[full0..]);
        Mlp {
            sizes,
            activation: self.mlp.activation,
            params,
        }
    }

    /// Maps the folded network's parameter gradient back onto the full network's (accumulating):
    /// first-layer position columns and bias map directly, the pose columns get `∂L/∂bias ⊗ code`,
    /// later layers are identical.
    pub(super) fn unfold_grad(&self, pose_code: &[T], d_folded: &[T], d_params: &mut [T]) {
        let full_in = ENC_DIM + NUM_POSE_FEATURES;
        let h = self.mlp.sizes[1];
        for r in 0..h {
            let db = d_folded[h * ENC_DIM + r];
            for c in 0..ENC_DIM {
                d_params[r * full_in + c] = d_params[r * full_in + c] + d_folded[r * ENC_DIM + c];
            }
            for (c, &code) in pose_code.iter().enumerate() {
                let k = r * full_in + ENC_DIM + c;
                d_params[k] = d_params[k] + db * code;
            }
            d_params[h * full_in + r] = d_params[h * full_in + r] + db;
        }
        let fold0 = h * (ENC_DIM + 1);
        let full0 = h * (full_in + 1);
        for (dst, src) in d_params[full0..].iter_mut().zip(&d_folded[fold0..]) {
            *dst = *dst + *src;
        }
    }

    /// ∂L/∂pose code from the folded network's parameter gradient: the code enters only through the
    /// folded first-layer bias `b + W_pose · code`, so `∂L/∂code_c = Σ_r ∂L/∂bias_r · W_pose[r, c]`.
    pub(super) fn pose_code_grad(&self, d_folded: &[T]) -> Vec<T> {
        let full_in = ENC_DIM + NUM_POSE_FEATURES;
        let h = self.mlp.sizes[1];
        let mut d_code = vec![T::zero(); NUM_POSE_FEATURES];
        for r in 0..h {
            let db = d_folded[h * ENC_DIM + r];
            let w = &self.mlp.params[r * full_in + ENC_DIM..(r + 1) * full_in];
            for (d, &wc) in d_code.iter_mut().zip(w) {
                *d = *d + db * wc;
            }
        }
        d_code
    }
}

/// The 207-value pose code from local joint rotations (`R_j − I`, joints 1..23, row-major).
pub fn pose_code<T: Real>(local_rotations: &[Mat3<T>]) -> Vec<T> {
    let mut out = Vec::with_capacity(NUM_POSE_FEATURES);
    for r in local_rotations.iter().skip(1) {
        for (k, &x) in r.iter().enumerate() {
            out.push(if k % 4 == 0 { x - T::one() } else { x });
        }
    }
    out
}

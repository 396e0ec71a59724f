//! The learned skinning field (canonical position → softmax weights over the 24 bones) with its
//! chunked forward and backward passes, and the skinning loss that supervises it against the body
//! model's weights. The fused deformation ([`super::deform`]) runs the same chunk passes inline.

use std::ops::Range;

use nn::mlp::{Activation, Mlp};
use nn::Real;
use rayon::prelude::*;

use super::encoding::{encode_rows, encode_rows_backward, Normalizer, ENC_DIM};
use super::{check_len, check_mlp, grow, rows_per_chunk, ChunkBuffers, LEAKY_SLOPE};
use crate::batch_mlp;
use crate::skeleton::NUM_JOINTS;

/// The learned skinning field: canonical position → weights over the 24 bones.
#[derive(Clone, Debug)]
pub struct SkinningField<T: Real> {
    /// The MLP `ENC_DIM → hidden × 4 → 24`.
    pub mlp: Mlp<T>,
    /// Input normalisation (canonical body box).
    pub norm: Normalizer<T>,
}

/// One chunk of a skinning-field forward pass.
#[derive(Clone, Debug)]
pub(super) struct SkinChunk<T> {
    rows: Range<usize>,
    enc: Vec<T>,
    pre: Vec<T>,
    pub(super) weights: Vec<T>,
}

/// What [`SkinningField::backward`] needs from the forward pass.
#[derive(Clone, Debug)]
pub struct SkinningCache<T> {
    n: usize,
    pub(super) chunks: Vec<SkinChunk<T>>,
}

impl<T: Real> SkinningCache<T> {
    /// The cache of an `n`-point pass made of `chunks` (in row order).
    pub(super) fn from_chunks(n: usize, chunks: Vec<SkinChunk<T>>) -> Self {
        Self { n, chunks }
    }

    /// The softmax weights `(N, 24)` of the forward pass (a copy).
    pub fn weights(&self) -> Vec<T> {
        let mut w = Vec::with_capacity(self.n * NUM_JOINTS);
        for c in &self.chunks {
            w.extend_from_slice(&c.weights);
        }
        w
    }
}

/// Row-wise softmax of `(rows, 24)` logits, in place.
pub(super) fn softmax_rows<T: Real>(v: &mut [T]) {
    for row in v.chunks_exact_mut(NUM_JOINTS) {
        let m = row.iter().fold(T::neg_infinity(), |a, &b| a.max(b));
        let mut s = T::zero();
        for x in row.iter_mut() {
            *x = (*x - m).exp();
            s = s + *x;
        }
        let inv = T::one() / s;
        for x in row.iter_mut() {
            *x = *x * inv;
        }
    }
}

/// Softmax backward: `∂L/∂logits = w ⊙ (g − ⟨w, g⟩)` per row, written to `d_logits`.
pub(super) fn softmax_rows_backward<T: Real>(w: &[T], g: &[T], d_logits: &mut [T]) {
    for ((w, g), d) in w
        .chunks_exact(NUM_JOINTS)
        .zip(g.chunks_exact(NUM_JOINTS))
        .zip(d_logits.chunks_exact_mut(NUM_JOINTS))
    {
        let dot: T = w.iter().zip(g).map(|(&a, &b)| a * b).sum();
        for j in 0..NUM_JOINTS {
            d[j] = w[j] * (g[j] - dot);
        }
    }
}

impl<T: Real> SkinningField<T> {
    /// A field with `hidden`-wide layers (128 in 3DGS-Avatar; see
    /// [`DEFAULT_HIDDEN`](super::DEFAULT_HIDDEN)), PyTorch init from `seed`, normalised by the
    /// canonical vertices' box.
    pub fn new(
        canonical_vertices: &[[f32; 3]],
        hidden: usize,
        seed: u64,
    ) -> Result<Self, nn::NnError> {
        let sizes = [ENC_DIM, hidden, hidden, hidden, hidden, NUM_JOINTS];
        Ok(Self {
            mlp: Mlp::new(&sizes, Activation::LeakyRelu(LEAKY_SLOPE), seed)?,
            norm: Normalizer::from_vertices(canonical_vertices),
        })
    }

    pub(super) fn check(&self) -> Result<(), nn::NnError> {
        check_mlp(&self.mlp, "skinning field", ENC_DIM, NUM_JOINTS)
    }

    /// Forward of one chunk of points (`wt`: the field's transposed weights).
    pub(super) fn chunk_forward(
        &self,
        wt: &[T],
        points: &[[T; 3]],
        rows: Range<usize>,
    ) -> SkinChunk<T> {
        let r = rows.len();
        let mut enc = vec![T::zero(); r * ENC_DIM];
        encode_rows(&self.norm, points, &mut enc);
        let mut pre = vec![T::zero(); r * batch_mlp::hidden_total(&self.mlp)];
        let mut weights = vec![T::zero(); r * NUM_JOINTS];
        batch_mlp::forward_chunk(&self.mlp, wt, &enc, r, &mut pre, &mut weights);
        softmax_rows(&mut weights);
        SkinChunk {
            rows,
            enc,
            pre,
            weights,
        }
    }

    /// Backward of one chunk: accumulates into `d_params`, writes `∂L/∂points` to `d_points`.
    pub(super) fn chunk_backward(
        &self,
        c: &SkinChunk<T>,
        d_weights: &[T],
        d_params: &mut [T],
        d_points: &mut [[T; 3]],
        buf: &mut ChunkBuffers<T>,
    ) {
        let r = c.rows.len();
        let d_logits = grow(&mut buf.d_logits, r * NUM_JOINTS);
        softmax_rows_backward(&c.weights, d_weights, d_logits);
        let d_enc = grow(&mut buf.d_enc, r * ENC_DIM);
        batch_mlp::backward_chunk(
            &self.mlp,
            &c.enc,
            &c.pre,
            r,
            d_logits,
            d_params,
            Some(d_enc),
            &mut buf.mlp,
        );
        encode_rows_backward(&self.norm, &c.enc, d_enc, d_points);
    }

    /// Weights `(N, 24)` (softmax rows) at the given canonical points. The weights depend on the
    /// points and the field only: evaluate once per parameter update and reuse them (and the cache)
    /// for every consumer, accumulating their `∂L/∂w` before one [`SkinningField::backward`].
    pub fn forward(&self, points: &[[T; 3]]) -> Result<(Vec<T>, SkinningCache<T>), nn::NnError> {
        self.check()?;
        let rows = rows_per_chunk(&self.mlp, &self.mlp);
        let wt = batch_mlp::transposed_weights(&self.mlp);
        let chunks: Vec<SkinChunk<T>> = batch_mlp::chunks(points.len(), rows)
            .into_par_iter()
            .map(|range| self.chunk_forward(&wt, &points[range.clone()], range))
            .collect();
        let cache = SkinningCache {
            n: points.len(),
            chunks,
        };
        Ok((cache.weights(), cache))
    }

    /// Backward: accumulates `∂L/∂params` into `d_params` and returns `∂L/∂points`.
    pub fn backward(
        &self,
        cache: &SkinningCache<T>,
        d_weights: &[T],
        d_params: &mut [T],
    ) -> Result<Vec<[T; 3]>, nn::NnError> {
        self.check()?;
        check_len("skinning d_weights", cache.n * NUM_JOINTS, d_weights.len())?;
        check_len("skinning d_params", self.mlp.params.len(), d_params.len())?;
        let np = self.mlp.params.len();
        let parts = batch_mlp::map_groups(cache.chunks.len(), |group| {
            let mut buf = ChunkBuffers::default();
            let mut dp = vec![T::zero(); np];
            let first = cache.chunks[group.start].rows.start;
            let last = cache.chunks[group.end - 1].rows.end;
            let mut d_points = vec![[T::zero(); 3]; last - first];
            for c in &cache.chunks[group] {
                let range = c.rows.clone();
                self.chunk_backward(
                    c,
                    &d_weights[range.start * NUM_JOINTS..range.end * NUM_JOINTS],
                    &mut dp,
                    &mut d_points[range.start - first..range.end - first],
                    &mut buf,
                );
            }
            (dp, d_points)
        });
        let mut out = Vec::with_capacity(cache.n);
        for (dp, d_points) in &parts {
            out.extend_from_slice(d_points);
            batch_mlp::sum_into(d_params, [dp]);
        }
        Ok(out)
    }
}

/// Skinning loss: mean over samples of the squared error summed over bones,
/// `L = (1/N) Σ_i Σ_b (w_ib − ŵ_ib)²`. Returns `(L, ∂L/∂w)`.
pub fn skinning_loss<T: Real>(pred: &[T], target: &[T]) -> (T, Vec<T>) {
    let n = (pred.len() / NUM_JOINTS).max(1);
    let inv = T::one() / T::of(n as f64);
    let mut loss = T::zero();
    let grad = pred
        .iter()
        .zip(target)
        .map(|(&p, &t)| {
            let d = p - t;
            loss = loss + d * d * inv;
            (d + d) * inv
        })
        .collect();
    (loss, grad)
}

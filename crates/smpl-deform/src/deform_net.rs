//! The two deformation networks of 3DGS-Avatar, on `nn::Mlp`, and the full Gaussian deformation
//! (non-rigid offsets, then linear blend skinning with learned weights) with its backward pass.
//!
//! - Input encoding: canonical xyz normalised by the canonical body's bounding box (centre, half
//!   extent × 1.1: 10% padding) to roughly [−1, 1], then a frequency encoding
//!   `[x, sin(2^k π x), cos(2^k π x)]_{k<L}` (L = [`NUM_FREQS`] = 4, 27 values). It replaces
//!   3DGS-Avatar's GPU hash grid: no table lookups, cheap on a CPU, smooth (C∞) for FD checks.
//! - Skinning field: encoding → MLP (4 hidden layers, LeakyReLU 0.01) → softmax over 24 bones
//!   (the flat softmax; the hierarchical variant is not implemented).
//! - Non-rigid network: encoding ⊕ pose code (the 207-value SMPL pose feature `R_j − I` of joints
//!   1..23) → MLP (3 hidden layers, LeakyReLU) → Δx (3), Δlog-scale (3), Δrotation (3: the vector part
//!   of a quaternion whose w is fixed to 1), feature (16). Its last layer starts at zero, so the
//!   initial deformation is the identity (as in 3DGS-Avatar).
//! - Order (3DGS-Avatar's): `x_nr = x + Δx`, `s' = s + Δs`, `q' = q ⊗ (1, Δr)` (Hamilton product),
//!   weights `w = field(x_nr)`, then LBS of `x_nr` and `q'` with the frame's bone transforms.
//! - Execution: rows are processed in fixed-size chunks (`batch_mlp`), every product a GEMM on the
//!   chunk, the whole pipeline fused per chunk and run in parallel over chunks; parameter and bone
//!   gradients are summed over a fixed number of groups in order, so results are bit-identical for
//!   any thread count. Hidden post-activations are cached for the backward pass.
//!
//! This module never reads files and knows nothing of rasterization or losses other than the
//! skinning loss.

use std::ops::Range;

use nn::mlp::{Activation, Mlp};
use nn::{gemm, Real};
use rayon::prelude::*;

use crate::batch_mlp;
use crate::math::{
    affine_apply, affine_rot, mat3_mul, mat3_mul_t, mat3_tmul, quat_to_mat3, quat_to_mat3_backward,
    Affine, Mat3,
};
use crate::skeleton::{NUM_JOINTS, NUM_POSE_FEATURES};

/// Octaves of the frequency encoding.
pub const NUM_FREQS: usize = 4;
/// Width of the position encoding (3 + 6·L).
pub const ENC_DIM: usize = 3 + 6 * NUM_FREQS;
/// Width of the non-rigid network's feature output.
pub const NR_FEATURE_DIM: usize = 16;
/// Outputs of the non-rigid network: Δx 3, Δlog-scale 3, Δrotation 3, feature 16.
pub const NR_OUT_DIM: usize = 9 + NR_FEATURE_DIM;
/// LeakyReLU slope of both networks (PyTorch's default).
pub const LEAKY_SLOPE: f64 = 0.01;
/// Hidden width the project uses for both networks: 64, half of 3DGS-Avatar's 128, because at 128
/// the two MLPs alone cost ≈ 28 GFLOP per forward + backward of 50k Gaussians, beyond the CPU
/// budget (see docs/BENCHMARKS.md, "deformation"). The constructors take any width.
pub const DEFAULT_HIDDEN: usize = 64;

/// Maps canonical positions (metres) to the box-normalised frame: `(x − centre) / half_extent`.
#[derive(Clone, Debug, PartialEq)]
pub struct Normalizer<T> {
    /// Box centre (metres).
    pub centre: [T; 3],
    /// 1 / (half extent · 1.1) per axis (1/metres).
    pub inv_half: [T; 3],
}

impl<T: Real> Normalizer<T> {
    /// The padded (10%) bounding box of `vertices` (non-empty).
    pub fn from_vertices(vertices: &[[f32; 3]]) -> Self {
        let mut lo = [f32::MAX; 3];
        let mut hi = [f32::MIN; 3];
        for v in vertices {
            for k in 0..3 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
        let centre = [0, 1, 2].map(|k| T::of(0.5 * (f64::from(lo[k]) + f64::from(hi[k]))));
        let inv_half = [0, 1, 2].map(|k| {
            let half = 0.5 * (f64::from(hi[k]) - f64::from(lo[k])) * 1.1;
            T::of(1.0 / half.max(1e-6))
        });
        Self { centre, inv_half }
    }

    fn apply(&self, x: [T; 3]) -> [T; 3] {
        [0, 1, 2].map(|k| (x[k] - self.centre[k]) * self.inv_half[k])
    }
}

/// Frequency encoding of a normalised point into `out` (length [`ENC_DIM`]):
/// `[x, sin(2^k π x), cos(2^k π x)]_{k<L}`. Only octave 0 calls `sin_cos`; higher octaves use the
/// double-angle recurrence `sin 2a = 2 sin a cos a`, `cos 2a = (cos a − sin a)(cos a + sin a)`
/// (a few ulps from the direct evaluation after L − 1 = 3 doublings).
pub fn encode<T: Real>(xn: [T; 3], out: &mut [T]) {
    out[..3].copy_from_slice(&xn);
    let pi = T::of(std::f64::consts::PI);
    for c in 0..3 {
        let (mut s, mut co) = (pi * xn[c]).sin_cos();
        for k in 0..NUM_FREQS {
            out[3 + 6 * k + c] = s;
            out[3 + 6 * k + 3 + c] = co;
            let s2 = (s + s) * co;
            co = (co - s) * (co + s);
            s = s2;
        }
    }
}

/// Backward of [`encode`]: `∂L/∂xn` from `∂L/∂encoding`.
pub fn encode_backward<T: Real>(xn: [T; 3], d_enc: &[T]) -> [T; 3] {
    let mut enc = [T::zero(); ENC_DIM];
    encode(xn, &mut enc);
    encode_backward_from(&enc, d_enc)
}

/// Backward of [`encode`] from its output `enc` (the sines and cosines it holds are the derivatives'
/// ingredients, so no trigonometry is evaluated): `∂L/∂xn` from `∂L/∂encoding`.
pub fn encode_backward_from<T: Real>(enc: &[T], d_enc: &[T]) -> [T; 3] {
    let mut g = [d_enc[0], d_enc[1], d_enc[2]];
    let mut f = T::of(std::f64::consts::PI);
    for k in 0..NUM_FREQS {
        for c in 0..3 {
            let (s, co) = (enc[3 + 6 * k + c], enc[3 + 6 * k + 3 + c]);
            g[c] = g[c] + f * (co * d_enc[3 + 6 * k + c] - s * d_enc[3 + 6 * k + 3 + c]);
        }
        f = f + f;
    }
    g
}

/// Encodes the (box-normalised) `points` into `out` (`(N, ENC_DIM)`).
fn encode_rows<T: Real>(norm: &Normalizer<T>, points: &[[T; 3]], out: &mut [T]) {
    for (p, row) in points.iter().zip(out.chunks_exact_mut(ENC_DIM)) {
        encode(norm.apply(*p), row);
    }
}

/// `∂L/∂points` (metres) of [`encode_rows`], written to `d_points`.
fn encode_rows_backward<T: Real>(
    norm: &Normalizer<T>,
    enc: &[T],
    d_enc: &[T],
    d_points: &mut [[T; 3]],
) {
    for ((d, e), de) in d_points
        .iter_mut()
        .zip(enc.chunks_exact(ENC_DIM))
        .zip(d_enc.chunks_exact(ENC_DIM))
    {
        let g = encode_backward_from(e, de);
        *d = [0, 1, 2].map(|k| g[k] * norm.inv_half[k]);
    }
}

/// Rows per chunk of the chunked passes of both networks (a function of their widths only).
fn rows_per_chunk<T: Real>(a: &Mlp<T>, b: &Mlp<T>) -> usize {
    batch_mlp::chunk_rows(batch_mlp::widest(a).max(batch_mlp::widest(b)))
}

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
struct SkinChunk<T> {
    rows: Range<usize>,
    enc: Vec<T>,
    pre: Vec<T>,
    weights: Vec<T>,
}

/// What [`SkinningField::backward`] needs from the forward pass.
#[derive(Clone, Debug)]
pub struct SkinningCache<T> {
    n: usize,
    chunks: Vec<SkinChunk<T>>,
}

impl<T: Real> SkinningCache<T> {
    /// Number of points of the forward pass.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether the forward pass had no points.
    pub fn is_empty(&self) -> bool {
        self.n == 0
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
fn softmax_rows<T: Real>(v: &mut [T]) {
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
fn softmax_rows_backward<T: Real>(w: &[T], g: &[T], d_logits: &mut [T]) {
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
    /// A field with `hidden`-wide layers (128 in 3DGS-Avatar; see [`DEFAULT_HIDDEN`]), PyTorch init
    /// from `seed`, normalised by the canonical vertices' box.
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

    fn check(&self) -> Result<(), nn::NnError> {
        check_mlp(&self.mlp, "skinning field", ENC_DIM, NUM_JOINTS)
    }

    /// Forward of one chunk of points (`wt`: the field's transposed weights).
    fn chunk_forward(&self, wt: &[T], points: &[[T; 3]], rows: Range<usize>) -> SkinChunk<T> {
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
    fn chunk_backward(
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
struct NrChunk<T> {
    enc: Vec<T>,
    pre: Vec<T>,
}

/// What [`NonRigidNet::backward`] needs from the forward pass.
#[derive(Clone, Debug)]
pub struct NonRigidCache<T: Real> {
    n: usize,
    rows: Vec<Range<usize>>,
    chunks: Vec<NrChunk<T>>,
    /// The network with the pose code folded into the first layer's bias.
    folded: Mlp<T>,
    pose_code: Vec<T>,
}

impl<T: Real> NonRigidNet<T> {
    /// A network with `hidden`-wide layers (128 in 3DGS-Avatar; see [`DEFAULT_HIDDEN`]), PyTorch
    /// init from `seed` except the last layer, which is zero (identity deformation at the start).
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

    fn check(&self, pose_code: &[T]) -> Result<(), nn::NnError> {
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
    fn chunk_forward(
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
    fn chunk_backward(
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

    /// Outputs `(N, 25)`: Δx (metres), Δlog-scale, Δrotation (quaternion vector part, w = 1), feature.
    /// `pose_code` is the 207-value pose feature of the frame.
    pub fn forward(
        &self,
        points: &[[T; 3]],
        pose_code: &[T],
    ) -> Result<(Vec<T>, NonRigidCache<T>), nn::NnError> {
        self.check(pose_code)?;
        // The pose code is the same for every point, so its share of the first layer is a bias:
        // fold it once per call (W_pose · code) and run a network whose input is the 27-value
        // position encoding only (8.7× fewer first-layer multiply-adds).
        let folded = self.fold(pose_code);
        let wt = batch_mlp::transposed_weights(&folded);
        let rows = batch_mlp::chunks(points.len(), rows_per_chunk(&folded, &folded));
        let mut out = vec![T::zero(); points.len() * NR_OUT_DIM];
        let per = rows.first().map_or(1, |r| r.len().max(1));
        let chunks: Vec<NrChunk<T>> = out
            .par_chunks_mut(per * NR_OUT_DIM)
            .zip(rows.par_iter())
            .map(|(o, range)| self.chunk_forward(&folded, &wt, &points[range.clone()], o))
            .collect();
        Ok((
            out,
            NonRigidCache {
                n: points.len(),
                rows,
                chunks,
                folded,
                pose_code: pose_code.to_vec(),
            },
        ))
    }

    fn fold(&self, pose_code: &[T]) -> Mlp<T> {
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
    fn unfold_grad(&self, pose_code: &[T], d_folded: &[T], d_params: &mut [T]) {
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

    /// Backward: accumulates `∂L/∂params` and returns `∂L/∂points` (the pose code is a constant).
    pub fn backward(
        &self,
        cache: &NonRigidCache<T>,
        d_out: &[T],
        d_params: &mut [T],
    ) -> Result<Vec<[T; 3]>, nn::NnError> {
        self.check(&cache.pose_code)?;
        check_len("non-rigid d_out", cache.n * NR_OUT_DIM, d_out.len())?;
        check_len("non-rigid d_params", self.mlp.params.len(), d_params.len())?;
        let nf = cache.folded.params.len();
        let parts = batch_mlp::map_groups(cache.chunks.len(), |group| {
            let mut buf = ChunkBuffers::default();
            let mut dp = vec![T::zero(); nf];
            let first = cache.rows[group.start].start;
            let last = cache.rows[group.end - 1].end;
            let mut d_points = vec![[T::zero(); 3]; last - first];
            for ci in group {
                let range = cache.rows[ci].clone();
                self.chunk_backward(
                    &cache.folded,
                    &cache.chunks[ci],
                    &d_out[range.start * NR_OUT_DIM..range.end * NR_OUT_DIM],
                    &mut dp,
                    &mut d_points[range.start - first..range.end - first],
                    &mut buf,
                );
            }
            (dp, d_points)
        });
        let mut d_folded = vec![T::zero(); nf];
        let mut out = Vec::with_capacity(cache.n);
        for (dp, d_points) in &parts {
            out.extend_from_slice(d_points);
            batch_mlp::sum_into(&mut d_folded, [dp]);
        }
        self.unfold_grad(&cache.pose_code, &d_folded, d_params);
        Ok(out)
    }
}

/// Hamilton product `a ⊗ b` of `(w, x, y, z)` quaternions.
pub fn quat_mul<T: Real>(a: [T; 4], b: [T; 4]) -> [T; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

fn conj<T: Real>(q: [T; 4]) -> [T; 4] {
    [q[0], -q[1], -q[2], -q[3]]
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

/// Human Gaussians in canonical space (inputs of [`deform_gaussians`]).
#[derive(Clone, Debug)]
pub struct CanonicalGaussians<'a, T> {
    /// Positions (metres).
    pub positions: &'a [[T; 3]],
    /// Log-scales (natural log of metres).
    pub log_scales: &'a [[T; 3]],
    /// Rotations `(w, x, y, z)`, unnormalised.
    pub quats: &'a [[T; 4]],
}

/// Posed Gaussians (outputs of [`deform_gaussians`]).
#[derive(Clone, Debug)]
pub struct PosedGaussians<T> {
    /// Posed positions (metres).
    pub positions: Vec<[T; 3]>,
    /// Posed log-scales (canonical + Δ).
    pub log_scales: Vec<[T; 3]>,
    /// Posed rotation-times-frame matrices `M` (covariance `M diag(exp 2s) Mᵀ`).
    pub mats: Vec<Mat3<T>>,
    /// Non-rigid features `(N, 16)`.
    pub features: Vec<T>,
}

/// One chunk of a deformation forward pass.
#[derive(Clone, Debug)]
struct DeformChunk<T> {
    rows: Range<usize>,
    nr: NrChunk<T>,
    nr_out: Vec<T>,
    skin: SkinChunk<T>,
    x_nr: Vec<[T; 3]>,
    q_nr: Vec<[T; 4]>,
    /// Blended transforms `Σ_b w_b T_b`, `(rows, 12)`.
    blended: Vec<T>,
}

/// Everything the backward pass needs.
#[derive(Clone, Debug)]
pub struct DeformCache<T: Real> {
    n: usize,
    folded: Mlp<T>,
    pose_code: Vec<T>,
    quats: Vec<[T; 4]>,
    chunks: Vec<DeformChunk<T>>,
}

impl<T: Real> DeformCache<T> {
    /// Whether every non-rigid position offset Δx was exactly zero (e.g. before the non-rigid
    /// network is switched on, its last layer being zero): then the skinning weights of the forward
    /// pass ([`DeformCache::skinning_weights`]) are the field at the canonical positions themselves,
    /// and a consumer of those can reuse them, passing its `∂L/∂w` to
    /// [`deform_gaussians_backward_with_weights`] instead of running the field again.
    pub fn nonrigid_offsets_are_zero(&self) -> bool {
        self.chunks.iter().all(|c| {
            c.nr_out
                .chunks_exact(NR_OUT_DIM)
                .all(|o| o[..3].iter().all(|&d| d == T::zero()))
        })
    }

    /// The skinning weights `(N, 24)` the forward pass used (the field at the non-rigidly moved
    /// positions), a copy.
    pub fn skinning_weights(&self) -> Vec<T> {
        let mut w = Vec::with_capacity(self.n * NUM_JOINTS);
        for c in &self.chunks {
            w.extend_from_slice(&c.skin.weights);
        }
        w
    }
}

/// The 24 bone transforms as a `(24, 12)` row-major matrix.
fn bones_matrix<T: Real>(bones: &[Affine<T>]) -> Vec<T> {
    bones.iter().flatten().copied().collect()
}

/// Deforms canonical Gaussians into a frame: non-rigid net, learned skinning weights at the
/// non-rigidly moved positions, LBS with `frame_from_canonical` bone transforms (24).
///
/// Runs in chunks of rows (every product a GEMM on the chunk, rayon over chunks); the result does
/// not depend on the thread count.
pub fn deform_gaussians<T: Real>(
    nonrigid: &NonRigidNet<T>,
    field: &SkinningField<T>,
    g: &CanonicalGaussians<'_, T>,
    pose_code: &[T],
    bones: &[Affine<T>],
) -> Result<(PosedGaussians<T>, DeformCache<T>), nn::NnError> {
    let n = g.positions.len();
    nonrigid.check(pose_code)?;
    field.check()?;
    check_len("deform log_scales", n, g.log_scales.len())?;
    check_len("deform quats", n, g.quats.len())?;
    check_len("deform bones", NUM_JOINTS, bones.len())?;
    let folded = nonrigid.fold(pose_code);
    let (nr_wt, field_wt) = (
        batch_mlp::transposed_weights(&folded),
        batch_mlp::transposed_weights(&field.mlp),
    );
    let bm = bones_matrix(bones);
    let rows = rows_per_chunk(&folded, &field.mlp);
    let mut positions = vec![[T::zero(); 3]; n];
    let mut log_scales = vec![[T::zero(); 3]; n];
    let mut mats = vec![[T::zero(); 9]; n];
    let mut features = vec![T::zero(); n * NR_FEATURE_DIM];
    let ranges = batch_mlp::chunks(n, rows);
    let chunks: Vec<DeformChunk<T>> = positions
        .par_chunks_mut(rows)
        .zip(log_scales.par_chunks_mut(rows))
        .zip(mats.par_chunks_mut(rows))
        .zip(features.par_chunks_mut(rows * NR_FEATURE_DIM))
        .zip(ranges.par_iter())
        .map(|((((pos, ls), ms), feat), range)| {
            let r = range.len();
            let x = &g.positions[range.clone()];
            let mut nr_out = vec![T::zero(); r * NR_OUT_DIM];
            let nr = nonrigid.chunk_forward(&folded, &nr_wt, x, &mut nr_out);
            let mut x_nr = Vec::with_capacity(r);
            let mut q_nr = Vec::with_capacity(r);
            for (k, o) in nr_out.chunks_exact(NR_OUT_DIM).enumerate() {
                let i = range.start + k;
                x_nr.push([0, 1, 2].map(|a| x[k][a] + o[a]));
                ls[k] = [0, 1, 2].map(|a| g.log_scales[i][a] + o[3 + a]);
                q_nr.push(quat_mul(g.quats[i], [T::one(), o[6], o[7], o[8]]));
                feat[k * NR_FEATURE_DIM..(k + 1) * NR_FEATURE_DIM].copy_from_slice(&o[9..]);
            }
            let skin = field.chunk_forward(&field_wt, &x_nr, range.clone());
            // Blended transforms (rows × 12) = weights (rows × 24) · bones (24 × 12).
            let mut blended = vec![T::zero(); r * 12];
            gemm(
                r,
                NUM_JOINTS,
                12,
                T::one(),
                &skin.weights,
                false,
                &bm,
                false,
                T::zero(),
                &mut blended,
            );
            for k in 0..r {
                let t: &Affine<T> = blended[12 * k..12 * k + 12]
                    .try_into()
                    .expect("12 values per blended transform");
                pos[k] = affine_apply(t, x_nr[k]);
                ms[k] = mat3_mul(&affine_rot(t), &quat_to_mat3(q_nr[k]));
            }
            DeformChunk {
                rows: range.clone(),
                nr,
                nr_out,
                skin,
                x_nr,
                q_nr,
                blended,
            }
        })
        .collect();
    Ok((
        PosedGaussians {
            positions,
            log_scales,
            mats,
            features,
        },
        DeformCache {
            n,
            folded,
            pose_code: pose_code.to_vec(),
            quats: g.quats.to_vec(),
            chunks,
        },
    ))
}

/// Gradients of [`deform_gaussians`].
#[derive(Clone, Debug)]
pub struct DeformGrad<T> {
    /// ∂L/∂canonical positions.
    pub positions: Vec<[T; 3]>,
    /// ∂L/∂canonical log-scales.
    pub log_scales: Vec<[T; 3]>,
    /// ∂L/∂canonical quaternions.
    pub quats: Vec<[T; 4]>,
    /// ∂L/∂bone transforms (summed in a fixed order).
    pub bones: Vec<Affine<T>>,
}

/// Per-group partial results of the deformation backward pass.
struct GroupGrad<T> {
    d_folded: Vec<T>,
    d_field: Vec<T>,
    d_bones: Vec<T>,
    d_x: Vec<[T; 3]>,
    d_q: Vec<[T; 4]>,
}

/// Backward of [`deform_gaussians`] from the gradients of its outputs (`d_features` `(N, 16)`).
/// Accumulates network parameter gradients into `d_nonrigid` and `d_field`.
///
/// Chunks are grouped into a fixed number of groups; each group sums its chunks' parameter and
/// bone gradients in order, and the groups are summed in order (bit-identical for any thread count).
#[allow(clippy::too_many_arguments)]
pub fn deform_gaussians_backward<T: Real>(
    nonrigid: &NonRigidNet<T>,
    field: &SkinningField<T>,
    bones: &[Affine<T>],
    cache: &DeformCache<T>,
    d_positions: &[[T; 3]],
    d_log_scales: &[[T; 3]],
    d_mats: &[Mat3<T>],
    d_features: &[T],
    d_nonrigid: &mut [T],
    d_field: &mut [T],
) -> Result<DeformGrad<T>, nn::NnError> {
    deform_backward_impl(
        nonrigid,
        field,
        bones,
        cache,
        d_positions,
        d_log_scales,
        d_mats,
        d_features,
        None,
        d_nonrigid,
        d_field,
    )
}

/// [`deform_gaussians_backward`] with an extra cotangent `d_weights` `(N, 24)` on the skinning
/// weights of the forward pass ([`DeformCache::skinning_weights`]), for a consumer that reuses those
/// weights instead of evaluating the field again (see [`DeformCache::nonrigid_offsets_are_zero`]).
/// Equal to [`deform_gaussians_backward`] plus a [`SkinningField::backward`] of `d_weights` at the
/// non-rigidly moved positions `x + Δx`, at the cost of one field backward instead of two. When
/// Δx ≡ 0 because the non-rigid net's last layer is zero, the position, field and bone gradients
/// equal those of a consumer evaluating the field at the canonical positions; the non-rigid
/// gradient additionally holds the effect of Δx on the reused weights (last layer, Δx rows only).
#[allow(clippy::too_many_arguments)]
pub fn deform_gaussians_backward_with_weights<T: Real>(
    nonrigid: &NonRigidNet<T>,
    field: &SkinningField<T>,
    bones: &[Affine<T>],
    cache: &DeformCache<T>,
    d_positions: &[[T; 3]],
    d_log_scales: &[[T; 3]],
    d_mats: &[Mat3<T>],
    d_features: &[T],
    d_weights: &[T],
    d_nonrigid: &mut [T],
    d_field: &mut [T],
) -> Result<DeformGrad<T>, nn::NnError> {
    check_len("deform d_weights", cache.n * NUM_JOINTS, d_weights.len())?;
    deform_backward_impl(
        nonrigid,
        field,
        bones,
        cache,
        d_positions,
        d_log_scales,
        d_mats,
        d_features,
        Some(d_weights),
        d_nonrigid,
        d_field,
    )
}

#[allow(clippy::too_many_arguments)]
fn deform_backward_impl<T: Real>(
    nonrigid: &NonRigidNet<T>,
    field: &SkinningField<T>,
    bones: &[Affine<T>],
    cache: &DeformCache<T>,
    d_positions: &[[T; 3]],
    d_log_scales: &[[T; 3]],
    d_mats: &[Mat3<T>],
    d_features: &[T],
    d_weights_extra: Option<&[T]>,
    d_nonrigid: &mut [T],
    d_field: &mut [T],
) -> Result<DeformGrad<T>, nn::NnError> {
    let n = cache.n;
    nonrigid.check(&cache.pose_code)?;
    field.check()?;
    check_len("deform bones", NUM_JOINTS, bones.len())?;
    check_len("deform d_positions", n, d_positions.len())?;
    check_len("deform d_log_scales", n, d_log_scales.len())?;
    check_len("deform d_mats", n, d_mats.len())?;
    check_len("deform d_features", n * NR_FEATURE_DIM, d_features.len())?;
    check_len(
        "deform d_nonrigid",
        nonrigid.mlp.params.len(),
        d_nonrigid.len(),
    )?;
    check_len("deform d_field", field.mlp.params.len(), d_field.len())?;
    let bm = bones_matrix(bones);
    let (nf, ns) = (cache.folded.params.len(), field.mlp.params.len());
    let parts = batch_mlp::map_groups(cache.chunks.len(), |group| {
        let mut buf = ChunkBuffers::default();
        let first = cache.chunks[group.start].rows.start;
        let last = cache.chunks[group.end - 1].rows.end;
        let mut out = GroupGrad {
            d_folded: vec![T::zero(); nf],
            d_field: vec![T::zero(); ns],
            d_bones: vec![T::zero(); NUM_JOINTS * 12],
            d_x: vec![[T::zero(); 3]; last - first],
            d_q: vec![[T::zero(); 4]; last - first],
        };
        for c in &cache.chunks[group] {
            let r = c.rows.len();
            let off = c.rows.start - first;
            let d_x = &mut out.d_x[off..off + r];
            let d_q = &mut out.d_q[off..off + r];
            // LBS backward: ∂L/∂T per row (rows × 12), ∂L/∂x_nr, ∂L/∂q_nr.
            let d_t = grow(&mut buf.d_t, r * 12);
            for k in 0..r {
                let i = c.rows.start + k;
                let t: &Affine<T> = c.blended[12 * k..12 * k + 12]
                    .try_into()
                    .expect("12 values per blended transform");
                let (x, dp) = (c.x_nr[k], d_positions[i]);
                let rq = quat_to_mat3(c.q_nr[k]);
                let a = affine_rot(t);
                // M = A R(q): ∂L/∂A = dM R(q)ᵀ, ∂L/∂R(q) = Aᵀ dM.
                let d_a = mat3_mul_t(&d_mats[i], &rq);
                let dt = &mut d_t[12 * k..12 * k + 12];
                for row in 0..3 {
                    for col in 0..3 {
                        dt[4 * row + col] = dp[row] * x[col] + d_a[3 * row + col];
                    }
                    dt[4 * row + 3] = dp[row];
                }
                d_x[k] = [
                    a[0] * dp[0] + a[3] * dp[1] + a[6] * dp[2],
                    a[1] * dp[0] + a[4] * dp[1] + a[7] * dp[2],
                    a[2] * dp[0] + a[5] * dp[1] + a[8] * dp[2],
                ];
                d_q[k] = quat_to_mat3_backward(c.q_nr[k], &mat3_tmul(&a, &d_mats[i]));
            }
            // ∂L/∂w (rows × 24) = ∂L/∂T · bonesᵀ; ∂L/∂bones (24 × 12) += wᵀ · ∂L/∂T.
            let d_w = grow(&mut buf.d_w, r * NUM_JOINTS);
            gemm(
                r,
                12,
                NUM_JOINTS,
                T::one(),
                d_t,
                false,
                &bm,
                true,
                T::zero(),
                d_w,
            );
            if let Some(extra) = d_weights_extra {
                let e = &extra[c.rows.start * NUM_JOINTS..c.rows.end * NUM_JOINTS];
                for (d, &x) in d_w.iter_mut().zip(e) {
                    *d = *d + x;
                }
            }
            gemm(
                NUM_JOINTS,
                r,
                12,
                T::one(),
                &c.skin.weights,
                true,
                d_t,
                false,
                T::one(),
                &mut out.d_bones,
            );
            // Skinning field at x_nr.
            let mut d_x_field = std::mem::take(&mut buf.d_x_field);
            let d_w_owned = std::mem::take(&mut buf.d_w);
            let mut d_nr_out = std::mem::take(&mut buf.d_nr_out);
            grow(&mut d_x_field, r);
            field.chunk_backward(
                &c.skin,
                &d_w_owned[..r * NUM_JOINTS],
                &mut out.d_field,
                &mut d_x_field[..r],
                &mut buf,
            );
            // Non-rigid outputs: Δx gets ∂L/∂x_nr, Δs gets ∂L/∂s, Δr from q_nr = q ⊗ r
            // (∂L/∂q = dq ⊗ r*, ∂L/∂r = q* ⊗ dq), feature gets its cotangent.
            grow(&mut d_nr_out, r * NR_OUT_DIM);
            for k in 0..r {
                let i = c.rows.start + k;
                let o = &c.nr_out[k * NR_OUT_DIM..(k + 1) * NR_OUT_DIM];
                let dxn = [0, 1, 2].map(|a| d_x[k][a] + d_x_field[k][a]);
                let d = &mut d_nr_out[k * NR_OUT_DIM..(k + 1) * NR_OUT_DIM];
                d[..3].copy_from_slice(&dxn);
                d[3..6].copy_from_slice(&d_log_scales[i]);
                let rr = [T::one(), o[6], o[7], o[8]];
                let dqn = d_q[k];
                d_q[k] = quat_mul(dqn, conj(rr));
                let dr = quat_mul(conj(cache.quats[i]), dqn);
                d[6..9].copy_from_slice(&dr[1..]);
                d[9..].copy_from_slice(&d_features[i * NR_FEATURE_DIM..(i + 1) * NR_FEATURE_DIM]);
                d_x[k] = dxn;
            }
            // The field's point gradient is consumed: reuse its buffer for the non-rigid one.
            nonrigid.chunk_backward(
                &cache.folded,
                &c.nr,
                &d_nr_out[..r * NR_OUT_DIM],
                &mut out.d_folded,
                &mut d_x_field[..r],
                &mut buf,
            );
            for k in 0..r {
                for a in 0..3 {
                    d_x[k][a] = d_x[k][a] + d_x_field[k][a];
                }
            }
            buf.d_w = d_w_owned;
            buf.d_nr_out = d_nr_out;
            buf.d_x_field = d_x_field;
        }
        out
    });
    let mut d_folded = vec![T::zero(); nf];
    let mut d_bones_flat = vec![T::zero(); NUM_JOINTS * 12];
    let mut positions = Vec::with_capacity(n);
    let mut quats = Vec::with_capacity(n);
    for p in &parts {
        batch_mlp::sum_into(&mut d_folded, [&p.d_folded]);
        batch_mlp::sum_into(d_field, [&p.d_field]);
        batch_mlp::sum_into(&mut d_bones_flat, [&p.d_bones]);
        positions.extend_from_slice(&p.d_x);
        quats.extend_from_slice(&p.d_q);
    }
    nonrigid.unfold_grad(&cache.pose_code, &d_folded, d_nonrigid);
    let bones_grad = d_bones_flat
        .chunks_exact(12)
        .map(|c| c.try_into().expect("12 values per bone"))
        .collect();
    Ok(DeformGrad {
        positions,
        log_scales: d_log_scales.to_vec(),
        quats,
        bones: bones_grad,
    })
}

#[cfg(test)]
mod tests {
    //! The chunked, fused passes against a slow oracle built from the unfused pieces (`nn::Mlp` on
    //! the full, unfolded input; per-point LBS kernels of `crate::lbs`), on a batch that spans
    //! several chunks and gradient groups; and bit-identity across thread counts.

    use super::*;
    use crate::lbs::{lbs_gaussians, lbs_gaussians_backward};

    const N: usize = 1500;

    fn lcg(seed: u64, n: usize) -> Vec<f64> {
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
            })
            .collect()
    }

    struct Case {
        nonrigid: NonRigidNet<f64>,
        field: SkinningField<f64>,
        x: Vec<[f64; 3]>,
        s: Vec<[f64; 3]>,
        q: Vec<[f64; 4]>,
        code: Vec<f64>,
        bones: Vec<Affine<f64>>,
        cot: Vec<f64>,
    }

    fn case() -> Case {
        let verts = [[-0.8f32, -1.0, -0.2], [0.8, 0.8, 0.3]];
        let mut nonrigid = NonRigidNet::<f64>::new(&verts, 16, 3).expect("net");
        let noise = lcg(9, nonrigid.mlp.params.len());
        for (p, r) in nonrigid.mlp.params.iter_mut().zip(&noise) {
            if *p == 0.0 {
                *p = 0.1 * r;
            }
        }
        let field = SkinningField::<f64>::new(&verts, 16, 4).expect("field");
        let v = lcg(5, N * 10);
        let bones = (0..NUM_JOINTS)
            .map(|b| {
                let r = lcg(100 + b as u64, 12);
                let mut a = [0.0; 12];
                for k in 0..12 {
                    a[k] = if k % 5 == 0 { 1.0 } else { 0.0 } + 0.2 * r[k];
                }
                a
            })
            .collect();
        Case {
            nonrigid,
            field,
            x: (0..N)
                .map(|i| [0.7 * v[10 * i], 0.9 * v[10 * i + 1], 0.2 * v[10 * i + 2]])
                .collect(),
            s: (0..N).map(|i| [v[10 * i + 3] - 4.0; 3]).collect(),
            q: (0..N)
                .map(|i| [1.0, v[10 * i + 7], v[10 * i + 8], v[10 * i + 9]])
                .collect(),
            code: lcg(7, NUM_POSE_FEATURES).iter().map(|x| 0.3 * x).collect(),
            bones,
            cot: lcg(11, N * (15 + NR_FEATURE_DIM)),
        }
    }

    fn rows<const K: usize>(v: &[f64], off: usize) -> Vec<[f64; K]> {
        let stride = 15 + NR_FEATURE_DIM;
        (0..N)
            .map(|i| std::array::from_fn(|k| v[i * stride + off + k]))
            .collect()
    }

    fn close(what: &str, a: &[f64], b: &[f64]) {
        assert_eq!(a.len(), b.len(), "{what}: lengths");
        let scale = b.iter().fold(1e-12f64, |m, v| m.max(v.abs()));
        let worst = a
            .iter()
            .zip(b)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        assert!(
            worst <= 1e-10 * scale,
            "{what}: max abs diff {worst:e} (scale {scale:e})"
        );
    }

    #[test]
    fn chunked_passes_match_the_unfused_oracle() {
        let c = case();
        assert!(N > 4 * rows_per_chunk(&c.nonrigid.mlp, &c.field.mlp));
        let g = CanonicalGaussians {
            positions: &c.x,
            log_scales: &c.s,
            quats: &c.q,
        };
        let (out, cache) =
            deform_gaussians(&c.nonrigid, &c.field, &g, &c.code, &c.bones).expect("fwd");
        let (d_pos, d_s, d_m) = (
            rows::<3>(&c.cot, 0),
            rows::<3>(&c.cot, 3),
            rows::<9>(&c.cot, 6),
        );
        let d_f: Vec<f64> = (0..N)
            .flat_map(|i| {
                let o = i * (15 + NR_FEATURE_DIM) + 15;
                c.cot[o..o + NR_FEATURE_DIM].to_vec()
            })
            .collect();
        let mut d_nr = vec![0.0; c.nonrigid.mlp.params.len()];
        let mut d_sf = vec![0.0; c.field.mlp.params.len()];
        let grad = deform_gaussians_backward(
            &c.nonrigid,
            &c.field,
            &c.bones,
            &cache,
            &d_pos,
            &d_s,
            &d_m,
            &d_f,
            &mut d_nr,
            &mut d_sf,
        )
        .expect("bwd");

        // Oracle forward.
        let full_in = ENC_DIM + NUM_POSE_FEATURES;
        let mut input = vec![0.0; N * full_in];
        for i in 0..N {
            encode(
                c.nonrigid.norm.apply(c.x[i]),
                &mut input[i * full_in..i * full_in + ENC_DIM],
            );
            input[i * full_in + ENC_DIM..(i + 1) * full_in].copy_from_slice(&c.code);
        }
        let (nr_out, nr_cache) = c.nonrigid.mlp.forward(&input, N).expect("nr");
        let x_nr: Vec<[f64; 3]> = (0..N)
            .map(|i| [0, 1, 2].map(|k| c.x[i][k] + nr_out[i * NR_OUT_DIM + k]))
            .collect();
        let q_nr: Vec<[f64; 4]> = (0..N)
            .map(|i| {
                let o = &nr_out[i * NR_OUT_DIM..];
                quat_mul(c.q[i], [1.0, o[6], o[7], o[8]])
            })
            .collect();
        let mut enc = vec![0.0; N * ENC_DIM];
        for i in 0..N {
            encode(
                c.field.norm.apply(x_nr[i]),
                &mut enc[i * ENC_DIM..(i + 1) * ENC_DIM],
            );
        }
        let (mut w, sf_cache) = c.field.mlp.forward(&enc, N).expect("sf");
        softmax_rows(&mut w);
        let (pos, mats) = lbs_gaussians(&w, &c.bones, &x_nr, &q_nr);
        close("positions", &out.positions.concat(), &pos.concat());
        close("mats", &out.mats.concat(), &mats.concat());
        let feats: Vec<f64> = (0..N)
            .flat_map(|i| nr_out[i * NR_OUT_DIM + 9..(i + 1) * NR_OUT_DIM].to_vec())
            .collect();
        close("features", &out.features, &feats);

        // Oracle backward.
        let lbs = lbs_gaussians_backward(&w, &c.bones, &x_nr, &q_nr, &d_pos, &d_m);
        let mut d_logits = vec![0.0; N * NUM_JOINTS];
        softmax_rows_backward(&w, &lbs.weights, &mut d_logits);
        let mut d_sf_ref = vec![0.0; d_sf.len()];
        let mut d_enc = vec![0.0; N * ENC_DIM];
        c.field
            .mlp
            .backward(&sf_cache, &d_logits, &mut d_sf_ref, Some(&mut d_enc))
            .expect("sf bwd");
        let mut d_nr_out = vec![0.0; N * NR_OUT_DIM];
        let mut d_x_ref = vec![[0.0; 3]; N];
        let mut d_q_ref = vec![[0.0; 4]; N];
        for i in 0..N {
            let gx = encode_backward(c.field.norm.apply(x_nr[i]), &d_enc[i * ENC_DIM..]);
            let dxn = [0, 1, 2].map(|k| lbs.positions[i][k] + gx[k] * c.field.norm.inv_half[k]);
            let o = &nr_out[i * NR_OUT_DIM..];
            let r = [1.0, o[6], o[7], o[8]];
            d_q_ref[i] = quat_mul(lbs.quats[i], conj(r));
            let dr = quat_mul(conj(c.q[i]), lbs.quats[i]);
            let d = &mut d_nr_out[i * NR_OUT_DIM..(i + 1) * NR_OUT_DIM];
            d[..3].copy_from_slice(&dxn);
            d[3..6].copy_from_slice(&d_s[i]);
            d[6..9].copy_from_slice(&dr[1..]);
            d[9..].copy_from_slice(&d_f[i * NR_FEATURE_DIM..(i + 1) * NR_FEATURE_DIM]);
            d_x_ref[i] = dxn;
        }
        let mut d_nr_ref = vec![0.0; d_nr.len()];
        let mut d_in = vec![0.0; N * full_in];
        c.nonrigid
            .mlp
            .backward(&nr_cache, &d_nr_out, &mut d_nr_ref, Some(&mut d_in))
            .expect("nr bwd");
        for i in 0..N {
            let gx = encode_backward(c.nonrigid.norm.apply(c.x[i]), &d_in[i * full_in..]);
            for k in 0..3 {
                d_x_ref[i][k] += gx[k] * c.nonrigid.norm.inv_half[k];
            }
        }
        close("d positions", &grad.positions.concat(), &d_x_ref.concat());
        close("d quats", &grad.quats.concat(), &d_q_ref.concat());
        close("d bones", &grad.bones.concat(), &lbs.bones.concat());
        close("d nonrigid params", &d_nr, &d_nr_ref);
        close("d field params", &d_sf, &d_sf_ref);

        // The standalone field passes agree with the fused ones.
        let (w2, sc) = c.field.forward(&x_nr).expect("field fwd");
        close("field weights", &w2, &w);
        close("cached weights", &cache.skinning_weights(), &w);
        let mut d_sf2 = vec![0.0; d_sf.len()];
        let d_x2 = c
            .field
            .backward(&sc, &lbs.weights, &mut d_sf2)
            .expect("field bwd");
        close("field d params", &d_sf2, &d_sf_ref);
        let gx: Vec<f64> = (0..N)
            .flat_map(|i| {
                let g = encode_backward(c.field.norm.apply(x_nr[i]), &d_enc[i * ENC_DIM..]);
                [0, 1, 2].map(|k| g[k] * c.field.norm.inv_half[k])
            })
            .collect();
        close("field d points", &d_x2.concat(), &gx);
    }

    fn run_f32(threads: usize) -> (Vec<u32>, Vec<u32>, Vec<u32>) {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            let verts = [[-0.8f32, -1.0, -0.2], [0.8, 0.8, 0.3]];
            let mut nonrigid = NonRigidNet::<f32>::new(&verts, 32, 1).expect("net");
            for (k, p) in nonrigid.mlp.params.iter_mut().enumerate() {
                if *p == 0.0 {
                    *p = 0.01 * ((k % 7) as f32 - 3.0);
                }
            }
            let field = SkinningField::<f32>::new(&verts, 32, 2).expect("field");
            let v = lcg(3, 5000 * 3);
            let x: Vec<[f32; 3]> = v
                .chunks(3)
                .map(|c| [c[0] as f32, c[1] as f32, 0.2 * c[2] as f32])
                .collect();
            let s = vec![[-4.0f32; 3]; x.len()];
            let q = vec![[1.0f32, 0.1, 0.0, 0.0]; x.len()];
            let code = vec![0.05f32; NUM_POSE_FEATURES];
            let bones =
                vec![[1.0f32, 0.0, 0.0, 0.1, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]; NUM_JOINTS];
            let g = CanonicalGaussians {
                positions: &x,
                log_scales: &s,
                quats: &q,
            };
            let (out, cache) = deform_gaussians(&nonrigid, &field, &g, &code, &bones).expect("fwd");
            let n = x.len();
            let mut d_nr = vec![0.0f32; nonrigid.mlp.params.len()];
            let mut d_sf = vec![0.0f32; field.mlp.params.len()];
            let grad = deform_gaussians_backward(
                &nonrigid,
                &field,
                &bones,
                &cache,
                &out.positions,
                &vec![[0.5f32; 3]; n],
                &out.mats,
                &vec![0.25f32; n * NR_FEATURE_DIM],
                &mut d_nr,
                &mut d_sf,
            )
            .expect("bwd");
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<u32>>();
            let mut params = bits(&d_nr);
            params.extend(bits(&d_sf));
            params.extend(bits(&grad.bones.concat()));
            (
                bits(&out.positions.concat()),
                bits(&grad.positions.concat()),
                params,
            )
        })
    }

    #[test]
    fn results_are_bit_identical_for_any_thread_count() {
        let one = run_f32(1);
        assert_eq!(one, run_f32(2));
        assert_eq!(one, run_f32(3));
    }

    #[test]
    fn reused_weights_backward_equals_two_separate_backwards() {
        // Identity non-rigid net (zero last layer): the deformation's weights are the field at the
        // canonical positions, and one backward with the extra weight cotangent equals the plain
        // backward plus a separate field backward.
        let mut c = case();
        let last = NR_OUT_DIM * (c.nonrigid.mlp.sizes[3] + 1);
        let np = c.nonrigid.mlp.params.len();
        for p in &mut c.nonrigid.mlp.params[np - last..] {
            *p = 0.0;
        }
        let g = CanonicalGaussians {
            positions: &c.x,
            log_scales: &c.s,
            quats: &c.q,
        };
        let (_, cache) =
            deform_gaussians(&c.nonrigid, &c.field, &g, &c.code, &c.bones).expect("fwd");
        assert!(cache.nonrigid_offsets_are_zero());
        let (w, sc) = c.field.forward(&c.x).expect("field");
        close("weights at canonical", &cache.skinning_weights(), &w);
        let (d_pos, d_s, d_m) = (
            rows::<3>(&c.cot, 0),
            rows::<3>(&c.cot, 3),
            rows::<9>(&c.cot, 6),
        );
        let d_f = vec![0.3; N * NR_FEATURE_DIM];
        let d_w: Vec<f64> = lcg(77, N * NUM_JOINTS);
        let (mut a_nr, mut a_sf) = (
            vec![0.0; c.nonrigid.mlp.params.len()],
            vec![0.0; c.field.mlp.params.len()],
        );
        let a = deform_gaussians_backward_with_weights(
            &c.nonrigid,
            &c.field,
            &c.bones,
            &cache,
            &d_pos,
            &d_s,
            &d_m,
            &d_f,
            &d_w,
            &mut a_nr,
            &mut a_sf,
        )
        .expect("bwd with weights");
        let (mut b_nr, mut b_sf) = (
            a_nr.iter().map(|_| 0.0).collect::<Vec<f64>>(),
            a_sf.iter().map(|_| 0.0).collect::<Vec<f64>>(),
        );
        let b = deform_gaussians_backward(
            &c.nonrigid,
            &c.field,
            &c.bones,
            &cache,
            &d_pos,
            &d_s,
            &d_m,
            &d_f,
            &mut b_nr,
            &mut b_sf,
        )
        .expect("bwd");
        let extra = c.field.backward(&sc, &d_w, &mut b_sf).expect("field bwd");
        let b_pos: Vec<f64> = b
            .positions
            .iter()
            .zip(&extra)
            .flat_map(|(p, e)| [0, 1, 2].map(|k| p[k] + e[k]))
            .collect();
        close("d positions", &a.positions.concat(), &b_pos);
        close("d field", &a_sf, &b_sf);
        close("d bones", &a.bones.concat(), &b.bones.concat());
        // The non-rigid gradient differs only where Δx enters the reused weights: the last layer's
        // Δx rows (outputs 0..3, weights and biases); every earlier layer sees a zero last layer.
        let h = c.nonrigid.mlp.sizes[3];
        let off = np - last;
        let dx_rows = |k: usize| {
            let k = k - off;
            (k < NR_OUT_DIM * h && k / h < 3) || (k >= NR_OUT_DIM * h && k - NR_OUT_DIM * h < 3)
        };
        let same: Vec<usize> = (0..np).filter(|&k| k < off || !dx_rows(k)).collect();
        close(
            "d nonrigid outside the Δx rows",
            &same.iter().map(|&k| a_nr[k]).collect::<Vec<_>>(),
            &same.iter().map(|&k| b_nr[k]).collect::<Vec<_>>(),
        );
        assert!((off..np)
            .filter(|&k| dx_rows(k))
            .any(|k| a_nr[k] != b_nr[k]));
        // A non-identity net moves the points: the weights are no longer the canonical ones.
        let c2 = case();
        let (_, cache2) =
            deform_gaussians(&c2.nonrigid, &c2.field, &g, &c2.code, &c2.bones).expect("fwd");
        assert!(!cache2.nonrigid_offsets_are_zero());
    }
}

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
//!
//! This module never reads files and knows nothing of rasterization or losses other than the
//! skinning loss.

use nn::mlp::{Activation, Mlp, MlpCache};
use nn::Real;

use crate::lbs::{lbs_gaussians, lbs_gaussians_backward};
use crate::math::{Affine, Mat3};
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

/// Frequency encoding of a normalised point into `out` (length [`ENC_DIM`]).
pub fn encode<T: Real>(xn: [T; 3], out: &mut [T]) {
    out[..3].copy_from_slice(&xn);
    let mut f = T::of(std::f64::consts::PI);
    for k in 0..NUM_FREQS {
        for c in 0..3 {
            let (s, co) = (f * xn[c]).sin_cos();
            out[3 + 6 * k + c] = s;
            out[3 + 6 * k + 3 + c] = co;
        }
        f = f + f;
    }
}

/// Backward of [`encode`]: `∂L/∂xn` from `∂L/∂encoding`.
pub fn encode_backward<T: Real>(xn: [T; 3], d_enc: &[T]) -> [T; 3] {
    let mut g = [d_enc[0], d_enc[1], d_enc[2]];
    let mut f = T::of(std::f64::consts::PI);
    for k in 0..NUM_FREQS {
        for c in 0..3 {
            let (s, co) = (f * xn[c]).sin_cos();
            g[c] = g[c] + f * (co * d_enc[3 + 6 * k + c] - s * d_enc[3 + 6 * k + 3 + c]);
        }
        f = f + f;
    }
    g
}

/// Encodes N points (box-normalised) into `(N, ENC_DIM)` rows of width `row` starting at column 0.
fn encode_points<T: Real>(norm: &Normalizer<T>, points: &[[T; 3]], row: usize) -> Vec<T> {
    let mut out = vec![T::zero(); points.len() * row];
    for (i, p) in points.iter().enumerate() {
        encode(norm.apply(*p), &mut out[i * row..i * row + ENC_DIM]);
    }
    out
}

fn encode_points_backward<T: Real>(
    norm: &Normalizer<T>,
    points: &[[T; 3]],
    d_input: &[T],
    row: usize,
) -> Vec<[T; 3]> {
    points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let g = encode_backward(norm.apply(*p), &d_input[i * row..i * row + ENC_DIM]);
            [0, 1, 2].map(|k| g[k] * norm.inv_half[k])
        })
        .collect()
}

/// The learned skinning field: canonical position → weights over the 24 bones.
#[derive(Clone, Debug)]
pub struct SkinningField<T: Real> {
    /// The MLP `ENC_DIM → hidden × 4 → 24`.
    pub mlp: Mlp<T>,
    /// Input normalisation (canonical body box).
    pub norm: Normalizer<T>,
}

/// What [`SkinningField::backward`] needs from the forward pass.
#[derive(Clone, Debug)]
pub struct SkinningCache<T> {
    points: Vec<[T; 3]>,
    mlp: MlpCache<T>,
    weights: Vec<T>,
}

impl<T: Real> SkinningField<T> {
    /// A field with `hidden`-wide layers (128 in 3DGS-Avatar), PyTorch init from `seed`, normalised
    /// by the canonical vertices' box.
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

    /// Weights `(N, 24)` (softmax rows) at the given canonical points.
    pub fn forward(&self, points: &[[T; 3]]) -> Result<(Vec<T>, SkinningCache<T>), nn::NnError> {
        let input = encode_points(&self.norm, points, ENC_DIM);
        let (logits, mlp) = self.mlp.forward(&input, points.len())?;
        let mut weights = logits;
        for row in weights.chunks_exact_mut(NUM_JOINTS) {
            let m = row.iter().fold(T::neg_infinity(), |a, &b| a.max(b));
            let mut s = T::zero();
            for v in row.iter_mut() {
                *v = (*v - m).exp();
                s = s + *v;
            }
            for v in row.iter_mut() {
                *v = *v / s;
            }
        }
        Ok((
            weights.clone(),
            SkinningCache {
                points: points.to_vec(),
                mlp,
                weights,
            },
        ))
    }

    /// Backward: accumulates `∂L/∂params` into `d_params` and returns `∂L/∂points`.
    pub fn backward(
        &self,
        cache: &SkinningCache<T>,
        d_weights: &[T],
        d_params: &mut [T],
    ) -> Result<Vec<[T; 3]>, nn::NnError> {
        let n = cache.points.len();
        let mut d_logits = vec![T::zero(); n * NUM_JOINTS];
        for i in 0..n {
            let w = &cache.weights[i * NUM_JOINTS..(i + 1) * NUM_JOINTS];
            let g = &d_weights[i * NUM_JOINTS..(i + 1) * NUM_JOINTS];
            let dot: T = w.iter().zip(g).map(|(&a, &b)| a * b).sum();
            for j in 0..NUM_JOINTS {
                d_logits[i * NUM_JOINTS + j] = w[j] * (g[j] - dot);
            }
        }
        let mut d_input = vec![T::zero(); n * ENC_DIM];
        self.mlp
            .backward(&cache.mlp, &d_logits, d_params, Some(&mut d_input))?;
        Ok(encode_points_backward(
            &self.norm,
            &cache.points,
            &d_input,
            ENC_DIM,
        ))
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

/// The pose-conditioned non-rigid deformation network.
#[derive(Clone, Debug)]
pub struct NonRigidNet<T: Real> {
    /// The MLP `ENC_DIM + 207 → hidden × 3 → 25`.
    pub mlp: Mlp<T>,
    /// Input normalisation (canonical body box).
    pub norm: Normalizer<T>,
}

/// What [`NonRigidNet::backward`] needs from the forward pass.
#[derive(Clone, Debug)]
pub struct NonRigidCache<T: Real> {
    points: Vec<[T; 3]>,
    mlp: MlpCache<T>,
    /// The network with the pose code folded into the first layer's bias.
    folded: Mlp<T>,
    pose_code: Vec<T>,
}

impl<T: Real> NonRigidNet<T> {
    /// A network with `hidden`-wide layers (128 in 3DGS-Avatar), PyTorch init from `seed` except the
    /// last layer, which is zero (identity deformation at the start).
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

    /// Outputs `(N, 25)`: Δx (metres), Δlog-scale, Δrotation (quaternion vector part, w = 1), feature.
    /// `pose_code` is the 207-value pose feature of the frame.
    pub fn forward(
        &self,
        points: &[[T; 3]],
        pose_code: &[T],
    ) -> Result<(Vec<T>, NonRigidCache<T>), nn::NnError> {
        if pose_code.len() != NUM_POSE_FEATURES {
            return Err(nn::NnError::Length {
                name: "non-rigid pose code",
                expected: NUM_POSE_FEATURES,
                actual: pose_code.len(),
            });
        }
        // The pose code is the same for every point, so its share of the first layer is a bias:
        // fold it once per call (W_pose · code) and run a network whose input is the 27-value
        // position encoding only (8.7× fewer first-layer multiply-adds).
        let folded = self.fold(pose_code);
        let input = encode_points(&self.norm, points, ENC_DIM);
        let (out, mlp) = folded.forward(&input, points.len())?;
        Ok((
            out,
            NonRigidCache {
                points: points.to_vec(),
                mlp,
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

    /// Backward: accumulates `∂L/∂params` and returns `∂L/∂points` (the pose code is a constant).
    pub fn backward(
        &self,
        cache: &NonRigidCache<T>,
        d_out: &[T],
        d_params: &mut [T],
    ) -> Result<Vec<[T; 3]>, nn::NnError> {
        let full_in = ENC_DIM + NUM_POSE_FEATURES;
        let h = self.mlp.sizes[1];
        if d_params.len() != self.mlp.params.len() {
            return Err(nn::NnError::Length {
                name: "non-rigid d_params",
                expected: self.mlp.params.len(),
                actual: d_params.len(),
            });
        }
        let mut d_folded = vec![T::zero(); cache.folded.params.len()];
        let mut d_input = vec![T::zero(); cache.points.len() * ENC_DIM];
        cache
            .folded
            .backward(&cache.mlp, d_out, &mut d_folded, Some(&mut d_input))?;
        // Unfold: first-layer position columns and bias map back directly; the pose columns get
        // ∂L/∂bias ⊗ code; later layers are identical.
        for r in 0..h {
            let db = d_folded[h * ENC_DIM + r];
            for c in 0..ENC_DIM {
                d_params[r * full_in + c] = d_params[r * full_in + c] + d_folded[r * ENC_DIM + c];
            }
            for (c, &code) in cache.pose_code.iter().enumerate() {
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
        Ok(encode_points_backward(
            &self.norm,
            &cache.points,
            &d_input,
            ENC_DIM,
        ))
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

/// Everything the backward pass needs.
#[derive(Clone, Debug)]
pub struct DeformCache<T: Real> {
    nr: NonRigidCache<T>,
    nr_out: Vec<T>,
    skin: SkinningCache<T>,
    x_nr: Vec<[T; 3]>,
    q_nr: Vec<[T; 4]>,
    quats: Vec<[T; 4]>,
    weights: Vec<T>,
}

/// Deforms canonical Gaussians into a frame: non-rigid net, learned skinning weights at the
/// non-rigidly moved positions, LBS with `frame_from_canonical` bone transforms.
pub fn deform_gaussians<T: Real>(
    nonrigid: &NonRigidNet<T>,
    field: &SkinningField<T>,
    g: &CanonicalGaussians<'_, T>,
    pose_code: &[T],
    bones: &[Affine<T>],
) -> Result<(PosedGaussians<T>, DeformCache<T>), nn::NnError> {
    let n = g.positions.len();
    let (nr_out, nr) = nonrigid.forward(g.positions, pose_code)?;
    let mut x_nr = Vec::with_capacity(n);
    let mut s = Vec::with_capacity(n);
    let mut q_nr = Vec::with_capacity(n);
    let mut features = Vec::with_capacity(n * NR_FEATURE_DIM);
    for i in 0..n {
        let o = &nr_out[i * NR_OUT_DIM..(i + 1) * NR_OUT_DIM];
        x_nr.push([0, 1, 2].map(|k| g.positions[i][k] + o[k]));
        s.push([0, 1, 2].map(|k| g.log_scales[i][k] + o[3 + k]));
        q_nr.push(quat_mul(g.quats[i], [T::one(), o[6], o[7], o[8]]));
        features.extend_from_slice(&o[9..]);
    }
    let (weights, skin) = field.forward(&x_nr)?;
    let (positions, mats) = lbs_gaussians(&weights, bones, &x_nr, &q_nr);
    Ok((
        PosedGaussians {
            positions,
            log_scales: s,
            mats,
            features,
        },
        DeformCache {
            nr,
            nr_out,
            skin,
            x_nr,
            q_nr,
            quats: g.quats.to_vec(),
            weights,
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

/// Backward of [`deform_gaussians`] from the gradients of its outputs (`d_features` `(N, 16)`).
/// Accumulates network parameter gradients into `d_nonrigid` and `d_field`.
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
    let n = cache.x_nr.len();
    let lbs = lbs_gaussians_backward(
        &cache.weights,
        bones,
        &cache.x_nr,
        &cache.q_nr,
        d_positions,
        d_mats,
    );
    let d_x_from_field = field.backward(&cache.skin, &lbs.weights, d_field)?;
    let mut d_nr_out = vec![T::zero(); n * NR_OUT_DIM];
    let mut d_x = Vec::with_capacity(n);
    let mut d_q = Vec::with_capacity(n);
    for i in 0..n {
        let o = &cache.nr_out[i * NR_OUT_DIM..(i + 1) * NR_OUT_DIM];
        let dxn = [0, 1, 2].map(|k| lbs.positions[i][k] + d_x_from_field[i][k]);
        let d = &mut d_nr_out[i * NR_OUT_DIM..(i + 1) * NR_OUT_DIM];
        d[..3].copy_from_slice(&dxn);
        d[3..6].copy_from_slice(&d_log_scales[i]);
        // q_nr = q ⊗ r with r = (1, o6, o7, o8): ∂L/∂q = dq ⊗ r*, ∂L/∂r = q* ⊗ dq.
        let r = [T::one(), o[6], o[7], o[8]];
        let dqn = lbs.quats[i];
        d_q.push(quat_mul(dqn, conj(r)));
        let dr = quat_mul(conj(cache.quats[i]), dqn);
        d[6..9].copy_from_slice(&dr[1..]);
        d[9..].copy_from_slice(&d_features[i * NR_FEATURE_DIM..(i + 1) * NR_FEATURE_DIM]);
        d_x.push(dxn);
    }
    let d_x_from_nr = nonrigid.backward(&cache.nr, &d_nr_out, d_nonrigid)?;
    for i in 0..n {
        for k in 0..3 {
            d_x[i][k] = d_x[i][k] + d_x_from_nr[i][k];
        }
    }
    Ok(DeformGrad {
        positions: d_x,
        log_scales: d_log_scales.to_vec(),
        quats: d_q,
        bones: lbs.bones,
    })
}

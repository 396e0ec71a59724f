//! Linear blend skinning of points and of Gaussian rotations, with analytic backward passes w.r.t.
//! the canonical position / rotation, the blend weights and the bone transforms.
//!
//! A point blends the bone transforms first: `T = Σ_b w_b T_b`, `x' = R_T x + t_T` (weights are not
//! renormalised here: the caller's softmax or body model guarantees Σ w = 1). A Gaussian's rotation
//! becomes the 3×3 matrix `M = R_T · R(q)` (as in 3DGS-Avatar's `rotation_precomp`); `M` is not
//! orthonormal in general, and the posed covariance is `M S² Mᵀ`. These kernels never renormalise,
//! clamp or allocate; batch wrappers run per point in parallel with rayon (deterministic: no
//! reductions across points).

use num_traits::Float;
use rayon::prelude::*;

use crate::math::{
    affine_apply, affine_rot, lit, mat3_mul, mat3_mul_t, mat3_tmul, quat_to_mat3,
    quat_to_mat3_backward, Affine, Mat3,
};

/// Blended transform `Σ_b w_b T_b` (3×4, row-major).
#[inline]
pub fn blend_transforms<T: Float>(weights: &[T], bones: &[Affine<T>]) -> Affine<T> {
    let mut out = [T::zero(); 12];
    for (w, b) in weights.iter().zip(bones) {
        if *w != T::zero() {
            for k in 0..12 {
                out[k] = out[k] + *w * b[k];
            }
        }
    }
    out
}

/// Skins one canonical point: `x' = (Σ_b w_b T_b) x`.
#[inline]
pub fn lbs_point<T: Float>(weights: &[T], bones: &[Affine<T>], x: [T; 3]) -> [T; 3] {
    affine_apply(&blend_transforms(weights, bones), x)
}

/// Backward of [`lbs_point`]. Accumulates `∂L/∂w` into `d_weights` and `∂L/∂T_b` into `d_bones`
/// (both added to, not overwritten) and returns `∂L/∂x`.
pub fn lbs_point_backward<T: Float>(
    weights: &[T],
    bones: &[Affine<T>],
    x: [T; 3],
    d_out: [T; 3],
    d_weights: &mut [T],
    d_bones: &mut [Affine<T>],
) -> [T; 3] {
    let blended = blend_transforms(weights, bones);
    // ∂L/∂T (3×4) = d_out ⊗ [x, 1].
    let mut d_t = [T::zero(); 12];
    for row in 0..3 {
        d_t[4 * row] = d_out[row] * x[0];
        d_t[4 * row + 1] = d_out[row] * x[1];
        d_t[4 * row + 2] = d_out[row] * x[2];
        d_t[4 * row + 3] = d_out[row];
    }
    for b in 0..bones.len() {
        let mut dw = T::zero();
        for k in 0..12 {
            dw = dw + d_t[k] * bones[b][k];
            d_bones[b][k] = d_bones[b][k] + weights[b] * d_t[k];
        }
        d_weights[b] = d_weights[b] + dw;
    }
    let r = affine_rot(&blended);
    [
        r[0] * d_out[0] + r[3] * d_out[1] + r[6] * d_out[2],
        r[1] * d_out[0] + r[4] * d_out[1] + r[7] * d_out[2],
        r[2] * d_out[0] + r[5] * d_out[1] + r[8] * d_out[2],
    ]
}

/// Skins a Gaussian rotation: `M = (Σ_b w_b R_b) · R(q)` with `q = (w, x, y, z)` unnormalised.
#[inline]
pub fn lbs_rotation<T: Float>(weights: &[T], bones: &[Affine<T>], q: [T; 4]) -> Mat3<T> {
    let blended = blend_transforms(weights, bones);
    mat3_mul(&affine_rot(&blended), &quat_to_mat3(q))
}

/// Backward of [`lbs_rotation`]. Accumulates into `d_weights` and `d_bones` (rotation blocks only;
/// translations do not affect `M`) and returns `∂L/∂q`.
pub fn lbs_rotation_backward<T: Float>(
    weights: &[T],
    bones: &[Affine<T>],
    q: [T; 4],
    d_m: &Mat3<T>,
    d_weights: &mut [T],
    d_bones: &mut [Affine<T>],
) -> [T; 4] {
    let rq = quat_to_mat3(q);
    let a = affine_rot(&blend_transforms(weights, bones));
    // M = A Rq: ∂L/∂A = dM Rqᵀ, ∂L/∂Rq = Aᵀ dM.
    let d_a = mat3_mul_t(d_m, &rq);
    let d_rq = mat3_tmul(&a, d_m);
    for b in 0..bones.len() {
        let rb = affine_rot(&bones[b]);
        let mut dw = T::zero();
        for row in 0..3 {
            for col in 0..3 {
                let g = d_a[3 * row + col];
                dw = dw + g * rb[3 * row + col];
                d_bones[b][4 * row + col] = d_bones[b][4 * row + col] + weights[b] * g;
            }
        }
        d_weights[b] = d_weights[b] + dw;
    }
    quat_to_mat3_backward(q, &d_rq)
}

/// Skins many points in parallel. `weights` is row-major `(N, B)` with `B = bones.len()`.
///
/// # Panics
/// If `weights.len() != points.len() · bones.len()`.
pub fn lbs_points<T: Float + Send + Sync>(
    weights: &[T],
    bones: &[Affine<T>],
    points: &[[T; 3]],
) -> Vec<[T; 3]> {
    let nb = bones.len();
    assert_eq!(weights.len(), points.len() * nb, "weights must be (N, B)");
    points
        .par_iter()
        .enumerate()
        .map(|(i, &x)| lbs_point(&weights[i * nb..(i + 1) * nb], bones, x))
        .collect()
}

/// Skins a body mesh in displacement form, `x' = x + Σ_b w_b ((R_b − I) x + t_b)`, which equals
/// [`lbs_point`] when the weights sum to 1 and returns `x` bit for bit when every bone is `[I | 0]`.
pub fn lbs_vertices_exact_rest(
    weights: &[f32],
    bones: &[Affine<f32>],
    points: &[[f32; 3]],
) -> Vec<[f32; 3]> {
    let nb = bones.len();
    assert_eq!(weights.len(), points.len() * nb, "weights must be (N, B)");
    let one = lit::<f32>(1.0);
    points
        .par_iter()
        .enumerate()
        .map(|(i, &x)| {
            let w = &weights[i * nb..(i + 1) * nb];
            let mut d = [0.0f32; 3];
            for (b, bone) in bones.iter().enumerate() {
                if w[b] == 0.0 {
                    continue;
                }
                for row in 0..3 {
                    let r0 = bone[4 * row] - if row == 0 { one } else { 0.0 };
                    let r1 = bone[4 * row + 1] - if row == 1 { one } else { 0.0 };
                    let r2 = bone[4 * row + 2] - if row == 2 { one } else { 0.0 };
                    d[row] += w[b] * (r0 * x[0] + r1 * x[1] + r2 * x[2] + bone[4 * row + 3]);
                }
            }
            [x[0] + d[0], x[1] + d[1], x[2] + d[2]]
        })
        .collect()
}

/// Points per parallel chunk in the batch backward; fixed so reductions do not depend on the thread
/// count.
pub const LBS_CHUNK: usize = 1024;

/// Skins Gaussians: positions `x' = T x` and rotation matrices `M = R_T R(q)` for each of N Gaussians
/// (`weights` row-major `(N, B)`, `quats` `(w, x, y, z)` unnormalised). Returns `(positions, mats)`.
pub fn lbs_gaussians<T: Float + Send + Sync>(
    weights: &[T],
    bones: &[Affine<T>],
    positions: &[[T; 3]],
    quats: &[[T; 4]],
) -> (Vec<[T; 3]>, Vec<Mat3<T>>) {
    let nb = bones.len();
    assert_eq!(
        weights.len(),
        positions.len() * nb,
        "weights must be (N, B)"
    );
    assert_eq!(quats.len(), positions.len(), "one quaternion per Gaussian");
    positions
        .par_iter()
        .zip(quats.par_iter())
        .enumerate()
        .map(|(i, (&x, &q))| {
            let w = &weights[i * nb..(i + 1) * nb];
            let t = blend_transforms(w, bones);
            (
                affine_apply(&t, x),
                mat3_mul(&affine_rot(&t), &quat_to_mat3(q)),
            )
        })
        .unzip()
}

/// Gradients of [`lbs_gaussians`].
#[derive(Clone, Debug)]
pub struct LbsGaussiansGrad<T> {
    /// ∂L/∂positions (canonical), `(N, 3)`.
    pub positions: Vec<[T; 3]>,
    /// ∂L/∂quats, `(N, 4)`.
    pub quats: Vec<[T; 4]>,
    /// ∂L/∂weights, row-major `(N, B)`.
    pub weights: Vec<T>,
    /// ∂L/∂bones, summed over Gaussians in a fixed order (chunks of [`LBS_CHUNK`], then chunk sums
    /// in order): bit-identical for any thread count.
    pub bones: Vec<Affine<T>>,
}

/// Backward of [`lbs_gaussians`] from `∂L/∂positions` and `∂L/∂mats`.
pub fn lbs_gaussians_backward<T: Float + Send + Sync>(
    weights: &[T],
    bones: &[Affine<T>],
    positions: &[[T; 3]],
    quats: &[[T; 4]],
    d_positions: &[[T; 3]],
    d_mats: &[Mat3<T>],
) -> LbsGaussiansGrad<T> {
    let n = positions.len();
    let nb = bones.len();
    assert_eq!(weights.len(), n * nb, "weights must be (N, B)");
    let mut g_pos = vec![[T::zero(); 3]; n];
    let mut g_q = vec![[T::zero(); 4]; n];
    let mut g_w = vec![T::zero(); n * nb];
    let chunk_bones: Vec<Vec<Affine<T>>> = g_pos
        .par_chunks_mut(LBS_CHUNK)
        .zip(g_q.par_chunks_mut(LBS_CHUNK))
        .zip(g_w.par_chunks_mut(LBS_CHUNK * nb))
        .enumerate()
        .map(|(c, ((gp, gq), gw))| {
            let mut db = vec![[T::zero(); 12]; nb];
            for k in 0..gp.len() {
                let i = c * LBS_CHUNK + k;
                let w = &weights[i * nb..(i + 1) * nb];
                let dw = &mut gw[k * nb..(k + 1) * nb];
                gp[k] = lbs_point_backward(w, bones, positions[i], d_positions[i], dw, &mut db);
                gq[k] = lbs_rotation_backward(w, bones, quats[i], &d_mats[i], dw, &mut db);
            }
            db
        })
        .collect();
    let mut g_b = vec![[T::zero(); 12]; nb];
    for db in chunk_bones {
        for b in 0..nb {
            for k in 0..12 {
                g_b[b][k] = g_b[b][k] + db[b][k];
            }
        }
    }
    LbsGaussiansGrad {
        positions: g_pos,
        quats: g_q,
        weights: g_w,
        bones: g_b,
    }
}

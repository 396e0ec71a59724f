//! Linear blend skinning as a stage of its own: the chunk kernels [`deform_gaussians`] runs after
//! its networks, and re-posing a finished deformation at other bones without evaluating either
//! network again ([`DeformCache::repose`]).
//!
//! Re-posing is what an exposure model needs: the S sub-exposure poses of one frame differ only in
//! their bones, so the non-rigid offsets (evaluated at the frame's pose code) and the skinning
//! weights (at the moved positions) are computed once and each sub-exposure pose costs one
//! `(rows × 24) · (24 × 12)` GEMM per chunk. Its backward returns the cotangents of the moved
//! Gaussians ([`MovedCotangents`]); summed over the re-posings, they enter the deformation's one
//! backward through [`deform_gaussians_backward_with_moved`](super::deform_gaussians_backward_with_moved).
//!
//! Chunks and gradient groups are those of the deformation, so every result is bit-identical for
//! any thread count.

use nn::{gemm, Real};
use rayon::prelude::*;

use super::check_len;
use super::deform::DeformCache;
use crate::batch_mlp;
use crate::math::{
    affine_apply, affine_rot, mat3_mul, mat3_mul_t, mat3_tmul, quat_to_mat3, quat_to_mat3_backward,
    Affine, Mat3,
};
use crate::skeleton::NUM_JOINTS;

/// The 24 bone transforms as a `(24, 12)` row-major matrix.
pub(super) fn bones_matrix<T: Real>(bones: &[Affine<T>]) -> Vec<T> {
    bones.iter().flatten().copied().collect()
}

/// LBS of one chunk: blended transforms `Σ_b w_b T_b` `(rows, 12)` = `weights (rows, 24) · bm
/// (24, 12)`, then the posed positions `T x_nr` into `positions` and `M = A R(q_nr)` into `mats`.
/// Returns the blended transforms (the backward needs them).
pub(super) fn lbs_chunk<T: Real>(
    weights: &[T],
    bm: &[T],
    x_nr: &[[T; 3]],
    q_nr: &[[T; 4]],
    positions: &mut [[T; 3]],
    mats: &mut [Mat3<T>],
) -> Vec<T> {
    let r = x_nr.len();
    let mut blended = vec![T::zero(); r * 12];
    gemm(
        r,
        NUM_JOINTS,
        12,
        T::one(),
        weights,
        false,
        bm,
        false,
        T::zero(),
        &mut blended,
    );
    for k in 0..r {
        let t: &Affine<T> = blended[12 * k..12 * k + 12]
            .try_into()
            .expect("12 values per blended transform");
        positions[k] = affine_apply(t, x_nr[k]);
        mats[k] = mat3_mul(&affine_rot(t), &quat_to_mat3(q_nr[k]));
    }
    blended
}

/// Per-row backward of [`lbs_chunk`]: `d_t` `(rows, 12)` gets ∂L/∂(blended transform), `d_x`
/// ∂L/∂x_nr and `d_q` ∂L/∂q_nr, from the posed-position and matrix cotangents of the chunk's rows.
#[allow(clippy::too_many_arguments)]
pub(super) fn lbs_chunk_backward_rows<T: Real>(
    blended: &[T],
    x_nr: &[[T; 3]],
    q_nr: &[[T; 4]],
    d_positions: &[[T; 3]],
    d_mats: &[Mat3<T>],
    d_t: &mut [T],
    d_x: &mut [[T; 3]],
    d_q: &mut [[T; 4]],
) {
    for k in 0..x_nr.len() {
        let t: &Affine<T> = blended[12 * k..12 * k + 12]
            .try_into()
            .expect("12 values per blended transform");
        let (x, dp) = (x_nr[k], d_positions[k]);
        let rq = quat_to_mat3(q_nr[k]);
        let a = affine_rot(t);
        // M = A R(q): ∂L/∂A = dM R(q)ᵀ, ∂L/∂R(q) = Aᵀ dM.
        let d_a = mat3_mul_t(&d_mats[k], &rq);
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
        d_q[k] = quat_to_mat3_backward(q_nr[k], &mat3_tmul(&a, &d_mats[k]));
    }
}

/// The blend's backward of one chunk of `r` rows: `d_w (r, 24) = d_t · bmᵀ` (overwritten) and
/// `d_bones (24, 12) += weightsᵀ · d_t`.
pub(super) fn lbs_chunk_backward_blend<T: Real>(
    r: usize,
    d_t: &[T],
    bm: &[T],
    weights: &[T],
    d_w: &mut [T],
    d_bones: &mut [T],
) {
    gemm(
        r,
        12,
        NUM_JOINTS,
        T::one(),
        d_t,
        false,
        bm,
        true,
        T::zero(),
        d_w,
    );
    gemm(
        NUM_JOINTS,
        r,
        12,
        T::one(),
        weights,
        true,
        d_t,
        false,
        T::one(),
        d_bones,
    );
}

/// A deformation re-posed at other bones (outputs of [`DeformCache::repose`]); the log-scales and
/// non-rigid features are the deformation's own.
#[derive(Clone, Debug)]
pub struct Reposed<T> {
    /// Posed positions (metres).
    pub positions: Vec<[T; 3]>,
    /// Posed rotation-times-frame matrices `M` (covariance `M diag(exp 2s) Mᵀ`).
    pub mats: Vec<Mat3<T>>,
}

/// What [`DeformCache::repose_backward`] needs: the blended transforms, chunk by chunk.
#[derive(Clone, Debug)]
pub struct ReposeCache<T> {
    blended: Vec<Vec<T>>,
}

/// Cotangents of the moved Gaussians — the inputs of LBS: moved positions `x_nr = x + Δx`, rotated
/// quaternions `q_nr = q ⊗ (1, Δr)` and skinning weights `(N, 24)`.
#[derive(Clone, Debug, PartialEq)]
pub struct MovedCotangents<T> {
    /// ∂L/∂x_nr.
    pub positions: Vec<[T; 3]>,
    /// ∂L/∂q_nr.
    pub quats: Vec<[T; 4]>,
    /// ∂L/∂weights, `(N, 24)` row-major.
    pub weights: Vec<T>,
}

impl<T: Real> MovedCotangents<T> {
    /// Zero cotangents of `n` Gaussians.
    pub fn zeros(n: usize) -> Self {
        Self {
            positions: vec![[T::zero(); 3]; n],
            quats: vec![[T::zero(); 4]; n],
            weights: vec![T::zero(); n * NUM_JOINTS],
        }
    }

    /// Adds `other` element by element.
    pub fn add(&mut self, other: &Self) {
        let add = |a: &mut [T], b: &[T]| a.iter_mut().zip(b).for_each(|(x, &y)| *x = *x + y);
        add(
            self.positions.as_flattened_mut(),
            other.positions.as_flattened(),
        );
        add(self.quats.as_flattened_mut(), other.quats.as_flattened());
        add(&mut self.weights, &other.weights);
    }

    pub(super) fn check(&self, n: usize) -> Result<(), nn::NnError> {
        check_len("moved cotangent positions", n, self.positions.len())?;
        check_len("moved cotangent quats", n, self.quats.len())?;
        check_len(
            "moved cotangent weights",
            n * NUM_JOINTS,
            self.weights.len(),
        )
    }
}

impl<T: Real> DeformCache<T> {
    /// The same moved Gaussians posed with other `frame_from_canonical` bones (24): LBS only, with
    /// the non-rigid offsets and skinning weights of the pass that made this cache. With the bones
    /// of that pass, the result is bit for bit its positions and matrices.
    pub fn repose(&self, bones: &[Affine<T>]) -> Result<(Reposed<T>, ReposeCache<T>), nn::NnError> {
        check_len("repose bones", NUM_JOINTS, bones.len())?;
        let bm = bones_matrix(bones);
        let n = self.len();
        let mut positions = vec![[T::zero(); 3]; n];
        let mut mats = vec![[T::zero(); 9]; n];
        let mut pos_rest = positions.as_mut_slice();
        let mut mat_rest = mats.as_mut_slice();
        let mut jobs = Vec::with_capacity(self.chunks().len());
        for (chunk, skin) in self.chunks().iter().zip(&self.skinning().chunks) {
            let (p, rest) = pos_rest.split_at_mut(chunk.rows.len());
            let (m, mrest) = mat_rest.split_at_mut(chunk.rows.len());
            pos_rest = rest;
            mat_rest = mrest;
            jobs.push((chunk, skin, p, m));
        }
        let blended = jobs
            .into_par_iter()
            .map(|(chunk, skin, p, m)| {
                lbs_chunk(&skin.weights, &bm, &chunk.x_nr, &chunk.q_nr, p, m)
            })
            .collect();
        Ok((Reposed { positions, mats }, ReposeCache { blended }))
    }

    /// Backward of [`DeformCache::repose`]: the moved Gaussians' cotangents and ∂L/∂bones (summed
    /// over the fixed gradient groups in order).
    pub fn repose_backward(
        &self,
        bones: &[Affine<T>],
        cache: &ReposeCache<T>,
        d_positions: &[[T; 3]],
        d_mats: &[Mat3<T>],
    ) -> Result<(MovedCotangents<T>, Vec<Affine<T>>), nn::NnError> {
        let n = self.len();
        check_len("repose bones", NUM_JOINTS, bones.len())?;
        check_len("repose d_positions", n, d_positions.len())?;
        check_len("repose d_mats", n, d_mats.len())?;
        check_len("repose cache", self.chunks().len(), cache.blended.len())?;
        let bm = bones_matrix(bones);
        let chunks = self.chunks();
        let skin = &self.skinning().chunks;
        let parts = batch_mlp::map_groups(chunks.len(), |group| {
            let first = chunks[group.start].rows.start;
            let last = chunks[group.end - 1].rows.end;
            let mut moved = MovedCotangents::zeros(last - first);
            let mut d_bones = vec![T::zero(); NUM_JOINTS * 12];
            let mut d_t = Vec::new();
            for c in group {
                let rows = chunks[c].rows.clone();
                let (r, off) = (rows.len(), rows.start - first);
                d_t.resize(r * 12, T::zero());
                lbs_chunk_backward_rows(
                    &cache.blended[c],
                    &chunks[c].x_nr,
                    &chunks[c].q_nr,
                    &d_positions[rows.clone()],
                    &d_mats[rows],
                    &mut d_t,
                    &mut moved.positions[off..off + r],
                    &mut moved.quats[off..off + r],
                );
                lbs_chunk_backward_blend(
                    r,
                    &d_t,
                    &bm,
                    &skin[c].weights,
                    &mut moved.weights[off * NUM_JOINTS..(off + r) * NUM_JOINTS],
                    &mut d_bones,
                );
            }
            (moved, d_bones)
        });
        let mut moved = MovedCotangents {
            positions: Vec::with_capacity(n),
            quats: Vec::with_capacity(n),
            weights: Vec::with_capacity(n * NUM_JOINTS),
        };
        let mut d_bones_flat = vec![T::zero(); NUM_JOINTS * 12];
        for (part, d_bones) in &parts {
            moved.positions.extend_from_slice(&part.positions);
            moved.quats.extend_from_slice(&part.quats);
            moved.weights.extend_from_slice(&part.weights);
            batch_mlp::sum_into(&mut d_bones_flat, [d_bones]);
        }
        let d_bones = d_bones_flat
            .chunks_exact(12)
            .map(|c| c.try_into().expect("12 values per bone"))
            .collect();
        Ok((moved, d_bones))
    }
}

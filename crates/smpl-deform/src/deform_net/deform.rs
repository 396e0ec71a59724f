//! The fused Gaussian deformation: non-rigid offsets, skinning weights at the moved positions and
//! linear blend skinning with the frame's bones, run chunk by chunk with both networks' chunk passes
//! inline, and its backward pass. Knows the order of the operations, not the networks' insides.

use std::ops::Range;

use nn::mlp::Mlp;
use nn::Real;
use rayon::prelude::*;

use super::nonrigid::{NonRigidNet, NrChunk, NR_FEATURE_DIM, NR_OUT_DIM};
use super::repose::{
    bones_matrix, lbs_chunk, lbs_chunk_backward_blend, lbs_chunk_backward_rows, MovedCotangents,
};
use super::skinning::{SkinChunk, SkinningCache, SkinningField};
use super::{check_len, grow, rows_per_chunk, ChunkBuffers};
use crate::batch_mlp;
use crate::math::{Affine, Mat3};
use crate::skeleton::NUM_JOINTS;

/// Hamilton product `a ⊗ b` of `(w, x, y, z)` quaternions.
pub fn quat_mul<T: Real>(a: [T; 4], b: [T; 4]) -> [T; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// Quaternion conjugate `(w, −x, −y, −z)`.
pub(super) fn conj<T: Real>(q: [T; 4]) -> [T; 4] {
    [q[0], -q[1], -q[2], -q[3]]
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
pub(super) struct DeformChunk<T> {
    pub(super) rows: Range<usize>,
    nr: NrChunk<T>,
    nr_out: Vec<T>,
    pub(super) x_nr: Vec<[T; 3]>,
    pub(super) q_nr: Vec<[T; 4]>,
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
    /// The skinning field's pass at the moved positions, chunk for chunk with `chunks`.
    skinning: SkinningCache<T>,
    /// Whether those chunks are the ones [`SkinningField::forward`] cuts for the same points.
    skinning_chunks_are_standalone: bool,
}

impl<T: Real> DeformCache<T> {
    /// Number of deformed Gaussians.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether no Gaussian was deformed.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    pub(super) fn chunks(&self) -> &[DeformChunk<T>] {
        &self.chunks
    }

    /// The skinning field's pass of this deformation, at the non-rigidly moved positions `x + Δx`:
    /// its weights `(N, 24)` are [`SkinningCache::weights`], and [`SkinningField::backward`] takes it.
    pub fn skinning(&self) -> &SkinningCache<T> {
        &self.skinning
    }

    /// [`DeformCache::skinning`] if it is bit for bit what [`SkinningField::forward`] of the same
    /// field returns at `points`, else `None`. That holds when every moved position `x + Δx` equals
    /// its `points` row bit for bit (the non-rigid offsets are zero, as before the non-rigid network
    /// is switched on, and `points` are the canonical positions) and the pass was cut into the same
    /// chunks (it is unless the non-rigid network's hidden layers are wider than every layer of the
    /// field). A consumer that needs the field at `points` can then reuse this pass, forward and
    /// backward, instead of evaluating the field a second time, with identical results.
    pub fn skinning_at(&self, points: &[[T; 3]]) -> Option<&SkinningCache<T>> {
        let same_bits = |a: T, b: T| a == b && a.is_sign_negative() == b.is_sign_negative();
        let moved_are_points = points.len() == self.n
            && self.chunks.iter().all(|c| {
                c.x_nr
                    .iter()
                    .zip(&points[c.rows.clone()])
                    .all(|(x, p)| (0..3).all(|a| same_bits(x[a], p[a])))
            });
        (self.skinning_chunks_are_standalone && moved_are_points).then_some(&self.skinning)
    }
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
    let (chunks, skin_chunks): (Vec<DeformChunk<T>>, Vec<SkinChunk<T>>) = positions
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
            let blended = lbs_chunk(&skin.weights, &bm, &x_nr, &q_nr, pos, ms);
            let chunk = DeformChunk {
                rows: range.clone(),
                nr,
                nr_out,
                x_nr,
                q_nr,
                blended,
            };
            (chunk, skin)
        })
        .unzip();
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
            skinning: SkinningCache::from_chunks(n, skin_chunks),
            skinning_chunks_are_standalone: rows == rows_per_chunk(&field.mlp, &field.mlp),
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
    /// ∂L/∂pose code (207 values: the non-rigid network's pose input).
    pub pose_code: Vec<T>,
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
    deform_gaussians_backward_with_moved(
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

/// [`deform_gaussians_backward`] with, when given, the cotangents `moved` of the moved Gaussians
/// from other posings of the same deformation ([`DeformCache::repose_backward`], summed) added to
/// those of this pass's own LBS, so that one network backward serves every posing. `bones` are this
/// pass's; ∂L/∂bones is for them alone. With `moved = None` it is [`deform_gaussians_backward`].
#[allow(clippy::too_many_arguments)]
pub fn deform_gaussians_backward_with_moved<T: Real>(
    nonrigid: &NonRigidNet<T>,
    field: &SkinningField<T>,
    bones: &[Affine<T>],
    cache: &DeformCache<T>,
    d_positions: &[[T; 3]],
    d_log_scales: &[[T; 3]],
    d_mats: &[Mat3<T>],
    d_features: &[T],
    moved: Option<&MovedCotangents<T>>,
    d_nonrigid: &mut [T],
    d_field: &mut [T],
) -> Result<DeformGrad<T>, nn::NnError> {
    let n = cache.n;
    if let Some(m) = moved {
        m.check(n)?;
    }
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
        for (c, skin) in cache.chunks[group.clone()]
            .iter()
            .zip(&cache.skinning.chunks[group])
        {
            let r = c.rows.len();
            let off = c.rows.start - first;
            let d_x = &mut out.d_x[off..off + r];
            let d_q = &mut out.d_q[off..off + r];
            // LBS backward: ∂L/∂T per row (rows × 12), ∂L/∂x_nr, ∂L/∂q_nr; then ∂L/∂w (rows × 24)
            // = ∂L/∂T · bonesᵀ and ∂L/∂bones (24 × 12) += wᵀ · ∂L/∂T.
            let d_t = grow(&mut buf.d_t, r * 12);
            lbs_chunk_backward_rows(
                &c.blended,
                &c.x_nr,
                &c.q_nr,
                &d_positions[c.rows.clone()],
                &d_mats[c.rows.clone()],
                d_t,
                d_x,
                d_q,
            );
            let d_w = grow(&mut buf.d_w, r * NUM_JOINTS);
            lbs_chunk_backward_blend(r, d_t, &bm, &skin.weights, d_w, &mut out.d_bones);
            if let Some(m) = moved {
                // Cotangents of other posings of the same moved Gaussians (re-posings).
                for k in 0..r {
                    let i = c.rows.start + k;
                    for a in 0..3 {
                        d_x[k][a] = d_x[k][a] + m.positions[i][a];
                    }
                    for a in 0..4 {
                        d_q[k][a] = d_q[k][a] + m.quats[i][a];
                    }
                    for b in 0..NUM_JOINTS {
                        d_w[k * NUM_JOINTS + b] =
                            d_w[k * NUM_JOINTS + b] + m.weights[i * NUM_JOINTS + b];
                    }
                }
            }
            // Skinning field at x_nr.
            let mut d_x_field = std::mem::take(&mut buf.d_x_field);
            let d_w_owned = std::mem::take(&mut buf.d_w);
            let mut d_nr_out = std::mem::take(&mut buf.d_nr_out);
            grow(&mut d_x_field, r);
            field.chunk_backward(
                skin,
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
    let pose_code = nonrigid.pose_code_grad(&d_folded);
    let bones_grad = d_bones_flat
        .chunks_exact(12)
        .map(|c| c.try_into().expect("12 values per bone"))
        .collect();
    Ok(DeformGrad {
        positions,
        log_scales: d_log_scales.to_vec(),
        quats,
        bones: bones_grad,
        pose_code,
    })
}

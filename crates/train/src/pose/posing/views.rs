//! The human colour network's view directions: each human Gaussian's direction from the camera,
//! carried into the canonical frame by its skinning-weighted bone rotation, and the backward of
//! that map (to the deformed positions, the skinning weights and the bones' rotations).

use nn::Real;
use rayon::prelude::*;
use smpl_deform::math::Affine;

/// The human Gaussians' view directions in the canonical frame, d = Rᵀ (x_def − c) with
/// R = Σ_b w_b R_b (the skinning-weighted bone rotation), and the v = x_def − c and R the backward
/// needs.
#[derive(Clone, Debug)]
pub(super) struct CanonicalViews<T> {
    pub directions: Vec<[T; 3]>,
    pub world: Vec<[T; 3]>,
    pub rotations: Vec<[T; 9]>,
}

/// [`CanonicalViews`] of the Gaussians at `positions` seen from the camera centre `c`, with
/// skinning weights `weights` (row per Gaussian, one column per bone of `bones`).
pub(super) fn canonical_view_directions<T: Real>(
    bones: &[Affine<T>],
    c: [T; 3],
    positions: &[[T; 3]],
    weights: &[T],
) -> CanonicalViews<T> {
    let nb = bones.len();
    // Row by row in parallel (each row its own).
    let rows: Vec<([T; 3], [T; 3], [T; 9])> = positions
        .par_iter()
        .enumerate()
        .map(|(i, x)| {
            let v = [0, 1, 2].map(|a| x[a] - c[a]);
            let mut r = [T::zero(); 9];
            for (b, bone) in bones.iter().enumerate() {
                let w = weights[i * nb + b];
                for row in 0..3 {
                    for col in 0..3 {
                        r[row * 3 + col] = r[row * 3 + col] + w * bone[row * 4 + col];
                    }
                }
            }
            let d = [0, 1, 2]
                .map(|col| (0..3).fold(T::zero(), |acc, row| acc + r[row * 3 + col] * v[row]));
            (d, v, r)
        })
        .collect();
    CanonicalViews {
        directions: rows.iter().map(|row| row.0).collect(),
        world: rows.iter().map(|row| row.1).collect(),
        rotations: rows.iter().map(|row| row.2).collect(),
    }
}

/// Backward of [`canonical_view_directions`]: d = Rᵀ v with v = x_def − c and R = Σ_b w_b R_b, so
/// dv = R dd (added to `d_x_def`), dR[row][col] = v[row]·dd[col], dw_b = ⟨dR, R_b⟩ and
/// dR_b += w_b dR. Returns ∂L/∂ the skinning weights (row per Gaussian) and ∂L/∂ each bone's
/// rotation (row-major 3×3). `views` holds the forward's v and R (its directions are not read);
/// `weights` are the forward's.
#[allow(clippy::type_complexity)]
pub(super) fn view_directions_backward<T: Real>(
    bones: &[Affine<T>],
    views: &CanonicalViews<T>,
    weights: &[T],
    d_directions: &[[T; 3]],
    d_x_def: &mut [[T; 3]],
) -> (Vec<T>, Vec<[T; 9]>) {
    let nb = bones.len();
    let na = views.world.len();
    let mut d_direction_weights = vec![T::zero(); na * nb];
    // Row by row in parallel: dv, dR and the row's weight gradients.
    let d_r: Vec<[T; 9]> = d_x_def[..na]
        .par_iter_mut()
        .zip(d_direction_weights.par_chunks_mut(nb.max(1)))
        .enumerate()
        .map(|(a, (dx, dw_row))| {
            let dd = d_directions[a];
            let v = views.world[a];
            let r = &views.rotations[a];
            for ax in 0..3 {
                let dv = (0..3).fold(T::zero(), |acc, col| acc + r[ax * 3 + col] * dd[col]);
                dx[ax] = dx[ax] + dv;
            }
            let d_r: [T; 9] = std::array::from_fn(|e| v[e / 3] * dd[e % 3]);
            for (dw, bone) in dw_row.iter_mut().zip(bones) {
                let mut acc = T::zero();
                for e in 0..9 {
                    acc = acc + d_r[e] * bone[(e / 3) * 4 + e % 3];
                }
                *dw = acc;
            }
            d_r
        })
        .collect();
    // dR_b = Σ_a w_ab dR_a, each sum over the rows in order (bone by bone in parallel).
    let d_bone_rotations = (0..nb)
        .into_par_iter()
        .map(|b| {
            let mut acc = [T::zero(); 9];
            for (a, d_r) in d_r.iter().enumerate() {
                let w = weights[a * nb + b];
                for e in 0..9 {
                    acc[e] = acc[e] + w * d_r[e];
                }
            }
            acc
        })
        .collect();
    (d_direction_weights, d_bone_rotations)
}

//! The human colour network's view directions: each human Gaussian's direction from the camera,
//! carried into the canonical frame by its skinning-weighted bone rotation, and the backward of
//! that map (to the deformed positions, the skinning weights and the bones' rotations).

use nn::Real;
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
    let mut world = Vec::with_capacity(positions.len());
    let mut rotations = Vec::with_capacity(positions.len());
    let directions = positions
        .iter()
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
            world.push(v);
            rotations.push(r);
            [0, 1, 2].map(|col| (0..3).fold(T::zero(), |acc, row| acc + r[row * 3 + col] * v[row]))
        })
        .collect();
    CanonicalViews {
        directions,
        world,
        rotations,
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
    let mut d_bone_rotations = vec![[T::zero(); 9]; nb];
    for a in 0..na {
        let dd = d_directions[a];
        let v = views.world[a];
        let r = &views.rotations[a];
        for ax in 0..3 {
            let dv = (0..3).fold(T::zero(), |acc, col| acc + r[ax * 3 + col] * dd[col]);
            d_x_def[a][ax] = d_x_def[a][ax] + dv;
        }
        let d_r: [T; 9] = std::array::from_fn(|e| v[e / 3] * dd[e % 3]);
        for (b, bone) in bones.iter().enumerate() {
            let w = weights[a * nb + b];
            let mut dw = T::zero();
            for e in 0..9 {
                dw = dw + d_r[e] * bone[(e / 3) * 4 + e % 3];
                d_bone_rotations[b][e] = d_bone_rotations[b][e] + w * d_r[e];
            }
            d_direction_weights[a * nb + b] = dw;
        }
    }
    (d_direction_weights, d_bone_rotations)
}

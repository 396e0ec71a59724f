//! Pose blend shapes (SMPL `posedirs`) and posing a body's vertices in generic precision, with the
//! backward pass w.r.t. the pose (through both the skinning transforms and the pose blend shapes)
//! and the translation — what pose refinement needs, and what the f64 finite-difference checks use.
//!
//! Same function as [`crate::BodyModel::pose`] (which stays f32, in displacement form, so the zero
//! pose reproduces the rest mesh bit for bit): `v' = Σ_b w_vb A_b [v_rest + P_v · f(pose); 1]`
//! with `f = (R_j − I)` of joints 1..23, row-major (207 values), and `A_b` the skinning transforms of
//! [`forward_kinematics`]. Shape blend shapes and the joint regressor are inputs already applied
//! (betas are constants here). This module must never read files.

use num_traits::Float;

use crate::fk::{forward_kinematics, forward_kinematics_backward, FkGradients, FkOutput};
use crate::math::{rodrigues_backward, Affine, Mat3};
use crate::skeleton::{NUM_JOINTS, NUM_POSE_FEATURES};

/// The pose-blend-shape feature `R_j − I` of joints 1..23 (207 values, row-major per joint).
pub fn pose_feature_of<T: Float>(local_rotations: &[Mat3<T>]) -> Vec<T> {
    let mut out = Vec::with_capacity(NUM_POSE_FEATURES);
    for r in local_rotations.iter().skip(1) {
        for (k, &x) in r.iter().enumerate() {
            out.push(if k % 4 == 0 { x - T::one() } else { x });
        }
    }
    out
}

/// Backward of the pose feature composed with Rodrigues: `∂L/∂pose` (3 per joint, joint 0 zero)
/// from `∂L/∂feature` (207).
pub fn pose_feature_backward<T: Float>(pose: &[T], d_feature: &[T]) -> Vec<T> {
    let mut d_pose = vec![T::zero(); 3 * NUM_JOINTS];
    for j in 1..NUM_JOINTS {
        let mut d_r = [T::zero(); 9];
        d_r.copy_from_slice(&d_feature[9 * (j - 1)..9 * j]);
        let g = rodrigues_backward([pose[3 * j], pose[3 * j + 1], pose[3 * j + 2]], &d_r);
        d_pose[3 * j..3 * j + 3].copy_from_slice(&g);
    }
    d_pose
}

/// Pose-blend-shape offsets `Δv[v][c] = Σ_k posedirs[(3v + c)·207 + k] · feature[k]` (metres) for
/// `posedirs` `(V, 3, 207)` row-major.
pub fn pose_blend_offsets<T: Float>(posedirs: &[f32], feature: &[T]) -> Vec<[T; 3]> {
    posedirs
        .chunks_exact(3 * NUM_POSE_FEATURES)
        .map(|v| {
            [0, 1, 2].map(|c| {
                v[c * NUM_POSE_FEATURES..(c + 1) * NUM_POSE_FEATURES]
                    .iter()
                    .zip(feature)
                    .fold(T::zero(), |acc, (&d, &f)| {
                        acc + T::from(d).unwrap_or_else(T::nan) * f
                    })
            })
        })
        .collect()
}

/// Backward of [`pose_blend_offsets`]: `∂L/∂feature` (207) from `∂L/∂offsets`.
pub fn pose_blend_offsets_backward<T: Float>(posedirs: &[f32], d_offsets: &[[T; 3]]) -> Vec<T> {
    let mut d_feature = vec![T::zero(); NUM_POSE_FEATURES];
    for (v, d) in posedirs.chunks_exact(3 * NUM_POSE_FEATURES).zip(d_offsets) {
        for c in 0..3 {
            let row = &v[c * NUM_POSE_FEATURES..(c + 1) * NUM_POSE_FEATURES];
            for (g, &p) in d_feature.iter_mut().zip(row) {
                *g = *g + T::from(p).unwrap_or_else(T::nan) * d[c];
            }
        }
    }
    d_feature
}

/// A body prepared for posing in precision `T` (shape blend shapes already applied).
#[derive(Clone, Copy, Debug)]
pub struct PosingBody<'a, T> {
    /// Shaped rest vertices (metres).
    pub shaped: &'a [[T; 3]],
    /// Rest joints of the shaped body (metres).
    pub joints_rest: &'a [[T; 3]],
    /// Parent of each joint (`None` for the root), parents first.
    pub parents: &'a [Option<usize>],
    /// Skinning weights `(V, 24)` row-major.
    pub weights: &'a [f32],
    /// Pose blend shapes `(V, 3, 207)` row-major, if any.
    pub posedirs: Option<&'a [f32]>,
}

/// What [`pose_vertices_backward`] needs from [`pose_vertices`].
#[derive(Clone, Debug)]
pub struct PosingCache<T> {
    /// Forward kinematics of the pose.
    pub fk: FkOutput<T>,
    /// Rest vertices with the pose blend shapes applied (metres).
    pub rest: Vec<[T; 3]>,
}

/// Posed vertices `v' = Σ_b w_vb A_b [v_rest + Δv(pose); 1]` (metres) and the cache.
///
/// # Panics
/// If the slices' lengths disagree (`pose` 72 values, one weight row per vertex; programming errors,
/// [`crate::BodyModel`] validates its arrays).
pub fn pose_vertices<T: Float>(
    body: &PosingBody<'_, T>,
    pose: &[T],
    transl: [T; 3],
) -> (Vec<[T; 3]>, PosingCache<T>) {
    let nv = body.shaped.len();
    assert_eq!(
        body.weights.len(),
        nv * NUM_JOINTS,
        "weights must be (V, 24)"
    );
    let fk = forward_kinematics(pose, transl, body.joints_rest, body.parents);
    let mut rest = body.shaped.to_vec();
    if let Some(pd) = body.posedirs {
        assert_eq!(
            pd.len(),
            nv * 3 * NUM_POSE_FEATURES,
            "posedirs must be (V, 3, 207)"
        );
        let offsets = pose_blend_offsets(pd, &pose_feature_of(&fk.local_rotations));
        for (r, o) in rest.iter_mut().zip(&offsets) {
            for c in 0..3 {
                r[c] = r[c] + o[c];
            }
        }
    }
    let vertices = rest
        .iter()
        .enumerate()
        .map(|(v, x)| {
            let t = blend(
                &body.weights[v * NUM_JOINTS..(v + 1) * NUM_JOINTS],
                &fk.posed_from_rest,
            );
            [0, 1, 2]
                .map(|r| t[4 * r] * x[0] + t[4 * r + 1] * x[1] + t[4 * r + 2] * x[2] + t[4 * r + 3])
        })
        .collect();
    (vertices, PosingCache { fk, rest })
}

fn blend<T: Float>(w: &[f32], bones: &[Affine<T>]) -> Affine<T> {
    let mut t = [T::zero(); 12];
    for (&wb, a) in w.iter().zip(bones) {
        if wb != 0.0 {
            let wb = T::from(wb).unwrap_or_else(T::nan);
            for k in 0..12 {
                t[k] = t[k] + wb * a[k];
            }
        }
    }
    t
}

/// Backward of [`pose_vertices`]: `∂L/∂pose` (72, through the skinning transforms and the pose
/// blend shapes) and `∂L/∂transl` from `∂L/∂vertices`.
pub fn pose_vertices_backward<T: Float>(
    body: &PosingBody<'_, T>,
    pose: &[T],
    cache: &PosingCache<T>,
    d_vertices: &[[T; 3]],
) -> FkGradients<T> {
    let mut d_bones = vec![[T::zero(); 12]; NUM_JOINTS];
    let mut d_rest = Vec::with_capacity(d_vertices.len());
    for (v, (x, d)) in cache.rest.iter().zip(d_vertices).enumerate() {
        let w = &body.weights[v * NUM_JOINTS..(v + 1) * NUM_JOINTS];
        for (b, &wb) in w.iter().enumerate() {
            if wb == 0.0 {
                continue;
            }
            let wb = T::from(wb).unwrap_or_else(T::nan);
            for r in 0..3 {
                let g = wb * d[r];
                d_bones[b][4 * r] = d_bones[b][4 * r] + g * x[0];
                d_bones[b][4 * r + 1] = d_bones[b][4 * r + 1] + g * x[1];
                d_bones[b][4 * r + 2] = d_bones[b][4 * r + 2] + g * x[2];
                d_bones[b][4 * r + 3] = d_bones[b][4 * r + 3] + g;
            }
        }
        let t = blend(w, &cache.fk.posed_from_rest);
        d_rest.push([0, 1, 2].map(|c| t[c] * d[0] + t[4 + c] * d[1] + t[8 + c] * d[2]));
    }
    let mut grads = forward_kinematics_backward(
        pose,
        body.joints_rest,
        body.parents,
        &cache.fk,
        &d_bones,
        None,
    );
    if let Some(pd) = body.posedirs {
        let d_feature = pose_blend_offsets_backward(pd, &d_rest);
        for (g, b) in grads
            .pose
            .iter_mut()
            .zip(pose_feature_backward(pose, &d_feature))
        {
            *g = *g + b;
        }
    }
    grads
}

//! What a canonical-space model consumes of one frame's SMPL pose — the per-bone transforms from the
//! canonical space to the frame and the pose code — in generic precision, with the backward pass to
//! the pose and translation (what learned pose correction differentiates).
//!
//! `frame_from_canonical_b = posed_from_rest_b(pose, transl) · rest_from_canonical_b` (see
//! [`crate::canonical`]); the pose code is `R_j − I` of joints 1..23 (see
//! [`crate::deform_net::pose_code`]). Rest joints and the canonical inverses are constants.

use num_traits::Float;

use crate::fk::{forward_kinematics, forward_kinematics_backward, FkGradients, FkOutput};
use crate::math::{affine_mul, affine_rot, affine_trans, Affine};
use crate::pose_blend::{pose_feature_backward, pose_feature_of};

/// A frame's pose as a canonical-space model consumes it.
#[derive(Clone, Debug)]
pub struct FramePose<T> {
    /// `frame_from_canonical` per bone (row-major 3×4).
    pub bones: Vec<Affine<T>>,
    /// The pose code `R_j − I` of joints 1..23 (207 values).
    pub pose_code: Vec<T>,
    /// The forward kinematics it was computed from (kept for the backward pass).
    pub fk: FkOutput<T>,
}

/// The bones and pose code of axis-angle `pose` (3 per joint, radians) and translation `transl`
/// (metres) for a body with rest joints `joints_rest`, `parents` and canonical inverses
/// `rest_from_canonical` (one per joint).
///
/// # Panics
/// If the lengths disagree (programming errors, as [`forward_kinematics`]).
pub fn frame_pose<T: Float>(
    pose: &[T],
    transl: [T; 3],
    joints_rest: &[[T; 3]],
    parents: &[Option<usize>],
    rest_from_canonical: &[Affine<T>],
) -> FramePose<T> {
    assert_eq!(
        rest_from_canonical.len(),
        joints_rest.len(),
        "one canonical inverse per joint"
    );
    let fk = forward_kinematics(pose, transl, joints_rest, parents);
    let bones = fk
        .posed_from_rest
        .iter()
        .zip(rest_from_canonical)
        .map(|(p, inv)| affine_mul(p, inv))
        .collect();
    FramePose {
        bones,
        pose_code: pose_feature_of(&fk.local_rotations),
        fk,
    }
}

/// Backward of [`frame_pose`]: `∂L/∂pose` and `∂L/∂transl` from `∂L/∂bones` (one 3×4 per bone) and
/// `∂L/∂pose_code` (207 values, or empty when the code is not differentiated).
pub fn frame_pose_backward<T: Float>(
    pose: &[T],
    joints_rest: &[[T; 3]],
    parents: &[Option<usize>],
    rest_from_canonical: &[Affine<T>],
    frame: &FramePose<T>,
    d_bones: &[Affine<T>],
    d_pose_code: &[T],
) -> FkGradients<T> {
    // F = P · C (affine): F_R = P_R C_R, F_t = P_R C_t + P_t, so
    // ∂L/∂P_R = ∂L/∂F_R C_Rᵀ + ∂L/∂F_t C_tᵀ and ∂L/∂P_t = ∂L/∂F_t.
    let d_posed_from_rest: Vec<Affine<T>> = d_bones
        .iter()
        .zip(rest_from_canonical)
        .map(|(d, c)| {
            let (c_r, c_t) = (affine_rot(c), affine_trans(c));
            let mut out = [T::zero(); 12];
            for row in 0..3 {
                for col in 0..3 {
                    let mut acc = d[4 * row + 3] * c_t[col];
                    for k in 0..3 {
                        acc = acc + d[4 * row + k] * c_r[3 * col + k];
                    }
                    out[4 * row + col] = acc;
                }
                out[4 * row + 3] = d[4 * row + 3];
            }
            out
        })
        .collect();
    let mut grads = forward_kinematics_backward(
        pose,
        joints_rest,
        parents,
        &frame.fk,
        &d_posed_from_rest,
        None,
    );
    if !d_pose_code.is_empty() {
        for (g, c) in grads
            .pose
            .iter_mut()
            .zip(pose_feature_backward(pose, d_pose_code))
        {
            *g = *g + c;
        }
    }
    grads
}

//! Forward kinematics along a kinematic tree, from axis-angle joint rotations to the skinning
//! transforms of linear blend skinning, with the analytic backward pass w.r.t. pose and translation.
//!
//! Conventions (those of SMPL/smplx): `pose` holds 3 axis-angle numbers per joint, joint 0 being the
//! global orientation about the root joint; joint `j` rotates about its rest position `J_j`; the
//! translation is added last. The skinning transform of bone `j` maps a rest-pose point to its posed
//! position, `posed_from_rest_j = G_j · [I | −J_j]`, where `G_j` is the joint's world transform.
//! It is computed by the equivalent recursion `A_j = A_parent · [R_j | (I − R_j) J_j]`, which yields
//! exactly `[I | 0]` for a zero pose (no round-off), so the zero pose reproduces the rest mesh bit for
//! bit. Parents must precede children (validated by the body model).

use num_traits::Float;

use crate::math::{
    affine_apply, affine_from_t, affine_rot, affine_trans, mat3_mul, mat3_mul_t, mat3_tmul,
    mat3_tvec, mat3_vec, rodrigues, rodrigues_backward, Affine, Mat3,
};

/// Result of [`forward_kinematics`].
#[derive(Clone, Debug)]
pub struct FkOutput<T> {
    /// Local rotation matrix of each joint (Rodrigues of its axis-angle), row-major.
    pub local_rotations: Vec<Mat3<T>>,
    /// Skinning transforms `posed_from_rest` per bone (translation included), row-major 3×4.
    pub posed_from_rest: Vec<Affine<T>>,
    /// Posed joint positions (metres), translation included.
    pub joints_posed: Vec<[T; 3]>,
}

/// Forward kinematics. `pose`: 3·J axis-angle values (radians); `transl`: global translation
/// (metres); `joints_rest`: J rest joint positions (metres); `parents`: parent of each joint
/// (`None` for the root, parents before children).
///
/// # Panics
/// If `pose.len() != 3 · joints_rest.len()` or `parents.len() != joints_rest.len()` (programming
/// errors; user input is validated by [`crate::BodyModel::pose`]).
pub fn forward_kinematics<T: Float>(
    pose: &[T],
    transl: [T; 3],
    joints_rest: &[[T; 3]],
    parents: &[Option<usize>],
) -> FkOutput<T> {
    let nj = joints_rest.len();
    assert_eq!(pose.len(), 3 * nj, "pose must hold 3 values per joint");
    assert_eq!(parents.len(), nj, "one parent per joint");
    let mut local_rotations = Vec::with_capacity(nj);
    let mut posed_from_rest: Vec<Affine<T>> = Vec::with_capacity(nj);
    for j in 0..nj {
        let r = rodrigues([pose[3 * j], pose[3 * j + 1], pose[3 * j + 2]]);
        let jr = joints_rest[j];
        let rj = mat3_vec(&r, jr);
        // Local transform about the joint: [R | (I − R) J].
        let t_local = [jr[0] - rj[0], jr[1] - rj[1], jr[2] - rj[2]];
        let a = match parents[j] {
            None => affine_from_t(
                &r,
                [
                    t_local[0] + transl[0],
                    t_local[1] + transl[1],
                    t_local[2] + transl[2],
                ],
            ),
            Some(p) => {
                let ap = &posed_from_rest[p];
                let rp = affine_rot(ap);
                affine_from_t(&mat3_mul(&rp, &r), affine_apply(ap, t_local))
            }
        };
        local_rotations.push(r);
        posed_from_rest.push(a);
    }
    let joints_posed = (0..nj)
        .map(|j| affine_apply(&posed_from_rest[j], joints_rest[j]))
        .collect();
    FkOutput {
        local_rotations,
        posed_from_rest,
        joints_posed,
    }
}

/// Gradients of [`forward_kinematics`] outputs w.r.t. its inputs.
#[derive(Clone, Debug)]
pub struct FkGradients<T> {
    /// ∂L/∂pose, 3 per joint.
    pub pose: Vec<T>,
    /// ∂L/∂transl.
    pub transl: [T; 3],
}

/// Backward of [`forward_kinematics`]: given `∂L/∂posed_from_rest` (row-major 3×4 per bone) and
/// optionally `∂L/∂joints_posed`, returns `∂L/∂pose` and `∂L/∂transl` (rest joints are constants).
pub fn forward_kinematics_backward<T: Float>(
    pose: &[T],
    joints_rest: &[[T; 3]],
    parents: &[Option<usize>],
    fk: &FkOutput<T>,
    d_posed_from_rest: &[Affine<T>],
    d_joints_posed: Option<&[[T; 3]]>,
) -> FkGradients<T> {
    let nj = joints_rest.len();
    let mut d_a: Vec<Affine<T>> = d_posed_from_rest.to_vec();
    if let Some(dj) = d_joints_posed {
        // J'_j = R_Aj J_j + t_Aj.
        for j in 0..nj {
            let jr = joints_rest[j];
            for row in 0..3 {
                for col in 0..3 {
                    d_a[j][4 * row + col] = d_a[j][4 * row + col] + dj[j][row] * jr[col];
                }
                d_a[j][4 * row + 3] = d_a[j][4 * row + 3] + dj[j][row];
            }
        }
    }
    let mut d_pose = vec![T::zero(); 3 * nj];
    let mut d_transl = [T::zero(); 3];
    for j in (0..nj).rev() {
        let r = fk.local_rotations[j];
        let jr = joints_rest[j];
        let d_ra = affine_rot(&d_a[j]);
        let d_ta = affine_trans(&d_a[j]);
        let (d_r, d_tlocal) = match parents[j] {
            None => {
                d_transl = d_ta;
                (d_ra, d_ta)
            }
            Some(p) => {
                let ap = fk.posed_from_rest[p];
                let rp = affine_rot(&ap);
                let rj = mat3_vec(&r, jr);
                let t_local = [jr[0] - rj[0], jr[1] - rj[1], jr[2] - rj[2]];
                // R_Aj = R_Ap R_j, t_Aj = R_Ap t_local + t_Ap.
                let d_rp_from_r = mat3_mul_t(&d_ra, &r);
                for row in 0..3 {
                    for col in 0..3 {
                        d_a[p][4 * row + col] = d_a[p][4 * row + col]
                            + d_rp_from_r[3 * row + col]
                            + d_ta[row] * t_local[col];
                    }
                    d_a[p][4 * row + 3] = d_a[p][4 * row + 3] + d_ta[row];
                }
                (mat3_tmul(&rp, &d_ra), mat3_tvec(&rp, d_ta))
            }
        };
        // t_local = J − R J  ⇒  ∂L/∂R −= d_tlocal Jᵀ.
        let mut d_r_total = d_r;
        for row in 0..3 {
            for col in 0..3 {
                d_r_total[3 * row + col] = d_r_total[3 * row + col] - d_tlocal[row] * jr[col];
            }
        }
        let g = rodrigues_backward([pose[3 * j], pose[3 * j + 1], pose[3 * j + 2]], &d_r_total);
        d_pose[3 * j..3 * j + 3].copy_from_slice(&g);
    }
    FkGradients {
        pose: d_pose,
        transl: d_transl,
    }
}

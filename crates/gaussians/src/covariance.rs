//! 3D covariance of a Gaussian from its stored parameters, Σ = R S Sᵀ Rᵀ, and its analytic backward.
//!
//! Parameters are the stored (pre-activation) ones of the INRIA 3DGS layout: log-scales (natural log of
//! metres) and an unnormalised quaternion (w, x, y, z) that is normalised on use. Everything is generic
//! over [`num_traits::Float`] so that hot loops run in f32 and gradient checks in f64. This module must
//! never allocate: it is called per Gaussian inside the rasterizer's projection loop.

use num_traits::Float;

/// A 3×3 matrix as rows: `m[row][col]`.
pub type Mat3<T> = [[T; 3]; 3];

/// Normalises a (w, x, y, z) quaternion. A zero quaternion has no direction: it maps to the identity
/// (1, 0, 0, 0) so rendering stays finite; loaders reject zero quaternions before they get here.
#[inline]
pub fn normalize_quat<T: Float>(q: [T; 4]) -> [T; 4] {
    let n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
    if n2 > T::zero() {
        let inv = n2.sqrt().recip();
        [q[0] * inv, q[1] * inv, q[2] * inv, q[3] * inv]
    } else {
        [T::one(), T::zero(), T::zero(), T::zero()]
    }
}

/// Rotation matrix of a unit (w, x, y, z) quaternion (no normalisation here; see [`rotation_from_quat`]).
#[inline]
pub fn rotation_from_unit_quat<T: Float>(q: [T; 4]) -> Mat3<T> {
    let [w, x, y, z] = q;
    let one = T::one();
    let two = one + one;
    [
        [
            one - two * (y * y + z * z),
            two * (x * y - w * z),
            two * (x * z + w * y),
        ],
        [
            two * (x * y + w * z),
            one - two * (x * x + z * z),
            two * (y * z - w * x),
        ],
        [
            two * (x * z - w * y),
            two * (y * z + w * x),
            one - two * (x * x + y * y),
        ],
    ]
}

/// Rotation matrix of an unnormalised (w, x, y, z) quaternion, normalising it first.
#[inline]
pub fn rotation_from_quat<T: Float>(q: [T; 4]) -> Mat3<T> {
    rotation_from_unit_quat(normalize_quat(q))
}

/// Backward of [`rotation_from_quat`]: given dL/dR (full 3×3), returns dL/dq for the *unnormalised*
/// quaternion, including the normalisation's Jacobian. Returns zero for a zero quaternion.
#[inline]
pub fn rotation_from_quat_backward<T: Float>(q: [T; 4], d_rot: &Mat3<T>) -> [T; 4] {
    let n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
    if n2 <= T::zero() {
        return [T::zero(); 4];
    }
    let n = n2.sqrt();
    let [w, x, y, z] = [q[0] / n, q[1] / n, q[2] / n, q[3] / n];
    let g = d_rot;
    let two = T::one() + T::one();
    let four = two + two;
    // dL/d(unit quaternion), from the partial derivatives of each entry of R.
    let dw =
        two * (-z * g[0][1] + y * g[0][2] + z * g[1][0] - x * g[1][2] - y * g[2][0] + x * g[2][1]);
    let dx = two
        * (y * g[0][1] + z * g[0][2] + y * g[1][0] - w * g[1][2] + z * g[2][0] + w * g[2][1])
        - four * (x * g[1][1] + x * g[2][2]);
    let dy = two
        * (x * g[0][1] + w * g[0][2] + x * g[1][0] + z * g[1][2] - w * g[2][0] + z * g[2][1])
        - four * (y * g[0][0] + y * g[2][2]);
    let dz = two
        * (-w * g[0][1] + x * g[0][2] + w * g[1][0] + y * g[1][2] + x * g[2][0] + y * g[2][1])
        - four * (z * g[0][0] + z * g[1][1]);
    // Through the normalisation q̂ = q/|q|: dq = (dq̂ − q̂ (q̂·dq̂)) / |q|.
    let dot = w * dw + x * dx + y * dy + z * dz;
    [
        (dw - w * dot) / n,
        (dx - x * dot) / n,
        (dy - y * dot) / n,
        (dz - z * dot) / n,
    ]
}

/// R (from the normalised quaternion), the scales s = exp(log-scale) and M = R·diag(s).
#[inline]
fn scaled_rotation<T: Float>(log_scale: [T; 3], quat: [T; 4]) -> (Mat3<T>, [T; 3], Mat3<T>) {
    let r = rotation_from_quat(quat);
    let s = log_scale.map(T::exp);
    let mut m = [[T::zero(); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = r[i][j] * s[j];
        }
    }
    (r, s, m)
}

/// World-space covariance Σ = R S Sᵀ Rᵀ (m²) from log-scales (ln m) and an unnormalised (w, x, y, z)
/// quaternion. The result is symmetric positive semi-definite.
#[inline]
pub fn covariance_3d<T: Float>(log_scale: [T; 3], quat: [T; 4]) -> Mat3<T> {
    let (_, _, m) = scaled_rotation(log_scale, quat);
    // Σ = M Mᵀ.
    let mut cov = [[T::zero(); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            cov[i][j] = m[i][0] * m[j][0] + m[i][1] * m[j][1] + m[i][2] * m[j][2];
        }
    }
    cov
}

/// Backward of [`covariance_3d`]. `d_cov` is dL/dΣ with the nine entries of Σ treated as independent
/// variables (a caller holding a gradient w.r.t. the six unique entries must spread each off-diagonal
/// gradient over both symmetric entries). Returns (dL/d log-scale, dL/d unnormalised quaternion).
#[inline]
pub fn covariance_3d_backward<T: Float>(
    log_scale: [T; 3],
    quat: [T; 4],
    d_cov: &Mat3<T>,
) -> ([T; 3], [T; 4]) {
    let (r, s, m) = scaled_rotation(log_scale, quat);
    // Σ = M Mᵀ  ⇒  dL/dM = (G + Gᵀ) M.
    let mut d_m = [[T::zero(); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let mut acc = T::zero();
            for k in 0..3 {
                acc = acc + (d_cov[i][k] + d_cov[k][i]) * m[k][j];
            }
            d_m[i][j] = acc;
        }
    }
    // M_ij = R_ij s_j.
    let mut d_rot = [[T::zero(); 3]; 3];
    let mut d_log_scale = [T::zero(); 3];
    for j in 0..3 {
        let mut d_s = T::zero();
        for i in 0..3 {
            d_rot[i][j] = d_m[i][j] * s[j];
            d_s = d_s + d_m[i][j] * r[i][j];
        }
        d_log_scale[j] = d_s * s[j];
    }
    (d_log_scale, rotation_from_quat_backward(quat, &d_rot))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_quaternion_gives_diagonal_covariance() {
        let cov = covariance_3d([0.0f64, 1.0f64.ln(), 2.0f64.ln()], [2.0, 0.0, 0.0, 0.0]);
        let expected = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 4.0]];
        for i in 0..3 {
            for j in 0..3 {
                assert!((cov[i][j] - expected[i][j]).abs() < 1e-12, "{cov:?}");
            }
        }
    }

    #[test]
    fn rotation_is_orthonormal_with_unit_determinant() {
        let r = rotation_from_quat([0.3f64, -1.2, 0.7, 2.0]);
        for i in 0..3 {
            for j in 0..3 {
                let dot: f64 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 1e-12);
            }
        }
        let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
            - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
        assert!((det - 1.0).abs() < 1e-12);
    }

    #[test]
    fn zero_quaternion_maps_to_identity() {
        let r = rotation_from_quat([0.0f32; 4]);
        assert_eq!(r, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
    }
}

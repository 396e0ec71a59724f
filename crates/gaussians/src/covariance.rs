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

/// Inverse of [`covariance_3d`] for a symmetric positive semi-definite Σ: log-scales and a unit
/// (w, x, y, z) quaternion with R diag(e^{2s}) Rᵀ = Σ (cyclic Jacobi eigen-decomposition in f64; the
/// rotation is made proper, det R = +1). Eigenvalues are floored at `min_variance` (m²) so the
/// log-scales stay finite. Used to export posed Gaussians whose covariance is not built from a stored
/// scale and rotation (skinning blends rotations into a general linear map).
pub fn decompose_covariance(sigma: &Mat3<f64>, min_variance: f64) -> ([f32; 3], [f32; 4]) {
    let mut a = *sigma;
    // Symmetrise (callers may pass a matrix with rounding asymmetry).
    for r in 0..3 {
        for c in r + 1..3 {
            let m = 0.5 * (a[r][c] + a[c][r]);
            a[r][c] = m;
            a[c][r] = m;
        }
    }
    let (_, mut v) = symmetric_eigen(&mut a);
    let det = v[0][0] * (v[1][1] * v[2][2] - v[1][2] * v[2][1])
        - v[0][1] * (v[1][0] * v[2][2] - v[1][2] * v[2][0])
        + v[0][2] * (v[1][0] * v[2][1] - v[1][1] * v[2][0]);
    if det < 0.0 {
        for row in &mut v {
            row[2] = -row[2];
        }
    }
    let log_scales = [0, 1, 2].map(|k| (0.5 * a[k][k].max(min_variance).ln()) as f32);
    (log_scales, quat_from_rotation(&v).map(|x| x as f32))
}

/// Eigen-decomposition of a symmetric N × N matrix by cyclic Jacobi rotations (at most 50 sweeps,
/// until the off-diagonal magnitude is below 1e-15 of the diagonal's): `a` is left with the
/// eigenvalues on its diagonal, which are also returned, with the matrix whose columns are the
/// eigenvectors (orthonormal; its determinant may be −1).
pub fn symmetric_eigen<const N: usize>(a: &mut [[f64; N]; N]) -> ([f64; N], [[f64; N]; N]) {
    let mut v = [[0.0f64; N]; N];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _sweep in 0..50 {
        let mut off = 0.0;
        for p in 0..N {
            for q in p + 1..N {
                off += a[p][q].abs();
            }
        }
        let scale = (0..N).fold(0.0, |acc, k| acc + a[k][k].abs());
        if off <= 1e-15 * f64::max(scale, f64::MIN_POSITIVE) {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                if a[p][q] == 0.0 {
                    continue;
                }
                // A ← Jᵀ A J with J the rotation in the (p, q) plane that zeroes a[p][q]; V ← V J.
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..N {
                    let (akp, akq) = (a[k][p], a[k][q]);
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..N {
                    let (apk, aqk) = (a[p][k], a[q][k]);
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in v.iter_mut() {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
    }
    (std::array::from_fn(|k| a[k][k]), v)
}

/// Unit (w, x, y, z) quaternion of a proper rotation matrix (Shepperd's method; w ≥ 0).
pub fn quat_from_rotation(r: &Mat3<f64>) -> [f64; 4] {
    let tr = r[0][0] + r[1][1] + r[2][2];
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0;
        [
            0.25 * s,
            (r[2][1] - r[1][2]) / s,
            (r[0][2] - r[2][0]) / s,
            (r[1][0] - r[0][1]) / s,
        ]
    } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
        let s = (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt() * 2.0;
        [
            (r[2][1] - r[1][2]) / s,
            0.25 * s,
            (r[0][1] + r[1][0]) / s,
            (r[0][2] + r[2][0]) / s,
        ]
    } else if r[1][1] > r[2][2] {
        let s = (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt() * 2.0;
        [
            (r[0][2] - r[2][0]) / s,
            (r[0][1] + r[1][0]) / s,
            0.25 * s,
            (r[1][2] + r[2][1]) / s,
        ]
    } else {
        let s = (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt() * 2.0;
        [
            (r[1][0] - r[0][1]) / s,
            (r[0][2] + r[2][0]) / s,
            (r[1][2] + r[2][1]) / s,
            0.25 * s,
        ]
    };
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
    q.map(|x| sign * x / n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

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

    #[test]
    fn decompose_inverts_covariance_3d() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut r = || rng.gen_range(-1.0..1.0);
        for _ in 0..200 {
            let s = [r() * 2.0 - 3.0, r() * 2.0 - 3.0, r() * 2.0 - 3.0];
            let q = [r(), r(), r(), r()];
            let sigma = covariance_3d(s, q);
            let (s2, q2) = decompose_covariance(&sigma, 1e-30);
            let back = covariance_3d(s2.map(f64::from), q2.map(f64::from));
            let norm: f64 = sigma.iter().flatten().map(|v| v * v).sum::<f64>().sqrt();
            for (a, b) in sigma.iter().flatten().zip(back.iter().flatten()) {
                assert!((a - b).abs() <= 1e-5 * norm, "{sigma:?} vs {back:?}");
            }
        }
    }
}

//! Small generic (f32/f64) rotation math with analytic backward passes: Rodrigues' formula for
//! axis-angle vectors, unnormalised quaternions to rotation matrices, and 3×3 / 3×4 helpers.
//!
//! Matrices are plain row-major arrays: `Mat3<T> = [T; 9]`, `Affine<T> = [T; 12]` (a 3×4 `[R | t]`).
//! Everything is generic over [`num_traits::Float`] so that the f64 instantiation can be checked by
//! finite differences while the f32 one runs in hot loops. Nothing here allocates.

use num_traits::Float;

/// Row-major 3×3 matrix.
pub type Mat3<T> = [T; 9];
/// Row-major 3×4 rigid/affine transform `[R | t]`: `y = R x + t`.
pub type Affine<T> = [T; 12];

/// Converts an f64 constant into `T` (exact for f64, rounded for f32).
#[inline]
pub fn lit<T: Float>(x: f64) -> T {
    T::from(x).unwrap_or_else(T::nan)
}

/// The identity matrix.
#[inline]
pub fn mat3_identity<T: Float>() -> Mat3<T> {
    let (o, z) = (T::one(), T::zero());
    [o, z, z, z, o, z, z, z, o]
}

/// `a · b` for 3×3 matrices.
#[inline]
pub fn mat3_mul<T: Float>(a: &Mat3<T>, b: &Mat3<T>) -> Mat3<T> {
    let mut c = [T::zero(); 9];
    for i in 0..3 {
        for j in 0..3 {
            c[3 * i + j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j];
        }
    }
    c
}

/// `aᵀ · b` for 3×3 matrices.
#[inline]
pub fn mat3_tmul<T: Float>(a: &Mat3<T>, b: &Mat3<T>) -> Mat3<T> {
    let mut c = [T::zero(); 9];
    for i in 0..3 {
        for j in 0..3 {
            c[3 * i + j] = a[i] * b[j] + a[3 + i] * b[3 + j] + a[6 + i] * b[6 + j];
        }
    }
    c
}

/// `a · bᵀ` for 3×3 matrices.
#[inline]
pub fn mat3_mul_t<T: Float>(a: &Mat3<T>, b: &Mat3<T>) -> Mat3<T> {
    let mut c = [T::zero(); 9];
    for i in 0..3 {
        for j in 0..3 {
            c[3 * i + j] =
                a[3 * i] * b[3 * j] + a[3 * i + 1] * b[3 * j + 1] + a[3 * i + 2] * b[3 * j + 2];
        }
    }
    c
}

/// `m · v`.
#[inline]
pub fn mat3_vec<T: Float>(m: &Mat3<T>, v: [T; 3]) -> [T; 3] {
    [
        m[0] * v[0] + m[1] * v[1] + m[2] * v[2],
        m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
        m[6] * v[0] + m[7] * v[1] + m[8] * v[2],
    ]
}

/// `mᵀ · v`.
#[inline]
pub fn mat3_tvec<T: Float>(m: &Mat3<T>, v: [T; 3]) -> [T; 3] {
    [
        m[0] * v[0] + m[3] * v[1] + m[6] * v[2],
        m[1] * v[0] + m[4] * v[1] + m[7] * v[2],
        m[2] * v[0] + m[5] * v[1] + m[8] * v[2],
    ]
}

/// Frobenius inner product `⟨a, b⟩ = Σ a_ij b_ij`.
#[inline]
pub fn mat3_dot<T: Float>(a: &Mat3<T>, b: &Mat3<T>) -> T {
    let mut s = T::zero();
    for k in 0..9 {
        s = s + a[k] * b[k];
    }
    s
}

/// The rotation block of an affine transform.
#[inline]
pub fn affine_rot<T: Float>(a: &Affine<T>) -> Mat3<T> {
    [a[0], a[1], a[2], a[4], a[5], a[6], a[8], a[9], a[10]]
}

/// The translation column of an affine transform.
#[inline]
pub fn affine_trans<T: Float>(a: &Affine<T>) -> [T; 3] {
    [a[3], a[7], a[11]]
}

/// Builds `[r | t]` (generic).
#[inline]
pub fn affine_from_t<T: Float>(r: &Mat3<T>, t: [T; 3]) -> Affine<T> {
    [
        r[0], r[1], r[2], t[0], r[3], r[4], r[5], t[1], r[6], r[7], r[8], t[2],
    ]
}

/// Applies `[R | t]` to a point: `R x + t`.
#[inline]
pub fn affine_apply<T: Float>(a: &Affine<T>, x: [T; 3]) -> [T; 3] {
    [
        a[0] * x[0] + a[1] * x[1] + a[2] * x[2] + a[3],
        a[4] * x[0] + a[5] * x[1] + a[6] * x[2] + a[7],
        a[8] * x[0] + a[9] * x[1] + a[10] * x[2] + a[11],
    ]
}

/// Composition `a ∘ b` (apply `b` first).
#[inline]
pub fn affine_mul<T: Float>(a: &Affine<T>, b: &Affine<T>) -> Affine<T> {
    let r = mat3_mul(&affine_rot(a), &affine_rot(b));
    let t = affine_apply(a, affine_trans(b));
    affine_from_t(&r, t)
}

/// Inverse of an affine transform with an invertible linear part (rigid transforms in practice:
/// uses the general 3×3 inverse, so it is also right for scaled transforms).
pub fn affine_inverse<T: Float>(a: &Affine<T>) -> Affine<T> {
    let m = affine_rot(a);
    let det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6])
        + m[2] * (m[3] * m[7] - m[4] * m[6]);
    let inv_det = T::one() / det;
    let inv = [
        (m[4] * m[8] - m[5] * m[7]) * inv_det,
        (m[2] * m[7] - m[1] * m[8]) * inv_det,
        (m[1] * m[5] - m[2] * m[4]) * inv_det,
        (m[5] * m[6] - m[3] * m[8]) * inv_det,
        (m[0] * m[8] - m[2] * m[6]) * inv_det,
        (m[2] * m[3] - m[0] * m[5]) * inv_det,
        (m[3] * m[7] - m[4] * m[6]) * inv_det,
        (m[1] * m[6] - m[0] * m[7]) * inv_det,
        (m[0] * m[4] - m[1] * m[3]) * inv_det,
    ];
    let t = mat3_vec(&inv, affine_trans(a));
    affine_from_t(&inv, [-t[0], -t[1], -t[2]])
}

/// Skew-symmetric cross-product matrix `[v]×` with `[v]× u = v × u`.
#[inline]
pub fn hat<T: Float>(v: [T; 3]) -> Mat3<T> {
    let z = T::zero();
    [z, -v[2], v[1], v[2], z, -v[0], -v[1], v[0], z]
}

/// Coefficients of Rodrigues' formula as functions of `s = θ²`:
/// `a = sin θ / θ`, `b = (1 − cos θ) / θ²` and their derivatives `da/ds`, `db/ds`.
///
/// Below `s < 5·ε^{1/4}` (ε = machine epsilon: ≈0.09 for f32, ≈6e-4 for f64) a 4-term Taylor series is
/// used, where the closed forms lose digits to cancellation; the crossover balances the Taylor
/// truncation error (~s⁴/9!) against the cancellation error (~ε/s) of the derivatives.
fn rodrigues_coeffs<T: Float>(s: T) -> (T, T, T, T) {
    let threshold = lit::<T>(5.0) * T::epsilon().sqrt().sqrt();
    if s < threshold {
        let a = T::one() - s / lit(6.0) + s * s / lit(120.0) - s * s * s / lit(5040.0);
        let b = lit::<T>(0.5) - s / lit(24.0) + s * s / lit(720.0) - s * s * s / lit(40320.0);
        let da =
            lit::<T>(-1.0 / 6.0) + s / lit(60.0) - s * s / lit(1680.0) + s * s * s / lit(90720.0);
        let db = lit::<T>(-1.0 / 24.0) + s / lit(360.0) - s * s / lit(13440.0)
            + s * s * s / lit(907200.0);
        (a, b, da, db)
    } else {
        let th = s.sqrt();
        let (sn, cs) = th.sin_cos();
        let a = sn / th;
        let b = (T::one() - cs) / s;
        let two = lit::<T>(2.0);
        let da = (th * cs - sn) / (two * s * th);
        let db = (th * sn - two * (T::one() - cs)) / (two * s * s);
        (a, b, da, db)
    }
}

/// Rotation matrix of an axis-angle vector `r` (axis · angle in radians) by Rodrigues' formula
/// `R = I + a [r]× + b [r]×²` with `a = sin θ/θ`, `b = (1 − cos θ)/θ²`, `θ = |r|`.
/// Stable at and near zero (Taylor series); exactly the identity for `r = 0`.
pub fn rodrigues<T: Float>(r: [T; 3]) -> Mat3<T> {
    let s = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
    let (a, b, _, _) = rodrigues_coeffs(s);
    let k = hat(r);
    let k2 = mat3_mul(&k, &k);
    let mut m = mat3_identity::<T>();
    for i in 0..9 {
        m[i] = m[i] + a * k[i] + b * k2[i];
    }
    m
}

/// Backward of [`rodrigues`]: given `d_rot = ∂L/∂R` (row-major), returns `∂L/∂r`.
pub fn rodrigues_backward<T: Float>(r: [T; 3], d_rot: &Mat3<T>) -> [T; 3] {
    let s = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
    let (a, b, da, db) = rodrigues_coeffs(s);
    let k = hat(r);
    let k2 = mat3_mul(&k, &k);
    let g_k = mat3_dot(d_rot, &k);
    let g_k2 = mat3_dot(d_rot, &k2);
    let two = lit::<T>(2.0);
    let mut out = [T::zero(); 3];
    for i in 0..3 {
        let mut e = [T::zero(); 3];
        e[i] = T::one();
        let ei = hat(e);
        let ek = mat3_mul(&ei, &k);
        let ke = mat3_mul(&k, &ei);
        let mut sym = [T::zero(); 9];
        for q in 0..9 {
            sym[q] = ek[q] + ke[q];
        }
        out[i] = two * r[i] * (da * g_k + db * g_k2)
            + a * mat3_dot(d_rot, &ei)
            + b * mat3_dot(d_rot, &sym);
    }
    out
}

/// Rotation matrix of a quaternion `(w, x, y, z)`, stored unnormalised and normalised here
/// (the workspace convention), in this module's flat row-major layout. The math is
/// `gaussians::covariance::rotation_from_quat` (a zero quaternion gives the identity).
pub fn quat_to_mat3<T: Float>(q: [T; 4]) -> Mat3<T> {
    let r = gaussians::covariance::rotation_from_quat(q);
    [
        r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2],
    ]
}

/// Backward of [`quat_to_mat3`] including the normalisation: `∂L/∂q` from `∂L/∂R`
/// (`gaussians::covariance::rotation_from_quat_backward`).
pub fn quat_to_mat3_backward<T: Float>(q: [T; 4], d_rot: &Mat3<T>) -> [T; 4] {
    let g = [
        [d_rot[0], d_rot[1], d_rot[2]],
        [d_rot[3], d_rot[4], d_rot[5]],
        [d_rot[6], d_rot[7], d_rot[8]],
    ];
    gaussians::covariance::rotation_from_quat_backward(q, &g)
}
